#!/usr/bin/env bash
# Runs every check of mfd: formatting, clippy with warnings as errors, and all
# tests (unit, property, integration against the independent fixture carried
# in tests/fixtures, end to end). Needs nothing beside the checkout.
# Installs what is missing first. Usage: scripts/test.sh
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/install-deps.sh

# No incremental cache unless asked (CARGO_INCREMENTAL=1): a clean checkout
# gains nothing from it, and its cache is a large part of target/.
export CARGO_INCREMENTAL="${CARGO_INCREMENTAL:-0}"

# Mesa (the display tests' lavapipe) wants a private runtime directory.
if [ ! -d "${XDG_RUNTIME_DIR:-}" ]; then
  XDG_RUNTIME_DIR="$(mktemp -d)" && export XDG_RUNTIME_DIR
fi

echo "== cargo fmt --check"
cargo fmt --all -- --check
echo "== cargo clippy -D warnings"
cargo clippy --all-targets --locked -- -D warnings
echo "== cargo clippy -D warnings (display, aravis, v4l)"
cargo clippy --all-targets --locked --features display,aravis,v4l -- -D warnings
echo "== cargo test"
cargo test --all-targets --locked
cargo test --doc --locked
cargo test --locked --features datx --test hw compare_datx::  # Zygo .datx through HDF5, files written by h5py
echo "== cargo test, hardware features: the window under Xvfb, Aravis's fake GigE Vision camera on loopback"
cargo test --locked --features display,aravis,v4l --lib --test hw
echo "== disk used by the build: $(du -sh target | cut -f1)"
