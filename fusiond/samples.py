"""What every sensor kind's sample is: a msgspec Struct whose first fields are ``sensor`` and ``stamp``
(``Sample``), what every codec produces and the fusion core consumes.

Each kind declares its own sample in its package (``fusiond.core.sensors.odom.sample``, ``imu``, ``gps``,
``pose``), exported by ``fusiond.core.sensors``; this module (which the codecs and the core load) imports
nothing of the kinds.
"""

from __future__ import annotations

import msgspec

Sample = msgspec.Struct
"""Any kind's sample: plain msgspec Structs (no numpy), so that codecs stay cheap and samples can be
serialised for tests and tools; covariances row-major, as in ROS messages."""

__all__ = ["Sample"]
