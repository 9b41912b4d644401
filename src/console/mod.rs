//! The operator's console: an HTTP + WebSocket server (axum on tokio) in the measuring process, a live camera preview, progress and results.
