//! mfd: multi-frequency fringe deflectometry of both faces of transparent
//! planar optics.
//!
//! The data flow one way, and the modules follow it:
//!
//! ```text
//!  optics (station, zernike, trace) ──► acquire (patterns, acquisition, cameras, display)
//!                                            │ frames
//!                                            ▼
//!        solve::spectral (S1, S2 per pixel) ──► solve::surfaces (Zernike front, back)
//!                                            │
//!              live (sequencer, recorder, streaming solver) · pipeline (the stages as one call)
//!                                            │
//!                                            ▼
//!                                   report, formats (files, pictures)
//! ```
//!
//! - [`optics`]: the station's geometry, the surface model and the exact
//!   forward model.
//! - [`acquire`]: fringe patterns, cameras, the display and the recorded
//!   acquisition folder.
//! - [`live`]: a live measurement — the sequencer between display and
//!   camera, the recorder and the streaming solver.
//! - [`solve`]: the spectral stage and the surface solvers.
//! - [`pipeline`]: the stages as one call, `reconstruct(input, station,
//!   options)`, and the result folder it writes.
//! - [`budget`]: the error budget — every degree of freedom's effect on
//!   every Zernike term, the noise, the total, what the data pin down.
//! - [`report`]: what a result tells its reader (`summary.json`, pictures,
//!   figures of merit against a truth).
//! - [`formats`]: NPY, PNG/TIFF frames, `surfaces.json`.
//! - [`sim`]: the whole simulated station (renderer, camera, scenes).
//! - [`kernels`]: numeric kernels shared by the stages.
//! - [`conventions`]: frames, units and orderings, stated once.
#![warn(missing_docs)]

pub mod acquire;
pub mod budget;
pub mod calibrate;
pub mod compare;
pub mod console;
pub mod conventions;
pub mod formats;
pub mod kernels;
pub mod limits;
pub mod live;
pub mod optics;
pub mod outcome;
pub mod pipeline;
pub mod plan;
pub mod plot;
pub mod report;
pub mod sim;
pub mod solve;
