//! What a reconstruction tells its reader: `summary.json` ([`summary`]),
//! the pictures ([`pictures`], drawn with [`crate::plot`]), and the figures of
//! merit against a truth that every comparison quotes ([`metrics`]), and
//! the operator's report page ([`page`]).

pub mod figures;
pub mod metrics;
pub mod page;
pub mod pictures;
pub mod records;
pub mod repeatability;
pub mod summary;
