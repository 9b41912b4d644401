//! After the acquisition: an interrupted one's exit, else the
//! reconstruction with `mfd reconstruct`'s stages, the result folder and
//! the report page.

use mfd::acquire::acquisition::Acquisition;
use mfd::live::{Measurement, Report};
use mfd::optics::station::Station;
use mfd::optics::trace::DEFAULT_EDGE_MARGIN_MM;
use mfd::pipeline::{self, find_station_uncertainty, Input, Options};

use super::MeasureArgs;

/// Ends the measurement: the interrupted error, or the reconstruction of
/// the recorded frames (unless `--no-reconstruct`) written with its report.
pub(super) fn finish(
    args: &MeasureArgs,
    input: &super::StationInput,
    report: &Report,
    measurement: &mut Measurement<'_>,
    acquire_s: f64,
    served: Option<&super::super::serve::Served>,
) -> anyhow::Result<()> {
    if report.interrupted {
        return Err(interrupted(args, report, measurement));
    }
    let Some(solver) = measurement.solver_mut() else {
        return Ok(());
    };
    let station = &input.station;
    let options = options(args, station)?;
    let mut fitting = |done: usize, total: usize| {
        if let Some(s) = served {
            s.fitting(done, total);
        }
    };
    // The streamed solver started from the station's wedge. The recording
    // says whether the back reflection lies there (the search reads a few
    // hundred pixels of it); where the frames show another wedge, the
    // points are fitted again from the recording with the wedge found, as
    // `mfd reconstruct` would, and where they show one that cannot be
    // measured the run is refused naming it (the recording stays).
    let dir = args.out.join("acquisition");
    let check = if options.skip_wedge_search {
        None
    } else {
        let acq = Acquisition::open(&dir)?;
        pipeline::wedge::check_wedge(&acq, &station.element_frame(), &options.spectral)?.1
    };
    let mut rec = if check.is_some_and(|c| c.used_found) {
        eprintln!(
            "the streamed points started from the station's wedge, which the frames do not \
             show: fitting them again from {}",
            dir.display()
        );
        let mut acq = Acquisition::open(&dir)?;
        pipeline::reconstruct(
            Input::Acquisition(&mut acq),
            station,
            &options,
            &mut fitting,
        )?
    } else {
        let mut rec =
            pipeline::reconstruct(Input::Streamed(solver), station, &options, &mut fitting)?;
        if let Some(s) = rec.spectral.as_mut() {
            s.wedge = check;
        }
        rec
    };
    if let Some(s) = rec.spectral.as_mut() {
        s.read_s = acquire_s;
        if let Some(served) = served {
            served.console.set_spectral(mfd::console::Spectral::Done {
                both_found: s.maps.found_both(),
                pixels: s.fitted_pixels,
            });
        }
    }
    let result = args.out.join("result");
    rec.inputs = Some(inputs(args, &input.sha256));
    super::super::output::write_and_print(&rec, &result, &args.checks)?;
    // The acquisition holds a copy of the station: the calibration is
    // where --station came from, if a calibration wrote it there (its
    // report.json); a station written by hand has none, and the report
    // refuses a --calibration folder that is not one.
    let options = mfd::report::page::ReportOptions {
        calibration: args
            .station
            .parent()
            .filter(|dir| dir.join("report.json").is_file())
            .map(std::path::Path::to_path_buf),
        ..Default::default()
    };
    let report = mfd::report::page::write(&result, None, &options)?;
    println!("wrote the report {}", report.display());
    Ok(())
}

/// The error of an acquisition the operator interrupted, after saying how
/// to go on.
fn interrupted(
    args: &MeasureArgs,
    report: &Report,
    measurement: &Measurement<'_>,
) -> anyhow::Error {
    println!(
        "interrupted: continue with `mfd measure ... --resume`, or reconstruct \
         what is there with `mfd reconstruct {}`",
        args.out.join("acquisition").display()
    );
    super::super::exit::classified(
        super::super::exit::Class::Interrupted,
        anyhow::anyhow!(
            "interrupted by the operator: {} of {} frames recorded in {}",
            measurement.recorded(),
            report.counters.total,
            measurement.dir().display()
        ),
    )
}

/// The reconstruction's options from the flags: the surfaces' (unless
/// `--no-surfaces`) with the station's uncertainty found for them, the
/// refined degrees of freedom, the estimator and the checks.
fn options(args: &MeasureArgs, station: &Station) -> anyhow::Result<Options> {
    let opts = args.surfaces.options(DEFAULT_EDGE_MARGIN_MM)?;
    let surfaces = (!args.surfaces.no_surfaces).then_some(opts);
    let station_uncertainty = match surfaces {
        Some(_) => {
            let found =
                find_station_uncertainty(&args.station, station, args.uncertainty.as_deref())?;
            super::super::output::print_uncertainty_source(found.as_ref(), &args.station);
            found.map(|f| f.uncertainty)
        }
        None => None,
    };
    let (estimator, max_expected_nm) = args.surfaces.estimator()?;
    let options = Options {
        surfaces,
        station_uncertainty,
        refine: args.refine.clone(),
        estimator,
        max_expected_nm,
        limits: args.checks.limits(),
        wavelength_nm: args.surfaces.wavelength_nm,
        skip_wedge_search: args.keep_station_wedge,
        ..Options::default()
    };
    Ok(options)
}

/// The result's inputs: the acquisition (its manifest's hash) and the
/// station (the digest of the bytes it was read from).
fn inputs(args: &MeasureArgs, station_sha256: &str) -> mfd::pipeline::Inputs {
    let mut inputs = mfd::pipeline::Inputs::new();
    let manifest = args
        .out
        .join("acquisition")
        .join(mfd::acquire::acquisition::MANIFEST);
    inputs.acquisition =
        mfd::pipeline::InputFile::of(&manifest)
            .ok()
            .map(|m| mfd::pipeline::InputFile {
                path: args.out.join("acquisition").display().to_string(),
                sha256: m.sha256,
            });
    inputs.station = Some(mfd::pipeline::InputFile {
        path: args.station.display().to_string(),
        sha256: station_sha256.to_string(),
    });
    inputs
}
