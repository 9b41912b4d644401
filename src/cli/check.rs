//! Value parsers for numeric command-line options: each number is checked
//! where it enters, for finiteness, sign and a range the instrument can
//! mean. clap reports a refused value with the option's name and exits 2
//! (`error: invalid value 'NaN' for '--noise <NOISE>': not a finite number`).
//! The table of options and rules is in docs/input-checks.md.

use std::fmt::Display;
use std::str::FromStr;

/// Parses `s` as a finite `f64`.
fn number(s: &str) -> Result<f64, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("`{s}` is not a number"))?;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(format!("{s}: not a finite number"))
    }
}

/// Any finite number.
pub fn finite(s: &str) -> Result<f64, String> {
    number(s)
}

/// A finite number above 0.
pub fn positive(s: &str) -> Result<f64, String> {
    let v = number(s)?;
    if v > 0.0 {
        Ok(v)
    } else {
        Err(format!("{v}: expected a number above 0"))
    }
}

/// A finite number of at least 0.
pub fn non_negative(s: &str) -> Result<f64, String> {
    let v = number(s)?;
    if v >= 0.0 {
        Ok(v)
    } else {
        Err(format!("{v}: expected a number of at least 0"))
    }
}

/// A fraction: a finite number from 0 to 1.
pub fn fraction(s: &str) -> Result<f64, String> {
    let v = number(s)?;
    if (0.0..=1.0).contains(&v) {
        Ok(v)
    } else {
        Err(format!("{v}: expected a fraction from 0 to 1"))
    }
}

/// An integer above 0.
pub fn positive_int<T>(s: &str) -> Result<T, String>
where
    T: FromStr + PartialOrd + Default + Display,
{
    let v: T = s
        .trim()
        .parse()
        .map_err(|_| format!("`{s}` is not a whole number of this range"))?;
    if v > T::default() {
        Ok(v)
    } else {
        Err(format!("{v}: expected a whole number above 0"))
    }
}

/// A finite number from `lo` to `hi` (inclusive); `reason` says why that
/// range, in the error.
pub fn range(
    lo: f64,
    hi: f64,
    reason: &'static str,
) -> impl Fn(&str) -> Result<f64, String> + Clone + Send + Sync + 'static {
    move |s: &str| {
        let v = number(s)?;
        if (lo..=hi).contains(&v) {
            Ok(v)
        } else {
            Err(format!("{v}: expected {lo} to {hi} ({reason})"))
        }
    }
}

/// An integer from `lo` to `hi` (inclusive); `reason` says why.
pub fn int_range<T>(
    lo: T,
    hi: T,
    reason: &'static str,
) -> impl Fn(&str) -> Result<T, String> + Clone + Send + Sync + 'static
where
    T: FromStr + PartialOrd + Display + Copy + Send + Sync + 'static,
{
    move |s: &str| {
        let v: T = s
            .trim()
            .parse()
            .map_err(|_| format!("`{s}` is not a whole number"))?;
        if v >= lo && v <= hi {
            Ok(v)
        } else {
            Err(format!("{v}: expected {lo} to {hi} ({reason})"))
        }
    }
}

/// A refractive index of glass or crystal: above 1 (else there is no
/// reflection to separate) and at most 4 (germanium's, the highest of
/// optical materials).
pub fn refractive_index(s: &str) -> Result<f64, String> {
    let v = number(s)?;
    if v > 1.0 && v <= 4.0 {
        Ok(v)
    } else {
        Err(format!(
            "{v}: expected above 1 and at most 4 (a plate's refractive index in air)"
        ))
    }
}

/// A display gamma, 0.5 to 5 (monitors are 1.8 to 2.6; linearised 1).
pub fn gamma(s: &str) -> Result<f64, String> {
    range(0.5, 5.0, "a display's gamma; monitors have 1.8 to 2.6")(s)
}

/// Bits per camera sample: 8, 12 or 16, the pixel formats of the cameras
/// mfd drives (Mono8, Mono12, Mono16) and so of its simulated camera and
/// the noise model of `plan` and `budget`.
pub fn sim_bit_depth(s: &str) -> Result<u32, String> {
    match s.trim().parse::<u32>() {
        Ok(v @ (8 | 12 | 16)) => Ok(v),
        _ => Err(format!(
            "{s}: expected 8, 12 or 16 (the cameras' pixel formats Mono8, Mono12, Mono16)"
        )),
    }
}

/// Read noise as a fraction of full scale above 0 and below 1: a bound on
/// the error (plan, budget) divides by the noise, and noise of full scale
/// leaves no signal.
pub fn noise_fraction(s: &str) -> Result<f64, String> {
    let v = number(s)?;
    if v > 0.0 && v < 1.0 {
        Ok(v)
    } else {
        Err(format!(
            "{v}: expected a fraction of full scale above 0 and below 1 (a bound needs noise)"
        ))
    }
}

/// A factor from a map's stored heights to nm: its magnitude from 1e-3 (the
/// map stores pm) to 1e9 (metres), the units a height map is written in;
/// negative flips the heights' sign. Beyond, a product of heights overflows
/// or vanishes, and the comparison would fail for a reason it cannot name.
pub fn height_scale(s: &str) -> Result<f64, String> {
    let v = number(s)?;
    if (1e-3..=1e9).contains(&v.abs()) {
        Ok(v)
    } else {
        Err(format!(
            "{}: expected ±1e-3 to ±1e9 (nm per stored unit: 1e-3 for pm, 1 for nm, 1e9 for m)",
            s.trim()
        ))
    }
}

/// The most Zernike terms per surface: every term up to radial order 20,
/// (20 + 1)(20 + 2)/2 = 231, the order the basis's round trips are tested
/// to (`optics::zernike` tests).
pub const MAX_TERMS: usize = 231;

/// Zernike terms per surface of a fit (Noll 1..=N): 3 to [`MAX_TERMS`].
/// Three is the first whole radial order (piston and both tilts): the
/// term choice's smallest candidate, and with the front's piston fixed by
/// the reference plane a model of 1 or 2 terms leaves one tilt or none.
pub fn terms(s: &str) -> Result<usize, String> {
    int_range(
        3usize,
        MAX_TERMS,
        "Noll terms: from piston and both tilts (order 1) to radial order 20",
    )(s)
}

/// Zernike terms per surface of an error budget or plan: 4 to
/// [`MAX_TERMS`]; figures leave out piston and tilt, so defocus (Noll 4)
/// is the first term they report.
pub fn budget_terms(s: &str) -> Result<usize, String> {
    int_range(
        4usize,
        MAX_TERMS,
        "Noll terms: defocus (4), the first one reported, to radial order 20",
    )(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_rule_refuses_what_it_says_and_takes_the_rest() {
        for bad in ["NaN", "inf", "-inf", "x", ""] {
            assert!(finite(bad).is_err(), "{bad}");
            assert!(positive(bad).is_err(), "{bad}");
        }
        assert_eq!(finite("-2.5"), Ok(-2.5));
        assert!(positive("0").is_err() && positive("-1").is_err());
        assert_eq!(positive("1e-9"), Ok(1e-9));
        assert!(non_negative("-1e-300").is_err());
        assert_eq!(non_negative("0"), Ok(0.0));
        assert!(fraction("1.0001").is_err() && fraction("-0.1").is_err());
        assert_eq!(fraction("1"), Ok(1.0));
        assert!(positive_int::<usize>("0").is_err() && positive_int::<usize>("-1").is_err());
        assert_eq!(positive_int::<u32>("3"), Ok(3));
        let settle = range(0.0, 10.0, "why");
        assert!(settle("10.5").unwrap_err().contains("why"));
        assert_eq!(settle("10"), Ok(10.0));
        assert!(refractive_index("1").is_err() && refractive_index("4.5").is_err());
        assert!(sim_bit_depth("10").is_err() && sim_bit_depth("7").is_err());
        assert!(noise_fraction("0").is_err() && noise_fraction("1").is_err());
        assert_eq!(noise_fraction("0.05"), Ok(0.05));
        assert!(terms("2").is_err() && terms("232").is_err());
        assert_eq!(terms("3"), Ok(3));
        assert!(budget_terms("3").is_err());
        assert!(height_scale("1e308").is_err() && height_scale("0").is_err());
        assert_eq!(height_scale("-1e9"), Ok(-1e9));
        assert_eq!(budget_terms("231"), Ok(231));
        assert_eq!(sim_bit_depth("12"), Ok(12));
    }
}
