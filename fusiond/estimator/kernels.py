"""Which implementation runs the EKF's fixed-size linear algebra: compiled C or numpy.

``fusiond.estimator._kernels`` (C, built by ``pip install`` when a compiler is there; see its
source for why C rather than numba) does the propagation F P F^T + Q and the whole masked Kalman
update in one call each. The numpy code in ``ekf.py`` is the reference: the same maths, and the
only path where the extension was not built. Tests run both and hold them to the same estimates
(tests/unit/test_kernels.py, the trajectory pin).

``use("numpy")`` selects the reference path for the whole process. The ``FUSIOND_KERNELS``
environment variable (``auto``, the default, ``compiled`` or ``numpy``) is applied by the
processes that fuse (``fusiond``'s command line, the latency bench's daemon) through
``use_environment``: the estimator itself reads no environment.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import ModuleType

from ..errors import EstimatorError

try:
    from . import _kernels as _compiled
except ImportError:  # built without a C compiler: the numpy reference path runs
    _compiled = None

__all__ = ["CHOICES", "ENVIRONMENT", "active", "available", "use", "use_environment"]

CHOICES = ("auto", "compiled", "numpy")
ENVIRONMENT = "FUSIOND_KERNELS"
_active: ModuleType | None = _compiled


def available() -> bool:
    """Was the compiled module built for this interpreter?"""
    return _compiled is not None


def active() -> ModuleType | None:
    """The compiled module when it runs, None when the numpy path does."""
    return _active


def use(name: str) -> str:
    """Select the implementation: "auto" (compiled when built), "compiled" (an error when it was
    not built) or "numpy". Returns the name of the one now running."""
    global _active
    if name not in CHOICES:
        raise EstimatorError(f"kernels must be one of {', '.join(CHOICES)}, got {name!r}")
    if name == "compiled" and _compiled is None:
        raise EstimatorError("the compiled kernels (fusiond.estimator._kernels) were not built: "
                             "no C compiler at install time")
    _active = None if name == "numpy" else _compiled
    return "compiled" if _active is not None else "numpy"


def use_environment(environ: Mapping[str, str]) -> str:
    """``use`` the choice that ``environ`` (the caller's os.environ) names in FUSIOND_KERNELS, "auto"
    when it names none; an unknown name is an EstimatorError that says so."""
    choice = environ.get(ENVIRONMENT) or "auto"
    try:
        return use(choice)
    except EstimatorError as e:
        raise EstimatorError(f"{ENVIRONMENT}={choice}: {e}") from None
