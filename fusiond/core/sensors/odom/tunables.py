"""The odometry's tunable keys (``SensorKind.tunables``): the linear and the angular part of its
``twist_noise``, two parameters (six free standard deviations would ask more of a recording than it
holds). An odometry whose messages mark some twist components "not measured" (the Jackal's wx, wy at
1e6) gets, with a tuned ``twist_noise``, a ``twist_measured`` that marks them so: the override then
leaves them exactly as the messages did (not used, default noise)."""

from __future__ import annotations

import math
from collections.abc import Sequence

from ..tunable import Param, median, own_samples
from .sample import OdomSample
from .table import OdomSensor


def odom_tunables(s: OdomSensor, samples: Sequence[object]) -> list[Param]:
    """The two parts of ``twist_noise``: from the config, else from the messages' median variances of the
    components they measure (the floors and caps of ``OdomPolicy``)."""
    names = (f"{s.name}.twist_noise.linear", f"{s.name}.twist_noise.angular")
    groups = ((0, 1, 2), (3, 4, 5))
    if s.twist_noise is not None:
        base = tuple(s.twist_noise)
        if any(v <= 0.0 for v in base):
            return [Param(n, s.name, "twist_noise", g, base, skipped="0 in the config") for n, g in zip(names, groups)]
        return [Param(n, s.name, "twist_noise", tuple(i for i in g if s.twist_measured[i]), base, unit=u, floor=f)
                for n, g, u, f in zip(names, groups, ("m/s", "rad/s"), s.twist_min_sigma)]
    mine = own_samples(samples, s.name, OdomSample)
    if not mine:
        return [Param(n, s.name, "twist_noise", g, skipped="no messages") for n, g in zip(names, groups)]
    floors = [s.twist_min_sigma[0]] * 3 + [s.twist_min_sigma[1]] * 3
    caps = [s.twist_max_sigma[0]] * 3 + [s.twist_max_sigma[1]] * 3
    unmeasured = [s.twist_unmeasured_sigma[0]] * 3 + [s.twist_unmeasured_sigma[1]] * 3
    base, measured = [], []
    for i in range(6):
        var = median(m.twist_covariance[7 * i] for m in mine if len(m.twist_covariance) == 36)
        ok = s.twist_measured[i] and var is not None and 0.0 <= var < caps[i] ** 2 and math.isfinite(var)
        measured.append(bool(ok))
        base.append(max(math.sqrt(var), floors[i]) if ok else unmeasured[i])  # type: ignore[arg-type]
    companions = () if all(measured) else (("twist_measured", tuple(measured)),)
    out = []
    for n, g, u, f in zip(names, groups, ("m/s", "rad/s"), s.twist_min_sigma):
        idx = tuple(i for i in g if measured[i])
        out.append(Param(n, s.name, "twist_noise", idx, tuple(base), "messages (median)", u,
                         "" if idx else "no component measured", companions, f))
    return out


__all__ = ["odom_tunables"]
