#!/usr/bin/env bash
# The demo: installs what is missing, builds mfd in release, simulates the
# paper's station (Baumer TXG12 + 16 mm lens, 21.3" LCD, a 10 mm window of
# n = 1.5 with random surfaces of 60 nm RMS), traces it, and prints the figures.
# Usage: scripts/demo.sh [OUT_DIR]   (default out/demo; needs ~5 GB of disk)
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/install-deps.sh

out="${1:-out/demo}"
mkdir -p "$out"
echo "== building (release)"
cargo build --release --locked --quiet
mfd=target/release/mfd

echo "== the paper's station, built from the hardware profiles"
$mfd station --camera hw/camera/baumer-txg12.toml --display hw/display/mtiph-e2m21gm.toml \
  --focal-length-mm 16 --out "$out/station.toml"
diff <(grep -v '^#' "$out/station.toml") <(grep -v '^#' calib/paper-sim.toml) >/dev/null \
  && echo "   identical to calib/paper-sim.toml"

echo "== simulate: paper schedule (±45°, tau 0.2..200 step 0.2 = 2000 frames), 12-bit, 5 % noise"
$mfd simulate --station calib/paper-sim.toml --random-surfaces 42 --noise 0.05 \
  --bit-depth 12 --seed 7 --out "$out/acquisition" --overwrite

echo "== trace: the ideal screen points of the same scene"
$mfd trace --station calib/paper-sim.toml --surfaces "$out/acquisition/truth/truth_surfaces.json" \
  --out "$out/trace"

echo "== reconstruct: screen points S1, S2 from the frames (spectral stage, a few minutes on 2 cores), then both surfaces"
$mfd reconstruct "$out/acquisition" --out "$out/result"

echo "== figures: the reconstruction against the simulation's truth"
$mfd compare --screen-coords "$out/result/screen_coords.npy" \
  --truth "$out/acquisition/truth/truth_screen_coords.npy" --std "$out/result/screen_std.npy"
$mfd compare --surfaces "$out/result/surfaces.json" \
  --truth-surfaces "$out/acquisition/truth/truth_surfaces.json" --summary "$out/result/summary.json"

echo "== the same frames through the statistics engine (fixed memory per pixel, seconds): the same points"
$mfd reconstruct "$out/acquisition" --out "$out/result-statistics" --engine statistics --no-surfaces
$mfd compare --screen-coords "$out/result-statistics/screen_coords.npy" \
  --truth "$out/acquisition/truth/truth_screen_coords.npy" --std "$out/result-statistics/screen_std.npy"

echo "== surfaces from the ideal (traced) screen points: the surface solvers alone, exact"
$mfd reconstruct --screen-coords "$out/trace/screen_coords.npy" --station calib/paper-sim.toml \
  --out "$out/from-trace" --terms 36
$mfd compare --surfaces "$out/from-trace/surfaces.json" \
  --truth-surfaces "$out/acquisition/truth/truth_surfaces.json"
du -sh "$out/acquisition" | awk '{print "   acquisition size: " $1}'
echo "files: $out/acquisition (frames.npy, acquisition.toml, truth/), $out/trace (screen_coords.npy),"
echo "       $out/result (screen_coords.npy, screen_std.npy, screen_cov.npy, quality maps, surfaces.json,"
echo "       front.png, back.png, *_coefficients.png, *_height_nm.npy, summary.json), $out/from-trace,"
echo "       $out/result-statistics (the spectral maps from the statistics engine)"
echo "== the measurement report: one HTML file to file (images inlined, opens without a network)"
$mfd report "$out/result" --out "$out/report.html"
echo "report: $(realpath "$out/report.html")"
