#!/usr/bin/env bash
# Create .venv (if missing) and install fusiond with its test extras into it.
# pip's own chatter (build-backend warnings of an editable install) goes to .venv/pip.log and is
# shown only if the install fails.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  "$PY" -m venv .venv
fi
.venv/bin/python -m pip install --quiet --upgrade pip >/dev/null 2>&1 || true
if ! .venv/bin/python -m pip install --quiet -e '.[test]' >.venv/pip.log 2>&1; then
  cat .venv/pip.log >&2
  echo "setup: pip install failed (log above, also in .venv/pip.log)" >&2
  exit 1
fi
# Byte-compile the package, as a non-editable install does: with PYTHONDONTWRITEBYTECODE set (CI, some
# shells) an editable install would otherwise compile every module from source at each start (~0.08 s of
# a replay). A module edited since is compiled from source again, as without the cache.
.venv/bin/python -m compileall -q fusiond >/dev/null
