#!/usr/bin/env bash
# Quick start: set up .venv, then replay a bag (default: the Jackal bag shipped in data/) with a config
# (default: the recommended examples/jackal.toml, which names the Jackal's topics), and say where the
# outputs went: out/<bag name>.{tum,jsonl,png}.
#   bash scripts/demo.sh [BAG [CONFIG]]
set -euo pipefail
# a BAG or CONFIG given relative to where the command was typed, before moving to the repository root
BAG=${1:+$(realpath -m "$1")}
CONFIG=${2:+$(realpath -m "$2")}
cd "$(dirname "$0")/.."
bash scripts/setup.sh
BAG=${BAG:-data/jackal_test2.bag}
CONFIG=${CONFIG:-examples/jackal.toml}
OUT=out
NAME=$(basename "${BAG%/}")
NAME=${NAME%.bag}
NAME=${NAME%.mcap}
mkdir -p "$OUT"
.venv/bin/fusiond replay "$BAG" --config "$CONFIG" \
  --tum "$OUT/$NAME.tum" --diagnostics "$OUT/$NAME.jsonl" --plot "$OUT/$NAME.png"
echo
echo "outputs of the replay of $BAG with $CONFIG:"
echo "  $PWD/$OUT/$NAME.tum    trajectory, TUM lines (stamp x y z qx qy qz qw; evo reads them)"
echo "  $PWD/$OUT/$NAME.jsonl  diagnostics, one JSON record per update"
echo "  $PWD/$OUT/$NAME.png    plot of the trajectory and NIS per sensor"
