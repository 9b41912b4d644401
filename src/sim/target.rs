//! A simulated point target seen by the camera: a pixel-integrated Gaussian
//! spot on an ambient background with a gradient and read noise
//! ([`render_spot`]), and a [`Camera`] that delivers such frames
//! ([`SpotCamera`]), for calibration sessions without hardware and for the
//! centroid's tests.

use std::time::{Duration, Instant};

use nalgebra::Point2;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use rand_xoshiro::Xoshiro256PlusPlus;

use crate::acquire::camera::{Camera, CameraConfig, CameraError, CameraInfo, Frame, PixelFormat};

/// What a target frame shows.
#[derive(Debug, Clone, PartialEq)]
pub struct SpotScene {
    /// Sensor `(width, height)`, px.
    pub resolution: (u32, u32),
    /// Bits per sample (8 or 16; the frame is clipped to full scale).
    pub bit_depth: u8,
    /// The spot's centre, pixel-centre convention (a spot centred on pixel
    /// `(i, j)` is at `(i + 0.5, j + 0.5)`), px; `None` for no spot.
    pub centre_px: Option<Point2<f64>>,
    /// The Gaussian's standard deviation, px.
    pub sigma_px: f64,
    /// The spot's peak above the background, counts.
    pub peak_counts: f64,
    /// Background at the sensor's centre, counts.
    pub ambient_counts: f64,
    /// Background gradient along x and y, counts per px.
    pub gradient_counts_per_px: [f64; 2],
    /// Read noise, 1 σ, counts.
    pub noise_counts: f64,
}

/// Sub-samples per pixel and axis: the midpoint rule's error on a Gaussian
/// of σ ≥ 0.8 px is below 1e-4 of a pixel's value, far under any noise.
const SUBSAMPLES: usize = 5;

/// Renders `scene` with the noise of `rng`, row-major counts.
pub fn render_spot(scene: &SpotScene, rng: &mut Xoshiro256PlusPlus) -> Vec<u16> {
    let (w, h) = (scene.resolution.0 as usize, scene.resolution.1 as usize);
    let full = f64::from((1u32 << scene.bit_depth) - 1);
    let (cx, cy) = (w as f64 / 2.0, h as f64 / 2.0);
    let [gx, gy] = scene.gradient_counts_per_px;
    let mut img: Vec<f64> = (0..w * h)
        .map(|k| {
            let (i, j) = ((k % w) as f64 + 0.5, (k / w) as f64 + 0.5);
            scene.ambient_counts + gx * (i - cx) + gy * (j - cy)
        })
        .collect();
    if let Some(c) = scene.centre_px {
        add_spot(&mut img, w, h, c, scene.sigma_px, scene.peak_counts);
    }
    let noise = Normal::new(0.0, scene.noise_counts.max(0.0)).ok();
    img.iter()
        .map(|v| {
            let n = noise.as_ref().map_or(0.0, |d| d.sample(rng));
            (v + n).round().clamp(0.0, full) as u16
        })
        .collect()
}

/// Adds a pixel-integrated Gaussian of peak `peak` (its value at the centre
/// of a continuous image) within ±6σ of `c`.
fn add_spot(img: &mut [f64], w: usize, h: usize, c: Point2<f64>, sigma: f64, peak: f64) {
    let reach = (6.0 * sigma).ceil() + 1.0;
    let i0 = (c.x - reach).floor().max(0.0) as usize;
    let j0 = (c.y - reach).floor().max(0.0) as usize;
    let i1 = ((c.x + reach).ceil().max(0.0) as usize).min(w);
    let j1 = ((c.y + reach).ceil().max(0.0) as usize).min(h);
    let step = 1.0 / SUBSAMPLES as f64;
    let inv = 1.0 / (2.0 * sigma * sigma);
    for j in j0..j1 {
        for i in i0..i1 {
            let mut sum = 0.0;
            for sj in 0..SUBSAMPLES {
                let y = j as f64 + (sj as f64 + 0.5) * step - c.y;
                for si in 0..SUBSAMPLES {
                    let x = i as f64 + (si as f64 + 0.5) * step - c.x;
                    sum += (-(x * x + y * y) * inv).exp();
                }
            }
            img[j * w + i] += peak * sum * step * step;
        }
    }
}

/// A camera looking at a point target: every frame is [`render_spot`] of
/// its scene, with fresh noise.
#[derive(Debug)]
pub struct SpotCamera {
    scene: SpotScene,
    rng: Xoshiro256PlusPlus,
    streaming: bool,
    sequence: u64,
}

impl SpotCamera {
    /// A camera showing `scene`, its noise seeded by `seed`.
    pub fn new(scene: SpotScene, seed: u64) -> SpotCamera {
        SpotCamera {
            scene,
            rng: Xoshiro256PlusPlus::seed_from_u64(seed),
            streaming: false,
            sequence: 0,
        }
    }

    /// The scene it shows.
    pub fn scene(&self) -> &SpotScene {
        &self.scene
    }

    /// One frame of the scene with fresh noise, row-major counts (what
    /// [`Camera::next_frame`] delivers, for a feed that serves it elsewhere).
    pub fn render(&mut self) -> Vec<u16> {
        render_spot(&self.scene, &mut self.rng)
    }
}

impl Camera for SpotCamera {
    fn describe(&self) -> CameraInfo {
        let (w, h) = self.scene.resolution;
        CameraInfo {
            backend: "sim",
            id: "sim".into(),
            model: "mfd simulated point target".into(),
            sensor: (w, h),
            resolution: (w, h),
            pixel_formats: PixelFormat::from_bit_depth(u32::from(self.scene.bit_depth))
                .into_iter()
                .collect(),
            software_trigger: true,
        }
    }

    fn configure(&mut self, config: &CameraConfig) -> Result<(), CameraError> {
        if let Some(f) = config.pixel_format {
            if f.bit_depth() != self.scene.bit_depth {
                return Err(CameraError::Config {
                    device: "sim".into(),
                    field: "pixel_format",
                    problem: format!(
                        "{f:?} asked, the target renders {} bits",
                        self.scene.bit_depth
                    ),
                });
            }
        }
        Ok(())
    }

    fn start(&mut self) -> Result<(), CameraError> {
        self.streaming = true;
        Ok(())
    }

    fn stop(&mut self) -> Result<(), CameraError> {
        self.streaming = false;
        Ok(())
    }

    fn trigger(&mut self) -> Result<(), CameraError> {
        Ok(())
    }

    fn next_frame(&mut self, timeout: Duration) -> Result<Frame, CameraError> {
        if !self.streaming {
            return Err(CameraError::Timeout {
                device: "sim".into(),
                waited: timeout,
            });
        }
        self.sequence += 1;
        Ok(Frame {
            data: self.render(),
            width: self.scene.resolution.0,
            height: self.scene.resolution.1,
            bit_depth: self.scene.bit_depth,
            timestamp: Instant::now(),
            sequence: self.sequence,
            exposed_pattern: None,
        })
    }
}
