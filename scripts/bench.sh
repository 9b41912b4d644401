#!/usr/bin/env bash
# Benchmarks: each prints one JSON line of figures.
# Usage: scripts/bench.sh [--against REV]
#   --against REV  also builds REV (any git revision) in a worktree beside
#                  this one, with its own target folder, runs every bench
#                  with both binaries, one after the other, and prints per
#                  bench both lines and, for each numeric figure, REV's, ours
#                  and their ratio (ours / REV's).
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/install-deps.sh

against=""
while [ $# -gt 0 ]; do
  case "$1" in
    --against) against="${2:?--against needs a revision}"; shift 2 ;;
    *) echo "usage: scripts/bench.sh [--against REV]" >&2; exit 2 ;;
  esac
done

# One bench per line: the arguments of `mfd bench`.
benches=(
  "render --station calib/bench-fill.toml"
  "render --station calib/paper-sim.toml"
  # The issue's scene: the element fills the 1296×966 sensor, 2000 frames
  # (about 3 minutes and 2 GiB with the statistics engine).
  "spectral --station calib/bench-fill.toml --pixels 0 --engine statistics"
  # The same centre of 20 000 pixels with each engine.
  "spectral --station calib/bench-fill.toml --pixels 20000 --engine series"
  "spectral --station calib/bench-fill.toml --pixels 20000 --engine statistics"
  "spectral --station calib/paper-sim.toml --pixels 0"
  # The surface solvers on the paper's station (150 terms): their 10 %
  # slowdown went unnoticed while this list lacked them (issue 39).
  "surfaces"
)

target="${CARGO_TARGET_DIR:-target}"
cargo build --release --locked --quiet
ours="$target/release/mfd"

if [ -z "$against" ]; then
  for b in "${benches[@]}"; do
    # shellcheck disable=SC2086 # a bench's arguments split on spaces
    "$ours" bench $b
  done
  exit 0
fi

# REV in a worktree beside this one, built in its own target folder (a
# shared one would mix the two builds).
rev="$(git rev-parse --verify "$against^{commit}")"
beside="$(cd .. && pwd)/.bench-$(basename "$PWD")-${rev:0:12}"
[ -d "$beside" ] || git worktree add --detach "$beside" "$rev" >/dev/null
(cd "$beside" && CARGO_TARGET_DIR="$beside/target" cargo build --release --locked --quiet)
theirs="$beside/target/release/mfd"

for b in "${benches[@]}"; do
  echo "== mfd bench $b"
  # shellcheck disable=SC2086
  a="$("$theirs" bench $b | tail -n 1)"
  # shellcheck disable=SC2086
  o="$("$ours" bench $b | tail -n 1)"
  echo "${rev:0:12}: $a"
  echo "ours:         $o"
  python3 - "$a" "$o" <<'PY'
import json, sys
a, o = (json.loads(x) for x in sys.argv[1:3])
def flat(d, pre=""):
    for k, v in d.items():
        if isinstance(v, dict):
            yield from flat(v, pre + k + ".")
        elif isinstance(v, (int, float)) and not isinstance(v, bool):
            yield pre + k, float(v)
fa, fo = dict(flat(a)), dict(flat(o))
for k, va in fa.items():
    if k in fo:
        vo = fo[k]
        ratio = f"{vo / va:.3f}" if va != 0 else "-"
        print(f"  {k}: {va:.6g} -> {vo:.6g}  (ours / REV {ratio})")
PY
done
echo "REV's worktree stays at $beside (git worktree remove it when done)."
