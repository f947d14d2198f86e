#!/usr/bin/env bash
# Quick start: set up .venv, then replay a bag (default: the Jackal bag shipped in data/) with the
# recommended config, and say where the outputs went.
#   bash scripts/demo.sh [BAG]
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
BAG=${1:-data/jackal_test2.bag}
OUT=out
mkdir -p "$OUT"
.venv/bin/fusiond replay "$BAG" --config examples/jackal.toml \
  --tum "$OUT/jackal.tum" --diagnostics "$OUT/jackal.jsonl" --plot "$OUT/jackal.png"
echo
echo "outputs of the replay of $BAG:"
echo "  $PWD/$OUT/jackal.tum    trajectory, TUM lines (stamp x y z qx qy qz qw; evo reads them)"
echo "  $PWD/$OUT/jackal.jsonl  diagnostics, one JSON record per update"
echo "  $PWD/$OUT/jackal.png    plot of the trajectory and NIS per sensor"
