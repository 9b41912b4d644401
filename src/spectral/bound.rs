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
    let sd = |j: usize| {
        let u = p.u_index(j);
        (cov[(u, u)] + cov[(u + 1, u + 1)]).max(0.0).sqrt()
    };
    Some([sd(0), sd(1)])
}
