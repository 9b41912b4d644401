//! The figures an optician reads (issue 38), each with its 1σ: per face
//! the ISO 10110-5 form figures (power, irregularity, RMSt, RMSi, RMSa),
//! and for the plate the wedge between the faces, the thickness variation
//! and the transmitted wavefront.
//!
//! Conventions (the spec's, `interchange.md`): Noll order, RMS-normalised
//! coefficients `a_j` in nm at index `j − 1`, Zernike radius `R` in mm;
//! the front is `z = W1`, the back `z = −t0 + W2`, so the thickness is
//! `t = t0 + W1 − W2`. A wedge declared in station v2 stays in the back's
//! tilt terms, so the wedge from `W1 − W2`'s tilt is the whole wedge.
//!
//! The σ come from the joint covariance of front and back (noise and the
//! station's part, cross block included: [`joint::covariance`]): linear
//! where a figure is linear in the coefficients (power), otherwise the
//! spread of the figure over [`DRAWS`] coefficient vectors drawn from that
//! covariance with the seed [`DRAWS_SEED`] (PV, RMS and the wedge's angles,
//! which are not linear, least of all near zero). `std_method` says which.

use std::collections::BTreeMap;

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use crate::optics::zernike::{noll_to_nm, ZernikeError};

mod draws;
pub mod grid;
pub mod joint;
pub mod table;

pub use grid::Grid;

/// The transmitted wavefront's wavelength unless one is given, nm.
pub const DEFAULT_WAVELENGTH_NM: f64 = 1053.0;

/// Coefficient vectors drawn for the σ of the non-linear figures.
pub const DRAWS: usize = 400;

/// The seed of those draws (stated in `std_method`).
pub const DRAWS_SEED: u64 = 38;

/// Side of the square grid over the aperture's bounding square on which
/// PV figures are taken (cell centres inside the disk).
pub const GRID_SIDE: usize = 192;

/// Arcseconds per radian.
const ARCSEC_PER_RAD: f64 = 180.0 * 3600.0 / std::f64::consts::PI;

/// What each figure leaves out, in words (`summary.json`, the report).
pub const REMOVED_NOTE: &str = "power = 2*sqrt(3)*a4 (the PV of Noll Z4 alone, signed as a4); \
irregularity PV with piston, tilt and Z4 (Noll 1-4) removed, over the aperture disk; \
RMSt over Noll j >= 4, RMSi over j >= 5, RMSa over j >= 5 with m != 0; the plate's thickness \
t = t0 + W1 - W2: the wedge is the angle of its best-fit plane (the tilt terms of W1 - W2) and \
its azimuth the direction in the element frame along which t decreases; thickness variation \
and transmitted wavefront (n - 1)(W1 - W2) at normal incidence with piston and tilt removed";

/// The figures of one face.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct FaceFigures {
    /// 2√3 a4: the PV of the Z4 term alone, signed as a4, nm.
    pub power_nm: f64,
    /// Its 1σ (linear), nm.
    pub power_std_nm: f64,
    /// PV over the aperture with piston, tilt and Z4 removed, nm.
    pub irregularity_pv_nm: f64,
    /// Its 1σ (draws), nm.
    pub irregularity_pv_std_nm: f64,
    /// √(Σ_{j≥4} a_j²), nm.
    pub rms_t_nm: f64,
    /// Its 1σ (draws), nm.
    pub rms_t_std_nm: f64,
    /// √(Σ_{j≥5} a_j²), nm.
    pub rms_i_nm: f64,
    /// Its 1σ (draws), nm.
    pub rms_i_std_nm: f64,
    /// √(Σ_{j≥5, m≠0} a_j²), the rotationally variant part, nm.
    pub rms_a_nm: f64,
    /// Its 1σ (draws), nm.
    pub rms_a_std_nm: f64,
}

/// The figures of the plate (front and back together).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct PlateFigures {
    /// The angle of the thickness's best-fit plane, arcsec.
    pub wedge_arcsec: f64,
    /// Its 1σ (draws), arcsec.
    pub wedge_std_arcsec: f64,
    /// The direction in the element frame (from +x towards +y) along which
    /// the plate thins, degrees in [0, 360).
    pub wedge_azimuth_deg: f64,
    /// Its 1σ (draws, differences wrapped to ±180°), degrees.
    pub wedge_azimuth_std_deg: f64,
    /// PV of W1 − W2, piston and tilt removed, nm.
    pub thickness_variation_pv_nm: f64,
    /// Its 1σ (draws), nm.
    pub thickness_variation_pv_std_nm: f64,
    /// RMS of W1 − W2, piston and tilt removed, nm.
    pub thickness_variation_rms_nm: f64,
    /// Its 1σ (draws), nm.
    pub thickness_variation_rms_std_nm: f64,
    /// RMS of the transmitted wavefront (n − 1)(W1 − W2), piston and tilt
    /// removed, nm.
    pub twe_rms_nm: f64,
    /// Its 1σ (draws), nm.
    pub twe_rms_std_nm: f64,
    /// PV of the transmitted wavefront, nm.
    pub twe_pv_nm: f64,
    /// Its 1σ (draws), nm.
    pub twe_pv_std_nm: f64,
    /// `twe_rms_nm` in waves of `wavelength_nm`.
    pub twe_rms_waves: f64,
    /// Its 1σ, waves.
    pub twe_rms_std_waves: f64,
    /// The wavelength of `twe_rms_waves`, nm.
    pub wavelength_nm: f64,
    /// The index `n` of the transmitted wavefront (the station's).
    pub refractive_index: f64,
}

/// Every figure of a result (`summary.json`'s `figures`).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Figures {
    /// What each figure leaves out ([`REMOVED_NOTE`]).
    pub removed: String,
    /// What the σ come from (the joint covariance, noise alone or with the
    /// station's part).
    pub covariance: String,
    /// How each `_std` key was computed: "linear", or "draws N (seed S)".
    pub std_method: BTreeMap<String, String>,
    /// The front's figures; `null` when the front is not reported.
    pub front: Option<FaceFigures>,
    /// The back's figures; `null` when the back is not reported.
    pub back: Option<FaceFigures>,
    /// The plate's figures; `null` unless both faces are reported.
    pub plate: Option<PlateFigures>,
    /// Why a part is `null` (`[front, back, plate]`, `null` where present).
    pub why_null: [Option<String>; 3],
}

/// What the figures are computed from.
#[derive(Debug, Clone)]
pub struct FigureInput<'a> {
    /// Front coefficients, nm (Noll j = k + 1 at index k).
    pub front_nm: &'a [f64],
    /// Back coefficients, nm (may be all zero when not reconstructed).
    pub back_nm: &'a [f64],
    /// Joint covariance of `front_nm` then `back_nm`, nm², square of their
    /// lengths together.
    pub covariance_nm2: &'a DMatrix<f64>,
    /// Zernike radius, mm.
    pub radius_mm: f64,
    /// Refractive index of the plate.
    pub refractive_index: f64,
    /// Wavelength of `twe_rms_waves`, nm.
    pub wavelength_nm: f64,
    /// What the covariance holds, in words.
    pub covariance_note: String,
    /// Why the front (0) or back (1) is not reported, where it is not.
    pub withheld: [Option<String>; 2],
    /// Where the element's outline is not the disk: the coefficients and
    /// covariance above are in the set orthonormal over it ([`Over`]), and
    /// every figure is taken over the outline.
    pub over: Option<&'a Over>,
}

/// The set orthonormal over an element's outline that a [`FigureInput`]'s
/// coefficients are in: PV on the grid's cells inside the outline, RMS
/// from the coefficients from the fourth (the plane over the outline
/// removed), the wedge from the plane over the outline.
#[derive(Debug, Clone)]
pub struct Over {
    /// The outline.
    pub outline: crate::optics::outline::Outline,
    /// The set (as many terms as the longer face).
    pub set: crate::optics::outline::Orthonormal,
}

impl Over {
    /// The Zernike plane (Noll 1–3) of orthonormal coefficients `a`: the
    /// first three of `L⁻ᵀ a` (upper triangular, so only `a_1…a_3` enter).
    fn zernike_plane(&self, a: &[f64]) -> Vec<f64> {
        let lt = self.set.matrix();
        let n = 3.min(lt.nrows()).min(a.len());
        let mut c = vec![0.0; n];
        for i in (0..n).rev() {
            let s: f64 = (i + 1..n).map(|j| lt[(i, j)] * c[j]).sum();
            c[i] = (a[i] - s) / lt[(i, i)];
        }
        c
    }
}

/// The wedge of `d = W1 − W2` in `input`'s coefficients (see [`wedge`]).
pub(crate) fn wedge_of(d: &[f64], input: &FigureInput<'_>) -> (f64, f64) {
    match input.over {
        None => wedge(d, input.radius_mm),
        Some(o) => wedge(&o.zernike_plane(d), input.radius_mm),
    }
}

/// The closed-form figures of one face's coefficients `c` (nm): power,
/// then PV (on `grid`), RMSt, RMSi, RMSa.
pub fn face_values(c: &[f64], grid: &Grid) -> [f64; 5] {
    let a4 = c.get(3).copied().unwrap_or(0.0);
    let [rt, ri, ra] = face_rms(c);
    [2.0 * 3f64.sqrt() * a4, grid.pv(c, 4), rt, ri, ra]
}

/// RMSt, RMSi, RMSa of one face's coefficients (orthonormal terms: root
/// sums of squares).
pub fn face_rms(c: &[f64]) -> [f64; 3] {
    let (mut t, mut i, mut a) = (0.0, 0.0, 0.0);
    for (k, x) in c.iter().enumerate().skip(3) {
        t += x * x;
        if k >= 4 {
            i += x * x;
            if noll_to_nm(k + 1).is_ok_and(|(_, m)| m != 0) {
                a += x * x;
            }
        }
    }
    [t.sqrt(), i.sqrt(), a.sqrt()]
}

/// `W1 − W2` of the coefficient vectors (the longer one's length).
pub fn difference(front: &[f64], back: &[f64]) -> Vec<f64> {
    let n = front.len().max(back.len());
    (0..n)
        .map(|k| front.get(k).copied().unwrap_or(0.0) - back.get(k).copied().unwrap_or(0.0))
        .collect()
}

/// The wedge of the thickness difference `d = W1 − W2` (nm) over the
/// Zernike radius `radius_mm`: its angle (arcsec) and the azimuth (degrees
/// in [0, 360)) along which the thickness decreases. `Z2 = 2x/R`,
/// `Z3 = 2y/R`: the plane's gradient is `(2 a2, 2 a3)/R` nm per mm.
pub fn wedge(d: &[f64], radius_mm: f64) -> (f64, f64) {
    let gx = 2.0 * d.get(1).copied().unwrap_or(0.0) / radius_mm * 1e-6;
    let gy = 2.0 * d.get(2).copied().unwrap_or(0.0) / radius_mm * 1e-6;
    let angle = gx.hypot(gy).atan() * ARCSEC_PER_RAD;
    let azimuth = (-gy).atan2(-gx).to_degrees().rem_euclid(360.0);
    (angle, azimuth)
}

/// The plate's closed-form figures of `input`: wedge (arcsec), azimuth
/// (deg), thickness variation PV and RMS (nm).
pub fn plate_values(input: &FigureInput<'_>, grid: &Grid) -> [f64; 4] {
    let d = difference(input.front_nm, input.back_nm);
    let (w, az) = wedge_of(&d, input);
    // Folded from +0.0: `Sum` starts at −0.0, and a plane's empty sum
    // printed "RMS -0.00 nm".
    let rms = d.iter().skip(3).fold(0.0, |s, x| s + x * x).sqrt();
    [w, az, grid.pv(&d, 3), rms]
}

/// Every figure of `input` with its σ.
///
/// # Errors
/// [`ZernikeError`] when the Zernike radius is not positive and finite.
pub fn figures(input: &FigureInput<'_>) -> Result<Figures, ZernikeError> {
    let terms = input.front_nm.len().max(input.back_nm.len()).max(4);
    let grid = match input.over {
        None => Grid::new(terms, input.radius_mm, GRID_SIDE)?,
        Some(o) => Grid::over(&o.outline, &o.set, GRID_SIDE)?,
    };
    let spread = draws::spread(input, &grid);
    let face = |k: usize| -> Option<FaceFigures> {
        if input.withheld[k].is_some() {
            return None;
        }
        let (c, nf) = (
            if k == 0 {
                input.front_nm
            } else {
                input.back_nm
            },
            input.front_nm.len(),
        );
        let v = face_values(c, &grid);
        let s = spread.face[k];
        let a4 = if k == 0 { 3 } else { nf + 3 };
        let var4 = if a4 < input.covariance_nm2.nrows() {
            input.covariance_nm2[(a4, a4)]
        } else {
            0.0
        };
        Some(FaceFigures {
            power_nm: v[0],
            power_std_nm: 2.0 * 3f64.sqrt() * var4.max(0.0).sqrt(),
            irregularity_pv_nm: v[1],
            irregularity_pv_std_nm: s[0],
            rms_t_nm: v[2],
            rms_t_std_nm: s[1],
            rms_i_nm: v[3],
            rms_i_std_nm: s[2],
            rms_a_nm: v[4],
            rms_a_std_nm: s[3],
        })
    };
    let (front, back) = (face(0), face(1));
    let plate = (front.is_some() && back.is_some()).then(|| {
        let v = plate_values(input, &grid);
        let s = spread.plate;
        let n1 = input.refractive_index - 1.0;
        PlateFigures {
            wedge_arcsec: v[0],
            wedge_std_arcsec: s[0],
            wedge_azimuth_deg: v[1],
            wedge_azimuth_std_deg: s[1],
            thickness_variation_pv_nm: v[2],
            thickness_variation_pv_std_nm: s[2],
            thickness_variation_rms_nm: v[3],
            thickness_variation_rms_std_nm: s[3],
            twe_rms_nm: n1 * v[3],
            twe_rms_std_nm: n1 * s[3],
            twe_pv_nm: n1 * v[2],
            twe_pv_std_nm: n1 * s[2],
            twe_rms_waves: n1 * v[3] / input.wavelength_nm,
            twe_rms_std_waves: n1 * s[3] / input.wavelength_nm,
            wavelength_nm: input.wavelength_nm,
            refractive_index: input.refractive_index,
        }
    });
    let plate_why = plate.is_none().then(|| {
        let face = if front.is_none() { "front" } else { "back" };
        format!("the plate's figures need both faces: the {face} is not reported")
    });
    Ok(Figures {
        removed: REMOVED_NOTE.into(),
        covariance: input.covariance_note.clone(),
        std_method: std_methods(),
        front,
        back,
        plate,
        why_null: [
            input.withheld[0].clone(),
            input.withheld[1].clone(),
            plate_why,
        ],
    })
}

/// Which method gave each `_std` key.
fn std_methods() -> BTreeMap<String, String> {
    let drawn = format!(
        "draws {DRAWS} (seed {DRAWS_SEED}) from the joint covariance of front and back; \
         PV on a {GRID_SIDE} x {GRID_SIDE} grid over the aperture (its cells inside the \
         element's outline)"
    );
    let mut m = BTreeMap::new();
    m.insert("power_std_nm".into(), "linear".into());
    for k in [
        "irregularity_pv_std_nm",
        "rms_t_std_nm",
        "rms_i_std_nm",
        "rms_a_std_nm",
        "wedge_std_arcsec",
        "wedge_azimuth_std_deg",
        "thickness_variation_pv_std_nm",
        "thickness_variation_rms_std_nm",
        "twe_rms_std_nm",
        "twe_pv_std_nm",
        "twe_rms_std_waves",
    ] {
        m.insert(k.into(), drawn.clone());
    }
    m
}

/// The figures of known coefficients (a simulation's truth), every σ 0:
/// what [`table::scores`] sets a result against.
///
/// # Errors
/// [`ZernikeError`] when the Zernike radius is not positive and finite.
pub fn of_truth(
    front_nm: &[f64],
    back_nm: &[f64],
    radius_mm: f64,
    refractive_index: f64,
    wavelength_nm: f64,
) -> Result<Figures, ZernikeError> {
    let n = front_nm.len() + back_nm.len();
    let zero = DMatrix::zeros(n, n);
    figures(&FigureInput {
        front_nm,
        back_nm,
        covariance_nm2: &zero,
        radius_mm,
        refractive_index,
        wavelength_nm,
        covariance_note: "none: known coefficients".into(),
        withheld: [None, None],
        over: None,
    })
}
