//! Numeric kernels shared by whoever needs them: fast `cos`/`sin`/`exp` of
//! known accuracy for the renderer and the spectral fits (with fused
//! multiply–add variants chosen at run time), the one small Cholesky
//! factorisation ([`cholesky`]), the one damped least-squares loop
//! ([`lm`]) that the spectral fits and the surface solvers share, and the
//! normal matrix of a chunk of Jacobian rows without a transposed copy
//! ([`gram`]).
//!
//! Written by hand because the per-pixel loops need bounded-error
//! polynomials and stack-held factorisations that inline and vectorise;
//! each is tested against `std` or nalgebra.

pub mod cholesky;
mod fastcos;
pub mod gram;
pub mod lm;
pub mod ordered;

pub use cholesky::SmallCholesky;
pub use fastcos::{cos_cycles, exp_fast, exp_fast_with, madd, sincos_cycles, sincos_cycles_with};
