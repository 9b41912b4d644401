//! Which μ a direction's periodogram cannot tell from its peak: the
//! aliases of the frames it takes, found from those frames' own τ and
//! phases rather than from a closed form for one kind of schedule.
//!
//! A fringe `B cos 2π(μτ + φ)` in the periodogram `Σ w (y − ȳ) r e^{−2πiμ'τ}`
//! (window `w`, `r` the frame's turn-back `e^{−2πiφ}` or 1) gives two
//! terms:
//! - `B/2 · W(μ' − μ)` with `W(δ) = Σ w r e^{2πiφ} e^{−2πiδτ}`: a copy of the
//!   peak at every `μ + δ` where `|W(δ)|` comes near `W(0)`;
//! - `B/2 · M(μ' + μ)` with `M(σ) = Σ w r e^{−2πiφ} e^{−2πiστ}`: a mirrored
//!   copy at every `σ − μ` where `|M(σ)|` does.
//!
//! On a grid of step Δ both repeat with period `1/Δ`, and with one phase
//! throughout `|M| = |W|`: the copies at `±μ + k/Δ`. But a grid whose
//! frames alternate between two phases has its periodogram on the frames of
//! one phase, every other grid point, until a gap of odd length shifts them
//! by one: its copies at `±μ + 1/(2Δ)` are nearly as strong as the peak,
//! and no closed form in Δ names them. So `W` and `M` are computed here,
//! once per direction, by the direction's own FFT over one period, and
//! their local maxima above [`ALIAS_SHARE`] of `W(0)` are the copies.

use rustfft::num_complex::Complex;

use super::Plan;

/// A copy whose window is at least this share of the peak's (in
/// amplitude: a quarter in power) may be the strongest of the periodogram
/// where noise, the pair's interference or the window's slope lower the
/// true peak by as much; a weaker one cannot be taken for it unless the
/// peak itself is barely detected. A Hann-windowed grid's sidelobes stay
/// below 0.03, and a gap of a third of the span raises them to about
/// a third: neither is counted.
pub const ALIAS_SHARE: f64 = 0.5;

/// A sidelobe of the window this near its peak ([`NEAR_BINS`]) and at
/// least this share of it (in amplitude) is a place the periodogram's
/// peak may sit instead of the fringe: the pair's two fringes, a bin or
/// so apart, add their lobes there, and a grid with a gap (two blocks of
/// τ some distance D apart) has sidelobes at `k/D`, about 0.6 of the peak
/// at two bins where the gap is a quarter to a third of the span. The
/// pair's start is scanned there too ([`Aliases::near`]).
pub const NEAR_SHARE: f64 = 0.3;

/// How far from the peak, in bins, [`NEAR_SHARE`]'s sidelobes are sought:
/// beyond the pair scan's own reach (1¼ pair offsets, about a bin) and a
/// gap's first few fringes.
pub const NEAR_BINS: f64 = 8.0;

/// The copies of a direction's periodogram peak, as offsets: the peak at
/// μ shows as strongly at `μ + shift + k·period` and at
/// `mirror − μ + k·period` (every integer k).
#[derive(Debug, Clone, PartialEq)]
pub struct Aliases {
    /// `1/Δ` of the grid the frames lie on.
    pub period: f64,
    /// `δ ∈ [0, period)` of `W`'s copies, 0 first.
    pub shifts: Vec<f64>,
    /// `σ ∈ [0, period)` of `M`'s copies.
    pub mirrors: Vec<f64>,
    /// The window's strong sidelobes near its peak ([`NEAR_SHARE`],
    /// [`NEAR_BINS`]), as signed offsets δ: a peak at μ may belong to a
    /// fringe at `μ − δ`.
    pub near: Vec<f64>,
}

impl Aliases {
    /// Every μ within `[lo, hi]` the periodogram cannot tell from a peak at
    /// `mu`, `mu` itself first.
    pub fn of(&self, mu: f64, lo: f64, hi: f64) -> Vec<f64> {
        let p = self.period;
        let mut out = vec![mu];
        let bases = self
            .shifts
            .iter()
            .map(|&d| mu + d)
            .chain(self.mirrors.iter().map(|&s| s - mu));
        for b in bases {
            let mut m = b - ((b - lo) / p).floor() * p;
            while m <= hi {
                out.push(m);
                m += p;
            }
        }
        out
    }
}

/// The aliases of one direction's periodogram: its `plan` (grids only:
/// `None` for τ off any grid, whose near-repeats are weaker than the
/// peak), its frames' window `w`, turn-back `rot`, phases `phase` in
/// cycles, τ span. Copies of `W` within three bins of its own peak at 0
/// are that peak's lobe, not copies.
pub fn aliases(
    plan: &Plan,
    window: &[f64],
    rot: &[Complex<f64>],
    phase: &[f64],
    span: f64,
) -> Option<Aliases> {
    let turn = |k: usize, sign: f64| {
        let (s, c) = (sign * std::f64::consts::TAU * phase[k]).sin_cos();
        rot[k] * Complex::new(c, s) * window[k]
    };
    let w: Vec<Complex<f64>> = (0..window.len()).map(|k| turn(k, 1.0)).collect();
    let m: Vec<Complex<f64>> = (0..window.len()).map(|k| turn(k, -1.0)).collect();
    let (period, wp) = one_period(plan, &w)?;
    let (_, mp) = one_period(plan, &m)?;
    let peak = window.iter().sum::<f64>();
    if !(peak > 0.0 && period.is_finite() && period > 0.0) {
        return None;
    }
    let lobe = 3.0 / span.max(1e-12);
    let step = period / wp.len() as f64;
    let mut shifts = vec![0.0];
    shifts.extend(
        maxima(&wp, ALIAS_SHARE * peak)
            .into_iter()
            .map(|j| j * step)
            .filter(|&d| d > lobe && period - d > lobe),
    );
    let mirrors = maxima(&mp, ALIAS_SHARE * peak)
        .into_iter()
        .map(|j| j * step)
        .collect();
    let reach = NEAR_BINS / span.max(1e-12);
    let near = maxima(&wp, NEAR_SHARE * peak)
        .into_iter()
        .map(|j| j * step)
        .flat_map(|d| [d, d - period])
        .filter(|d| d.abs() > 0.5 * step && d.abs() <= reach)
        .collect();
    Some(Aliases {
        period,
        shifts,
        mirrors,
        near,
    })
}

/// `|Σ c_k e^{−2πi f τ_k}|` over one period of the grid, `f = j·period/N`:
/// the period and the N magnitudes; `None` off a grid.
fn one_period(plan: &Plan, c: &[Complex<f64>]) -> Option<(f64, Vec<f64>)> {
    let (fft, dtau, mut buf) = match plan {
        Plan::Uniform { fft, n_fft, dtau } => {
            let mut buf = c.to_vec();
            buf.resize(*n_fft, Complex::new(0.0, 0.0));
            (fft, *dtau, buf)
        }
        Plan::Grid {
            fft, slot, dtau, ..
        } => {
            let mut buf = vec![Complex::new(0.0, 0.0); fft.len()];
            for (&k, &v) in slot.iter().zip(c) {
                buf[k as usize] += v;
            }
            (fft, *dtau, buf)
        }
        Plan::Direct { .. } => return None,
    };
    let mut scratch = vec![Complex::new(0.0, 0.0); fft.get_inplace_scratch_len()];
    fft.process_with_scratch(&mut buf, &mut scratch);
    Some((1.0 / dtau, buf.iter().map(|z| z.norm()).collect()))
}

/// Local maxima of the circular sequence `a` at or above `floor`, each at
/// its parabola-refined fractional index.
fn maxima(a: &[f64], floor: f64) -> Vec<f64> {
    let n = a.len();
    (0..n)
        .filter(|&j| {
            let (l, r) = (a[(j + n - 1) % n], a[(j + 1) % n]);
            a[j] >= floor && a[j] >= l && a[j] > r
        })
        .map(|j| {
            let (l, c, r) = (a[(j + n - 1) % n], a[j], a[(j + 1) % n]);
            let denom = l - 2.0 * c + r;
            let frac = if denom < 0.0 {
                0.5 * (l - r) / denom
            } else {
                0.0
            };
            (j as f64 + frac).rem_euclid(n as f64)
        })
        .collect()
}
