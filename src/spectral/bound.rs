//! The Cramér–Rao bound of the screen points under the joint model.

use super::model::{normal_equations, Design, Params, MAX_REFLECTIONS};

/// Standard deviations `sqrt(σ_u² + σ_v²)` of S1 and S2 that no unbiased
/// estimator can beat, for two reflections at `uv` with background `offset`
/// and amplitudes `amp` (counts), falloff κ, and white noise of `sigma`
/// counts on every frame of `design`: the inverse Fisher information
/// `σ² (JᵀJ)⁻¹` of all 3K + 2 parameters. `None` if it is singular.
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
    let mut p = Params {
        k: 2,
        offset,
        amp: [0.0; MAX_REFLECTIONS],
        uv: [[0.0; 2]; MAX_REFLECTIONS],
        kappa,
    };
    p.amp[..2].copy_from_slice(&amp);
    p.uv[..2].copy_from_slice(&uv);
    let index: Vec<u32> = (0..design.frames.len() as u32).collect();
    let zeros = vec![0.0; index.len()];
    let cov = normal_equations(design, &index, &zeros, &p)
        .jtj
        .try_inverse()?
        * (sigma * sigma);
    let idx = [
        p.u_index(0),
        p.u_index(0) + 1,
        p.u_index(1),
        p.u_index(1) + 1,
    ];
    Some(std::array::from_fn(|a| {
        std::array::from_fn(|b| cov[(idx[a], idx[b])])
    }))
}
