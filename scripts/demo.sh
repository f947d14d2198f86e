#!/usr/bin/env bash
# Quick start: set up, then replay the shared Jackal bag with the recommended config.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
BAG=${1:-../shared/data/jackal_test2.bag}
mkdir -p out
.venv/bin/fusiond replay "$BAG" --config examples/jackal.toml \
  --tum out/jackal.tum --diagnostics out/jackal.jsonl --plot out/jackal.png
echo "wrote out/jackal.tum (TUM trajectory), out/jackal.jsonl (diagnostics), out/jackal.png (plot)"
