"""Running the doctor on simulated samples and picking its verdicts."""

from __future__ import annotations

import re

from fusiond.doctor import Verdict
from fusiond.replay.run import run_samples


def verdicts_of(cfg, samples) -> list[Verdict]:
    result = run_samples(samples, cfg)
    verdicts = result.verdicts()
    agree(result.doctor, verdicts)
    return verdicts


def agree(doctor, verdicts: list[Verdict]) -> None:
    """One verdict per channel, and it never contradicts the channel's whole-run NIS verdict (what the
    summary prints): no 'ok' beside a NIS high or low unless it says that NIS and why it is expected (a slow
    altitude error over a short run), no 'NIS high' beside an ok."""
    keys = [(v.sensor, v.channel) for v in verdicts]
    assert len(keys) == len(set(keys)), keys
    by_key = dict(zip(keys, verdicts))
    for key, ch in doctor.channels.items():
        v = by_key[key]
        if ch.verdict() in ("nis_high", "nis_low"):
            said = ch.verdict().replace("nis_", "NIS ")
            assert v.level != "ok" or (v.message.startswith(said) and "expects" in v.message), (key, ch.verdict(), v)
        else:
            assert "NIS high" not in v.message and "NIS low" not in v.message, (key, v)


def one(verdicts: list[Verdict], sensor: str, channel: str) -> Verdict:
    found = [v for v in verdicts if v.sensor == sensor and v.channel == channel]
    assert len(found) == 1, f"expected one verdict for {sensor}/{channel}: {verdicts}"
    return found[0]


def vector(suggestion: str) -> list[float]:
    return [float(v) for v in re.search(r"\[([^\]]*)\]", suggestion).group(1).split(",")]


# The mounting-yaw fit's precision in sim_mount's world (derivation: tests/doctor/test_doctor.py, above
# the mounting tests): five standard errors of 0.002 rad.
MOUNT_TOLERANCE_RAD = 0.01
