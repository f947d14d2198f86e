"""The checks, in the order they run.

The cross-source checks come first (what they find decides who is to blame, and the IMU's yaw NIS
reads the heading check), then one check per channel kind, then the whole-run checks and the core's
counters. Within a channel, findings are listed in this order (the most severe leads when they are
merged), so the order is part of what the doctor prints.
"""

from __future__ import annotations

from .channel_checks import (AbsoluteNis, ChannelNis, Frozen, GpsWander, GyroBiasAtRest, OrientationNis, Reacquired,
                             Unaligned, YawJumps, YawRateSlip)
from .check import Check
from .cross_checks import Heading, LeverArm, Speed, UnmeasuredYawRate, WheelHeading, YawRateNotMeasured
from .run_checks import (Clocks, Coast, CovarianceCap, CovarianceResets, Drops, GapHeading, GyroBiasUnseen, LateBias,
                         Lean, Mounting, TwistFrame)

__all__ = ["CHECKS"]

CHECKS: tuple[Check, ...] = (
    LeverArm(), UnmeasuredYawRate(), YawRateNotMeasured(), WheelHeading(), Heading(), Speed(),
    OrientationNis(), YawRateSlip(), GyroBiasAtRest(), YawJumps(), Reacquired(), Frozen(), Unaligned(), AbsoluteNis(),
    GpsWander(), ChannelNis(),
    GyroBiasUnseen(), Lean(), Mounting(), GapHeading(), LateBias(), Coast(), TwistFrame(), CovarianceCap(),
    Drops(), Clocks(), CovarianceResets(),
)
