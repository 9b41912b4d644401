//! The diverging colour map of height maps: ColorBrewer "RdBu" (11 classes,
//! reversed), dark blue for the most negative value through near-white at
//! zero to dark red for the most positive, interpolated linearly in sRGB
//! between the eleven published colours. It is symmetric in lightness about
//! its centre and readable by the common forms of colour blindness.

use super::canvas::Rgb;

/// Pixels outside the aperture (NaN heights): a mid-light grey, distinct
/// from the map's near-white centre and from the white page.
pub const OUTSIDE: Rgb = [190, 190, 190];

/// ColorBrewer RdBu, from blue (low) to red (high).
const STOPS: [Rgb; 11] = [
    [5, 48, 97],
    [33, 102, 172],
    [67, 147, 195],
    [146, 197, 222],
    [209, 229, 240],
    [247, 247, 247],
    [253, 219, 199],
    [244, 165, 130],
    [214, 96, 77],
    [178, 24, 43],
    [103, 0, 31],
];

/// The colour at `t` in [0, 1] (0 the low end, 1 the high end, 0.5 zero);
/// `t` outside is clamped, NaN gives [`OUTSIDE`].
pub fn diverging(t: f64) -> Rgb {
    if t.is_nan() {
        return OUTSIDE;
    }
    let x = t.clamp(0.0, 1.0) * (STOPS.len() - 1) as f64;
    let i = (x.floor() as usize).min(STOPS.len() - 2);
    let f = x - i as f64;
    let (a, b) = (STOPS[i], STOPS[i + 1]);
    std::array::from_fn(|c| {
        (f64::from(a[c]) + f * (f64::from(b[c]) - f64::from(a[c]))).round() as u8
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ends_centre_and_clamping() {
        assert_eq!(diverging(0.0), STOPS[0]);
        assert_eq!(diverging(1.0), STOPS[10]);
        assert_eq!(diverging(0.5), [247, 247, 247]);
        assert_eq!(diverging(-3.0), STOPS[0]);
        assert_eq!(diverging(7.0), STOPS[10]);
        assert_eq!(diverging(f64::NAN), OUTSIDE);
        // Halfway between the first two stops.
        assert_eq!(diverging(0.05), [19, 75, 135]);
    }

    #[test]
    fn high_side_is_red_low_side_is_blue() {
        for k in 0..50 {
            let d = k as f64 / 100.0;
            let (lo, hi) = (diverging(0.5 - d - 0.01), diverging(0.5 + d + 0.01));
            assert!(lo[2] > lo[0], "low side not blue at {d}: {lo:?}");
            assert!(hi[0] > hi[2], "high side not red at {d}: {hi:?}");
        }
    }
}
