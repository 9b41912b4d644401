//! An independent generator of calibration sessions: from a [`Draw`] it
//! builds the truth (camera, screen, element and stage frame) with its own
//! geometry ([`super::optics`]), every reading of `calibration.md` as the
//! lab's instruments would give it, and the truth and nominal stations as
//! `mfd-station/2` TOML text, which reaches mfd only through its reader
//! (`Station::from_toml_str`): the spec's contract, not mfd's optics, is
//! what the two implementations share.
//!
//! Marked screen pixels are drawn only without a cover glass: the spec
//! does not say where a PSM's best focus stands on a mark seen through the
//! glass (the slab is astigmatic off its normal), so a generator written
//! from the spec has no model of it to be independent with.

use mfd::calibrate::input::{CalibrationInput, FlatPixel, MarkedPixel, Target};
use mfd::calibrate::params::WorldFrame;
use mfd::optics::station::Station;
use nalgebra::{Matrix2, Matrix3, Point2, Point3, Rotation3, Unit, Vector3};
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, StandardNormal};
use rand_xoshiro::Xoshiro256PlusPlus;

use super::draw::Draw;
use super::optics::{flat_uv, Cam, Scr};
use super::toml::station_toml;

/// The element as the station file has it.
#[derive(Debug, Clone, PartialEq)]
pub struct Elem {
    /// Refractive index.
    pub index: f64,
    /// Thickness, mm.
    pub thickness_mm: f64,
    /// Aperture radius, mm (centred on the world origin).
    pub radius_mm: f64,
    /// `offset_mm`, world, mm.
    pub offset_mm: Vector3<f64>,
    /// `tilt_deg`: about world x, then world y.
    pub tilt_deg: [f64; 2],
}

/// The stage frame: `stage = m · world + origin`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StageFrame {
    /// Columns: the world's axes in stage coordinates.
    pub m: Matrix3<f64>,
    /// Stage reading of the world origin, mm.
    pub origin: Vector3<f64>,
}

impl StageFrame {
    /// Stage reading of world point `p` (no noise).
    pub fn stage(&self, p: &Point3<f64>) -> Vector3<f64> {
        self.m * p.coords + self.origin
    }

    /// The same frame as mfd writes it (`calibration.md`'s definition:
    /// the plane `z = h + sx (x − cx) + sy (y − cy)` in the stage frame).
    pub fn world_frame(&self) -> WorldFrame {
        let n = self.m.column(2);
        WorldFrame {
            plane: [self.origin.z, -n.x / n.z, -n.y / n.z],
            center_stage_mm: [self.origin.x, self.origin.y],
        }
    }
}

/// One generated session and its truth.
#[derive(Debug, Clone)]
pub struct Session {
    /// What it was drawn with.
    pub draw: Draw,
    /// The truth's camera, screen and element (the generator's own types).
    pub cam: Cam,
    /// See [`Session::cam`].
    pub scr: Scr,
    /// See [`Session::cam`].
    pub elem: Elem,
    /// The truth as mfd reads it from its TOML text.
    pub truth: Station,
    /// The truth's stage frame.
    pub stage: StageFrame,
    /// The session's numbers, the nominal station read from its TOML text.
    pub input: CalibrationInput,
}

fn normal(rng: &mut Xoshiro256PlusPlus) -> f64 {
    StandardNormal.sample(rng)
}

fn random_axis(rng: &mut Xoshiro256PlusPlus) -> Unit<Vector3<f64>> {
    Unit::new_normalize(Vector3::new(normal(rng), normal(rng), normal(rng)))
}

/// A rotation by `max_deg` times a uniform fraction about a random axis.
fn small_turn(rng: &mut Xoshiro256PlusPlus, max_deg: f64) -> Matrix3<f64> {
    let axis = random_axis(rng);
    let angle = rng.random_range(0.0..=1.0) * max_deg.to_radians();
    *Rotation3::from_axis_angle(&axis, angle).matrix()
}

/// The stage turned by the drawn angle, then about world z so that the
/// stage's x axis projects onto the world's +x (the spec's definition of
/// the world's x), shifted so the element's centre is at stage x, y in
/// 50–150 mm and the flat 0–50 mm up.
fn stage_frame(draw: &Draw, rng: &mut Xoshiro256PlusPlus) -> StageFrame {
    let m = small_turn(rng, draw.stage_turn_deg);
    let sx = m.row(0).transpose();
    let m = m * Rotation3::from_axis_angle(&Vector3::z_axis(), sx.y.atan2(sx.x)).matrix();
    let origin = Vector3::new(
        rng.random_range(50.0..150.0),
        rng.random_range(50.0..150.0),
        rng.random_range(0.0..50.0),
    );
    StageFrame { m, origin }
}

/// The camera at the drawn distance and tilt, at a random azimuth, aimed
/// near the flat's centre, rolled at random about its axis.
fn camera(draw: &Draw, rng: &mut Xoshiro256PlusPlus) -> Cam {
    let (t, phi) = (
        draw.tilt_deg.to_radians(),
        rng.random_range(0.0..std::f64::consts::TAU),
    );
    let aim = Point3::new(
        0.05 * draw.flat_radius_mm * rng.random_range(-1.0..1.0),
        0.05 * draw.flat_radius_mm * rng.random_range(-1.0..1.0),
        0.0,
    );
    let centre =
        aim + draw.distance_mm * Vector3::new(t.sin() * phi.cos(), t.sin() * phi.sin(), t.cos());
    let z = (aim - centre).normalize();
    let x0 = Vector3::z().cross(&z).normalize();
    let y0 = z.cross(&x0);
    let roll = rng.random_range(0.0..std::f64::consts::TAU);
    let x = roll.cos() * x0 + roll.sin() * y0;
    let [w, h] = draw.sensor;
    let focal_mm =
        f64::from(w) / 2.0 * draw.pixel_pitch_um / 1000.0 / draw.half_fov_deg.to_radians().tan();
    Cam {
        centre,
        rotation: Matrix3::from_columns(&[x, z.cross(&x), z]),
        focal_mm,
        pitch_um: draw.pixel_pitch_um,
        resolution: draw.sensor,
        principal_px: [
            f64::from(w) / 2.0 + rng.random_range(-20.0..20.0),
            f64::from(h) / 2.0 + rng.random_range(-20.0..20.0),
        ],
        k: [draw.k[0], draw.k[1], 0.0],
        p: draw.p,
        aspect: draw.aspect,
    }
}

/// The camera pixels sampled for the flat map (a 36 × 27 grid over the
/// sensor) whose rays meet the flat inside its radius.
fn flat_pixels(cam: &Cam, scr: &Scr, radius: f64) -> Vec<([u32; 2], Point2<f64>)> {
    let [w, h] = cam.resolution;
    let (nx, ny) = (36, 27);
    let mut out = Vec::new();
    for a in 0..nx {
        for b in 0..ny {
            let i = ((f64::from(a) + 0.5) / f64::from(nx) * f64::from(w)) as u32;
            let j = ((f64::from(b) + 0.5) / f64::from(ny) * f64::from(h)) as u32;
            let px = Point2::new(f64::from(i) + 0.5, f64::from(j) + 0.5);
            if let Some((uv, hit)) = flat_uv(cam, scr, px) {
                if hit.coords.xy().norm() <= radius {
                    out.push(([i, j], uv));
                }
            }
        }
    }
    out
}

/// The screen facing the flat along the camera's reflected axis, turned
/// up to 5° off it and rolled at random, sized to hold every sampled flat
/// pixel's landing with a 20-pixel margin.
fn screen(draw: &Draw, cam: &Cam, rng: &mut Xoshiro256PlusPlus) -> Scr {
    let z = cam.rotation.column(2).into_owned();
    let aim = cam.centre + (-cam.centre.z / z.z) * z;
    let r = Vector3::new(z.x, z.y, -z.z);
    let centre = aim + draw.screen_distance_mm * r;
    let n = small_turn(rng, 5.0) * -r;
    let u0 = (Vector3::x() - Vector3::x().dot(&n) * n).normalize();
    let roll = Rotation3::from_axis_angle(
        &Unit::new_normalize(n),
        rng.random_range(0.0..std::f64::consts::TAU),
    );
    let u = roll * u0;
    let pitch_mm = [0.18, 0.27, 0.311][rng.random_range(0..3)];
    let mut scr = Scr {
        origin: centre,
        u,
        v: n.cross(&u),
        pitch_mm,
        resolution: [1, 1],
        glass: draw.cover_glass,
    };
    // Landings relative to the centre: the glass only depends on the
    // pixel plane, not on where its origin lies in it.
    let extent = flat_pixels(cam, &scr, draw.flat_radius_mm)
        .iter()
        .fold([0.0f64; 2], |e, (_, uv)| {
            [e[0].max(uv.x.abs()), e[1].max(uv.y.abs())]
        });
    let size = extent.map(|e| 2 * (e.ceil() as u32 + 20));
    scr.origin =
        centre - pitch_mm * (f64::from(size[0]) / 2.0 * scr.u + f64::from(size[1]) / 2.0 * scr.v);
    scr.resolution = size;
    scr
}

/// The element's rotation `R_y(ry) R_x(rx)` (`interchange.md`).
fn element_rotation(e: &Elem) -> Matrix3<f64> {
    let [rx, ry] = e.tilt_deg.map(f64::to_radians);
    *(Rotation3::from_axis_angle(&Vector3::y_axis(), ry)
        * Rotation3::from_axis_angle(&Vector3::x_axis(), rx))
    .matrix()
}

/// The nominal station: the truth's camera and screen moved and turned by
/// up to the drawn fraction of 10 mm and 0.5°, its focal length by 0.5 mm,
/// its principal point by 10 px, the cover glass by 0.05 mm; no
/// distortion (the lab does not know its lens's); the element untilted.
fn nominal(
    draw: &Draw,
    cam: &Cam,
    scr: &Scr,
    elem: &Elem,
    rng: &mut Xoshiro256PlusPlus,
) -> (Cam, Scr, Elem) {
    let s = draw.nominal_scale;
    let mut shift = || Vector3::from_fn(|_, _| s * rng.random_range(-10.0..10.0));
    let (dc, ds) = (shift(), shift());
    let mut c = cam.clone();
    c.centre += dc;
    c.rotation = small_turn(rng, 0.5 * s) * c.rotation;
    c.focal_mm += s * rng.random_range(-0.5..0.5);
    c.principal_px = c
        .principal_px
        .map(|v| v + s * rng.random_range(-10.0..10.0));
    c.k = [0.0; 3];
    c.p = [0.0; 2];
    // A camera that is not square is declared so, as square pixels: the
    // lab knows to have it estimated, not its value.
    c.aspect = cam.aspect.map(|_| 1.0);
    let mut sc = scr.clone();
    let q = sc.world(
        f64::from(sc.resolution[0]) / 2.0,
        f64::from(sc.resolution[1]) / 2.0,
    );
    let turn = small_turn(rng, 0.5 * s);
    sc.origin = q + turn * (sc.origin - q) + ds;
    sc.u = turn * sc.u;
    sc.v = turn * sc.v;
    if let Some((t, n)) = sc.glass {
        sc.glass = Some((t + s * rng.random_range(-0.05..0.05), n));
    }
    let e = Elem {
        offset_mm: Vector3::zeros(),
        tilt_deg: [0.0; 2],
        ..elem.clone()
    };
    (c, sc, e)
}

impl Session {
    /// Generates the session of `draw`.
    pub fn new(draw: &Draw) -> Session {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(draw.seed ^ 0x3535_3535);
        let stage = stage_frame(draw, &mut rng);
        let cam = camera(draw, &mut rng);
        let scr = screen(draw, &cam, &mut rng);
        let elem = Elem {
            index: rng.random_range(1.45..1.6),
            thickness_mm: rng.random_range(5.0..20.0),
            radius_mm: draw.flat_radius_mm,
            offset_mm: Vector3::new(0.0, 0.0, draw.element_dz_mm),
            tilt_deg: draw.element_tilt_deg,
        };
        let truth_text = station_toml(&cam, &scr, &elem);
        let truth = Station::from_toml_str(&truth_text, std::path::Path::new("soak-truth.toml"))
            .unwrap_or_else(|e| {
                panic!(
                    "seed {}: the truth station is invalid: {e}\n{truth_text}",
                    draw.seed
                )
            });
        let (nc, ns, ne) = nominal(draw, &cam, &scr, &elem, &mut rng);
        let nominal_text = station_toml(&nc, &ns, &ne);
        let nominal =
            Station::from_toml_str(&nominal_text, std::path::Path::new("soak-nominal.toml"))
                .unwrap_or_else(|e| {
                    panic!(
                        "seed {}: the nominal station is invalid: {e}\n{nominal_text}",
                        draw.seed
                    )
                });
        let readings = Readings::new(draw, &stage, &cam, &scr, &elem, &mut rng);
        let input = CalibrationInput {
            nominal,
            stage_std_mm: draw.stage_std_mm,
            element_center_stage_mm: [stage.origin.x, stage.origin.y],
            thickness_mm: (elem.thickness_mm, 0.002),
            refractive_index: (elem.index, 0.0002),
            flat_points_stage_mm: readings.flat_points,
            element_points_stage_mm: readings.element_points,
            targets: readings.targets,
            flat_screen: readings.flat_screen,
            screen_points: readings.marks,
        };
        Session {
            draw: draw.clone(),
            cam,
            scr,
            elem,
            truth,
            stage,
            input,
        }
    }

    /// The camera pixels of the flat map (noise-free truth screen points):
    /// what the calibrated station's flat reflection is compared with.
    pub fn truth_flat_points(&self) -> Vec<([u32; 2], Point2<f64>)> {
        flat_pixels(&self.cam, &self.scr, self.elem.radius_mm)
            .into_iter()
            .filter(|(_, uv)| on_screen(&self.scr, uv))
            .collect()
    }
}

fn on_screen(scr: &Scr, uv: &Point2<f64>) -> bool {
    let [w, h] = scr.resolution.map(f64::from);
    (0.0..=w).contains(&uv.x) && (0.0..=h).contains(&uv.y)
}

/// Every reading of the session, with the drawn noise.
struct Readings {
    flat_points: Vec<Vector3<f64>>,
    element_points: Vec<Vector3<f64>>,
    targets: Vec<Target>,
    flat_screen: Vec<FlatPixel>,
    marks: Vec<MarkedPixel>,
}

/// Draws the readings' noise (none for a noise-free session).
struct Noise<'a> {
    rng: &'a mut Xoshiro256PlusPlus,
    on: f64,
}

impl Noise<'_> {
    fn draw(&mut self, sd: f64) -> f64 {
        self.on * sd * normal(self.rng)
    }

    /// A stage reading of world point `p`.
    fn read(&mut self, stage: &StageFrame, sd: f64, p: &Point3<f64>) -> Vector3<f64> {
        stage.stage(p) + Vector3::new(self.draw(sd), self.draw(sd), self.draw(sd))
    }

    fn px(&mut self, sd: f64) -> nalgebra::Vector2<f64> {
        nalgebra::Vector2::new(self.draw(sd), self.draw(sd))
    }
}

impl Readings {
    fn new(
        draw: &Draw,
        stage: &StageFrame,
        cam: &Cam,
        scr: &Scr,
        elem: &Elem,
        rng: &mut Xoshiro256PlusPlus,
    ) -> Readings {
        let mut n = Noise {
            rng,
            on: if draw.noise_free { 0.0 } else { 1.0 },
        };
        let s = draw.stage_std_mm;
        let r = draw.flat_radius_mm;
        let flat_points = (0..9)
            .map(|k| {
                let at = |m: i32| 0.6 * r * f64::from(m - 1);
                n.read(stage, s, &Point3::new(at(k % 3), at(k / 3), 0.0))
            })
            .collect();
        // The element's front `z' = 0` at five points of its own frame,
        // placed by `p = c + R (p' − c) + offset` with `c` the origin.
        let rot = element_rotation(elem);
        let element_points = [(0.0, 0.0), (0.5, 0.0), (-0.5, 0.0), (0.0, 0.5), (0.0, -0.5)]
            .iter()
            .take(draw.element_points)
            .map(|&(a, b)| {
                let p = Point3::from(rot * Vector3::new(a * r, b * r, 0.0) + elem.offset_mm);
                n.read(stage, s, &p)
            })
            .collect();
        let sd = draw.centroid_std_px;
        let targets = target_points(draw, cam)
            .into_iter()
            .map(|p| {
                let pixel = cam.project(&p).expect("targets lie in front of the camera");
                Target {
                    stage_mm: n.read(stage, s, &p),
                    pixel: pixel + n.px(sd),
                    pixel_cov_px2: Matrix2::identity() * sd * sd,
                }
            })
            .collect();
        let sd = draw.flat_std_px;
        let flat_screen = flat_pixels(cam, scr, r)
            .into_iter()
            .filter(|(_, uv)| on_screen(scr, uv))
            .map(|(pixel, uv)| FlatPixel {
                pixel,
                screen_px: uv + n.px(sd),
                screen_cov_px2: Matrix2::identity() * sd * sd,
            })
            .collect();
        let [w, h] = scr.resolution;
        let marks = (0..draw.marks as u32)
            .map(|k| {
                // Pixel centres of a 3 × 3 grid at 1/6, 1/2, 5/6 of the screen.
                let c = f64::from(w * (1 + 2 * (k % 3)) / 6) + 0.5;
                let r = f64::from(h * (1 + 2 * (k / 3)) / 6) + 0.5;
                MarkedPixel {
                    stage_mm: n.read(stage, s, &scr.world(c, r)),
                    screen_px: Point2::new(c, r),
                }
            })
            .collect();
        Readings {
            flat_points,
            element_points,
            targets,
            flat_screen,
            marks,
        }
    }
}

/// The targets' true positions: `draw.targets` over the layers, each at a
/// random position of the central `sensor_fraction` of the sensor (by the
/// distortion-free ray: where on the sensor does not need to be exact),
/// at its layer's height.
fn target_points(draw: &Draw, cam: &Cam) -> Vec<Point3<f64>> {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(draw.seed ^ 0x7a7a);
    let [w, h] = cam.resolution.map(f64::from);
    let f = draw.sensor_fraction;
    (0..draw.targets)
        .map(|k| {
            let z = draw.layer_base_mm + draw.layer_gap_mm * (k % draw.layers) as f64;
            let px = Point2::new(
                w * (0.5 + f * rng.random_range(-0.5..0.5)),
                h * (0.5 + f * rng.random_range(-0.5..0.5)),
            );
            let d = cam
                .ray(px)
                .expect("the drawn distortion is invertible over the sensor");
            cam.centre + ((z - cam.centre.z) / d.z) * d
        })
        .collect()
}
