"""Where `fusiond bench` and `fusiond bench-latency` find their code: ``benchmarks/`` of the source tree
fusiond runs from (a clone, an editable install). Benchmarks are measurement code, not the service, so
they are not installed with the package; an installed fusiond without its source tree says where they live.
"""

from __future__ import annotations

import importlib
import sys
from pathlib import Path
from types import ModuleType

from .common import EXIT_USAGE

__all__ = ["REPO_ROOT", "load"]

# The source tree fusiond runs from: `bench`'s defaults (the Jackal bag, its config) and the benchmarks'
# code are found there, not beside the current directory.
REPO_ROOT = Path(__file__).resolve().parents[2]


def load(name: str) -> ModuleType:
    """``benchmarks.<name>`` of the source tree, or exit 2 with one line saying where the benchmarks live.
    The tree goes on ``sys.path`` (and so into the latency benchmark's spawned children, which import its
    module by name)."""
    if not (REPO_ROOT / "benchmarks" / f"{name}.py").is_file():
        print(f"fusiond: the benchmarks are not installed with fusiond: they live in benchmarks/ of its source "
              f"tree, and there is no {REPO_ROOT / 'benchmarks' / (name + '.py')}; run this command from a clone "
              "installed with `pip install -e .`", file=sys.stderr)
        raise SystemExit(EXIT_USAGE)
    root = str(REPO_ROOT)
    if root not in sys.path:
        sys.path.insert(0, root)
    return importlib.import_module(f"benchmarks.{name}")
