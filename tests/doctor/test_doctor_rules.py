"""The doctor's checks share one interface, and the blame rules decide on typed fields.

Each check in the registry is run the same way (``run(evidence) -> list[Verdict]``) and runs after the
checks whose findings it reads. The rule table rewrites a finding by who found what (the check, the level,
the sensor, the evidence), never by the text of a message: a wrong twist frame explains the speed, a
contradicted IMU yaw's NIS is dropped, a gyro-bias problem explains a wheel-vs-gyro offset, a candidate
finding is never shown on its own. ``gated_out`` is the gated branch of ``absolute_verdict``.
"""

from __future__ import annotations

import numpy as np
import pytest

from fusiond.core.diagnostics import DiagnosticsRecord
from fusiond.doctor import ChannelStats, Series, Verdict
from fusiond.doctor.attitude import TiltStats
from fusiond.doctor.blame import ANY_CHECK, CANDIDATES, RULES, Entry, apply_rules
from fusiond.doctor.channels import gated_out
from fusiond.doctor.checks.absolute import absolute_verdict
from fusiond.doctor.check import Check, run_check
from fusiond.doctor.evidence import Evidence
from fusiond.doctor.registry import CHECKS
from fusiond.doctor.channels import GATED_FRACTION
from fusiond.doctor.twist import TwistStats


def test_every_check_has_one_interface_and_runs_after_what_it_reads():
    names = [c.name for c in CHECKS]
    assert len(set(names)) == len(names), names
    for i, check in enumerate(CHECKS):
        assert isinstance(check, Check), check
        for need in check.needs:
            assert need in names[:i], (check.name, need)
    for rule in RULES:  # a rule explains findings of checks that exist (or of every check)
        assert rule.explains == ANY_CHECK or set(rule.explains) <= set(names), rule.why
    assert CANDIDATES <= set(names)


def test_with_no_config_and_no_channels_no_check_speaks():
    ev = _evidence()
    assert all(run_check(check, ev) == [] for check in CHECKS)


def _evidence(channels: dict | None = None) -> Evidence:
    return Evidence(None, Series(), channels or {}, TwistStats(), TiltStats())


def _rules(*found: tuple[str, Verdict], channels: dict | None = None) -> list[Verdict]:
    entries = [Entry(check, (v.sensor, v.channel), v) for check, v in found]
    return [e.verdict for e in apply_rules(_evidence(channels), entries)]


def test_a_wrong_twist_frame_explains_the_speed_and_takes_its_key():
    frame = Verdict("wheel", "twist", "problem", "the twist is in the body frame", "sensors.wheel.twist_frame",
                    'twist_frame = "body"')
    speed = Verdict("wheel", "speed", "problem", "wheel speed 12% off the GPS", "sensors.wheel.wheel_scale",
                    "wheel_scale = 0.88", {"scale": 0.88})
    out = _rules(("speed", speed), ("twist_frame", frame))
    assert out[1] == frame
    assert (out[0].level, out[0].key, out[0].suggestion) == ("warn", frame.key, "")
    assert out[0].message.endswith("explained by wheel/twist (see it): fix that first")
    assert out[0].evidence == speed.evidence
    ok = Verdict("wheel", "speed", "ok", "wheel speed agrees with the GPS")
    assert _rules(("speed", ok), ("twist_frame", frame))[0] == ok


def test_a_warned_twist_frame_is_no_culprit():
    frame = Verdict("wheel", "twist", "warn", "the twist frame could not be told")
    speed = Verdict("wheel", "speed", "problem", "wheel speed 12% off the GPS", "sensors.wheel.wheel_scale")
    assert _rules(("speed", speed), ("twist_frame", frame))[0] == speed


def test_a_contradicted_imu_yaw_keeps_only_its_mounting_finding():
    heading = Verdict("imu", "orientation", "problem", "the IMU's yaw is disturbed", "sensors.imu.orientation")
    nis = Verdict("imu", "orientation", "problem", "NIS high", "sensors.imu.orientation_noise", "x = 1")
    mount = Verdict("imu", "orientation", "warn", "constant roll offset", "sensors.imu.extrinsic_rpy")
    other = Verdict("imu2", "orientation", "problem", "NIS high", "sensors.imu2.orientation_noise")
    out = _rules(("heading", heading), ("orientation", nis), ("orientation", mount), ("orientation", other),
                 channels={("imu2", "orientation"): _stats(np.full(200, 1.0))})
    assert out == [heading, mount, other]  # imu2's NIS is consistent: the culprit explains nothing there


def test_a_gyro_bias_problem_explains_a_wheel_vs_gyro_offset_only():
    bias = Verdict("imu", "gyro_bias", "problem", "the bias learned at a false standstill", "sensors.imu.x")
    offset = Verdict("wheel", "yaw_rate", "problem", "wheels 0.02 rad/s off the gyro", "sensors.wheel.y",
                     "y = 1", {"mean_rad_s": 0.02})
    slip = Verdict("wheel", "yaw_rate", "warn", "slip", "sensors.wheel.slip_threshold", evidence={"rms": 0.1})
    out = _rules(("gyro_bias", bias), ("slip", offset), ("slip", slip))
    assert (out[1].level, out[1].key, out[1].suggestion) == ("warn", bias.key, "")
    assert out[1].message == offset.message + ": explained by imu/gyro_bias (see it)"
    assert out[2] == slip
    calm = Verdict("imu", "gyro_bias", "warn", "noise understated")
    assert _rules(("gyro_bias", calm), ("slip", offset))[1] == offset


def test_a_candidate_is_never_shown_on_its_own():
    wander = Verdict("gps", "position", "warn", "the fixes wander", "sensors.gps.error_tau_s")
    assert _rules(("gps_wander", wander)) == []


def _stats(nis: np.ndarray, rejected: np.ndarray | None = None) -> ChannelStats:
    rejected = np.zeros(len(nis), bool) if rejected is None else rejected
    ch = ChannelStats(["east", "north"])
    ch.extend([DiagnosticsRecord(1000.0 + k, "gps", ["east", "north"], [0.0, 0.0], [1.0, 1.0], float(v), 2, bool(r),
                                 channel="position") for k, (v, r) in enumerate(zip(nis, rejected))])
    return ch


@pytest.mark.parametrize("share", [0.0, 0.05, GATED_FRACTION - 0.01, GATED_FRACTION + 0.02, 0.3, 0.6])
def test_gated_out_is_the_gated_verdict_of_an_absolute_channel(share):
    n = 400
    rejected = np.arange(n) < round(share * n)
    ch = _stats(np.full(n, 2.0), rejected)
    v = absolute_verdict("gps", "position", ch, 1000.0)
    gated_branch = v.key == "sensors.gps.mahalanobis_threshold" or (v.level == "problem" and
                                                                  v.evidence["gated_fraction"] > GATED_FRACTION)
    assert gated_out(ch) == gated_branch == (share > GATED_FRACTION), v
