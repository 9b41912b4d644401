//! Fixed-length arrays in TOML files, read strictly.
//!
//! The `toml` crate (0.8) fills a `[f64; 2]` from the first two elements of
//! a longer array and drops the rest without a word, so `tilt_deg = [1, 2,
//! 3]` would read as `[1, 2]`. The formats of `interchange.md` and
//! `calibration.md` give every array's length; these readers reject any
//! other length with serde's "invalid length" error, which the TOML error
//! then places at the field. Use with `#[serde(deserialize_with = ...)]`.

use serde::de::{Deserialize, Deserializer, Error};

/// Exactly `N` values.
///
/// # Errors
/// Serde's invalid-length error when the array holds another count.
pub fn array<'de, D, T, const N: usize>(d: D) -> Result<[T; N], D::Error>
where
    D: Deserializer<'de>,
    T: Deserialize<'de>,
{
    let v: Vec<T> = Vec::deserialize(d)?;
    let len = v.len();
    v.try_into()
        .map_err(|_| D::Error::invalid_length(len, &format!("exactly {N} values").as_str()))
}

/// Exactly `N` values, for an optional field (`#[serde(default)]` beside it).
///
/// # Errors
/// As [`array()`].
pub fn option_array<'de, D, T, const N: usize>(d: D) -> Result<Option<[T; N]>, D::Error>
where
    D: Deserializer<'de>,
    T: Deserialize<'de>,
{
    array(d).map(Some)
}

/// A 3 × 3 matrix as three rows of three values.
///
/// # Errors
/// Serde's invalid-length error when a row or the matrix has another count.
pub fn matrix3<'de, D>(d: D) -> Result<[[f64; 3]; 3], D::Error>
where
    D: Deserializer<'de>,
{
    let rows: Vec<Vec<f64>> = Vec::deserialize(d)?;
    if rows.len() != 3 {
        return Err(D::Error::invalid_length(rows.len(), &"exactly 3 rows"));
    }
    let mut m = [[0.0; 3]; 3];
    for (r, row) in rows.iter().enumerate() {
        if row.len() != 3 {
            return Err(D::Error::invalid_length(
                row.len(),
                &format!("exactly 3 values in row {r}").as_str(),
            ));
        }
        m[r].copy_from_slice(row);
    }
    Ok(m)
}

#[cfg(test)]
mod tests {
    #[derive(Debug, serde::Deserialize)]
    struct Probe {
        #[serde(deserialize_with = "super::array")]
        pair: [f64; 2],
        #[serde(default, deserialize_with = "super::option_array")]
        triple: Option<[u32; 3]>,
        #[serde(default = "zero", deserialize_with = "super::matrix3")]
        m: [[f64; 3]; 3],
    }

    fn zero() -> [[f64; 3]; 3] {
        [[0.0; 3]; 3]
    }

    #[test]
    fn right_lengths_read_and_wrong_ones_name_the_field() {
        let p: Probe = toml::from_str("pair = [1.0, 2.0]\ntriple = [1, 2, 3]").unwrap();
        assert_eq!((p.pair, p.triple), ([1.0, 2.0], Some([1, 2, 3])));
        assert_eq!(p.m, zero());
        for bad in [
            "pair = [1.0, 2.0, 3.0]",
            "pair = [1.0]",
            "pair = [1.0, 2.0]\ntriple = [1, 2]",
            "pair = [1.0, 2.0]\nm = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]",
            "pair = [1.0, 2.0]\nm = [[1.0, 0.0, 0.0], [0.0, 1.0], [0.0, 0.0, 1.0]]",
        ] {
            let err = toml::from_str::<Probe>(bad).unwrap_err().to_string();
            assert!(err.contains("invalid length"), "{bad}: {err}");
        }
    }
}
