//! Sizes refused before they are allocated: what a request would need
//! against the memory the machine has free now. A command told to design
//! a billion frames, draw a billion stations or lay out a 10¹⁰-target grid
//! used to allocate until the kernel killed it (exit 134, issue 37); it is
//! refused up front instead, with the figure it would need.
//!
//! The memory free is `MemAvailable` of `/proc/meminfo` (Linux: what can
//! be allocated without swapping). Where that cannot be read (another
//! system, a sandbox without `/proc`) the fallback is
//! [`FALLBACK_AVAILABLE_BYTES`], 4 GiB: the full-sensor reconstruction's
//! own peak (docs/figures.md, 3.80 GiB), so a machine that runs mfd at all
//! has it, and a request above it is refused rather than risked.

use std::fmt;

/// Memory assumed free where `/proc/meminfo` cannot be read, bytes.
pub const FALLBACK_AVAILABLE_BYTES: u64 = 4 << 30;

/// Memory that can be allocated now, bytes, and where the figure comes from.
pub fn available_bytes() -> (u64, &'static str) {
    std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|text| mem_available(&text))
        .map_or(
            (
                FALLBACK_AVAILABLE_BYTES,
                "the 4 GiB assumed without /proc/meminfo",
            ),
            |b| (b, "MemAvailable in /proc/meminfo"),
        )
}

/// `MemAvailable` of a `/proc/meminfo` text, bytes (the file says kB,
/// meaning KiB).
fn mem_available(text: &str) -> Option<u64> {
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    kib.checked_mul(1024)
}

/// A size refused: what it was for, what it needs, what the machine has.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{what}: would need {} of memory, above the {} free ({source_of_free})", Bytes(*.need_bytes), Bytes(*.free_bytes))]
pub struct TooLarge {
    /// What was asked, e.g. `--monte-carlo 1000000000 (700 B per draw)`.
    pub what: String,
    /// What it would need, bytes (saturating).
    pub need_bytes: u64,
    /// What the machine has free, bytes.
    pub free_bytes: u64,
    /// Where the free figure comes from.
    pub source_of_free: &'static str,
}

impl crate::outcome::Classify for TooLarge {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        // A size asked for on the command line or by a file: the request
        // is at fault, not the machine.
        Some(crate::outcome::Outcome::Input)
    }
}

/// Refuses `count` items of `bytes_each` when together they exceed the
/// memory free now.
///
/// # Errors
/// [`TooLarge`] naming `what`, the need and the memory free.
pub fn check_fits(what: &str, count: u64, bytes_each: u64) -> Result<(), TooLarge> {
    let (free_bytes, source_of_free) = available_bytes();
    fits(
        what,
        count.saturating_mul(bytes_each),
        free_bytes,
        source_of_free,
    )
}

fn fits(
    what: &str,
    need_bytes: u64,
    free_bytes: u64,
    source_of_free: &'static str,
) -> Result<(), TooLarge> {
    if need_bytes <= free_bytes {
        return Ok(());
    }
    Err(TooLarge {
        what: what.to_string(),
        need_bytes,
        free_bytes,
        source_of_free,
    })
}

/// A byte count in the unit a reader takes in at a glance.
#[derive(Debug, Clone, Copy)]
pub struct Bytes(pub u64);

impl fmt::Display for Bytes {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let b = self.0 as f64;
        match self.0 {
            0..=9_999 => write!(f, "{} B", self.0),
            10_000..=9_999_999 => write!(f, "{:.1} kB", b / 1e3),
            10_000_000..=9_999_999_999 => write!(f, "{:.1} MB", b / 1e6),
            10_000_000_000..=9_999_999_999_999 => write!(f, "{:.1} GB", b / 1e9),
            _ => write!(f, "{:.1} TB", b / 1e12),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_mem_available_in_kib() {
        let text = "MemTotal:       24576000 kB\nMemFree:  100 kB\nMemAvailable:   2048 kB\n";
        assert_eq!(mem_available(text), Some(2048 * 1024));
        assert_eq!(mem_available("MemTotal: 5 kB\n"), None);
    }

    #[test]
    fn refuses_above_the_free_memory_naming_both_figures() {
        assert!(fits("x", 1000, 1000, "test").is_ok());
        let e = fits("--frames 5", 32_000_000_000, 1_000_000_000, "test").unwrap_err();
        assert_eq!(
            e.to_string(),
            "--frames 5: would need 32.0 GB of memory, above the 1000.0 MB free (test)"
        );
        // The machine this runs on has some memory free, and not 2^64 bytes.
        let (free, _) = available_bytes();
        assert!(free > 0 && check_fits("all", u64::MAX, 1).is_err());
    }
}
