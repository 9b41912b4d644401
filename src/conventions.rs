//! Conventions used throughout mfd; the interchange spec
//! (`shared/spec/interchange.md`) is the outside view of the same rules.
//!
//! ```text
//!            camera C                     screen (u → +x, v → −y)
//!              \   optical axis            ┌──────────────┐
//!               \                          │ S1   S2      │
//!                \            z            └──────────────┘
//!                 \           ↑               ↗    ↗
//!   front  z = W1(x, y)  ─────●─────────────  M1   M3      ← +z towards camera
//!   back   z = −t + W2(x, y) ─────────────────── M2           and screen
//! ```
//!
//! * **Frames.** World frame right-handed, origin at the nominal centre of the
//!   element's front surface, `+z` the reference-plane normal pointing from the
//!   element to camera and screen. The camera frame has x along increasing
//!   column `i`, y along increasing row `j` and z along the optical axis (out of
//!   the camera); `world_from_camera` maps camera vectors to world vectors.
//! * **Units.** Millimetres for every length inside the library; surface
//!   heights and Zernike coefficients in nanometres only at the edges
//!   (`surfaces.json`, reports). Angles in degrees at the edges, radians inside
//!   (`_rad` suffix). Pixel pitch of the camera in µm in files, mm inside.
//! * **Heights.** The front surface is `z = W1(x, y)`, the back
//!   `z = −thickness + W2(x, y)`: a positive coefficient raises the surface
//!   towards the camera on both faces. Surface normals point `+z`.
//! * **Camera pixels.** `(i, j)` = (column, row), 0 at the top left; the ray of
//!   pixel `(i, j)` passes through its centre `(i + 0.5, j + 0.5)`. Arrays are
//!   row-major `[row, column, ...]`.
//! * **Screen pixels.** `(u, v)` continuous, the centre of screen pixel
//!   (column c, row r) at `(c + 0.5, r + 0.5)`; the screen spans `[0, W] × [0, H]`.
//! * **Fringes.** `s(u, v) = (u cos θ + v sin θ − s0) / L` ∈ [0, 1] and
//!   `g = 0.5 + 0.5 cos(2π τ s + φ)` ([`crate::acquire::patterns`]).
//! * **Zernike.** Noll ordering (j = 1 piston, 2 x-tilt, 3 y-tilt, 4 defocus …),
//!   RMS normalisation over the unit disk, `θ` from +x towards +y,
//!   `ρ = r / radius_mm` from `center_mm`; coefficient index k is Noll j = k + 1
//!   ([`crate::optics::zernike`]). The polynomial is the surface also outside ρ = 1.
//! * **Reflections.** Index 0 = front (S1), 1 = back (S2, one internal
//!   reflection), 2 = two internal round trips (S3, paper §5.1b).
//! * **FFT.** Forward transforms unnormalised (`Σ x_n e^{−2πi kn/N}`), as
//!   rustfft computes them.
//! * **Arrays in files.** Every array of the formats has the length its spec
//!   gives, read strictly by [`exact`].

pub mod exact;
