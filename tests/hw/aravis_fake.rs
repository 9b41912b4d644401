//! The live loop over the real GigE Vision protocol: libaravis's fake
//! camera on loopback serves the simulated station's frames, the Aravis
//! backend receives them, and every recorded frame must equal the
//! simulator's rendering of its pattern. Only one fake camera can bind
//! 127.0.0.1:3956 at a time, so the tests take turns.
#![cfg(feature = "aravis")]

use crate::common;

use std::sync::atomic::AtomicBool;
use std::sync::Mutex;
use std::time::Duration;

use mfd::acquire::acquisition::Acquisition;
use mfd::acquire::camera::{Camera, CameraConfig, StreamStatistics, TriggerMode};
use mfd::acquire::patterns::Schedule;
use mfd::calibrate::centroid::centroid_of_file;
use mfd::calibrate::frame::WorldFrame;
use mfd::calibrate::make::plan_targets;
use mfd::calibrate::session_file::SessionFile;
use mfd::live::{acquire, Counters, FrameSink, Recorder, SequencerConfig, Session};
use mfd::optics::station::Station;
use mfd::optics::trace::{Plate, TracedView};
use mfd::optics::zernike::ZernikeSurface;
use mfd::sim::aravis_fake::FakeStation;
use mfd::sim::{
    MirroredDisplay, Renderer, ScreenState, SimDisplay, SimFaults, SimParams, SimulatedCamera,
};

static LOOPBACK: Mutex<()> = Mutex::new(());

fn flat_view(station: &Station) -> TracedView {
    let flat = ZernikeSurface::flat(station.element.aperture_radius_mm, [0.0, 0.0]).unwrap();
    TracedView::trace(station, &Plate::new(station, flat.clone(), flat, 3.0))
}

/// Runs 30 patterns of the fixture station through the fake camera with
/// `loss` of its GVSP packets lost; checks every recorded frame bit-exactly
/// against the simulator and returns the counters and stream figures.
fn run_fake(loss: f64) -> (Counters, StreamStatistics) {
    let station = Station::load(&common::public_small().join("station.toml")).unwrap();
    let view = flat_view(&station);
    let params = SimParams {
        bit_depth: 12,
        ..SimParams::default()
    };
    let renderer = || Renderer::new(&view, &station.screen, params.clone()).unwrap();
    let screen = ScreenState::new();
    let sim = SimulatedCamera::new(renderer(), screen.clone(), SimFaults::default());
    let mut camera = FakeStation::start(sim).unwrap();
    camera.set_packet_loss(loss);
    assert!(!camera.describe().software_trigger);
    let config = CameraConfig {
        trigger: TriggerMode::FreeRunning,
        frame_rate_hz: Some(100.0),
        exposure_us: Some(500.0),
        ..CameraConfig::default()
    };
    camera.configure(&config).unwrap();
    assert_eq!(camera.describe().resolution, (48, 48));
    camera.start().unwrap();

    let patterns = Schedule {
        tau_start: 1.0,
        tau_stop: 15.0,
        tau_step: 1.0,
        ..Schedule::default()
    }
    .patterns();
    let dir = tempfile::tempdir().unwrap();
    let mut recorder = Recorder::create(dir.path(), &station, &patterns, false).unwrap();
    let res = (station.screen.width, station.screen.height);
    let mut display = MirroredDisplay::new(
        Box::new(SimDisplay::new(res, Duration::from_millis(2))),
        screen,
    );
    let stop = AtomicBool::new(false);
    let session = Session {
        camera: &mut camera,
        display: &mut display,
        patterns: &patterns,
        first: 0,
        trigger: TriggerMode::FreeRunning,
        resolution: (48, 48),
        config: SequencerConfig {
            frame_timeout: Duration::from_secs(2),
            ..SequencerConfig::default()
        },
        stop: &stop,
    };
    let mut sinks: Vec<&mut dyn FrameSink> = vec![&mut recorder];
    let report = acquire(session, &mut sinks, &mut |_: &Counters| {}).unwrap();
    camera.stop().unwrap();
    // Read after stop: the figures of the stream that just ended.
    let stats = camera.statistics();
    eprintln!(
        "aravis fake camera, packet loss {loss}: {:?}\nstream: {stats:?}",
        report.counters
    );

    let acq = Acquisition::open(dir.path()).unwrap();
    assert_eq!(acq.complete_frames(), 30);
    let mut expected = vec![0u16; 48 * 48];
    let mut got = Vec::new();
    let mut r = renderer();
    for (k, p) in patterns.iter().enumerate() {
        r.render(p, k as u64, &mut expected);
        acq.read_frame(k, &mut got).unwrap();
        assert!(got == expected, "frame {k} differs from the simulator's");
    }
    (report.counters, stats)
}

#[test]
fn fake_gige_camera_through_a_whole_acquisition() {
    let _turn = LOOPBACK.lock().unwrap_or_else(|p| p.into_inner());
    let (c, stats) = run_fake(0.0);
    assert_eq!(c.captured, 30);
    // The fill callback tags each frame with the pattern it saw: none of
    // the frames picked by timestamp may carry another pattern.
    assert_eq!(c.mismatches, 0, "{c:?}");
    assert!(stats.completed >= 30, "{stats:?}");
    assert_eq!((stats.failures, stats.missing_packets), (0, 0), "{stats:?}");
}

#[test]
fn lost_packets_give_incomplete_frames_that_are_never_recorded() {
    let _turn = LOOPBACK.lock().unwrap_or_else(|p| p.into_inner());
    // 10 % of ~5 packets per frame over ≥ 30 frames: P(no loss) ≈ 1e-7.
    let (c, stats) = run_fake(0.1);
    assert_eq!((c.captured, c.mismatches), (30, 0), "{c:?}");
    assert!(c.incomplete > 0 && stats.failures > 0, "{c:?} {stats:?}");
}

#[test]
fn measure_over_the_fake_camera_reconstructs() {
    let _turn = LOOPBACK.lock().unwrap_or_else(|p| p.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let st = common::public_small()
        .join("station.toml")
        .display()
        .to_string();
    let out = dir.path().display().to_string();
    let run = common::mfd(&[
        "measure",
        "--station",
        &st,
        "--camera",
        "aravis:fake",
        "--out",
        &out,
        "--tau-start",
        "2",
        "--tau-stop",
        "60",
        "--tau-step",
        "2",
        "--frame-rate",
        "100",
        "--exposure-us",
        "500",
        // The fake camera shows its own test pattern, not the fringes: the
        // spectral stage's answers there are not screen points, and whether
        // the surface stage finds enough of them is chance (with warm
        // starts it stops with "joint: 0 measured values for 4 unknowns").
        // The acquisition path and the spectral maps are what this tests.
        "--no-surfaces",
        // Nor can its points agree with the station.
        "--accept-inconsistent",
    ]);
    let log = format!(
        "{}{}",
        String::from_utf8_lossy(&run.stdout),
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(run.status.success(), "{log}");
    assert!(
        log.contains("captured 60 frames") && log.contains("stream:"),
        "{log}"
    );
    assert!(dir.path().join("result/screen_coords.npy").is_file());
    let acq = Acquisition::open(&dir.path().join("acquisition")).unwrap();
    assert_eq!(acq.complete_frames(), 60);
}

#[test]
fn measure_shows_a_designed_schedule_over_the_fake_camera() {
    let _turn = LOOPBACK.lock().unwrap_or_else(|p| p.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let st = common::public_small()
        .join("station.toml")
        .display()
        .to_string();
    // A short designed schedule: non-uniform τ with repeats, which the
    // uniform flags cannot express.
    let sched = dir.path().join("schedule.toml");
    let plan = common::mfd(&[
        "plan",
        "--station",
        &st,
        "--frames",
        "80",
        "--out",
        sched.to_str().unwrap(),
    ]);
    assert!(
        plan.status.success(),
        "{}",
        String::from_utf8_lossy(&plan.stderr)
    );
    let want = mfd::acquire::schedule_file::load(&sched).unwrap().frames();
    assert_eq!(want.len(), 80);
    let out = dir.path().join("meas");
    let run = common::mfd(&[
        "measure",
        "--station",
        &st,
        "--camera",
        "aravis:fake",
        "--schedule",
        sched.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--frame-rate",
        "100",
        "--exposure-us",
        "500",
        // As above: the acquisition path is what this tests, not the
        // fake camera's points.
        "--no-surfaces",
        "--accept-inconsistent",
    ]);
    let log = format!(
        "{}{}",
        String::from_utf8_lossy(&run.stdout),
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(run.status.success(), "{log}");
    assert!(log.contains("captured 80 frames"), "{log}");
    // The recorder wrote exactly the schedule, in its order.
    let acq = Acquisition::open(&out.join("acquisition")).unwrap();
    assert_eq!(acq.complete_frames(), want.len());
    let rec = acq.frames().to_vec();
    assert_eq!(rec.len(), want.len());
    for (k, (a, b)) in rec.iter().zip(&want).enumerate() {
        assert_eq!(
            (a.direction_deg, a.tau, a.phase_rad),
            (b.direction_deg, b.tau, b.phase_rad),
            "frame {k}"
        );
    }
}

#[test]
fn calibrate_capture_takes_target_frames_over_the_fake_camera() {
    // `mfd calibrate capture --camera aravis:fake`: the simulated target
    // (a spot where the nominal station images the stage reading, through
    // the frame the session's flat points define) served over GigE Vision.
    // Each frame crosses the real protocol into targets/NNN.png, its entry
    // is appended, and its centroid must sit where the plan put the target.
    let _turn = LOOPBACK.lock().unwrap_or_else(|p| p.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let session = dir.path().join("session");
    let nominal = common::repo("calib/paper-sim.toml");
    common::mfd_ok(&[
        "calibrate",
        "template",
        session.to_str().unwrap(),
        "--nominal",
        nominal.to_str().unwrap(),
    ]);
    // Flat points at the reference plane, the stage's axes those of the
    // world: the session's frame is the nominal world frame.
    let toml = session.join("session.toml");
    let mut text = std::fs::read_to_string(&toml).unwrap();
    let flat: Vec<nalgebra::Point3<f64>> = (0..9)
        .map(|k| {
            let (x, y) = (f64::from(k % 3) - 1.0, f64::from(k / 3) - 1.0);
            nalgebra::Point3::new(40.0 * x, 40.0 * y, 0.0)
        })
        .collect();
    for p in &flat {
        text.push_str(&format!(
            "\n[[flat_point]]\nstage_mm = [{}, {}, {}]\n",
            p.x, p.y, p.z
        ));
    }
    std::fs::write(&toml, text).unwrap();
    let station = Station::load(&nominal).unwrap();
    let frame = WorldFrame::from_flat_points(&flat, [0.0, 0.0], 1e-3).unwrap();
    let planned = plan_targets(&station, Some(&frame), &[0.0, 30.0], (2, 2)).unwrap();
    assert_eq!(planned.len(), 8);
    let size = Some((station.camera.width, station.camera.height));
    for (k, t) in planned.iter().enumerate() {
        let s = t.stage_mm;
        let stage = format!("{},{},{}", s.x, s.y, s.z);
        let log = common::mfd_ok(&[
            "calibrate",
            "capture",
            session.to_str().unwrap(),
            "--stage-mm",
            &stage,
            "--camera",
            "aravis:fake",
            "--exposure-us",
            "500",
        ]);
        assert!(
            log.contains(&format!("target_point[{k}]: wrote targets/{k:03}.png")),
            "{log}"
        );
        let png = session.join(format!("targets/{k:03}.png"));
        let c = centroid_of_file(&png, &format!("target_point[{k}]"), size).unwrap();
        // Found within 5σ of its own centroid σ (2-D: exceeded with
        // probability e^-12.5) of where the plan put it.
        let err = (c.position_px - t.expected_px).norm();
        let sd = c.std_px()[0].max(c.std_px()[1]);
        assert!(err < 5.0 * sd, "target {k}: {err} px off, σ {sd} px");
    }
    let file: SessionFile = toml::from_str(&std::fs::read_to_string(&toml).unwrap()).unwrap();
    assert_eq!(file.target_point.len(), planned.len());
    // A stage reading that puts the spot off the sensor is named.
    let run = common::mfd(&[
        "calibrate",
        "capture",
        session.to_str().unwrap(),
        "--stage-mm",
        "900,0,0",
        "--camera",
        "aravis:fake",
    ]);
    let log = String::from_utf8_lossy(&run.stderr);
    assert!(log.contains("target_point[8]"), "{log}");
}
