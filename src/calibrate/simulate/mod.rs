//! Simulated calibration sessions (`mfd-calibration/1`) from a known truth
//! station: a stage frame tilted and shifted against the world, stage
//! readings with noise, point targets at several heights spread over the
//! sensor with their centroids (and, for the files, rendered frames), the
//! reference flat's screen points from the exact tracer, and a nominal
//! station that is the truth perturbed by what assembling to drawings
//! leaves. The tests check that a calibration brings the truth back within
//! its reported covariance.
//!
//! Here in `calibrate`, not in `sim`: a session is made of calibrate's own
//! types (`CalibrationInput`, the session file, the planned target layout),
//! and the simulated station below knows nothing of them.

use std::path::Path;

use nalgebra::{Matrix2, Point2, Point3, Vector3};
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, StandardNormal};
use rand_xoshiro::Xoshiro256PlusPlus;

use crate::calibrate::input::{CalibrationInput, FlatPixel, MarkedPixel, Target};
use crate::calibrate::make::target_layout;
use crate::calibrate::params::{prior, WorldFrame, ASPECT_PRIOR, COVER_GLASS_PRIOR_MM};
use crate::calibrate::screen_mark::mark_focus;
use crate::optics::refraction::reflect;
use crate::optics::station::{Distortion, Dof, Station, StationError};
use crate::optics::trace::to_screen;
use crate::sim::SimError;

mod files;
pub mod flat;

pub use files::{render_target, write_session};

/// What to simulate.
#[derive(Debug, Clone, PartialEq)]
pub struct SessionSpec {
    /// Seed of every random draw.
    pub seed: u64,
    /// 1 σ of a stage reading, each axis, mm.
    pub stage_std_mm: f64,
    /// 1 σ of a target centroid, each axis, px.
    pub centroid_std_px: f64,
    /// 1 σ of a decoded flat screen point, each axis, screen px.
    pub flat_std_px: f64,
    /// World heights of the target layers, mm (two or more).
    pub target_heights_mm: Vec<f64>,
    /// Targets per layer, columns × rows over the sensor.
    pub targets_grid: [u32; 2],
    /// The part of the sensor the targets span, about its centre (1: the
    /// layout of `mfd calibrate targets`, edge to edge inside its inset).
    pub target_span: f64,
    /// Flat pixels sampled, columns × rows over the sensor.
    pub flat_grid: [u32; 2],
    /// Radius of the reference flat, mm: pixels that see it carry a screen point.
    pub flat_radius_mm: f64,
    /// Element points on its front (0, or at least 3).
    pub element_points: usize,
    /// The stage frame: the flat plane's stage z at the centre, mm, and its slopes.
    pub plane: [f64; 3],
    /// Stage x, y of the element's centre, mm.
    pub center_stage_mm: [f64; 2],
    /// Marked screen pixels the PSM is focused on (`[[screen_point]]`),
    /// columns × rows over the screen; `[0, 0]`: none.
    pub screen_points: [u32; 2],
}

impl Default for SessionSpec {
    /// 1 µm stage, 0.05 px centroids, 0.02 px flat decode; targets 5 × 4 at
    /// 0, 60 and 120 mm; a Ø 150 mm flat sampled 40 × 30; 6 element points;
    /// the stage tilted by about 0.3° and shifted by a hundred millimetres;
    /// no marked screen pixels.
    fn default() -> Self {
        SessionSpec {
            seed: 1,
            stage_std_mm: 1e-3,
            centroid_std_px: 0.05,
            flat_std_px: 0.02,
            target_heights_mm: vec![0.0, 60.0, 120.0],
            targets_grid: [5, 4],
            target_span: 1.0,
            flat_grid: [40, 30],
            flat_radius_mm: 75.0,
            element_points: 6,
            plane: [12.3456, 0.004, -0.003],
            center_stage_mm: [102.4, 87.9],
            screen_points: [0, 0],
        }
    }
}

/// A simulated session and its truth.
#[derive(Debug, Clone)]
pub struct SimulatedSession {
    /// What a calibration reads.
    pub input: CalibrationInput,
    /// The true station, world frame.
    pub truth: Station,
    /// The true world frame in the stage frame.
    pub frame: WorldFrame,
}

/// The nominal station's errors, 1 σ per degree of freedom: millimetres and
/// tenths of a degree for the camera and screen, 0.1 mm and 5 px for the
/// lens, the pitch and the element's in-plane position at their prior
/// ranges (they are held, so their errors must be what the calibration
/// says it carries). The element's height and tilts start from zero.
const NOMINAL_ERRORS: [(Dof, f64); 18] = [
    (Dof::CameraX, 2.0),
    (Dof::CameraY, 2.0),
    (Dof::CameraZ, 2.0),
    (Dof::CameraRx, 0.2),
    (Dof::CameraRy, 0.2),
    (Dof::CameraRz, 0.2),
    (Dof::FocalLength, 0.1),
    (Dof::Cx, 5.0),
    (Dof::Cy, 5.0),
    (Dof::ScreenX, 2.0),
    (Dof::ScreenY, 2.0),
    (Dof::ScreenZ, 2.0),
    (Dof::ScreenRx, 0.2),
    (Dof::ScreenRy, 0.2),
    (Dof::ScreenRz, 0.2),
    (Dof::ScreenPitch, f64::NAN),
    (Dof::ElementX, f64::NAN),
    (Dof::ElementY, f64::NAN),
];

fn gauss(rng: &mut Xoshiro256PlusPlus, sigma: f64) -> f64 {
    let z: f64 = StandardNormal.sample(rng);
    sigma * z
}

fn noisy(rng: &mut Xoshiro256PlusPlus, v: Vector3<f64>, sigma: f64) -> Vector3<f64> {
    v + Vector3::from_fn(|_, _| gauss(rng, sigma))
}

/// The ray of pixel position `(x, y)` to the world plane `z = h`.
fn on_plane(station: &Station, x: f64, y: f64, h: f64) -> Option<Point3<f64>> {
    let c = station.camera.position_mm;
    let d = station.camera.ray_through(x, y);
    let t = (h - c.z) / d.z;
    (t > 0.0 && t.is_finite()).then(|| c + t * d.as_ref())
}

/// The true station's screen point for the flat reflection of pixel `(i,
/// j)` (the tracer's screen landing, cover glass included), with the
/// mirror's hit point; `None` off the screen.
pub fn flat_truth(station: &Station, i: u32, j: u32) -> Option<(Point2<f64>, Point3<f64>)> {
    let d = station.camera.ray_direction(i, j);
    let hit = on_plane(station, f64::from(i) + 0.5, f64::from(j) + 0.5, 0.0)?;
    let r = reflect(&d, &Vector3::z_axis());
    let (u, v) = to_screen(&station.screen, &hit, &r).ok()?;
    Some((Point2::new(u, v), hit))
}

fn targets(
    truth: &Station,
    frame: &WorldFrame,
    spec: &SessionSpec,
    rng: &mut Xoshiro256PlusPlus,
) -> Vec<Target> {
    let cam = &truth.camera;
    let [nx, ny] = spec.targets_grid;
    let mut out = Vec::new();
    // The operator's layout (`mfd calibrate targets`), placed by the truth.
    for (layer, &h) in spec.target_heights_mm.iter().enumerate() {
        for at in target_layout(layer, (nx, ny), cam.width, cam.height) {
            let middle = Point2::new(f64::from(cam.width), f64::from(cam.height)) / 2.0;
            let at = middle + (at - middle) * spec.target_span;
            let Some(world) = on_plane(truth, at.x, at.y, h) else {
                continue;
            };
            let Some(px) = cam.project(&world) else {
                continue;
            };
            let s = spec.centroid_std_px;
            out.push(Target {
                stage_mm: noisy(rng, frame.to_stage(&world), spec.stage_std_mm),
                pixel: Point2::new(px.x + gauss(rng, s), px.y + gauss(rng, s)),
                pixel_cov_px2: Matrix2::identity() * (s * s),
            });
        }
    }
    out
}

fn flat_screen(
    truth: &Station,
    spec: &SessionSpec,
    rng: &mut Xoshiro256PlusPlus,
) -> Vec<FlatPixel> {
    let cam = &truth.camera;
    let [nx, ny] = spec.flat_grid;
    let s = spec.flat_std_px;
    let mut out = Vec::new();
    for r in 0..ny {
        for c in 0..nx {
            let i = ((f64::from(c) + 0.5) / f64::from(nx) * f64::from(cam.width)) as u32;
            let j = ((f64::from(r) + 0.5) / f64::from(ny) * f64::from(cam.height)) as u32;
            let Some((uv, hit)) = flat_truth(truth, i, j) else {
                continue;
            };
            if hit.coords.xy().norm() > spec.flat_radius_mm {
                continue;
            }
            out.push(FlatPixel {
                pixel: [i, j],
                screen_px: Point2::new(uv.x + gauss(rng, s), uv.y + gauss(rng, s)),
                screen_cov_px2: Matrix2::identity() * (s * s),
            });
        }
    }
    out
}

/// The PSM focused on a grid of marked screen pixels (pixel centres,
/// 5 % to 95 % of the screen): the truth's focus ([`mark_focus`], the PSM
/// along the stage's z), its best focus drawn uniformly between the
/// mark's two images as the model says, then the stage's noise.
fn screen_marks(
    truth: &Station,
    frame: &WorldFrame,
    spec: &SessionSpec,
    rng: &mut Xoshiro256PlusPlus,
) -> Vec<MarkedPixel> {
    let [nx, ny] = spec.screen_points;
    let screen = &truth.screen;
    let axis = nalgebra::Unit::new_normalize(frame.stage_from_world().inverse() * Vector3::z());
    let mut out = Vec::new();
    for r in 0..ny {
        for c in 0..nx {
            let at = |k: u32, n: u32, size: u32| {
                let f = 0.05 + 0.9 * (f64::from(k) + 0.5) / f64::from(n);
                (f * f64::from(size)).floor() + 0.5
            };
            let (u, v) = (at(c, nx, screen.width), at(r, ny, screen.height));
            let f = mark_focus(screen, &axis, u, v);
            let spread = (12.0 * f.focus_cov_mm2.trace()).sqrt();
            let along: f64 = rng.random::<f64>() - 0.5;
            let focus = f.world_mm - along * spread * axis.into_inner();
            out.push(MarkedPixel {
                stage_mm: noisy(rng, frame.to_stage(&focus), spec.stage_std_mm),
                screen_px: Point2::new(u, v),
            });
        }
    }
    out
}

/// The truth perturbed by [`NOMINAL_ERRORS`], the lens undistorted but
/// for k3, the element on the reference plane.
fn nominal(truth: &Station, rng: &mut Xoshiro256PlusPlus) -> Station {
    let mut s = truth.clone();
    for (name, sigma) in NOMINAL_ERRORS {
        let sigma = if sigma.is_nan() {
            prior(name).map_or(0.0, |p| p.prior_std)
        } else {
            sigma
        };
        s = s.perturbed(name, gauss(rng, sigma));
    }
    // The lens is unknown but for k3, which a short lens's data cannot
    // determine: its nominal value is off by its prior range.
    let k3 = s.camera.distortion.map_or(0.0, |d| d.k[2]);
    let p3 = prior(Dof::K3).map_or(0.0, |p| p.prior_std);
    s.camera.distortion = Some(Distortion {
        k: [0.0, 0.0, k3 + gauss(rng, p3)],
        p: [0.0; 2],
    });
    s.element.pose.offset_mm.z = 0.0;
    s.element.pose.tilt_deg = [0.0; 2];
    // The cover glass's thickness from a datasheet, off by its prior range.
    if let Some(g) = &mut s.screen.cover_glass {
        g.thickness_mm += gauss(rng, COVER_GLASS_PRIOR_MM);
    }
    // A declared aspect ratio (fx ≠ fy) off by its prior range.
    if let Some(a) = &mut s.camera.aspect_ratio {
        *a += gauss(rng, ASPECT_PRIOR);
    }
    s
}

/// A simulated session of `truth` (world frame). The truth's element
/// in-plane offset is drawn from its prior range (where the operator
/// centred the PSM), the rest of its pose kept.
///
/// # Errors
/// [`SimError::Invalid`] when the spec cannot give a session (fewer than
/// two target heights, too few targets or flat pixels on the sensor).
pub fn simulate_session(truth: &Station, spec: &SessionSpec) -> Result<SimulatedSession, SimError> {
    let invalid = |field, problem: &str| SimError::Invalid {
        field,
        problem: problem.into(),
    };
    if spec.target_heights_mm.len() < 2 {
        return Err(invalid(
            "target_heights_mm",
            "two or more heights are needed",
        ));
    }
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(spec.seed);
    let mut truth = truth.clone();
    for dof in [Dof::ElementX, Dof::ElementY] {
        let p = prior(dof).map_or(0.0, |p| p.prior_std);
        truth = truth.perturbed(dof, gauss(&mut rng, p));
    }
    let frame = WorldFrame {
        plane: spec.plane,
        center_stage_mm: spec.center_stage_mm,
    };
    let sd = spec.stage_std_mm;
    let flat_points = (0..9)
        .map(|k| {
            let w = Point3::new(
                40.0 * f64::from(k % 3) - 40.0,
                40.0 * f64::from(k / 3) - 40.0,
                0.0,
            );
            noisy(&mut rng, frame.to_stage(&w), sd)
        })
        .collect();
    let c = truth.element.pivot();
    let radius = 0.8 * truth.element.aperture_radius_mm;
    let element_points = (0..spec.element_points)
        .map(|k| {
            let a = std::f64::consts::TAU * k as f64 / spec.element_points as f64;
            let local = c + Vector3::new(radius * a.cos(), radius * a.sin(), 0.0);
            let w = truth.element.pose.to_world(&c, &local);
            noisy(&mut rng, frame.to_stage(&w), sd)
        })
        .collect();
    let targets = targets(&truth, &frame, spec, &mut rng);
    let flat = flat_screen(&truth, spec, &mut rng);
    if targets.len() < 6 || flat.len() < 50 {
        return Err(invalid(
            "targets_grid",
            "too few targets or flat pixels land on the sensor",
        ));
    }
    let e = &truth.element;
    let nominal = nominal(&truth, &mut rng);
    // Drawn last, so that a session without them is the one it always was.
    let screen_points = screen_marks(&truth, &frame, spec, &mut rng);
    let input = CalibrationInput {
        nominal,
        stage_std_mm: sd,
        element_center_stage_mm: spec.center_stage_mm,
        thickness_mm: (e.thickness_mm, 0.002),
        refractive_index: (e.refractive_index, 0.0002),
        flat_points_stage_mm: flat_points,
        element_points_stage_mm: element_points,
        targets,
        flat_screen: flat,
        screen_points,
    };
    Ok(SimulatedSession {
        input,
        truth,
        frame,
    })
}

/// A truth station of the paper's geometry for the simulated sessions: the
/// paper's camera (1296 × 966, 3.75 µm, f = 16 mm) at 825 mm and 15°, its
/// lens distorted (k1 = −0.12, k2 = 0.03, p = 4e-4, −2e-4), the screen
/// behind 1.8 mm of n = 1.52 cover glass, camera and screen turned a few
/// tenths of a degree off the symmetric layout, the element tilted by 1°
/// and 12 µm off the reference plane.
///
/// # Errors
/// [`StationError`] if the layout were not a valid station.
pub fn example_truth() -> Result<Station, StationError> {
    use crate::optics::station::{CoverGlass, SymmetricLayout};
    let layout = SymmetricLayout {
        camera_height_mm: 825.0,
        screen_height_mm: 825.0,
        tilt_deg: 15.0,
        focal_length_mm: 16.0,
        element: SymmetricLayout::paper_element(),
    };
    let camera = crate::optics::station::CameraProfile {
        format: "mfd-camera-profile/1".into(),
        model: "paper camera".into(),
        resolution: [1296, 966],
        pixel_pitch_um: 3.75,
        bit_depth: 12,
        distortion: None,
    };
    let display = crate::optics::station::DisplayProfile::paper_lcd();
    let mut s = layout.build(&camera, &display)?;
    s.camera.distortion = Some(Distortion {
        k: [-0.12, 0.03, 0.0],
        p: [0.0004, -0.0002],
    });
    s.screen.cover_glass = Some(CoverGlass {
        thickness_mm: 1.8,
        refractive_index: 1.52,
    });
    s.camera.principal_point_px = Point2::new(655.3, 478.9);
    for (name, d) in [
        (Dof::CameraRx, 0.3),
        (Dof::CameraRz, -0.4),
        (Dof::ScreenRy, 0.5),
        (Dof::ScreenRz, 0.2),
        (Dof::ScreenX, 3.0),
    ] {
        s = s.perturbed(name, d);
    }
    s.element.pose.tilt_deg = [1.0, -0.3];
    s.element.pose.offset_mm = Vector3::new(0.0, 0.0, 0.012);
    Station::from_file(&s.to_file(), Path::new("<example truth>"))
}

#[cfg(test)]
mod tests;
