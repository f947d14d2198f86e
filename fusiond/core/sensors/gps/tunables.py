"""The GPS's tunable keys (``SensorKind.tunables``): the horizontal and the vertical of its
``position_noise``, and its Gauss-Markov error's size (``error_sigma``, or without ``error_tau_s`` the
vertical one's ``vertical_error_sigma``) and time constant, less those a recording is too short for; and
what that error adds between two fixes (``difference_variance``), which the floors measured at rest take
off."""

from __future__ import annotations

import math
import statistics
from collections.abc import Sequence
from dataclasses import replace

from ..tunable import Param, own_samples
from .sample import GpsSample
from .table import GpsSensor


def fix_sigmas(s: GpsSensor, m: GpsSample) -> tuple[float, float, float] | None:
    """The per-axis sigma the GPS policy takes from one fix (``GpsPolicy.convert``), None for no fix."""
    if m.status < 0:
        return None
    c = m.position_covariance
    if unstated(m):
        return tuple(s.unknown_position_sigma)  # type: ignore[return-value]
    if len(c) != 9 or not all(map(math.isfinite, c)) or min(c[0], c[4], c[8]) < 0.0:
        return None
    f = s.position_min_sigma
    return (max(math.sqrt(c[0]), f), max(math.sqrt(c[4]), f), max(math.sqrt(c[8]), f))


def error_params(s: GpsSensor) -> list[Param]:
    """The Gauss-Markov error states' size and time constant: all three axes with ``error_tau_s``,
    else the vertical one (``vertical_error_*``). Off in the config (0) stays off: switching a state
    on is a change of model, not of noise."""
    if s.error_tau_s > 0.0 and s.error_sigma is not None:
        base = tuple(s.error_sigma)
        out = [Param(f"{s.name}.error_sigma.{part}", s.name, "error_sigma", g, base, unit="m",
                     skipped="" if all(base[i] > 0.0 for i in g) else "0 in the config")
               for part, g in (("horizontal", (0, 1)), ("vertical", (2,)))]
        return out + [Param(f"{s.name}.error_tau_s", s.name, "error_tau_s", None, s.error_tau_s, unit="s")]
    if s.vertical_error_sigma > 0.0 and s.vertical_error_tau_s > 0.0:
        return [Param(f"{s.name}.vertical_error_sigma", s.name, "vertical_error_sigma", None, s.vertical_error_sigma,
                      unit="m"),
                Param(f"{s.name}.vertical_error_tau_s", s.name, "vertical_error_tau_s", None, s.vertical_error_tau_s,
                      unit="s")]
    return []


SPAN_TAUS = 3.0  # time constants a recording must span for a Gauss-Markov error to be fitted (below)


def slow_errors(s: GpsSensor, span: float) -> dict[str, float]:
    """The parts ("horizontal", "vertical") of the GPS's error whose Gauss-Markov time constant is too long
    for a recording of ``span`` seconds to identify (fewer than SPAN_TAUS of them), with that constant."""
    taus = {}
    if s.error_tau_s > 0.0 and s.error_sigma is not None:
        taus = {"horizontal": s.error_tau_s, "vertical": s.error_tau_s}
    elif s.vertical_error_sigma > 0.0 and s.vertical_error_tau_s > 0.0:
        taus = {"vertical": s.vertical_error_tau_s}
    return {part: tau for part, tau in taus.items() if span < SPAN_TAUS * tau} if span > 0.0 else {}


def difference_variance(s: GpsSensor, dt: float) -> list[float]:
    """What the GPS's configured Gauss-Markov error adds to the variance of the difference of two fixes ``dt``
    seconds apart, east/north/up: 2 sigma^2 (1 - exp(-dt / tau)) an axis (``error_sigma`` with ``error_tau_s``,
    else the vertical one's ``vertical_error_*``); ``[]`` without one."""
    if s.error_tau_s > 0.0 and s.error_sigma is not None:
        return [2.0 * e * e * (1.0 - math.exp(-dt / s.error_tau_s)) for e in s.error_sigma]
    if s.vertical_error_sigma > 0.0 and s.vertical_error_tau_s > 0.0:
        e = s.vertical_error_sigma
        return [0.0, 0.0, 2.0 * e * e * (1.0 - math.exp(-dt / s.vertical_error_tau_s))]
    return []


def gps_tunables(s: GpsSensor, samples: Sequence[object]) -> list[Param]:
    """The GPS's noise and error-model parameters, less those of an axis whose error the recording cannot
    identify. A Gauss-Markov error decorrelates over its time constant tau: a recording shorter than
    SPAN_TAUS of them holds fewer than three independent stretches of it, and there its error is a slow
    offset the fixes share, which their innovations cannot tell from the truth. Fitted anyway, the
    likelihood takes it for the truth: on the highway car's 60 s (altitude tau 300 s) the vertical
    white noise went to 0.01 m and the error to 5 mm, and z followed the fixes' altitude (1.14 m off the
    reference, against 0.54 m as configured), which no held-back fix shows (they share the offset)."""
    params = noise_params(s, samples) + error_params(s)
    stamps = [m.stamp for m in own_samples(samples, s.name, GpsSample)]
    span = max(stamps) - min(stamps) if len(stamps) > 1 else 0.0
    slow = slow_errors(s, span)
    if not slow:
        return params
    out = []
    for p in params:
        part = "vertical" if p.key.startswith("vertical_error") else p.name.rsplit(".", 1)[-1]
        tau = slow.get(part, max(slow.values()) if p.key == "error_tau_s" else None)
        if tau is not None and not p.skipped:
            p = replace(p, skipped=f"the recording spans {span:.0f} s, less than {SPAN_TAUS:g} time constants of the "
                                   f"{part} error ({tau:g} s): its slow error cannot be told from the truth")
        out.append(p)
    return out


def noise_params(s: GpsSensor, samples: Sequence[object]) -> list[Param]:
    names = (f"{s.name}.position_noise.horizontal", f"{s.name}.position_noise.vertical")
    groups = ((0, 1), (2,))
    if s.position_noise is not None:
        base = tuple(s.position_noise)
        return [Param(n, s.name, "position_noise", g, base, unit="m",
                      skipped="" if all(base[i] > 0.0 for i in g) else "0 in the config", floor=s.position_min_sigma)
                for n, g in zip(names, groups)]
    fixes = [x for x in (fix_sigmas(s, m) for m in own_samples(samples, s.name, GpsSample)) if x is not None]
    if not fixes:
        return [Param(n, s.name, "position_noise", g, unit="m", skipped="no fixes") for n, g in zip(names, groups)]
    base = tuple(statistics.median(f[k] for f in fixes) for k in range(3))
    # one key: an axis stated "not measured" leaves both parts alone (an override would fuse it)
    bad = "the fixes state an axis not measured (an override would fuse it)" \
        if any(b >= s.max_sigma for b in base) else ""
    # fixes that state nothing have their horizontal noise measured by the filter (estimate_unknown_noise):
    # the default is then only its upper bound, and the table says so
    fixes_unstated = sum(unstated(m) for m in own_samples(samples, s.name, GpsSample)) > len(fixes) / 2
    sources = ("unstated: measured, at most" if fixes_unstated and s.estimate_unknown_noise else "messages (median)",
               "messages (median)")
    return [Param(n, s.name, "position_noise", g, base, src, "m", bad, floor=s.position_min_sigma)
            for n, g, src in zip(names, groups, sources)]


def unstated(m: GpsSample) -> bool:
    """A fix valid but without a stated accuracy (``GpsPolicy.convert`` takes the unknown default)."""
    c = m.position_covariance
    return m.status >= 0 and (m.covariance_type == 0 or (len(c) == 9 and c[0] == 0.0 and c[4] == 0.0 and c[8] == 0.0))


__all__ = ["SPAN_TAUS", "difference_variance", "error_params", "fix_sigmas", "gps_tunables", "noise_params", "slow_errors", "unstated"]
