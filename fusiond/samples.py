"""What every sensor kind's sample is: a msgspec Struct whose first fields are ``sensor`` and ``stamp``
(``Sample``), what every codec produces and the fusion core consumes.

Each kind declares its own sample in its package (``fusiond.core.sensors.odom.sample``, ``imu``, ``gps``,
``pose``). The built-in kinds' samples are also answered here by name, imported on first read so that
this module (which the codecs and the core load) imports nothing of the kinds: the doctor names them
from here.
"""

from __future__ import annotations

from importlib import import_module
from typing import Any

import msgspec

Sample = msgspec.Struct
"""Any kind's sample: plain msgspec Structs (no numpy), so that codecs stay cheap and samples can be
serialised for tests and tools; covariances row-major, as in ROS messages."""

_KIND_SAMPLES = {"GpsSample": "gps", "ImuSample": "imu", "OdomSample": "odom"}


def __getattr__(name: str) -> Any:
    """A built-in kind's sample class, from its package (module doc)."""
    kind = _KIND_SAMPLES.get(name)
    if kind is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(f"fusiond.core.sensors.{kind}.sample"), name)
    globals()[name] = value
    return value


__all__ = ["Sample"]
