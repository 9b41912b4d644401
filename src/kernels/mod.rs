//! Numeric kernels shared by whoever needs them: fast `cos`/`sin`/`exp` of
//! known accuracy for the renderer and the spectral fits (with fused
//! multiply–add variants chosen at run time).
//!
//! Written by hand because the per-pixel loops need bounded-error
//! polynomials that inline and vectorise; each is tested against `std`.

mod fastcos;

pub use fastcos::{cos_cycles, exp_fast, exp_fast_with, madd, sincos_cycles, sincos_cycles_with};
