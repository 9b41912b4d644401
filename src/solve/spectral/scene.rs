//! The scene's model: how many reflections the whole scene shows (the BIC
//! summed over the pixels), and every camera pixel's answer under it.

use rayon::prelude::*;

use super::model::MAX_REFLECTIONS;
use super::pixel::{PixelFits, Scored};
use super::prior::GeometryPrior;
use super::{PixelFlags, PixelResult};

/// The answer of a pixel that is not fitted.
pub(super) fn no_data() -> PixelResult {
    PixelResult {
        flags: PixelFlags::NO_DATA,
        ..PixelResult::empty()
    }
}

/// The scene's number of reflections: the model with the smallest BIC summed
/// over the pixels where every compared model was fitted (a pixel's
/// log-likelihoods add up over the scene). Returns it with the sums.
pub(super) fn scene_model(results: &[PixelFits], allow_third: bool) -> (usize, [f64; 3]) {
    let top = if allow_third { 3 } else { 2 };
    // Fixed chunks, summed in order: the same sums on every run.
    let partial: Vec<[f64; 3]> = results
        .par_chunks(4096)
        .map(|chunk| {
            let mut sums = [0.0; 3];
            for f in chunk {
                if (0..top).all(|k| f.model(k).is_some()) {
                    for (k, sum) in sums.iter_mut().enumerate().take(top) {
                        *sum += f.model(k).map_or(0.0, |c| c.bic);
                    }
                } else if let (2, Some(one), Some(two)) = (top, f.one_bic, f.model(1)) {
                    // A warm pixel: the one-reflection BIC from its pair's
                    // weaker amplitude.
                    sums[0] += one;
                    sums[1] += two.bic;
                }
            }
            sums
        })
        .collect();
    let sums = partial
        .iter()
        .fold([0.0; 3], |a, b| [a[0] + b[0], a[1] + b[1], a[2] + b[2]]);
    let best = (1..top).fold(0, |b, k| if sums[k] < sums[b] { k } else { b });
    // With no pixel fitted under every model, fall back to the largest.
    let chosen = if sums.iter().all(|&v| v == 0.0) {
        top
    } else {
        best + 1
    };
    (chosen, sums)
}

/// Every camera pixel's answer, in parallel, into `pixels` (one per
/// camera pixel, prepared as no data; a new array when it is not that
/// size): its candidate's fits under the scene's model, or no data. Returns
/// them with, per pixel, the number of reflections its own BIC prefers
/// (0: none fitted).
pub(super) fn pixel_answers(
    fits: &[PixelFits],
    prior: &GeometryPrior,
    scene_model: usize,
    pixels: Option<Vec<PixelResult>>,
) -> (Vec<PixelResult>, Vec<u8>) {
    let view = &prior.view;
    let mut index = vec![u32::MAX; view.width * view.height];
    for (q, &p) in prior.candidates.iter().enumerate() {
        index[p as usize] = q as u32;
    }
    // The model among the first `top` that this pixel's own BIC prefers.
    fn own(fits: &PixelFits, top: usize) -> Option<(usize, &Scored)> {
        (0..top)
            .filter_map(|k| fits.model(k).map(|c| (k, c)))
            .min_by(|a, b| a.1.bic.total_cmp(&b.1.bic))
    }
    let mut pixels = pixels
        .filter(|v| v.len() == index.len())
        .unwrap_or_else(|| vec![no_data(); index.len()]);
    let mut preferred = vec![0u8; index.len()];
    pixels
        .par_iter_mut()
        .zip(preferred.par_iter_mut())
        .zip(index.par_iter())
        .enumerate()
        .for_each(|(p, ((out, pref), &q))| {
            // Not a candidate: the prepared no-data answer stands.
            let Some(fits) = fits.get(q as usize) else {
                return;
            };
            // The scene's model where it applies; where the geometry
            // allows fewer reflections (the back path leaves through the
            // rim), the largest model that applies. Where the flat
            // plate's back path leaves through the rim but the real one
            // may not (the offset is borrowed), the pixel's own BIC decides.
            let rim = view.pixels[p].back.is_err();
            let chosen = if rim {
                own(fits, scene_model).map(|(_, c)| c)
            } else {
                (0..scene_model).rev().find_map(|k| fits.model(k))
            };
            *out = chosen.map_or_else(|| fits.base(), |c| c.result);
            *pref = own(fits, MAX_REFLECTIONS).map_or(0, |(k, _)| k as u8 + 1);
        });
    (pixels, preferred)
}
