//! What a reconstruction tells its reader: `summary.json` ([`summary`]),
//! the pictures ([`pictures`], drawn with [`plot`]), and the figures of
//! merit against a truth that every comparison quotes ([`metrics`]).

pub mod metrics;
pub mod pictures;
pub mod plot;
pub mod summary;
