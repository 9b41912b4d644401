//! The operator's console: an HTTP + WebSocket server (axum on tokio) in the
//! measuring process, a live camera preview, progress and results.
//!
//! ```text
//!  sequencer thread ──LiveTap──► Console (watch slots: latest frame, status)
//!                                   │ read, never waited on
//!  tokio runtime (own thread) ◄─────┘  axum: page, /api/preview (PNG in the
//!                                      blocking pool), /api/ws (status), stop
//! ```
//!
//! [`Console`] is the shared state a run writes (as the sequencer's
//! [`LiveTap`](crate::live::LiveTap), and through its stage setters);
//! [`serve`] starts the server on its own thread. The measurement knows
//! nothing of HTTP: a page that falls behind skips frames, and the stop
//! button sets the flag Ctrl-C sets.
//!
//! Bound to a loopback address the console serves anyone on this machine;
//! on any other address every request needs the token [`serve`] draws
//! (`401` without it). Either way it refuses what another site's page could
//! make a browser send (`console/guard.rs`): a foreign `Host` (DNS
//! rebinding), a foreign `Origin` (cross-site fetch, form or WebSocket), and
//! a state-changing request without the token the page holds in
//! `X-Mfd-Token`. The page builds its DOM from data as text only, under
//! `Content-Security-Policy: default-src 'self'`, and a result folder's
//! files are served so that none runs in the console's origin
//! ([`result_file`]).

mod guard;
mod page;
pub mod preview;
pub mod probe;
mod results;
mod server;
mod state;

use std::net::SocketAddr;

pub use preview::{Encoded, Preview, PreviewError};
pub use results::{list_results, result_file, ResultFile, ResultListing, Served};
pub use server::{serve, serve_with_names, ConsoleHandle};
pub use state::{Console, Mode, Progress, ResultDir, Showing, Spectral, Stage, Status};

/// Errors of starting the console.
#[derive(Debug, thiserror::Error)]
pub enum ConsoleError {
    /// The address cannot be listened on.
    #[error(
        "console: cannot listen on {addr}: {source} (choose another port, e.g. \
         127.0.0.1:0 for any free one)"
    )]
    Bind {
        /// The address asked for.
        addr: SocketAddr,
        /// The system's error.
        #[source]
        source: std::io::Error,
    },
    /// The server's runtime or thread could not start.
    #[error("console: starting the server thread: {source}")]
    Runtime {
        /// The system's error.
        #[source]
        source: std::io::Error,
    },
}

impl crate::outcome::Classify for ConsoleError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        use crate::outcome::Outcome;
        match self {
            // The address asked for (--addr, --serve) cannot be listened on.
            ConsoleError::Bind { .. } => Some(Outcome::Input),
            ConsoleError::Runtime { .. } => None,
        }
    }
}
