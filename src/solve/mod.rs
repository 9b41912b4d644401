//! The solvers, in the order the data meet them: the [`spectral`] stage
//! turns each camera pixel's intensity over the schedule into its screen
//! points S1 and S2 with their covariance; the [`surfaces`] stage turns those
//! into the Zernike coefficients of front and back with theirs; the
//! [`direct`] estimator fits the surfaces to the frames themselves (thin
//! plates, whose reflections no pixel resolves alone).

pub mod direct;
pub mod spectral;
pub mod surfaces;
