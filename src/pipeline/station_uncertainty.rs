//! Where a reconstruction's station uncertainty comes from: the file the
//! operator names, else the `station_uncertainty.toml` a calibration writes
//! beside its `station.toml` (`calibration.md`, "What a calibration
//! writes"), else none (the geometry counts as exact). Whichever file it
//! is, its `station` field must name the station used.

use std::path::{Path, PathBuf};

use super::PipelineError;
use crate::optics::station::{Station, StationUncertainty};

/// The name a calibration gives the uncertainty beside its station file.
pub const STATION_UNCERTAINTY_FILE: &str = "station_uncertainty.toml";

/// How the uncertainty was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum UncertaintySource {
    /// Named by the operator (`--uncertainty`).
    Given,
    /// [`STATION_UNCERTAINTY_FILE`] beside the station file.
    BesideStation,
}

/// A station uncertainty, checked against the station it is used with.
#[derive(Debug, Clone)]
pub struct FoundUncertainty {
    /// The uncertainty.
    pub uncertainty: StationUncertainty,
    /// Its file.
    pub path: PathBuf,
    /// How it was found.
    pub source: UncertaintySource,
}

/// The station uncertainty for the station `station` read from
/// `station_path`: `given` when the operator names one, else
/// [`STATION_UNCERTAINTY_FILE`] beside `station_path` when it exists, else
/// `None`. Logs which (or that the geometry counts as exact).
///
/// The file's `station` field (relative to the file's folder) must be
/// `station_path`, or a file holding the same station.
///
/// # Errors
/// [`PipelineError::Uncertainty`] for an unreadable or invalid file,
/// [`PipelineError::UncertaintyOfAnotherStation`] when it names another
/// station.
pub fn find_station_uncertainty(
    station_path: &Path,
    station: &Station,
    given: Option<&Path>,
) -> Result<Option<FoundUncertainty>, PipelineError> {
    let (path, source) = match given {
        Some(p) => (p.to_path_buf(), UncertaintySource::Given),
        None => {
            let beside = station_path.with_file_name(STATION_UNCERTAINTY_FILE);
            if !beside.is_file() {
                log::info!(
                    "no station uncertainty given and no {STATION_UNCERTAINTY_FILE} beside {}: \
                     the station's geometry is taken as exact, the reported σ are the noise alone",
                    station_path.display()
                );
                return Ok(None);
            }
            (beside, UncertaintySource::BesideStation)
        }
    };
    let uncertainty = StationUncertainty::load(&path)?;
    check_names_station(&uncertainty, &path, station_path, station)?;
    let how = match source {
        UncertaintySource::Given => "as given",
        UncertaintySource::BesideStation => "found beside the station file",
    };
    log::info!(
        "station uncertainty from {} ({how}): {} degrees of freedom with a σ; every reported σ \
         includes the station's geometry",
        path.display(),
        uncertainty.names.len()
    );
    Ok(Some(FoundUncertainty {
        uncertainty,
        path,
        source,
    }))
}

/// Whether `uncertainty` (read from `path`) is that of `station_path`: its
/// `station` field, relative to `path`'s folder, is the same file, or a
/// file that holds the same station (a copy, as a simulation or an
/// acquisition keeps beside its frames).
fn check_names_station(
    uncertainty: &StationUncertainty,
    path: &Path,
    station_path: &Path,
    station: &Station,
) -> Result<(), PipelineError> {
    let dir = path.parent().unwrap_or(Path::new(""));
    let resolved = dir.join(&uncertainty.station);
    let same_file = match (resolved.canonicalize(), station_path.canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    };
    if same_file {
        return Ok(());
    }
    let same_station = Station::load(&resolved).is_ok_and(|s| &s == station);
    if same_station {
        log::info!(
            "{}: its station {} is not {} but holds the same station",
            path.display(),
            resolved.display(),
            station_path.display()
        );
        return Ok(());
    }
    Err(PipelineError::UncertaintyOfAnotherStation {
        uncertainty: path.to_path_buf(),
        named: uncertainty.station.clone(),
        resolved,
        station: station_path.to_path_buf(),
    })
}
