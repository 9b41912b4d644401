//! The records `summary.json` embeds that the stages above fill: what a
//! result was made from ([`Inputs`], also `inputs.json`) and the station
//! check ([`Consistency`]). Defined here so that `report` reads result
//! types, not pipeline internals; `pipeline` fills them (`InputFile::of`
//! and the check itself are in `pipeline::result_dir` and
//! `pipeline::consistency`).

use serde::{Deserialize, Serialize};

/// One input file, by path and content.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InputFile {
    /// The path as given.
    pub path: String,
    /// SHA-256 of the file's bytes, lower-case hex.
    pub sha256: String,
}

/// What a result was made from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Inputs {
    /// The acquisition folder; the digest is its manifest's (which lists
    /// every frame), beside the number of frames read.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub acquisition: Option<InputFile>,
    /// Frames read from the acquisition.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frames: Option<usize>,
    /// The screen points the surface stage started from (`--screen-coords`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub screen_coords: Option<InputFile>,
    /// The station file.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub station: Option<InputFile>,
    /// The station's uncertainty file, when one was used.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uncertainty: Option<InputFile>,
    /// The mfd version that made the result.
    pub mfd_version: String,
}

impl Default for Inputs {
    /// No inputs named yet, this version of mfd.
    fn default() -> Inputs {
        Inputs {
            acquisition: None,
            frames: None,
            screen_coords: None,
            station: None,
            uncertainty: None,
            mfd_version: env!("CARGO_PKG_VERSION").into(),
        }
    }
}

impl Inputs {
    /// No inputs named yet, this version of mfd.
    pub fn new() -> Inputs {
        Inputs::default()
    }
}

/// The station check in `summary.json` (`"consistency"`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Consistency {
    /// Whether the screen points agree with the station.
    pub consistent: bool,
    /// Whether the test was made (enough measured pixels).
    pub tested: bool,
    /// Pixels compared (with a measured front point and a predicted one).
    pub pixels: usize,
    /// Median displacement of the measured front points from the station's
    /// nominal-plate prediction, screen px (u, v); `null` when none was
    /// measured.
    pub median_displacement_px: Option<[f64; 2]>,
    /// The same for the back, where measured.
    pub median_back_displacement_px: Option<[f64; 2]>,
    /// The spread the surfaces and the station may cause, screen px.
    pub allowed_px: f64,
    /// Surface departure behind `allowed_px`, nm RMS defocus.
    pub max_departure_nm: f64,
    /// Pixels flagged far from the prediction.
    pub far_pixels: usize,
    /// Pixels flagged with a residual far above the noise.
    pub poor_fit_pixels: usize,
    /// The schedule's shortest alias spacing (the nearest false maximum of
    /// its ambiguity function over the screen, any direction), screen px;
    /// `null` when no direction has one on the screen.
    pub alias_spacing_px: Option<f64>,
    /// In words.
    pub note: String,
}
