//! How fine a grid of calibration targets may be (issue 37: `--grid
//! 100000,100000` ran out of memory): a limit from the sensor, and the
//! positions' memory against what the machine has free.

use super::make::{MakeError, PlannedTarget, TARGET_EDGE_PX, TARGET_INSET};
use crate::limits::{check_fits, Bytes};

/// The most targets [`target_layout`](super::make::target_layout) puts
/// across a sensor side of `side` px: neighbours at least a pixel apart
/// within the inset sensor. Closer, two targets land in one pixel: the
/// grid asks for positions the sensor cannot tell apart (and a grid of
/// 10⁵ × 10⁵ allocated until memory ran out).
pub fn max_targets_across(side: u32) -> u32 {
    let side_px = f64::from(side);
    let inset = (TARGET_INSET * side_px)
        .max(TARGET_EDGE_PX)
        .min(0.5 * side_px);
    (side_px - 2.0 * inset).floor().max(1.0) as u32 + 1
}

/// Refuses a `grid` of more targets across or down than
/// [`max_targets_across`], or whose positions (`levels` heights of them)
/// are more than memory holds, before any is laid out.
pub(super) fn check_grid(
    grid: (u32, u32),
    levels: usize,
    width: u32,
    height: u32,
) -> Result<(), MakeError> {
    let (nx, ny) = grid;
    let (mx, my) = (max_targets_across(width), max_targets_across(height));
    let bad = |problem: String| MakeError::Grid { nx, ny, problem };
    // Each position is kept, then printed as a TOML stanza of about 160 B.
    let each = (std::mem::size_of::<PlannedTarget>() + 160) as u64;
    let count = u64::from(nx) * u64::from(ny) * levels as u64;
    if nx > mx || ny > my {
        return Err(bad(format!(
            "at most {mx},{my} on this {width}x{height} px sensor (neighbouring targets a \
             pixel apart or more inside the larger of a {TARGET_EDGE_PX} px and a {} % inset: \
             closer, two land in one pixel); {count} targets would need {} of memory",
            TARGET_INSET * 100.0,
            Bytes(count.saturating_mul(each))
        )));
    }
    check_fits(&format!("{count} targets"), count, each).map_err(|e| bad(e.to_string()))
}
