//! The live loop end to end on the simulated 48×48 station: every recorded
//! frame must equal what the simulator renders for its pattern, whatever
//! faults the camera injects, and every re-shoot must be accounted for.

use crate::common;

use std::sync::atomic::AtomicBool;
use std::time::Duration;

use mfd::acquire::acquisition::Acquisition;
use mfd::acquire::camera::{Camera, CameraConfig, CameraError, Frame, TriggerMode};
use mfd::acquire::patterns::{Pattern, Schedule};
use mfd::live::{
    acquire, Counters, FrameSink, LiveError, Recorder, Report, SequencerConfig, Session,
};
use mfd::optics::station::Station;
use mfd::optics::trace::{Plate, TracedView};
use mfd::sim::{
    MirroredDisplay, RandomSurfaceSpec, Renderer, ScreenState, SimDisplay, SimFaults, SimParams,
    SimulatedCamera,
};

/// The simulated station: the fixture's 48×48 camera and a random plate.
struct Rig {
    station: Station,
    view: TracedView,
    patterns: Vec<Pattern>,
}

impl Rig {
    fn new() -> Self {
        let station = Station::load(&common::public_small().join("station.toml")).unwrap();
        let (front, back) = RandomSurfaceSpec::default()
            .draw_pair(station.element.aperture_radius_mm, [0.0, 0.0], 3)
            .unwrap();
        let plate = Plate::new(&station, front, back, 3.0);
        let view = TracedView::trace(&station, &plate);
        let patterns = Schedule {
            tau_start: 1.0,
            tau_stop: 20.0,
            tau_step: 1.0,
            ..Schedule::default()
        }
        .patterns();
        Rig {
            station,
            view,
            patterns,
        }
    }

    /// Noise-free, so a frame is a function of its pattern alone.
    fn renderer(&self) -> Renderer {
        let params = SimParams {
            bit_depth: 12,
            ..SimParams::default()
        };
        Renderer::new(&self.view, &self.station.screen, params).unwrap()
    }

    fn camera(
        &self,
        screen: &ScreenState,
        faults: SimFaults,
        mode: TriggerMode,
    ) -> SimulatedCamera {
        let mut cam = SimulatedCamera::new(self.renderer(), screen.clone(), faults);
        let config = CameraConfig {
            trigger: mode,
            frame_rate_hz: Some(400.0),
            ..CameraConfig::default()
        };
        cam.configure(&config).unwrap();
        cam.start().unwrap();
        cam
    }

    fn display(&self, screen: &ScreenState) -> MirroredDisplay<'static> {
        let res = (self.station.screen.width, self.station.screen.height);
        let inner = SimDisplay::new(res, Duration::from_millis(1));
        MirroredDisplay::new(Box::new(inner), screen.clone())
    }

    /// Runs the loop from where `recorder` stands, `extra` sinks after it.
    fn run(
        &self,
        camera: &mut dyn Camera,
        screen: &ScreenState,
        recorder: &mut Recorder,
        extra: Option<&mut dyn FrameSink>,
        mode: TriggerMode,
        capacity: usize,
    ) -> Result<Report, LiveError> {
        let stop = AtomicBool::new(false);
        let mut display = self.display(screen);
        let session = Session {
            camera,
            display: &mut display,
            patterns: &self.patterns,
            first: recorder.recorded(),
            trigger: mode,
            resolution: (48, 48),
            config: SequencerConfig {
                frame_timeout: Duration::from_millis(60),
                max_reshoots: 5,
                capacity,
            },
            stop: &stop,
        };
        let mut sinks: Vec<&mut dyn FrameSink> = vec![recorder];
        if let Some(s) = extra {
            sinks.push(s);
        }
        acquire(session, &mut sinks, &mut |_: &Counters| {})
    }

    /// Runs the whole schedule into a new acquisition in `dir`.
    fn measure(
        &self,
        dir: &std::path::Path,
        faults: SimFaults,
        mode: TriggerMode,
    ) -> (Result<Report, LiveError>, Recorder) {
        let screen = ScreenState::new();
        let mut camera = self.camera(&screen, faults, mode);
        let mut recorder = Recorder::create(dir, &self.station, &self.patterns, false).unwrap();
        let result = self.run(&mut camera, &screen, &mut recorder, None, mode, 4);
        (result, recorder)
    }

    /// Asserts that `dir` holds exactly `n` frames, each the simulator's
    /// rendering of its pattern (bit-exact: no noise, same renderer).
    fn assert_recorded(&self, dir: &std::path::Path, n: usize) {
        let acq = Acquisition::open(dir).unwrap();
        assert_eq!(acq.frames().len(), n);
        assert_eq!(acq.complete_frames(), n);
        let mut expected = vec![0u16; 48 * 48];
        let mut renderer = self.renderer();
        let mut got = Vec::new();
        for (k, f) in acq.frames().iter().enumerate() {
            let p = self.patterns[k];
            assert_eq!(
                (f.direction_deg, f.tau, f.phase_rad),
                (p.direction_deg, p.tau, p.phase_rad)
            );
            renderer.render(&p, k as u64, &mut expected);
            acq.read_frame(k, &mut got).unwrap();
            assert!(got == expected, "frame {k} differs from the simulator's");
        }
    }
}

/// Exposures the camera makes when every `k`-th one fails and is re-shot:
/// returns how many failed over `n` patterns.
fn failures_every(k: u64, n: usize) -> u64 {
    let (mut exposures, mut failed) = (0u64, 0u64);
    for _ in 0..n {
        loop {
            exposures += 1;
            if exposures % k != 0 {
                break;
            }
            failed += 1;
        }
    }
    failed
}

#[test]
fn recorded_frames_are_the_simulators_frames() {
    let rig = Rig::new();
    let dir = tempfile::tempdir().unwrap();
    let (result, recorder) = rig.measure(dir.path(), SimFaults::default(), TriggerMode::Software);
    let report = result.unwrap();
    let c = &report.counters;
    assert!(!report.interrupted);
    assert_eq!((c.captured, recorder.recorded()), (40, 40));
    assert_eq!(
        (c.reshoots, c.timeouts, c.mismatches, c.lost_frames),
        (0, 0, 0, 0)
    );
    rig.assert_recorded(dir.path(), 40);
}

#[test]
fn every_kth_drop_is_reshot_and_counted() {
    let rig = Rig::new();
    let dir = tempfile::tempdir().unwrap();
    let faults = SimFaults {
        drop_every: Some(6),
        ..SimFaults::default()
    };
    let (result, _) = rig.measure(dir.path(), faults, TriggerMode::Software);
    let c = result.unwrap().counters;
    let drops = failures_every(6, 40);
    assert!(drops >= 6);
    // Each lost exposure: one timeout, one re-shoot, one gap in the counter.
    assert_eq!(
        (c.timeouts, c.reshoots, c.lost_frames),
        (drops, drops, drops)
    );
    assert_eq!(c.mismatches, 0);
    rig.assert_recorded(dir.path(), 40);
}

#[test]
fn random_drops_are_reshot() {
    let rig = Rig::new();
    let dir = tempfile::tempdir().unwrap();
    let faults = SimFaults {
        drop_probability: 0.2,
        seed: 7,
        latency: Duration::from_millis(2),
        ..SimFaults::default()
    };
    let (result, _) = rig.measure(dir.path(), faults, TriggerMode::Software);
    let c = result.unwrap().counters;
    assert!(
        c.timeouts > 0,
        "seed 7 drops some of ~50 exposures at p = 0.2"
    );
    assert_eq!(c.reshoots, c.timeouts);
    // Exposures lost before the first delivered frame leave no visible gap
    // (the counter's start is unknown to the sequencer), so ≤, not =.
    assert!(c.lost_frames <= c.timeouts && c.lost_frames > 0, "{c:?}");
    rig.assert_recorded(dir.path(), 40);
}

#[test]
fn frames_exposed_before_the_settle_point_are_rejected() {
    let rig = Rig::new();
    let dir = tempfile::tempdir().unwrap();
    let faults = SimFaults {
        early_every: Some(5),
        ..SimFaults::default()
    };
    let (result, _) = rig.measure(dir.path(), faults, TriggerMode::Software);
    let c = result.unwrap().counters;
    let early = failures_every(5, 40);
    assert_eq!((c.mismatches, c.reshoots, c.timeouts), (early, early, 0));
    // Had one been kept, its frame would show the previous pattern.
    rig.assert_recorded(dir.path(), 40);
}

#[test]
fn a_disconnect_names_the_frame_and_keeps_the_ones_before() {
    let rig = Rig::new();
    let dir = tempfile::tempdir().unwrap();
    let faults = SimFaults {
        disconnect_after: Some(13),
        ..SimFaults::default()
    };
    let (result, recorder) = rig.measure(dir.path(), faults, TriggerMode::Software);
    match result {
        Err(LiveError::Camera {
            frame: 13,
            source: CameraError::Disconnected { .. },
        }) => {}
        other => panic!("expected a disconnect at frame 13, got {other:?}"),
    }
    assert_eq!(recorder.recorded(), 13);
    drop(recorder);
    rig.assert_recorded(dir.path(), 13);

    // Resume with a working camera: the acquisition is completed in place.
    let screen = ScreenState::new();
    let mut camera = rig.camera(&screen, SimFaults::default(), TriggerMode::Software);
    let mut recorder = Recorder::resume(dir.path(), &rig.patterns).unwrap();
    assert_eq!(recorder.recorded(), 13);
    let report = rig
        .run(
            &mut camera,
            &screen,
            &mut recorder,
            None,
            TriggerMode::Software,
            4,
        )
        .unwrap();
    assert_eq!((report.counters.first, report.counters.captured), (13, 27));
    rig.assert_recorded(dir.path(), 40);
}

/// A consumer slower than the camera, recording what it saw.
struct Slow {
    seen: Vec<usize>,
    frames: Vec<Frame>,
}

impl FrameSink for Slow {
    fn name(&self) -> &'static str {
        "slow"
    }

    fn accept(&mut self, index: usize, frame: &Frame) -> Result<(), mfd::live::SinkError> {
        std::thread::sleep(Duration::from_millis(8));
        self.seen.push(index);
        self.frames.push(frame.clone());
        Ok(())
    }
}

#[test]
fn a_slow_consumer_holds_the_sequencer_back_and_loses_nothing() {
    let rig = Rig::new();
    let dir = tempfile::tempdir().unwrap();
    let screen = ScreenState::new();
    let mut camera = rig.camera(&screen, SimFaults::default(), TriggerMode::Software);
    let mut recorder = Recorder::create(dir.path(), &rig.station, &rig.patterns, false).unwrap();
    let mut slow = Slow {
        seen: Vec::new(),
        frames: Vec::new(),
    };
    let report = rig
        .run(
            &mut camera,
            &screen,
            &mut recorder,
            Some(&mut slow),
            TriggerMode::Software,
            2,
        )
        .unwrap();
    let c = &report.counters;
    // 40 frames into a 2-frame buffer drained at ≥ 8 ms each while a frame
    // takes ~1 ms to shoot: the buffer must have been full.
    assert!(c.backpressure_waits > 0 && c.backpressure_s > 0.0, "{c:?}");
    assert_eq!(slow.seen, (0..40).collect::<Vec<_>>());
    assert_eq!(c.reshoots, 0);
    rig.assert_recorded(dir.path(), 40);
    let mut renderer = rig.renderer();
    let mut expected = vec![0u16; 48 * 48];
    for (k, f) in slow.frames.iter().enumerate() {
        renderer.render(&rig.patterns[k], 0, &mut expected);
        assert_eq!(f.data, expected, "frame {k}");
        assert_eq!(f.exposed_pattern, Some(k));
    }
}

#[test]
fn free_running_frames_are_picked_after_the_settle_point() {
    let rig = Rig::new();
    let dir = tempfile::tempdir().unwrap();
    let faults = SimFaults {
        drop_every: Some(4),
        latency: Duration::from_millis(3),
        ..SimFaults::default()
    };
    let (result, _) = rig.measure(dir.path(), faults, TriggerMode::FreeRunning);
    let c = result.unwrap().counters;
    // Every 4th frame of the stream is lost; the sequencer sees the gaps.
    assert!(c.lost_frames > 0, "{c:?}");
    assert_eq!(c.mismatches, 0, "{c:?}");
    rig.assert_recorded(dir.path(), 40);
}

#[test]
fn a_consumer_error_stops_the_run_and_is_reported() {
    struct Failing;
    impl FrameSink for Failing {
        fn name(&self) -> &'static str {
            "failing"
        }
        fn accept(&mut self, index: usize, _: &Frame) -> Result<(), mfd::live::SinkError> {
            if index == 9 {
                return Err("disk full".into());
            }
            Ok(())
        }
    }
    let rig = Rig::new();
    let dir = tempfile::tempdir().unwrap();
    let screen = ScreenState::new();
    let mut camera = rig.camera(&screen, SimFaults::default(), TriggerMode::Software);
    let mut recorder = Recorder::create(dir.path(), &rig.station, &rig.patterns, false).unwrap();
    let err = rig
        .run(
            &mut camera,
            &screen,
            &mut recorder,
            Some(&mut Failing),
            TriggerMode::Software,
            2,
        )
        .unwrap_err();
    assert!(
        matches!(
            err,
            LiveError::Sink {
                sink: "failing",
                frame: 9,
                ..
            }
        ),
        "{err}"
    );
    // The recorder kept every frame handed over before the stop.
    let n = recorder.recorded();
    assert!((10..40).contains(&n), "{n}");
    drop(recorder);
    rig.assert_recorded(dir.path(), n);
}

#[test]
fn a_consumer_failing_to_finish_is_reported_as_such() {
    struct Unflushable;
    impl FrameSink for Unflushable {
        fn name(&self) -> &'static str {
            "unflushable"
        }
        fn accept(&mut self, _: usize, _: &Frame) -> Result<(), mfd::live::SinkError> {
            Ok(())
        }
        fn finish(&mut self) -> Result<(), mfd::live::SinkError> {
            Err("disk full".into())
        }
    }
    let rig = Rig::new();
    let dir = tempfile::tempdir().unwrap();
    let screen = ScreenState::new();
    let mut camera = rig.camera(&screen, SimFaults::default(), TriggerMode::Software);
    let mut recorder = Recorder::create(dir.path(), &rig.station, &rig.patterns, false).unwrap();
    let err = rig
        .run(
            &mut camera,
            &screen,
            &mut recorder,
            Some(&mut Unflushable),
            TriggerMode::Software,
            2,
        )
        .unwrap_err();
    assert!(
        matches!(
            err,
            LiveError::SinkFinish {
                sink: "unflushable",
                ..
            }
        ),
        "{err}"
    );
    // Regression: the finish step was reported as frame usize::MAX.
    let text = err.to_string();
    assert!(
        text.contains("finishing") && !text.contains(&usize::MAX.to_string()),
        "{text}"
    );
    assert_eq!(recorder.recorded(), 40);
}
