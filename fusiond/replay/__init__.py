"""Offline replay of bags through the fusion core, with its plot and HTML report.
Its public surface is ``__all__``; the rest are this package's internals.
"""

from __future__ import annotations

from importlib import import_module

# public name -> the module of this package that defines it (imported on first use, so that
# importing the package stays cheap and no import cycle is created)
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
