//! The adjustment's residuals, each block against its own noise: the flat
//! points' heights above the plane (against the stage's σ), the element
//! points' heights above the element's front, the targets' reprojections
//! (against each centroid's covariance plus the stage noise carried through
//! the projection) and the reference flat's fringe map (the screen point
//! the flat mirror at `z = 0` reflects each camera pixel's ray to, against
//! the decoded one and its covariance) and the marked screen pixels (the
//! PSM's focus on each, predicted from the screen's pose and pitch
//! ([`super::screen_mark`]), against the stage reading mapped into the
//! world frame, in mm, against the stage noise and the focus's spread).
//! Whitened residuals are `L⁻¹ e`
//! with `L Lᵀ` the residual's covariance, so each is N(0, 1) at the truth.

use nalgebra::{Matrix2, Matrix2x3, Matrix3, Point2, Point3, Unit, Vector2, Vector3};
use rayon::prelude::*;

use super::error::CalibrationError;
use super::input::{CalibrationInput, FlatPixel, MarkedPixel, Target};
use super::params::State;
use super::screen_mark::{mark_focus, MarkFocus};
use crate::optics::station::Station;

/// Which residual blocks a step of the calibration fits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Blocks {
    /// The flat points (the plane).
    pub flat_points: bool,
    /// The element points (the element's pose).
    pub element_points: bool,
    /// The targets' reprojections (the camera).
    pub targets: bool,
    /// The reference flat's fringe map (the screen).
    pub flat_map: bool,
    /// The marked screen pixels (the screen).
    pub screen_points: bool,
}

impl Blocks {
    /// Every block.
    pub const ALL: Blocks = Blocks {
        flat_points: true,
        element_points: true,
        targets: true,
        flat_map: true,
        screen_points: true,
    };
    /// The targets alone: what the camera's resection fits.
    pub const TARGETS: Blocks = Blocks {
        flat_points: false,
        element_points: false,
        targets: true,
        flat_map: false,
        screen_points: false,
    };
}

/// The whitening matrices of the two-dimensional residuals, fixed for one
/// adjustment so that its costs compare.
#[derive(Debug, Clone)]
pub struct Whitening {
    /// `L⁻¹` per target.
    pub targets: Vec<Matrix2<f64>>,
    /// `L⁻¹` per flat pixel.
    pub flat_map: Vec<Matrix2<f64>>,
    /// `L⁻¹` per marked screen pixel (3 × 3, world mm).
    pub screen_points: Vec<Matrix3<f64>>,
}

/// Step of the projection's central differences over a world point, mm:
/// the projection is smooth on the scale of metres, so 1 µm gives the
/// Jacobian to rounding.
const PROJECTION_STEP_MM: f64 = 1e-3;

/// `L⁻¹` of a 2×2 covariance (`None` when it is not positive definite).
fn whitener(cov: &Matrix2<f64>) -> Option<Matrix2<f64>> {
    let l = cov.cholesky()?.l();
    l.try_inverse()
}

/// `∂ pixel / ∂ world point` of the camera at `p` (central differences).
pub fn projection_jacobian(station: &Station, p: &Point3<f64>) -> Option<Matrix2x3<f64>> {
    let mut j = Matrix2x3::zeros();
    for k in 0..3 {
        let mut e = Vector3::zeros();
        e[k] = PROJECTION_STEP_MM;
        let a = station.camera.project(&(p + e))?;
        let b = station.camera.project(&(p - e))?;
        j.set_column(k, &((a - b) / (2.0 * PROJECTION_STEP_MM)));
    }
    Some(j)
}

impl Whitening {
    /// The whitening at `state`: each target's centroid covariance plus the
    /// stage's isotropic noise through the projection there.
    ///
    /// # Errors
    /// [`CalibrationError::Degenerate`] for a target behind the camera,
    /// [`CalibrationError::BadCovariance`] for a covariance that is not
    /// positive definite.
    pub fn at(input: &CalibrationInput, state: &State) -> Result<Whitening, CalibrationError> {
        let s2 = input.stage_std_mm * input.stage_std_mm;
        let targets = input
            .targets
            .iter()
            .enumerate()
            .map(|(index, t)| {
                let w = state.frame.to_world(&t.stage_mm);
                let j = projection_jacobian(&state.station, &w).ok_or_else(|| CalibrationError::Degenerate {
                    entry: "target_point",
                    problem: format!(
                        "{index} lies behind the camera: check its stage reading against the nominal station"
                    ),
                })?;
                whitener(&(t.pixel_cov_px2 + s2 * j * j.transpose())).ok_or(CalibrationError::BadCovariance {
                    entry: "target_point",
                    index,
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        let flat_map = input
            .flat_screen
            .iter()
            .enumerate()
            .map(|(index, f)| {
                whitener(&f.screen_cov_px2).ok_or(CalibrationError::BadCovariance {
                    entry: "reference_flat",
                    index,
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        let s2_mark = Matrix3::identity() * s2;
        let screen_points = input
            .screen_points
            .iter()
            .enumerate()
            .map(|(index, m)| {
                let cov = s2_mark + mark(state, m).focus_cov_mm2;
                cov.cholesky().and_then(|c| c.l().try_inverse()).ok_or(
                    CalibrationError::BadCovariance {
                        entry: "screen_point",
                        index,
                    },
                )
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Whitening {
            targets,
            flat_map,
            screen_points,
        })
    }
}

/// The PSM's axis in the world frame: the stage's `z` (it focuses by
/// moving along it), from the element towards the screen.
pub fn psm_axis(state: &State) -> Unit<Vector3<f64>> {
    Unit::new_normalize(state.frame.stage_from_world().inverse() * Vector3::z())
}

fn mark(state: &State, m: &MarkedPixel) -> MarkFocus {
    mark_focus(
        &state.station.screen,
        &psm_axis(state),
        m.screen_px.x,
        m.screen_px.y,
    )
}

/// The screen point `(u, v)` that the ray of camera pixel `(i, j)` reaches
/// after one reflection off a flat mirror at the world's `z = 0` (through
/// the cover glass where the screen has one), without checking that it is
/// on the screen. `None` when the ray does not reach the mirror or the
/// screen.
pub fn flat_reflection_uv(station: &Station, i: u32, j: u32) -> Option<Point2<f64>> {
    let cam = &station.camera;
    let d = cam.ray_through(f64::from(i) + 0.5, f64::from(j) + 0.5);
    let c = cam.position_mm;
    if d.z >= 0.0 || !d.z.is_finite() {
        return None;
    }
    let hit = c + (-c.z / d.z) * d.as_ref();
    let r = Unit::new_unchecked(Vector3::new(d.x, d.y, -d.z));
    let screen = &station.screen;
    let landing = match &screen.cover_glass {
        Some(g) => g.land(&screen.origin_mm, &screen.normal_towards(&hit), &hit, &r)?,
        None => {
            let n = screen.normal();
            let denom = r.dot(&n);
            let s = (screen.origin_mm - hit).dot(&n) / denom;
            if s.is_nan() || s <= 0.0 {
                return None;
            }
            hit + s * r.as_ref()
        }
    };
    let (u, v) = screen.coordinates(&landing);
    Some(Point2::new(u, v))
}

/// Raw residuals of one state, model − data, by block: flat points and
/// element points in mm, targets in px (x, y interleaved), the flat map in
/// screen px (u, v interleaved). NaN where the model has no value.
#[derive(Debug, Clone, Default)]
pub struct Raw {
    /// World z of each flat point, mm.
    pub flat_points: Vec<f64>,
    /// Element-frame z of each element point, mm.
    pub element_points: Vec<f64>,
    /// Projection − centroid per target.
    pub targets: Vec<Vector2<f64>>,
    /// Predicted − decoded screen point per flat pixel.
    pub flat_map: Vec<Vector2<f64>>,
    /// Predicted focus − stage reading (world) per marked pixel, mm.
    pub screen_points: Vec<Vector3<f64>>,
}

fn flat_point(state: &State, p: &Vector3<f64>) -> f64 {
    state.frame.to_world(p).z
}

fn element_point(state: &State, p: &Vector3<f64>) -> f64 {
    let e = &state.station.element;
    e.pose.to_element(&e.pivot(), &state.frame.to_world(p)).z
}

fn target(state: &State, t: &Target) -> Vector2<f64> {
    state
        .station
        .camera
        .project(&state.frame.to_world(&t.stage_mm))
        .map_or(Vector2::new(f64::NAN, f64::NAN), |p| p - t.pixel)
}

fn flat_pixel(state: &State, f: &FlatPixel) -> Vector2<f64> {
    flat_reflection_uv(&state.station, f.pixel[0], f.pixel[1])
        .map_or(Vector2::new(f64::NAN, f64::NAN), |p| p - f.screen_px)
}

fn screen_point(state: &State, m: &MarkedPixel) -> Vector3<f64> {
    mark(state, m).world_mm - state.frame.to_world(&m.stage_mm)
}

/// The raw residuals of the blocks asked for (the others left empty).
pub fn raw(input: &CalibrationInput, state: &State, blocks: Blocks) -> Raw {
    let mut out = Raw::default();
    if blocks.flat_points {
        out.flat_points = input
            .flat_points_stage_mm
            .iter()
            .map(|p| flat_point(state, p))
            .collect();
    }
    if blocks.element_points {
        out.element_points = input
            .element_points_stage_mm
            .iter()
            .map(|p| element_point(state, p))
            .collect();
    }
    if blocks.targets {
        out.targets = input.targets.iter().map(|t| target(state, t)).collect();
    }
    if blocks.flat_map {
        out.flat_map = input
            .flat_screen
            .par_iter()
            .with_min_len(64)
            .map(|f| flat_pixel(state, f))
            .collect();
    }
    if blocks.screen_points {
        out.screen_points = input
            .screen_points
            .iter()
            .map(|m| screen_point(state, m))
            .collect();
    }
    out
}

/// The readings of the blocks asked for, each giving one to three
/// residuals, in the order flat points, element points, targets, flat map,
/// screen points.
pub fn item_count(input: &CalibrationInput, blocks: Blocks) -> usize {
    let on = |b: bool, n: usize| if b { n } else { 0 };
    on(blocks.flat_points, input.flat_points_stage_mm.len())
        + on(blocks.element_points, input.element_points_stage_mm.len())
        + on(blocks.targets, input.targets.len())
        + on(blocks.flat_map, input.flat_screen.len())
        + on(blocks.screen_points, input.screen_points.len())
}

/// The whitened residuals of reading `k` ([`item_count`]'s order) and how
/// many of the three it has.
pub fn item(
    input: &CalibrationInput,
    state: &State,
    blocks: Blocks,
    w: &Whitening,
    k: usize,
) -> ([f64; 3], usize) {
    let s = input.stage_std_mm;
    let mut k = k;
    let mut take = |on: bool, n: usize| {
        if !on {
            return None;
        }
        if k < n {
            Some(k)
        } else {
            k -= n;
            None
        }
    };
    if let Some(i) = take(blocks.flat_points, input.flat_points_stage_mm.len()) {
        return (
            [
                flat_point(state, &input.flat_points_stage_mm[i]) / s,
                0.0,
                0.0,
            ],
            1,
        );
    }
    if let Some(i) = take(blocks.element_points, input.element_points_stage_mm.len()) {
        return (
            [
                element_point(state, &input.element_points_stage_mm[i]) / s,
                0.0,
                0.0,
            ],
            1,
        );
    }
    if let Some(i) = take(blocks.targets, input.targets.len()) {
        let e = w.targets[i] * target(state, &input.targets[i]);
        return ([e.x, e.y, 0.0], 2);
    }
    if let Some(i) = take(blocks.flat_map, input.flat_screen.len()) {
        let e = w.flat_map[i] * flat_pixel(state, &input.flat_screen[i]);
        return ([e.x, e.y, 0.0], 2);
    }
    if let Some(i) = take(blocks.screen_points, input.screen_points.len()) {
        let e = w.screen_points[i] * screen_point(state, &input.screen_points[i]);
        return ([e.x, e.y, e.z], 3);
    }
    ([f64::NAN; 3], 0)
}
