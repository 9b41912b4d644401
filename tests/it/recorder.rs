//! The recorder's crash-safe acquisition: a recording killed between frames
//! reads back with exactly the frames it listed, its `[[frame]]` tables are
//! serde's (the same text the whole-acquisition writer makes, `f64` values
//! bit-exact), and `--resume`'s reopening continues it.

use crate::common;

use std::time::Instant;

use mfd::acquire::acquisition::{
    Acquisition, AcquisitionWriter, FrameInfo, FrameLayout, ManifestFile, MANIFEST,
};
use mfd::acquire::camera::Frame;
use mfd::acquire::patterns::Pattern;
use mfd::live::Recorder;
use mfd::optics::station::Station;

const W: u32 = 6;
const H: u32 = 4;

/// Values whose shortest decimal forms need 16–17 significant digits.
fn patterns() -> Vec<Pattern> {
    (0..5)
        .map(|k| Pattern {
            direction_deg: 100.0 / 3.0 * k as f64,
            tau: 0.1 + 0.2 * (k + 1) as f64,
            phase_rad: std::f64::consts::TAU / 3.0 * k as f64,
        })
        .collect()
}

fn frame(k: usize) -> Frame {
    Frame {
        data: (0..W * H)
            .map(|p| (p as u16 * 97 + k as u16 * 613) % 4096)
            .collect(),
        width: W,
        height: H,
        bit_depth: 12,
        timestamp: Instant::now(),
        sequence: k as u64,
        exposed_pattern: Some(k),
    }
}

fn station() -> Station {
    Station::load(&common::public_small().join("station.toml")).unwrap()
}

#[test]
fn a_recording_killed_between_frames_reads_back() {
    let dir = tempfile::tempdir().unwrap();
    let patterns = patterns();
    // τ = 0.1 + 0.2 needs all 17 significant digits to read back.
    assert_eq!(format!("{:?}", patterns[0].tau), "0.30000000000000004");
    let mut recorder = Recorder::create(dir.path(), &station(), &patterns, false).unwrap();
    for k in 0..3 {
        recorder.write(k, &frame(k)).unwrap();
    }
    // Killed before frame 3: nothing is flushed or finished.
    drop(recorder);
    let acq = Acquisition::open(dir.path()).unwrap();
    assert_eq!((acq.frames().len(), acq.complete_frames()), (3, 3));
    let mut got = Vec::new();
    for (k, f) in acq.frames().iter().enumerate() {
        let p = patterns[k];
        // Bit-exact: the manifest's decimal text reads back to the same f64.
        assert_eq!(f.tau.to_bits(), p.tau.to_bits(), "frame {k}");
        assert_eq!(f.direction_deg.to_bits(), p.direction_deg.to_bits());
        assert_eq!(f.phase_rad.to_bits(), p.phase_rad.to_bits());
        acq.read_frame(k, &mut got).unwrap();
        assert_eq!(got, frame(k).data, "frame {k}");
    }
    assert!(Station::load(acq.station_path()).is_ok());
}

#[test]
fn frame_tables_are_serdes_and_every_prefix_is_a_manifest() {
    let dir = tempfile::tempdir().unwrap();
    let patterns = patterns();
    let mut recorder = Recorder::create(dir.path(), &station(), &patterns, false).unwrap();
    for k in 0..3 {
        recorder.write(k, &frame(k)).unwrap();
    }
    drop(recorder);
    let text = std::fs::read_to_string(dir.path().join(MANIFEST)).unwrap();
    // The whole-acquisition writer serialises the same three frames.
    let whole = tempfile::tempdir().unwrap();
    let infos = FrameInfo::from_patterns(&patterns[..3]);
    let png = FrameLayout::Png { bit_depth: 16 };
    AcquisitionWriter::create(whole.path(), "station.toml", png, &infos, W, H, false).unwrap();
    let whole_text = std::fs::read_to_string(whole.path().join(MANIFEST)).unwrap();
    let body = |t: &str| t.split_once('\n').unwrap().1.to_string();
    assert_eq!(body(&text), body(&whole_text));
    // Each prefix that ends before a table lists only the frames before it.
    let cuts: Vec<usize> = text.match_indices("[[frame]]").map(|(i, _)| i).collect();
    assert_eq!(cuts.len(), 3);
    for (n, &cut) in cuts.iter().enumerate().chain([(3, &text.len())]) {
        let file: ManifestFile = toml::from_str(&text[..cut]).unwrap();
        assert_eq!(file.frames.len(), n);
    }
}

#[test]
fn resume_continues_a_killed_recording() {
    let dir = tempfile::tempdir().unwrap();
    let patterns = patterns();
    let mut recorder = Recorder::create(dir.path(), &station(), &patterns, false).unwrap();
    for k in 0..2 {
        recorder.write(k, &frame(k)).unwrap();
    }
    drop(recorder);
    let mut recorder = Recorder::resume(dir.path(), &patterns).unwrap();
    assert_eq!(recorder.recorded(), 2);
    let err = recorder.write(3, &frame(3)).unwrap_err().to_string();
    assert!(
        err.contains("frame 3") && err.contains("out of order"),
        "{err}"
    );
    for k in 2..5 {
        recorder.write(k, &frame(k)).unwrap();
    }
    drop(recorder);
    let acq = Acquisition::open(dir.path()).unwrap();
    assert_eq!(acq.frames().len(), 5);
    let mut got = Vec::new();
    acq.read_frame(4, &mut got).unwrap();
    assert_eq!(got, frame(4).data);
    // A schedule the recording is not a prefix of is refused.
    let mut other = patterns.clone();
    other[1].tau = 0.25;
    let err = Recorder::resume(dir.path(), &other)
        .unwrap_err()
        .to_string();
    assert!(err.contains("frame[1]"), "{err}");
}
