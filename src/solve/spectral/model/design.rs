//! The schedule as the model sees it: each frame's τ, phase and direction,
//! the directions' fringe axes on the screen, and their falloff groups with
//! the κ of each ([`Falloff`]).

use super::MAX_GROUPS;
use crate::acquire::patterns::FringeAxis;

/// The modulation falloff: κ = 1/τ_max² of each falloff group
/// ([`Design::falloff_group`]); indexed by group.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Falloff {
    /// Groups in use, 1 ≤ G ≤ [`MAX_GROUPS`].
    pub groups: usize,
    /// κ per group (entries past `groups` unused).
    pub kappa: [f64; MAX_GROUPS],
}

impl Falloff {
    /// The same κ in each of `groups` groups.
    pub fn uniform(groups: usize, kappa: f64) -> Self {
        Falloff {
            groups: groups.clamp(1, MAX_GROUPS),
            kappa: [kappa; MAX_GROUPS],
        }
    }

    /// κ of the groups in use.
    pub fn values(&self) -> &[f64] {
        &self.kappa[..self.groups]
    }

    /// Whether every group's κ lies in `[lo, hi]`.
    pub fn within(&self, lo: f64, hi: f64) -> bool {
        self.values().iter().all(|&k| k >= lo && k <= hi)
    }
}

impl std::ops::Index<usize> for Falloff {
    type Output = f64;
    #[inline]
    fn index(&self, g: usize) -> &f64 {
        &self.kappa[g]
    }
}

impl std::ops::IndexMut<usize> for Falloff {
    #[inline]
    fn index_mut(&mut self, g: usize) -> &mut f64 {
        &mut self.kappa[g]
    }
}

/// What the model needs of one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameMeta {
    /// Fringe periods across the screen.
    pub tau: f64,
    /// Phase offset in cycles (φ / 2π).
    pub phase_cycles: f64,
    /// Index of the frame's direction in the design's axes.
    pub dir: usize,
}

/// `s = a u + b v + c` of one direction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Axis {
    /// ∂s/∂u, per screen px.
    pub a: f64,
    /// ∂s/∂v, per screen px.
    pub b: f64,
    /// s at (0, 0).
    pub c: f64,
    /// `L₄₅ / L`: how much finer this direction's fringes are on the screen
    /// than the diagonals' at equal τ ([`FringeAxis::stretch_from_diagonal`]).
    pub stretch: f64,
}

impl Axis {
    /// The axis of a [`FringeAxis`] on a `width × height` screen.
    pub fn from_fringe(f: &FringeAxis, width: u32, height: u32) -> Self {
        let (a, b) = f.gradient();
        Axis {
            a,
            b,
            c: f.s(0.0, 0.0),
            stretch: f.stretch_from_diagonal(width, height),
        }
    }

    /// `s(u, v)`.
    #[inline]
    pub fn s(&self, u: f64, v: f64) -> f64 {
        self.a * u + self.b * v + self.c
    }
}

/// The schedule as the model sees it: every frame and every direction.
#[derive(Debug, Clone, PartialEq)]
pub struct Design {
    /// Frames in capture order.
    pub frames: Vec<FrameMeta>,
    /// Fringe axes, indexed by [`FrameMeta::dir`].
    pub axes: Vec<Axis>,
    /// Directions in degrees, same order.
    pub directions_deg: Vec<f64>,
    /// Falloff group of each axis (see the module doc): axes of equal
    /// fringe length share one.
    pub falloff_group: Vec<usize>,
}

impl Design {
    /// The design of `frames` on `axes` (directions `directions_deg`), with
    /// the axes grouped by fringe length (equal [`Axis::stretch`] to 1e-9).
    /// More than [`MAX_GROUPS`] lengths share one group (logged).
    pub fn new(frames: Vec<FrameMeta>, axes: Vec<Axis>, directions_deg: Vec<f64>) -> Design {
        let mut lengths: Vec<f64> = Vec::new();
        let mut falloff_group: Vec<usize> = axes
            .iter()
            .map(|ax| {
                match lengths
                    .iter()
                    .position(|&l| (l - ax.stretch).abs() <= 1e-9 * l.abs())
                {
                    Some(g) => g,
                    None => {
                        lengths.push(ax.stretch);
                        lengths.len() - 1
                    }
                }
            })
            .collect();
        if lengths.len() > MAX_GROUPS {
            log::warn!(
                "directions {directions_deg:?} have {} fringe lengths; more than {MAX_GROUPS} \
                 share one modulation falloff κ",
                lengths.len()
            );
            falloff_group.fill(0);
        }
        Design {
            frames,
            axes,
            directions_deg,
            falloff_group,
        }
    }

    /// Number of falloff groups (1 without axes).
    pub fn falloff_groups(&self) -> usize {
        self.falloff_group.iter().max().map_or(1, |&g| g + 1)
    }

    /// The falloff groups' κ of a blur that acts on the screen period, with
    /// `kappa` that of the diagonals: `κ (L₄₅/L_g)²` (what a physical scene
    /// shows, for the bounds and predictions; the fits estimate each group's).
    pub fn physical_falloff(&self, kappa: f64) -> Falloff {
        let mut f = Falloff::uniform(self.falloff_groups(), kappa);
        for (ax, &g) in self.axes.iter().zip(&self.falloff_group) {
            f[g] = kappa * ax.stretch * ax.stretch;
        }
        f
    }

    /// The same starting κ in every falloff group.
    pub fn uniform_falloff(&self, kappa: f64) -> Falloff {
        Falloff::uniform(self.falloff_groups(), kappa)
    }

    /// κ of frame `f`'s group in `falloff`.
    #[inline]
    pub fn kappa_of(&self, f: &FrameMeta, falloff: &Falloff) -> f64 {
        falloff[self.falloff_group[f.dir]]
    }

    /// A pixel's separation of its reflections given `seps`, that along
    /// each axis: over the pairs of non-parallel axes, the largest of the
    /// pair's smaller one (two directions that each see the reflections
    /// apart fix both points in the plane; one along which they coincide
    /// adds only their blend); with no such pair (one direction, or
    /// parallel ones), the smallest. `None` without axes.
    pub fn pair_separation(&self, seps: &[f64]) -> Option<f64> {
        let mut best: Option<f64> = None;
        for (i, p) in self.axes.iter().enumerate() {
            for (j, q) in self.axes.iter().enumerate().skip(i + 1) {
                // |sin| of the angle between the two fringe gradients.
                let cross = (p.a * q.b - p.b * q.a).abs() / (p.a.hypot(p.b) * q.a.hypot(q.b));
                if cross > 1e-6 {
                    let m = seps[i].min(seps[j]);
                    best = Some(best.map_or(m, |b| b.max(m)));
                }
            }
        }
        best.or_else(|| seps.iter().copied().reduce(f64::min))
    }

    /// The screen point `(u, v)` whose fringe coordinate along each
    /// direction is `mus[d]`: least squares of `a_d u + b_d v = μ_d − c_d`
    /// over the directions; `None` when the directions do not span the plane.
    pub fn screen_point(&self, mus: &[f64]) -> Option<[f64; 2]> {
        let (mut saa, mut sab, mut sbb, mut sar, mut sbr) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for (ax, &mu) in self.axes.iter().zip(mus) {
            let r = mu - ax.c;
            saa += ax.a * ax.a;
            sab += ax.a * ax.b;
            sbb += ax.b * ax.b;
            sar += ax.a * r;
            sbr += ax.b * r;
        }
        let det = saa * sbb - sab * sab;
        if det.abs() < 1e-12 * (saa * sbb).max(1e-300) {
            return None;
        }
        Some([(sbb * sar - sab * sbr) / det, (saa * sbr - sab * sar) / det])
    }
}

#[cfg(test)]
impl Design {
    /// The axes of `dirs` on a `width × height` screen, no frames: what
    /// tests of direction geometry need.
    pub(crate) fn of_directions(dirs: &[f64], width: u32, height: u32) -> Design {
        use crate::acquire::patterns::FringeAxis;
        Design::new(
            Vec::new(),
            dirs.iter()
                .map(|&d| Axis::from_fringe(&FringeAxis::new(d, width, height), width, height))
                .collect(),
            dirs.to_vec(),
        )
    }
}

#[cfg(test)]
#[path = "design_tests.rs"]
mod tests;
