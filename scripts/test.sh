#!/usr/bin/env bash
# Runs every check of mfd: formatting, clippy with warnings as errors, and all
# tests (unit, property, integration against ../shared/fixtures, end to end).
# Installs what is missing first. Usage: scripts/test.sh
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/install-deps.sh

export MFD_SHARED="${MFD_SHARED:-$(cd .. && pwd)/shared}"
if [ ! -d "$MFD_SHARED/fixtures" ]; then
  echo "error: shared fixtures not found at $MFD_SHARED/fixtures (set MFD_SHARED)" >&2
  exit 1
fi

# Mesa (the display tests' lavapipe) wants a private runtime directory.
if [ ! -d "${XDG_RUNTIME_DIR:-}" ]; then
  XDG_RUNTIME_DIR="$(mktemp -d)" && export XDG_RUNTIME_DIR
fi

echo "== cargo fmt --check"
cargo fmt --all -- --check
echo "== cargo clippy -D warnings"
cargo clippy --all-targets --locked -- -D warnings
echo "== cargo clippy --features display -D warnings"
cargo clippy --all-targets --features display --locked -- -D warnings
echo "== cargo test"
cargo test --all-targets --locked
echo "== cargo test --features display (fullscreen window under Xvfb)"
cargo test --features display --locked --lib --test display_xvfb --test display_offscreen
cargo test --doc --locked
