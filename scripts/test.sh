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

echo "== cargo fmt --check"
cargo fmt --all -- --check
echo "== cargo clippy -D warnings"
cargo clippy --all-targets --locked -- -D warnings
echo "== cargo clippy -D warnings (camera backends)"
cargo clippy --all-targets --locked --features aravis,v4l -- -D warnings
echo "== cargo test"
cargo test --all-targets --locked
cargo test --doc --locked
echo "== cargo test (camera backends: Aravis fake camera on loopback)"
cargo test --all-targets --locked --features aravis,v4l
