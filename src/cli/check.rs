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

/// Bits per camera sample, 1 to 16 (samples are stored as 16-bit counts).
pub fn bit_depth(s: &str) -> Result<u32, String> {
    int_range(1u32, 16, "bits per sample, stored in 16-bit counts")(s)
}

/// Bits per sample of the simulated camera: 8, 12 or 16 (its pixel formats).
pub fn sim_bit_depth(s: &str) -> Result<u32, String> {
    match s.trim().parse::<u32>() {
        Ok(v @ (8 | 12 | 16)) => Ok(v),
        _ => Err(format!(
            "{s}: expected 8, 12 or 16 (the simulated camera's pixel formats)"
        )),
    }
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
        assert!(bit_depth("0").is_err() && bit_depth("17").is_err());
        assert!(sim_bit_depth("10").is_err());
        assert_eq!(sim_bit_depth("12"), Ok(12));
    }
}
