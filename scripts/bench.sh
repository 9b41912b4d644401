#!/usr/bin/env bash
# Benchmarks: each prints one JSON line of figures. Usage: scripts/bench.sh
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/install-deps.sh
cargo build --release --locked --quiet
target/release/mfd bench render --station calib/bench-fill.toml
target/release/mfd bench render --station calib/paper-sim.toml
target/release/mfd bench spectral --station calib/bench-fill.toml --pixels 20000
target/release/mfd bench spectral --station calib/paper-sim.toml --pixels 0
