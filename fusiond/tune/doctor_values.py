"""The doctor's measured values as tune's candidates: one number per key, or the reason why not.

The doctor and tune read the same recording two ways. The doctor measures a figure directly (the
gyro's scatter at rest, the GPS's scatter, a chord scale, the innovations' second moment through the
mount) and prints it as a paste line; tune fits the innovations' likelihood. Two tools that disagree
on one key leave the user to pick. So tune takes the doctor's line as a second candidate for each
key it fits: after the fit is validated, the doctor's value is put in place of tune's for that key,
and the config so changed is judged the way the fit was (the held-back updates' -log L, the
held-back fixes' prediction). The doctor's value wins when it scores no worse than the fit (within
INFORMED, the likelihood difference the fit itself cannot resolve) and predicts the held-back fixes
no worse: a direct measurement needs no optimiser to be believed. Otherwise tune's value stands and
the table says what the doctor measured and by how much it lost.
"""

from __future__ import annotations

from collections.abc import Sequence
from contextlib import nullcontext
from dataclasses import dataclass
from typing import TYPE_CHECKING

from ..config import Config, ConfigError
from ..doctor import Verdict
from ..doctor.gyro import rest_windows
from ..logs import muted
from .advice import split_key, with_suggestion
from .params import FILTER, Param

if TYPE_CHECKING:
    from ..estimator.backend import Backend


@dataclass(frozen=True)
class DoctorLine:
    """The doctor's paste line for one of tune's keys, with the config it makes from the original."""

    verdict: Verdict
    config: Config


def _group(key: str) -> tuple[str, str] | None:
    """(table, key) of a verdict's dotted key as tune's parameters name it: "sensors.imu.gyro_noise" ->
    ("imu", "gyro_noise"), "filter.process_noise" -> ("filter", "process_noise")."""
    where = split_key(key)
    if where is None or where[0] not in ("sensors", FILTER):
        return None
    return (where[1], where[2]) if where[0] == "sensors" else (FILTER, where[2])


def diagnose(cfg: Config, samples: Sequence[object], backend: Backend | None = None, records: list | None = None,
             quiet: bool = True, plan: Sequence[bool | None] | None = None
             ) -> tuple[list[Verdict], list[tuple[float, float]]]:
    """One replay of the recording with the doctor: its verdicts, and the standstills it reads a noise at rest
    over (``doctor.gyro.rest_windows``: the filter's, confirmed, in filter time), which ``floors`` measures over.
    ``backend``: the estimator's (``FusionCore``). ``records``: every diagnostics record of the replay is appended to it
    (tune scores the original config's held-back part on them: the same replay). ``quiet``: the replay's
    warnings are not logged (False: they are, as the recording's, said once). ``plan``: the samples' snapshot plan
    with ``cfg`` (``likelihood.Plans``), when the caller has it."""
    from ..replay.run import run_samples

    with muted() if quiet else nullcontext():
        result = run_samples(samples, cfg, backend=backend, records=records, plan=plan)
        verdicts = result.verdicts()
    if result.doctor is None:
        return verdicts, []
    return verdicts, rest_windows(result.doctor.series(), cfg)


def doctor_lines(cfg: Config, verdicts: Sequence[Verdict], params: Sequence[Param]) -> dict[tuple[str, str], DoctorLine]:
    """The doctor's paste lines (``verdicts``, from ``diagnose``) for the keys of ``params``, by (table, key)."""
    groups = {p.group for p in params}
    out: dict[tuple[str, str], DoctorLine] = {}
    for v in verdicts:
        group = _group(v.key) if v.suggestion else None
        if group is None or group not in groups or group in out:
            continue
        try:
            changed, _ = with_suggestion(cfg, v)
        except ConfigError:
            continue  # a line that does not apply to this config is not a value for this key
        out[group] = DoctorLine(v, changed)
    return out


def untuned_problems(verdicts: Sequence[Verdict], params: Sequence[Param]) -> list[Verdict]:
    """The doctor's problems on keys none of ``params`` fits (a frame, a mount, what the driver fills): a noise
    fitted around one of them fits the mistake (a world twist read as body, fitted, scored 16.5 m where the
    doctor's one line took the car to 0.26 m)."""
    groups = {p.group for p in params}
    return [v for v in verdicts if v.level == "problem" and v.key and _group(v.key) not in groups]


__all__ = ["DoctorLine", "diagnose", "doctor_lines", "untuned_problems"]
