//! Tests of the design: the rounding of weights to frames.

use super::problem::round;
use super::*;

#[test]
fn cumulative_rounding_keeps_the_count_and_the_shares() {
    let c: Vec<FrameInfo> = (0..10)
        .map(|k| FrameInfo {
            index: k,
            direction_deg: 45.0,
            tau: 1.0 + k as f64,
            phase_rad: 0.0,
        })
        .collect();
    let mut w = vec![0.01; 10];
    w[3] = 0.91;
    let f = round(&c, &w, 100);
    assert_eq!(f.len(), 100);
    // Share 0.91 of 100 frames: 91 repeats, within one of rounding.
    let at3 = f.iter().filter(|x| x.tau == 4.0).count();
    assert!((90..=92).contains(&at3), "{at3}");
    // Repeats of one pattern follow one another.
    assert_eq!(super::super::timing::switches(&f), 10);
}
