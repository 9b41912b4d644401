//! The Cramér–Rao bound of the screen points under the joint model, and
//! under the phase-shifting one-reflection model ([`phase_shifting_cov`]).

use super::model::{normal_equations, Design, Params, Repeats, MAX_REFLECTIONS};

/// Standard deviations `sqrt(σ_u² + σ_v²)` of S1 and S2 that no unbiased
/// estimator can beat, for two reflections at `uv` with background `offset`
/// and amplitudes `amp` (counts), falloff κ on the diagonals (a blur on the
/// screen period: [`Design::physical_falloff`] for the other fringe
/// lengths), and white noise of `sigma` counts on every frame of `design`:
/// the inverse Fisher information `σ² (JᵀJ)⁻¹` of all 3K + 1 + G
/// parameters, each falloff group's κ among them. `None` if it is singular.
pub fn two_reflection_bound(
    design: &Design,
    uv: [[f64; 2]; 2],
    offset: f64,
    amp: [f64; 2],
    kappa: f64,
    sigma: f64,
) -> Option<[f64; 2]> {
    let c = two_reflection_cov(design, uv, offset, amp, kappa, sigma)?;
    Some([
        (c[0][0] + c[1][1]).max(0.0).sqrt(),
        (c[2][2] + c[3][3]).max(0.0).sqrt(),
    ])
}

/// The bound's full covariance of `(u1, v1, u2, v2)`, px²: the two screen
/// points of one pixel are correlated where their spectra overlap.
pub fn two_reflection_cov(
    design: &Design,
    uv: [[f64; 2]; 2],
    offset: f64,
    amp: [f64; 2],
    kappa: f64,
    sigma: f64,
) -> Option<[[f64; 4]; 4]> {
    let rows = reflections_cov(design, None, &uv, offset, &amp, kappa, sigma)?;
    Some(std::array::from_fn(|a| rows[a]))
}

/// The bound's covariance of the reflections present, `(u, v)` per
/// reflection in `uv` order (1 or 2 reflections); the information summed
/// over `repeats` when given (the same sum, bit for bit without repeats),
/// else over every frame.
fn reflections_cov(
    design: &Design,
    repeats: Option<&Repeats>,
    uv: &[[f64; 2]],
    offset: f64,
    amp: &[f64],
    kappa: f64,
    sigma: f64,
) -> Option<Vec<[f64; 2 * 2]>> {
    let k = uv.len();
    let mut p = Params {
        k,
        offset,
        amp: [0.0; MAX_REFLECTIONS],
        uv: [[0.0; 2]; MAX_REFLECTIONS],
        kappa: design.physical_falloff(kappa),
    };
    p.amp[..k].copy_from_slice(amp);
    p.uv[..k].copy_from_slice(uv);
    let information = match repeats {
        Some(r) => r.information(design, &p),
        None => {
            let index: Vec<u32> = (0..design.frames.len() as u32).collect();
            let zeros = vec![0.0; index.len()];
            normal_equations(design, &index, &zeros, &p).jtj
        }
    };
    let cov = information.try_inverse()? * (sigma * sigma);
    // Flattened 2k × 2k block of the screen coordinates, row by row.
    let idx: Vec<usize> = (0..k)
        .flat_map(|j| [p.u_index(j), p.u_index(j) + 1])
        .collect();
    Some(
        idx.iter()
            .map(|&a| std::array::from_fn(|b| if b < idx.len() { cov[(a, idx[b])] } else { 0.0 }))
            .collect(),
    )
}

/// The bound at the truth for every pixel of a traced view, in the layout of
/// `screen_cov.npy` (`[rows, columns, 4, 4]`, covariance of u1, v1, u2, v2,
/// px², NaN where a reflection is absent): amplitudes `½·gain·weight`,
/// background `gain·(ambient + ½ Σ weights)`, falloff `kappa = 1/τ_max²` on
/// the diagonals ([`Design::physical_falloff`] on other directions), white
/// noise `sigma` counts per frame.
pub fn truth_cov_map(
    design: &Design,
    view: &crate::optics::trace::TracedView,
    gain: f64,
    ambient: f64,
    kappa: f64,
    sigma: f64,
) -> Vec<f64> {
    truth_cov_map_in(design, None, view, [gain, ambient, kappa, sigma])
}

/// [`truth_cov_map`] with the information summed over `repeats`, the
/// distinct frames of `design` with their counts
/// ([`Repeats::information`]): the same sums in exact arithmetic (bit for
/// bit without repeats), at a cost in distinct frames, not frames.
pub fn truth_cov_map_repeated(
    design: &Design,
    repeats: &Repeats,
    view: &crate::optics::trace::TracedView,
    gain: f64,
    ambient: f64,
    kappa: f64,
    sigma: f64,
) -> Vec<f64> {
    truth_cov_map_in(design, Some(repeats), view, [gain, ambient, kappa, sigma])
}

fn truth_cov_map_in(
    design: &Design,
    repeats: Option<&Repeats>,
    view: &crate::optics::trace::TracedView,
    [gain, ambient, kappa, sigma]: [f64; 4],
) -> Vec<f64> {
    let mut out = vec![f64::NAN; view.pixels.len() * 16];
    for (q, px) in view.pixels.iter().enumerate() {
        let present: Vec<(usize, crate::optics::trace::ScreenHit)> = [px.front, px.back]
            .into_iter()
            .enumerate()
            .filter_map(|(k, h)| h.ok().filter(|h| h.weight > 0.0).map(|h| (k, h)))
            .collect();
        if present.is_empty() {
            continue;
        }
        let uv: Vec<[f64; 2]> = present.iter().map(|(_, h)| [h.u, h.v]).collect();
        let amp: Vec<f64> = present.iter().map(|(_, h)| 0.5 * gain * h.weight).collect();
        let offset = gain * (ambient + 0.5 * present.iter().map(|(_, h)| h.weight).sum::<f64>());
        let Some(c) = reflections_cov(design, repeats, &uv, offset, &amp, kappa, sigma) else {
            continue;
        };
        let slots: Vec<usize> = present
            .iter()
            .flat_map(|(k, _)| [2 * k, 2 * k + 1])
            .collect();
        for (a, row) in c.iter().enumerate() {
            for (b, &sb) in slots.iter().enumerate() {
                out[16 * q + 4 * slots[a] + sb] = row[b];
            }
        }
    }
    out
}

/// The Cramér–Rao bound of a phase-shifting pixel's screen point under the
/// one-reflection model of [`super::phase`] at `params`, with the noise
/// variance `variance(μ)` (counts²) of a sample of mean μ on every frame of
/// the model's schedule: the `(u, v)` block of `(JᵀWJ)⁻¹`, px². `None` if
/// the information is singular.
pub fn phase_shifting_cov(
    model: &super::phase::PhaseModel,
    params: &super::phase::PhaseParams,
    variance: impl Fn(f64) -> f64,
) -> Option<[[f64; 2]; 2]> {
    let index: Vec<u32> = (0..model.design.frames.len() as u32).collect();
    let mut row = vec![0.0; model.len()];
    let w: Vec<f64> = index
        .iter()
        .map(|&i| 1.0 / variance(model.eval(i as usize, params, &mut row)))
        .collect();
    let zeros = vec![0.0; index.len()];
    let cov = model
        .normal(&index, &zeros, &w, params)
        .jtj
        .cholesky()?
        .inverse();
    Some([[cov[(0, 0)], cov[(0, 1)]], [cov[(1, 0)], cov[(1, 1)]]])
}
