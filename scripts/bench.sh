#!/usr/bin/env bash
# Benchmarks: each prints one JSON line of figures. Usage: scripts/bench.sh
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/install-deps.sh
cargo build --release --locked --quiet
target/release/mfd bench render --station calib/bench-fill.toml
target/release/mfd bench render --station calib/paper-sim.toml
# The issue's scene: the element fills the 1296×966 sensor, 2000 frames
# (about 3 minutes and 3.7 GiB with the statistics engine).
target/release/mfd bench spectral --station calib/bench-fill.toml --pixels 0 --engine statistics
# The same centre of 20 000 pixels with each engine.
target/release/mfd bench spectral --station calib/bench-fill.toml --pixels 20000 --engine series
target/release/mfd bench spectral --station calib/bench-fill.toml --pixels 20000 --engine statistics
target/release/mfd bench spectral --station calib/paper-sim.toml --pixels 0
