"""The IMU sensor kind: its descriptor (``kind``), its model (``model``), the filter input a message
becomes (``inputs``), its [[sensors]] table (``table``), its slice of the filter state (``own``), the gyro bias learned at standstills
(``gyro_bias``), the heading carried across logging gaps by the IMU's own yaw (``gap_turn``) and where a
noise stated in the IMU's axes lands in base_link's (``axes``), the keys tune may fit (``tunables``), its sample (``sample``) and its wire
formats and struct fast path (``codec``, imported only when a decoder is asked for)."""

from __future__ import annotations

from .gyro_bias import BiasLearning, quiet_bound
from .inputs import ImuInput
from .kind import ImuKind
from .model import G_UNITS_BAND, GRAVITY, ORIENTATION_BURST, YAW_JUMP_GATE, ImuModel, ImuPolicy
from .own import ImuOwn
from .sample import ImuSample
from .table import ImuSensor

__all__ = ["G_UNITS_BAND", "GRAVITY", "ORIENTATION_BURST", "YAW_JUMP_GATE", "BiasLearning", "ImuInput", "ImuKind",
           "ImuModel", "ImuOwn", "ImuPolicy", "ImuSample", "ImuSensor", "quiet_bound"]
