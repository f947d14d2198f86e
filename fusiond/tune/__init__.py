"""`fusiond tune`: the configured sensors' and the process's noise fitted to a recording.

``params``: which config keys are tunable, where they start, how a value enters a Config;
``likelihood``: the innovations' negative log-likelihood of one replay; ``fit``: the optimiser
and the held-back validation; ``toml_out``: the complete tuned config with a comment per
changed key; ``recording``: the samples read once from the bags; ``advice``: the doctor's paste
lines replayed before they are printed. Its public surface is
``__all__``.
"""

from __future__ import annotations

from ..lazy_exports import lazy_exports

# public name -> the module of this package that defines it (imported on first use)
_EXPORTS = {
    "Param": "params",
    "tunable_params": "params",
    "select": "params",
    "apply": "params",
    "Score": "likelihood",
    "Reference": "likelihood",
    "replay_records": "likelihood",
    "reference": "likelihood",
    "score": "likelihood",
    "residuals": "likelihood",
    "tune": "fit",
    "TuneResult": "fit",
    "Row": "fit",
    "format_table": "fit",
    "dumps": "toml_out",
    "write": "toml_out",
    "read_samples": "recording",
    "prove_advice": "advice",
    "with_suggestion": "advice",
}

__all__, __getattr__, __dir__ = lazy_exports(__name__, globals(), _EXPORTS)
