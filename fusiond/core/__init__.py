"""The fusion core: time, ordering, sensor policies, late-data history and diagnostics around the
estimator (no I/O). Its public surface is ``__all__``; the rest are this package's internals.
"""

from __future__ import annotations

from ..lazy_exports import lazy_exports

# public name -> the module of this package that defines it (imported on first use)
_EXPORTS = {
    "FusionCore": "fusion",
    "Estimate": "fusion",
    "Step": "fusion",
    "SensorStats": "fusion",
    "DiagnosticsRecord": "diagnostics",
    "NisWindow": "diagnostics",
    "History": "history",
    "FilterState": "state",
    "Rejected": "sensors",
    "ResumeState": "resume",
    "state_fingerprint": "resume",
    "OdomFrame": "tf_tree",
    "map_to_odom": "tf_tree",
    "tf_tree_active": "tf_tree",
}

__all__, __getattr__, __dir__ = lazy_exports(__name__, globals(), _EXPORTS)
