//! mfd: multi-frequency fringe deflectometry of both faces of transparent
//! planar optics.
//!
//! Data flows one way: [`station`] and [`patterns`] describe the instrument,
//! [`trace`] is the exact forward model, [`sim`] renders what the camera sees,
//! [`acquisition`] reads and writes recorded frames, [`surfaces_file`] /
//! [`npy`] hold the results, and [`plot`] draws report pictures of them.
//! [`conventions`] states frames, units and orderings.
#![warn(missing_docs)]

pub mod acquisition;
pub mod camera;
pub mod conventions;
pub mod display;
pub mod image_io;
pub mod live;
pub mod npy;
pub mod optics;
pub mod patterns;
pub mod plot;
pub mod sim;
pub mod spectral;
pub mod station;
pub mod surfaces;
pub mod surfaces_file;
pub mod trace;
pub mod zernike;
