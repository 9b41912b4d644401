//! `surfaces.json` version 2 (`mfd-surfaces/2`, `interchange.md`): the
//! writer's files read back as written, version 1 is still read, every
//! rule of the reader is an error naming the file and the field; the
//! pipeline writes version 2 with the noise-only σ (and says the geometry
//! was taken as exact) or with the station's part included; and the
//! station uncertainty is found beside the station file and checked
//! against it.

use std::path::Path;

use mfd::formats::surfaces_file::{
    SurfaceCoefficients, SurfaceEntry, SurfacesFile, ZernikeSpec, SURFACES_FORMAT_V2,
};
use mfd::optics::station::{bench_station, Station};
use mfd::optics::trace::{Plate, TracedView, DEFAULT_EDGE_MARGIN_MM};
use mfd::pipeline::{
    self, find_station_uncertainty, Input, Options, PipelineError, PointUncertainty, ScreenPoints,
    UncertaintySource, STATION_UNCERTAINTY_FILE,
};
use mfd::report::summary::{Summary, UNCERTAINTY_NOISE_ONLY, UNCERTAINTY_WITH_STATION};
use mfd::sim::RandomSurfaceSpec;
use mfd::solve::surfaces::SurfaceOptions;

const V1: &str = r#"{"format": "mfd-surfaces/1",
    "zernike": {"ordering": "noll", "normalization": "rms", "radius_mm": 25.5, "center_mm": [0.0, 0.0]},
    "front": {"coefficients_nm": [0.0, 12.5, -3.1, 40.2]}, "back": null}"#;

/// The spec's version-2 example (front), and a back not reconstructed.
const V2: &str = r#"{"format": "mfd-surfaces/2",
    "zernike": {"ordering": "noll", "normalization": "rms", "radius_mm": 25.5, "center_mm": [0.0, 0.0]},
    "front": {"coefficients_nm": [0.0, 12.5, -3.1, 40.2],
              "std_nm": [0.0, 1.1, 1.0, 0.6],
              "expected_error_rms_nm": 1.9,
              "not_reconstructed_because": null},
    "back": {"coefficients_nm": null, "not_reconstructed_because": "no back reflection was measured"}}"#;

fn parse(text: &str) -> Result<SurfacesFile, String> {
    SurfacesFile::from_json_str(text, Path::new("dir/surfaces.json")).map_err(|e| e.to_string())
}

#[test]
fn version_2_round_trips_and_version_1_still_reads() {
    let f = parse(V2).unwrap();
    assert_eq!(f.format, SURFACES_FORMAT_V2);
    let front = f.front.coefficients().unwrap();
    assert_eq!(front.std_nm.as_deref(), Some(&[0.0, 1.1, 1.0, 0.6][..]));
    assert_eq!(front.expected_error_rms_nm, Some(1.9));
    assert_eq!(
        f.back,
        SurfaceEntry::NotReconstructed {
            because: Some("no back reflection was measured".into())
        }
    );
    assert!(f.back_coefficients().is_none());
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("s.json");
    f.save(&p).unwrap();
    assert_eq!(SurfacesFile::load(&p).unwrap(), f);
    // A reconstructed surface carries `"not_reconstructed_because": null`,
    // as the spec's example does.
    let text = std::fs::read_to_string(&p).unwrap();
    assert!(
        text.contains("\"not_reconstructed_because\": null"),
        "{text}"
    );

    let v1 = parse(V1).unwrap();
    assert_eq!(v1.front_coefficients().unwrap().len(), 4);
    assert!(v1.front.coefficients().unwrap().std_nm.is_none());
    assert!(v1.back.is_none());
    v1.save(&p).unwrap();
    let text = std::fs::read_to_string(&p).unwrap();
    assert!(
        !text.contains("std_nm") && !text.contains("not_reconstructed"),
        "{text}"
    );
    assert_eq!(SurfacesFile::load(&p).unwrap(), v1);
}

#[test]
fn each_rule_of_the_reader_names_the_file_and_field() {
    let cases = [
        // A field version 2 does not allow.
        (V2.replace("\"std_nm\"", "\"sigma_nm\""), "sigma_nm"),
        (
            V2.replace("\"back\": {", "\"extra\": 1, \"back\": {"),
            "extra",
        ),
        // σ of another length than the coefficients.
        (
            V2.replace("[0.0, 1.1, 1.0, 0.6]", "[0.0, 1.1, 1.0]"),
            "front.std_nm",
        ),
        // A negative σ, a negative expected error.
        (
            V2.replace("[0.0, 1.1, 1.0, 0.6]", "[0.0, 1.1, -1.0, 0.6]"),
            "front.std_nm[2]",
        ),
        (V2.replace("1.9", "-1.9"), "front.expected_error_rms_nm"),
        // Not reconstructed, but no reason; a reason beside coefficients;
        // σ for a surface that is not there.
        (
            V2.replace(
                ", \"not_reconstructed_because\": \"no back reflection was measured\"",
                "",
            ),
            "back.not_reconstructed_because",
        ),
        (
            V2.replace(
                "\"not_reconstructed_because\": null",
                "\"not_reconstructed_because\": \"x\"",
            ),
            "front.not_reconstructed_because",
        ),
        (
            V2.replace(
                "\"coefficients_nm\": null,",
                "\"coefficients_nm\": null, \"std_nm\": [1.0],",
            ),
            "back.std_nm",
        ),
        // Version 2's fields in a version-1 file; version 2's null surface.
        (
            V1.replace("40.2]}", "40.2], \"std_nm\": [0, 1, 1, 1]}"),
            "front.std_nm",
        ),
        (
            V1.replace("[0.0, 12.5, -3.1, 40.2]", "null"),
            "front.coefficients_nm",
        ),
        // Version 3 is the outline proposal (docs/proposals/outline.md).
        (V1.replace("mfd-surfaces/1", "mfd-surfaces/4"), "format"),
        (V1.replace("\"rms\"", "\"peak\""), "zernike.normalization"),
    ];
    for (text, field) in cases {
        let err = parse(&text).unwrap_err();
        assert!(
            err.contains("dir/surfaces.json") && err.contains(field),
            "{field}: {err}"
        );
    }
}

#[test]
fn the_writer_refuses_what_the_reader_would() {
    let mut f = parse(V2).unwrap();
    if let SurfaceEntry::Reconstructed(c) = &mut f.front {
        c.std_nm = Some(vec![1.0]);
    }
    let dir = tempfile::tempdir().unwrap();
    let err = f.save(&dir.path().join("s.json")).unwrap_err().to_string();
    assert!(err.contains("front.std_nm"), "{err}");
    assert!(!dir.path().join("s.json").exists());
}

/// The bench station's plate traced exactly: screen points with a stated
/// σ of 0.01 px for every coordinate.
fn traced_points(station: &Station) -> ScreenPoints {
    let spec = RandomSurfaceSpec {
        n_terms: 15,
        ..RandomSurfaceSpec::default()
    };
    let (front, back) = spec.draw_pair(25.5, [0.0, 0.0], 7).unwrap();
    let plate = Plate::new(station, front, back, DEFAULT_EDGE_MARGIN_MM);
    let coords = TracedView::trace(station, &plate).screen_coords();
    let std = vec![0.01; coords.len()];
    ScreenPoints {
        coords,
        uncertainty: PointUncertainty::Std(std),
    }
}

fn write_result(station: &Station, uncertainty: Option<&str>, out: &Path) -> Summary {
    let options = Options {
        surfaces: Some(SurfaceOptions {
            terms: Some(15),
            ..SurfaceOptions::default()
        }),
        station_uncertainty: uncertainty.map(|t| {
            mfd::optics::station::StationUncertainty::from_toml_str(t, Path::new("u.toml")).unwrap()
        }),
        ..Options::default()
    };
    let input = Input::ScreenPoints(traced_points(station));
    let rec = pipeline::reconstruct(input, station, &options, &mut |_, _| {}).unwrap();
    let written = rec.write(out).unwrap();
    assert!(written.contains(&out.join("uncertainty_breakdown.png")));
    let text = std::fs::read_to_string(out.join("summary.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

const UNCERTAINTY: &str = r#"
format = "mfd-station-uncertainty/1"
station = "station.toml"
[std]
"camera.z_mm" = 0.5
"screen.rx_deg" = 0.02
"element.thickness_mm" = 0.002
"#;

#[test]
fn the_pipeline_writes_version_2_with_what_the_sigma_include() {
    let station = bench_station(10.0, 1.5, 15.0).unwrap();
    let dir = tempfile::tempdir().unwrap();
    // Without a station uncertainty: the noise's σ, and the summary says so.
    let noise_dir = dir.path().join("noise");
    let summary = write_result(&station, None, &noise_dir);
    assert_eq!(summary.uncertainty_note, UNCERTAINTY_NOISE_ONLY);
    assert!(summary.station.is_none());
    let file = SurfacesFile::load(&noise_dir.join("surfaces.json")).unwrap();
    assert_eq!(file.format, SURFACES_FORMAT_V2);
    for (entry, figures) in [
        (&file.front, &summary.front),
        (&file.back, summary.back.as_ref().unwrap()),
    ] {
        let c = entry.coefficients().unwrap();
        assert_eq!(c.std_nm.as_ref().unwrap(), &figures.std_nm);
        assert_eq!(c.expected_error_rms_nm, Some(figures.error_rms_nm));
    }
    // With one: every σ at least the noise's, and the expected error
    // squared the sum of the noise's and the station's (independent parts,
    // RMS-normalised terms orthonormal).
    let with_dir = dir.path().join("with");
    let summary = write_result(&station, Some(UNCERTAINTY), &with_dir);
    assert_eq!(summary.uncertainty_note, UNCERTAINTY_WITH_STATION);
    let part = summary.station.as_ref().unwrap();
    assert_eq!(part.largest.len(), 3);
    let file = SurfacesFile::load(&with_dir.join("surfaces.json")).unwrap();
    for (entry, split) in [
        (&file.front, &part.front),
        (&file.back, part.back.as_ref().unwrap()),
    ] {
        let c = entry.coefficients().unwrap();
        let std = c.std_nm.as_ref().unwrap();
        assert_eq!(std, &split.total_std_nm);
        for (t, n) in std.iter().zip(&split.noise_std_nm) {
            assert!(
                *t >= *n * (1.0 - 1e-12),
                "total σ {t} below the noise's {n}"
            );
        }
        let e = c.expected_error_rms_nm.unwrap();
        let sum = split.noise_rms_nm.hypot(split.station_rms_nm);
        // Rounding of a sum of ~12 squares: 1e-12 relative.
        assert!((e - sum).abs() <= 1e-9 * sum, "{e} vs {sum}");
        assert!(split.station_rms_nm > 0.0);
    }
}

#[test]
fn the_uncertainty_is_found_beside_the_station_and_must_name_it() {
    let dir = tempfile::tempdir().unwrap();
    let station_path = dir.path().join("station.toml");
    bench_station(10.0, 1.5, 15.0)
        .unwrap()
        .save(&station_path)
        .unwrap();
    // As the command line has it: the station read from its file.
    let station = Station::load(&station_path).unwrap();
    // None beside it: geometry exact.
    assert!(find_station_uncertainty(&station_path, &station, None)
        .unwrap()
        .is_none());
    // The calibration's file beside it.
    let beside = dir.path().join(STATION_UNCERTAINTY_FILE);
    std::fs::write(&beside, UNCERTAINTY).unwrap();
    let found = find_station_uncertainty(&station_path, &station, None)
        .unwrap()
        .unwrap();
    assert_eq!(found.source, UncertaintySource::BesideStation);
    assert_eq!(found.uncertainty.names.len(), 3);
    // Given elsewhere, naming a copy of the same station: accepted.
    let other = tempfile::tempdir().unwrap();
    station.save(&other.path().join("station.toml")).unwrap();
    let given = other.path().join("u.toml");
    std::fs::write(&given, UNCERTAINTY).unwrap();
    let found = find_station_uncertainty(&station_path, &station, Some(&given))
        .unwrap()
        .unwrap();
    assert_eq!(found.source, UncertaintySource::Given);
    // Naming another station: an error naming both files.
    let thicker = bench_station(12.0, 1.5, 15.0).unwrap();
    thicker.save(&other.path().join("station.toml")).unwrap();
    let err = find_station_uncertainty(&station_path, &station, Some(&given)).unwrap_err();
    assert!(matches!(
        err,
        PipelineError::UncertaintyOfAnotherStation { .. }
    ));
    let text = err.to_string();
    assert!(
        text.contains("u.toml") && text.contains(station_path.to_str().unwrap()),
        "{text}"
    );
    // Naming a file that is not there: the same error.
    std::fs::write(&given, UNCERTAINTY.replace("station.toml", "gone.toml")).unwrap();
    assert!(find_station_uncertainty(&station_path, &station, Some(&given)).is_err());
}

/// The v2 constructor's basis block is the surface's.
#[test]
fn zernike_block_of_a_basis() {
    let b = mfd::optics::zernike::ZernikeBasis::new(4, 25.5, [1.0, -2.0]).unwrap();
    let z = ZernikeSpec::of(&b);
    assert_eq!((z.radius_mm, z.center_mm), (25.5, [1.0, -2.0]));
    let f = SurfacesFile::v2(
        z,
        SurfaceEntry::Reconstructed(SurfaceCoefficients {
            coefficients_nm: vec![0.0; 4],
            std_nm: Some(vec![0.0; 4]),
            expected_error_rms_nm: Some(0.0),
            orthonormal_std_nm: None,
        }),
        SurfaceEntry::NotReconstructed { because: None },
    );
    let text = f.to_json_string(Path::new("x.json")).unwrap();
    assert_eq!(parse(&text).unwrap(), f);
}
