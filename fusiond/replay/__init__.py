"""Offline replay of bags through the fusion core, with its plot and HTML report.
Its public surface is ``__all__``; the rest are this package's internals.
"""

from __future__ import annotations

from ..lazy_exports import lazy_exports

# public name -> the module of this package that defines it (imported on first use)
_EXPORTS = {
    "replay": "run",
    "summary": "run",
    "ReplayResult": "run",
    "Trace": "run",
    "tum_line": "run",
    "open_bag_samples": "bag",
    "iter_raw_cdr": "bag",
    "BagSamples": "bag",
    "BagError": "bag",
    "plot_replay": "plot",
    "write_report": "report",
    "evaluate": "evaluate",
    "Evaluation": "evaluate",
    "Recorder": "evaluate",
    "format_evaluation": "evaluate",
}

__all__, __getattr__, __dir__ = lazy_exports(__name__, globals(), _EXPORTS)
