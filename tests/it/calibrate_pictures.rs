//! The calibration report's pictures (`mfd::calibrate::pictures`): every
//! one is written and shows something (its pixels vary), the reprojected
//! targets get a panel per height, and the flat's v map is not the u map.

use mfd::calibrate::calibration::calibrate;
use mfd::calibrate::pictures::write_pictures;
use mfd::calibrate::pictures_sensor::{arrow_scale, layers, reprojected};
use mfd::calibrate::simulate::{example_truth, simulate_session, SessionSpec};

/// Width, height and the 8-bit grey level of every pixel of a PNG.
fn grey(path: &std::path::Path) -> (u32, u32, Vec<f64>) {
    let file = std::io::BufReader::new(std::fs::File::open(path).unwrap());
    let mut reader = png::Decoder::new(file).read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    let channels = info.color_type.samples();
    let px: Vec<f64> = buf[..info.buffer_size()]
        .chunks(channels)
        .map(|c| c.iter().take(3).map(|&v| f64::from(v)).sum::<f64>() / 3.0f64.min(channels as f64))
        .collect();
    (info.width, info.height, px)
}

fn variance(v: &[f64]) -> f64 {
    let m = v.iter().sum::<f64>() / v.len() as f64;
    v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / v.len() as f64
}

#[test]
fn the_report_pictures_are_written_and_not_blank() {
    let truth = example_truth().unwrap();
    let sim = simulate_session(&truth, &SessionSpec::default()).unwrap();
    let cal = calibrate(&sim.input).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let written = write_pictures(&cal, &sim.input, dir.path()).unwrap();
    let names: Vec<String> = written
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    assert_eq!(
        names,
        [
            "targets.png",
            "targets_on_sensor.png",
            "flat_residuals.png",
            "flat_residuals_v.png"
        ]
    );
    for path in &written {
        let (_, _, px) = grey(path);
        // A blank picture is one grey level (variance 0); one with axes,
        // labels and marks on white has thousands of dark pixels: at
        // least 1 % of them, and a variance of at least 1 % of white's
        // (255²/100 ≈ 650 would be 1 % of pixels black).
        let dark = px.iter().filter(|&&v| v < 128.0).count();
        assert!(
            dark * 100 > px.len(),
            "{}: {dark} dark pixels",
            path.display()
        );
        assert!(
            variance(&px) > 500.0,
            "{}: variance {}",
            path.display(),
            variance(&px)
        );
    }
    // Three heights (0, 60, 120 mm): three panels side by side.
    let (w, _, _) = grey(&dir.path().join("targets_on_sensor.png"));
    let r = reprojected(&cal, &sim.input);
    assert_eq!(layers(&r).len(), 3);
    assert_eq!(w, 3 * 560);
    // The arrows: the longest residual (a tenth of a pixel or so) drawn at
    // 8 % of the sensor's width at most, and, the scale being a 1-2-5
    // value, at no less than 8 % / 2.5.
    let longest = r
        .iter()
        .map(|t| (t.measured[0] - t.predicted[0]).hypot(t.measured[1] - t.predicted[1]))
        .fold(0.0, f64::max);
    let drawn = arrow_scale(&r, 1296.0) * longest / 1296.0;
    assert!((0.08 / 2.5..=0.08).contains(&drawn), "{drawn}");
    // The v map is its own picture, not the u map again.
    // (Its colour bar's labels may make it another size; where it is the
    // same, 5 % of its pixels at least must differ.)
    let (wu, hu, u) = grey(&dir.path().join("flat_residuals.png"));
    let (wv, hv, v) = grey(&dir.path().join("flat_residuals_v.png"));
    if (wu, hu) == (wv, hv) {
        let differ = u.iter().zip(&v).filter(|(a, b)| a != b).count();
        assert!(
            differ * 20 > u.len(),
            "{differ} of {} pixels differ",
            u.len()
        );
    }
}
