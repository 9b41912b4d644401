//! What a reconstruction tells its reader: pictures of the results.

pub mod plot;
