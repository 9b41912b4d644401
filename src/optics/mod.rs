//! The instrument's optics: what a station is and how light runs through it.
//!
//! [`station`] describes the geometry (camera, screen, element) and reads and
//! writes station files; [`zernike`] is the surface model; [`refraction`]
//! holds the vector laws of reflection, refraction and Fresnel reflectance;
//! [`trace`] is the exact forward model that follows every camera pixel's
//! rays to the screen. Everything downstream (simulator, solvers) builds on
//! these.

pub mod outline;
pub mod refraction;
pub mod station;
pub mod trace;
pub mod zernike;
