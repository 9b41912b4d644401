//! Helpers shared by the Zernike tests: a seeded generator, Gauss-Legendre
//! nodes and the textbook factorial formula used as an independent reference.

/// xorshift64* generator: deterministic, good enough for test data.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Rng(seed.max(1))
    }

    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }

    /// A point uniform on the disk of `radius` about `center`.
    pub fn in_disk(&mut self, radius: f64, center: [f64; 2]) -> (f64, f64) {
        let r = radius * self.uniform().sqrt();
        let th = std::f64::consts::TAU * self.uniform();
        (center[0] + r * th.cos(), center[1] + r * th.sin())
    }
}

/// Gauss-Legendre nodes and weights on [0, 1] (exact for polynomials of
/// degree <= 2 n - 1), by Newton iteration on P_n.
pub fn gauss_legendre_01(n: usize) -> Vec<(f64, f64)> {
    let nf = n as f64;
    (0..n)
        .map(|i| {
            let mut x = (std::f64::consts::PI * (i as f64 + 0.75) / (nf + 0.5)).cos();
            let mut dp = 1.0;
            for _ in 0..100 {
                let (mut p0, mut p1) = (1.0, x);
                for k in 2..=n {
                    let kf = k as f64;
                    (p0, p1) = (p1, ((2.0 * kf - 1.0) * x * p1 - (kf - 1.0) * p0) / kf);
                }
                dp = nf * (x * p1 - p0) / (x * x - 1.0);
                let dx = p1 / dp;
                x -= dx;
                if dx.abs() < 1e-16 {
                    break;
                }
            }
            let w = 2.0 / ((1.0 - x * x) * dp * dp);
            (0.5 * (x + 1.0), 0.5 * w)
        })
        .collect()
}

fn factorial(k: u32) -> f64 {
    (1..=k).map(f64::from).product()
}

/// `R_n^m(rho)` by the explicit factorial sum, and the sum of the absolute
/// values of its terms (the scale of its rounding error).
pub fn radial_factorial(n: u32, m: u32, rho: f64) -> (f64, f64) {
    let (mut sum, mut abs) = (0.0, 0.0);
    for s in 0..=(n - m) / 2 {
        let c = factorial(n - s)
            / (factorial(s) * factorial((n + m) / 2 - s) * factorial((n - m) / 2 - s));
        let term = c * rho.powi((n - 2 * s) as i32);
        let term = if s % 2 == 0 { term } else { -term };
        sum += term;
        abs += term.abs();
    }
    (sum, abs)
}
