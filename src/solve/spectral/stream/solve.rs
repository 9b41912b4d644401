//! The solve once all frames are in: every candidate's fits (through the
//! backend), the scene's number of reflections and each pixel's answer; or
//! the phase-shifting path.

use crate::solve::spectral::batch::{CpuFits, FitBackend, FitBatch, FitSettings};
use crate::solve::spectral::maps::SpectralMaps;
use crate::solve::spectral::phase::{self, PhaseModel, PhaseSchedule, PhaseSettings, Response};
use crate::solve::spectral::scene::{pixel_answers, scene_model};
use crate::solve::spectral::SpectralError;

use super::SpectralSolver;

impl SpectralSolver {
    /// Fits every pixel (all cores) once all frames are in.
    ///
    /// # Errors
    /// [`SpectralError::Frame`] when frames are missing.
    pub fn solve(&mut self) -> Result<SpectralMaps, SpectralError> {
        self.solve_with(&CpuFits)
    }

    /// [`SpectralSolver::solve`] with the per-pixel fits run by `backend`.
    /// The first solve takes the output arrays prepared while the frames
    /// streamed in; later ones allocate their own.
    ///
    /// # Errors
    /// [`SpectralError::Frame`] when frames are missing;
    /// [`SpectralError::Backend`] when the backend answers for the wrong
    /// number of pixels.
    pub fn solve_with(&mut self, backend: &dyn FitBackend) -> Result<SpectralMaps, SpectralError> {
        if self.received != self.frames() {
            return Err(SpectralError::Frame {
                frame: self.received,
                problem: format!(
                    "missing: only {} of {} frames arrived",
                    self.received,
                    self.frames()
                ),
            });
        }
        let sat = self.saturation();
        if let Some((schedule, response)) = &self.phase {
            return Ok(self.solve_phase(schedule, response, sat));
        }
        let prepared = self.prepared.take().and_then(|h| h.join().ok());
        let (fits_out, pixels_out) = match prepared {
            Some(p) => (Some(p.fits), Some(p.pixels)),
            None => (None, None),
        };
        let settings = FitSettings {
            saturation: sat,
            kappa0: self.config.falloff_start(&self.design),
            allow_third: self.config.third_reflection,
            max_iter: self.config.max_iter,
            warm_starts: self.config.warm_starts,
        };
        let mut batch = FitBatch::new(
            &self.design,
            &self.plans,
            &self.prior,
            (&self.series, self.stats.as_deref()),
            settings,
            fits_out,
        );
        let fits = backend.fit(&mut batch);
        let candidates = self.prior.candidates.len();
        if fits.len() != candidates {
            return Err(SpectralError::Backend {
                problem: format!("returned {} results for {candidates} pixels", fits.len()),
            });
        }
        let (scene_model, bic_sums) = scene_model(&fits, self.config.third_reflection);
        let (pixels, preferred) = pixel_answers(&fits, &self.prior, scene_model, pixels_out);
        // The fits (~0.3 kB per pixel) are freed off the caller's path.
        std::thread::spawn(move || drop(fits));
        Ok(SpectralMaps {
            width: self.width,
            height: self.height,
            pixels,
            preferred,
            scene_model: scene_model as u8,
            bic_sums,
            saturation_counts: sat,
        })
    }

    /// The phase-shifting path ([`phase`]): one reflection per pixel.
    fn solve_phase(
        &self,
        schedule: &PhaseSchedule,
        response: &Response,
        saturation: Option<u16>,
    ) -> SpectralMaps {
        let model = PhaseModel {
            design: &self.design,
            schedule,
            response,
        };
        let settings = PhaseSettings {
            saturation,
            kappa0: self.config.kappa_start(&self.design),
            max_iter: self.config.max_iter,
        };
        let fits = phase::solve_all(&model, &self.series, settings);
        let bic_one = fits.iter().filter_map(|f| f.model(0).map(|s| s.bic)).sum();
        let (pixels, preferred) = pixel_answers(&fits, &self.prior, 1, None);
        SpectralMaps {
            width: self.width,
            height: self.height,
            pixels,
            preferred,
            scene_model: 1,
            bic_sums: [bic_one, 0.0, 0.0],
            saturation_counts: saturation,
        }
    }
}
