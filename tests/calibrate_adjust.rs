//! The calibration's joint adjustment on simulated sessions.

use mfd::calibrate::calibration::calibrate;
use mfd::calibrate::params::{difference, Param, State};
use mfd::sim::session::{example_truth, simulate_session, SessionSpec};

#[test]
fn explore_one_seed() {
    let truth = example_truth().unwrap();
    let spec = SessionSpec::default();
    let sim = simulate_session(&truth, &spec).unwrap();
    println!("targets {} flat {}", sim.input.targets.len(), sim.input.flat_screen.len());
    let cal = calibrate(&sim.input).unwrap();
    println!("{}", cal.report.summary());
    let est = State { frame: cal.frame, station: cal.station.clone() };
    let tru = State { frame: sim.frame, station: sim.truth.clone() };
    let params: Vec<Param> = cal.names.iter().map(|n| match n.as_str() {
        "frame.height_mm" => Param::PlaneHeight,
        "frame.slope_x" => Param::PlaneSlopeX,
        "frame.slope_y" => Param::PlaneSlopeY,
        _ => Param::Station(mfd::calibrate::params::prior(n).unwrap().name),
    }).collect();
    let d = difference(&tru, &est, &params);
    for (k, n) in cal.names.iter().enumerate() {
        println!("{n:<24} err {:+.3e} sigma {:.3e} ratio {:+.2}", d[k], cal.covariance[(k,k)].sqrt(), d[k]/cal.covariance[(k,k)].sqrt());
    }
}
