"""The fusion core: time, ordering, sensor policies, late-data history and diagnostics around the
estimator (no I/O). Its public surface is ``__all__``; the rest are this package's internals.
"""

from __future__ import annotations

from importlib import import_module

# public name -> the module of this package that defines it (imported on first use, so that
# importing the package stays cheap and no import cycle is created)
_EXPORTS = {
    "FusionCore": "fusion",
    "Estimate": "fusion",
    "Step": "fusion",
    "SensorStats": "fusion",
    "DiagnosticsRecord": "diagnostics",
    "NisWindow": "diagnostics",
    "Doctor": "doctor",
    "Verdict": "doctor",
    "format_verdicts": "doctor",
    "History": "history",
    "FilterState": "state",
    "Rejected": "sensors",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
