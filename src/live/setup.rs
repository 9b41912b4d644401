//! What a live acquisition was begun with, kept beside its manifest in
//! `recording.toml` so that `--resume` can refuse to append frames that do
//! not fit: the whole schedule, the station file's SHA-256, the camera and
//! its settings (bit depth, exposure, gain, region, frame rate).
//!
//! The spec's manifest (`mfd-acquisition/1`) allows no extra field, so this
//! is a side file of the recorder's own (`mfd-recording/1`), not part of
//! the interchange format: other tools may ignore it.

use std::path::Path;

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use crate::acquire::acquisition::AcquisitionError;
use crate::acquire::camera::{CameraConfig, CameraInfo};
use crate::acquire::patterns::Pattern;

/// Name of the side file beside the manifest.
pub const RECORDING_FILE: &str = "recording.toml";

/// Format tag of [`RECORDING_FILE`].
pub const RECORDING_FORMAT: &str = "mfd-recording/1";

/// The settings an acquisition was begun with.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RecordingSetup {
    /// Must be [`RECORDING_FORMAT`].
    pub format: String,
    /// SHA-256 (hex) of the station file's bytes.
    pub station_sha256: String,
    /// Camera backend (`sim`, `aravis`, `v4l`).
    pub camera_backend: String,
    /// Camera id.
    pub camera_id: String,
    /// Vendor and model.
    pub camera_model: String,
    /// Significant bits per sample asked for (`None`: the device's own).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bit_depth: Option<u8>,
    /// Exposure asked for, µs (`None`: the device's own).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exposure_us: Option<f64>,
    /// Gain asked for, dB (`None`: the device's own).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gain_db: Option<f64>,
    /// Region of interest `[x, y, width, height]` (`None`: the whole sensor).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub region: Option<[u32; 4]>,
    /// Free-running frame rate asked for, frames/s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frame_rate_hz: Option<f64>,
    /// Every pattern of the schedule, `[direction_deg, tau, phase_rad]`,
    /// in display order.
    pub patterns: Vec<[f64; 3]>,
}

/// One setting that differs between a recording and its resume.
#[derive(Debug, Clone, PartialEq)]
pub struct Mismatch {
    /// The setting.
    pub what: &'static str,
    /// The value the recording holds.
    pub held: String,
    /// The value given now.
    pub given: String,
}

/// SHA-256 of `bytes`, lower-case hex.
pub fn sha256_hex(bytes: &[u8]) -> String {
    Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

fn show<T: std::fmt::Debug>(v: &Option<T>, none: &str) -> String {
    v.as_ref()
        .map_or_else(|| none.to_string(), |v| format!("{v:?}"))
}

impl RecordingSetup {
    /// The setup of a recording of `patterns` on `camera` configured with
    /// `config`, from a station file of SHA-256 `station_sha256`.
    pub fn new(
        station_sha256: &str,
        camera: &CameraInfo,
        config: &CameraConfig,
        patterns: &[Pattern],
    ) -> Self {
        RecordingSetup {
            format: RECORDING_FORMAT.to_string(),
            station_sha256: station_sha256.to_string(),
            camera_backend: camera.backend.to_string(),
            camera_id: camera.id.clone(),
            camera_model: camera.model.clone(),
            bit_depth: config.pixel_format.map(|f| f.bit_depth()),
            exposure_us: config.exposure_us,
            gain_db: config.gain_db,
            region: config.region.map(|r| [r.x, r.y, r.width, r.height]),
            frame_rate_hz: config.frame_rate_hz,
            patterns: patterns
                .iter()
                .map(|p| [p.direction_deg, p.tau, p.phase_rad])
                .collect(),
        }
    }

    /// Writes `dir/recording.toml` (atomically: temporary file and rename).
    ///
    /// # Errors
    /// [`AcquisitionError::Io`] or [`AcquisitionError::Serialize`] naming the file.
    pub fn write(&self, dir: &Path) -> Result<(), AcquisitionError> {
        let path = dir.join(RECORDING_FILE);
        let body = toml::to_string(self).map_err(|source| AcquisitionError::Serialize {
            path: path.clone(),
            source,
        })?;
        let text = format!(
            "# what this acquisition was begun with; `mfd measure --resume` checks it\n{body}"
        );
        let tmp = dir.join(format!("{RECORDING_FILE}.tmp"));
        let io = |path: &Path| {
            let path = path.to_path_buf();
            move |source| AcquisitionError::Io { path, source }
        };
        std::fs::write(&tmp, text).map_err(io(&tmp))?;
        std::fs::rename(&tmp, &path).map_err(io(&path))
    }

    /// Reads `dir/recording.toml`; `None` when there is none (an
    /// acquisition begun before it was written).
    ///
    /// # Errors
    /// [`AcquisitionError::Io`], [`AcquisitionError::Parse`] or
    /// [`AcquisitionError::Invalid`] (another format) naming the file.
    pub fn read(dir: &Path) -> Result<Option<Self>, AcquisitionError> {
        let path = dir.join(RECORDING_FILE);
        let text = match std::fs::read_to_string(&path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(source) => return Err(AcquisitionError::Io { path, source }),
        };
        let setup: RecordingSetup =
            toml::from_str(&text).map_err(|source| AcquisitionError::Parse {
                path: path.clone(),
                source,
            })?;
        if setup.format != RECORDING_FORMAT {
            return Err(AcquisitionError::Invalid {
                path,
                field: "format".into(),
                problem: format!("\"{}\", expected \"{RECORDING_FORMAT}\"", setup.format),
            });
        }
        Ok(Some(setup))
    }

    /// Every setting in which `given` differs from `self` (the held one),
    /// in a fixed order; empty when they agree.
    pub fn mismatches(&self, given: &RecordingSetup) -> Vec<Mismatch> {
        let mut out = Vec::new();
        let mut differ = |what: &'static str, held: String, now: String| {
            if held != now {
                out.push(Mismatch {
                    what,
                    held,
                    given: now,
                });
            }
        };
        differ(
            "schedule",
            self.schedule_text(given),
            given.schedule_text(self),
        );
        differ(
            "station (SHA-256 of the file)",
            self.station_sha256.clone(),
            given.station_sha256.clone(),
        );
        let camera = |s: &RecordingSetup| {
            format!("{} {} ({})", s.camera_backend, s.camera_id, s.camera_model)
        };
        differ("camera", camera(self), camera(given));
        let device = "the device's own";
        differ(
            "bit depth",
            show(&self.bit_depth, device),
            show(&given.bit_depth, device),
        );
        let value = |v: &Option<f64>| show(v, device);
        differ(
            "exposure, µs",
            value(&self.exposure_us),
            value(&given.exposure_us),
        );
        differ("gain, dB", value(&self.gain_db), value(&given.gain_db));
        differ(
            "frame rate, frames/s",
            value(&self.frame_rate_hz),
            value(&given.frame_rate_hz),
        );
        differ(
            "region [x, y, width, height]",
            show(&self.region, "the whole sensor"),
            show(&given.region, "the whole sensor"),
        );
        out
    }

    /// The schedule as a mismatch shows it: its length and the first
    /// pattern that differs from `other`'s (bit for bit), or only the
    /// length when they agree.
    fn schedule_text(&self, other: &RecordingSetup) -> String {
        let n = self.patterns.len();
        let first = self
            .patterns
            .iter()
            .zip(&other.patterns)
            .position(|(a, b)| a.map(f64::to_bits) != b.map(f64::to_bits));
        match first {
            Some(k) => {
                let [d, t, p] = self.patterns[k];
                format!("{n} patterns, pattern {k} at {d}°, τ {t}, phase {p} rad")
            }
            None => format!("{n} patterns"),
        }
    }
}
