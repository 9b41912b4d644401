//! Camera errors: what a caller handles differently gets its own variant.

use std::time::Duration;

/// What can go wrong with a camera.
#[derive(Debug, thiserror::Error)]
pub enum CameraError {
    /// No frame arrived in time; the device may still be there.
    #[error("camera {device}: no frame within {} ms", waited.as_millis())]
    Timeout {
        /// Device identifier.
        device: String,
        /// How long we waited.
        waited: Duration,
    },
    /// The device is gone (cable, power, driver); nothing more will come.
    #[error("camera {device}: disconnected: {problem}")]
    Disconnected {
        /// Device identifier.
        device: String,
        /// What the driver said.
        problem: String,
    },
    /// The backend was not compiled in.
    #[error("camera backend `{backend}`: not built; rebuild with `--features {feature}`")]
    NotBuilt {
        /// The backend asked for.
        backend: String,
        /// The cargo feature that builds it.
        feature: &'static str,
    },
    /// A setting was refused or is out of the device's range.
    #[error("camera {device}: setting `{field}`: {problem}")]
    Config {
        /// Device identifier.
        device: String,
        /// The setting (`exposure_us`, `gain_db`, `pixel_format`, `region`, ...).
        field: &'static str,
        /// What is wrong, with the allowed range where known.
        problem: String,
    },
    /// The device cannot do this.
    #[error("camera {device}: {what} is not supported by this device")]
    Unsupported {
        /// Device identifier.
        device: String,
        /// The capability.
        what: String,
    },
    /// A frame that cannot be used (wrong size, unknown pixel format, incomplete).
    #[error("camera {device}: frame {sequence}: {problem}")]
    BadFrame {
        /// Device identifier.
        device: String,
        /// The device's frame counter.
        sequence: u64,
        /// What is wrong.
        problem: String,
    },
    /// Any other device or driver failure.
    #[error("camera {device}: {problem}")]
    Device {
        /// Device identifier.
        device: String,
        /// What the driver said.
        problem: String,
    },
    /// The camera string does not name a backend.
    #[error("camera `{spec}`: {problem}")]
    BadSpec {
        /// The string given.
        spec: String,
        /// What is expected.
        problem: String,
    },
}

impl crate::outcome::Classify for CameraError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        use crate::outcome::Outcome;
        Some(match self {
            CameraError::NotBuilt { .. } => Outcome::Input,
            _ => Outcome::Device,
        })
    }
}
