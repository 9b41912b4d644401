//! An acquisition checked against the station it is reconstructed with:
//! what the manifest alone cannot know. Every τ must be one the station's
//! screen can show (the display's Nyquist limit,
//! [`FringeAxis::max_tau`](crate::acquire::patterns::FringeAxis::max_tau)):
//! beyond it the frames hold an alias of a coarser fringe, the spectral
//! stage's frequency grid grows with the largest τ (τ = 1e300 overflowed
//! its capacity, 1e9 exhausted memory, 1e4 ran for minutes) and a result
//! comes out wrong with a confident uncertainty (τ = 1000 on a 1600×1200
//! screen: a front error 4.5 times the reported one).

use super::{Acquisition, AcquisitionError};
use crate::acquire::patterns::first_beyond_screen;
use crate::optics::station::Station;

/// Checks `acq` against `station`: every frame's τ at most what the
/// station's screen can show in that frame's direction.
///
/// # Errors
/// [`AcquisitionError::Invalid`] naming the manifest, `frame[k].tau`, the
/// value and the allowed range.
pub fn check_against_station(acq: &Acquisition, station: &Station) -> Result<(), AcquisitionError> {
    let screen = &station.screen;
    let frames = acq.frames().iter().map(|f| (f.direction_deg, f.tau));
    match first_beyond_screen(frames, screen.width, screen.height) {
        None => Ok(()),
        Some((k, problem)) => Err(AcquisitionError::Invalid {
            path: acq.manifest_path().to_path_buf(),
            field: format!("frame[{}].tau", acq.frames()[k].index),
            problem,
        }),
    }
}
