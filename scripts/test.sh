#!/usr/bin/env bash
# The test command (README, CI): set up, then run the whole suite (--fast: the fast tier, under a minute).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
exec .venv/bin/python -m pytest "$@"
