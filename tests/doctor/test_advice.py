"""The doctor's paste lines are replayed before they are printed (fusiond.tune.advice).

Simulated drives (tests/support/sim.py: gyro white noise 0.002 rad/s, roll/pitch of the IMU's orientation
with noise 0.0024 rad, 5 s at rest first) with a config mistake planted: a gyro noise stated 10x
too large, an orientation noise stated 12x too small. The doctor's line for each must, replayed,
raise the innovations' likelihood by more than its one key (the advice rule) and be printed as a
fix; a line that states the wrong direction must come out as tried and not advised.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from fusiond.cli import main
from fusiond.config import ConfigError
from fusiond.doctor import Proof, Verdict, format_verdicts
from fusiond.replay.run import run_samples
from fusiond.tune.advice import prove_advice, with_suggestion

from tests.support.configs import robot_config, robot_config_text
from tests.support.ros2_bags import write_ros2_bag
from tests.support.sim import SimConfig, simulate

GYRO_SIGMA = 0.002  # the simulation's gyro noise, rad/s


@pytest.fixture(scope="module")
def drive() -> list:
    return simulate(SimConfig(duration=60.0, standstill=5.0, gyro_sigma=GYRO_SIGMA, seed=11))


def _proven(samples: list, imu: str = "", budget_s: float = 60.0) -> list[Verdict]:
    cfg = robot_config(imu=imu)
    return prove_advice(cfg, samples, run_samples(samples, cfg).verdicts(), budget_s)


def _by_key(verdicts: list[Verdict], key: str) -> Verdict:
    (v,) = [v for v in verdicts if v.key == key and v.suggestion]
    return v


def test_an_overstated_gyro_noise_is_advised_with_its_replayed_gain(drive) -> None:
    v = _by_key(_proven(drive, imu="gyro_noise = 0.02"), "sensors.imu.gyro_noise")
    assert v.proof is not None and v.proof.tried and v.proof.advised, v
    gain = float(v.proof.effect.split("likelihood ")[1].split(",")[0])
    assert gain > 1.0, v.proof  # more than the one key it sets
    text = format_verdicts([v])
    assert f"-> in the [[sensors]] table with name = \"imu\": {v.suggestion}" in text
    assert "(replayed: likelihood +" in text


def test_an_understated_orientation_noise_is_advised_and_brings_the_nis_near_one(drive) -> None:
    v = _by_key(_proven(drive, imu="orientation_noise = [0.0002, 0.0002, 0.0002]"), "sensors.imu.orientation_noise")
    assert v.proof is not None and v.proof.advised, v
    before, after = (float(x) for x in v.proof.effect.split("NIS/dof ")[1].split(" -> "))
    # stated 0.0002 against 0.0024: the NIS per dof is ~(0.0024 / 0.0002)^2 / 2.6 or more before, and
    # within a factor 2 of one once the measured noise is stated
    assert before > 10.0 and 0.5 < after < 2.0, v.proof


def test_a_line_that_makes_the_likelihood_worse_is_not_printed_as_advice(drive) -> None:
    cfg = robot_config()
    wrong = Verdict("imu", "orientation", "warn", "planted: ten times too small", "sensors.imu.orientation_noise",
                    "orientation_noise = [0.00024, 0.00024, 0.00024]")
    (v,) = prove_advice(cfg, drive, [wrong])
    assert v.proof is not None and v.proof.tried and not v.proof.advised, v
    assert v.proof.effect.startswith("likelihood -"), v.proof
    text = format_verdicts([v])
    assert "       ->" not in text and "not advised" in text and v.suggestion in text


def test_a_key_the_filter_does_not_use_here_is_said_to_change_nothing(drive) -> None:
    """The gyro drives heading: the wheels' yaw-rate floor is read only by the doctor's wheel-vs-gyro check."""
    cfg = robot_config()
    floor = Verdict("wheel", "yaw_rate", "warn", "planted", "sensors.wheel.twist_min_sigma",
                    "twist_min_sigma = [0.01, 0.03]")
    (v,) = prove_advice(cfg, drive, [floor])
    assert v.proof is not None and not v.proof.advised and "changes none of the filter's updates" in v.proof.effect
    assert not v.proof.judged and "moves the final pose" not in v.proof.effect  # nothing to judge it by
    assert "not advised" not in format_verdicts([v])


def test_lines_replayed_side_by_side_get_the_proofs_of_lines_replayed_in_turn(drive) -> None:
    """Each line in a forked process of its own (two at a time) or all here, one after the other: the same
    proofs, in the verdicts' order."""
    cfg = robot_config(imu="gyro_noise = 0.02")
    planted = [
        Verdict("imu", "orientation", "warn", "planted", "sensors.imu.orientation_noise",
                "orientation_noise = [0.00024, 0.00024, 0.00024]"),
        Verdict("wheel", "yaw_rate", "warn", "planted", "sensors.wheel.twist_min_sigma", "twist_min_sigma = [0.01, 0.03]"),
        Verdict("imu", "gyro", "warn", "planted", "sensors.imu.gyro_noise", "gyro_noise = 0.002"),
    ]
    in_turn = prove_advice(cfg, drive, planted, workers=1)
    side_by_side = prove_advice(cfg, drive, planted, workers=2)
    assert [v.proof for v in side_by_side] == [v.proof for v in in_turn]
    assert len({v.proof.effect for v in in_turn}) == 3 and all(v.proof.tried for v in in_turn)


def test_out_of_budget_lines_are_printed_as_not_replayed(drive) -> None:
    v = _by_key(_proven(drive, imu="gyro_noise = 0.02", budget_s=0.0), "sensors.imu.gyro_noise")
    assert v.proof is not None and not v.proof.tried and v.proof.advised
    assert "(not replayed: the 0 s budget" in format_verdicts([v])


def test_with_suggestion_sets_every_key_of_the_line_in_the_named_table() -> None:
    cfg = robot_config(gps="")
    two = Verdict("gps", "position", "warn", "", "sensors.gps.error_tau_s",
                  "error_tau_s = 8\nerror_sigma = [0.06, 0.28, 5.00]")
    changed, n = with_suggestion(cfg, two)
    assert n == 2 and changed.sensor("gps").error_tau_s == 8.0
    assert tuple(changed.sensor("gps").error_sigma) == (0.06, 0.28, 5.0)
    assert changed.sensor("imu") == cfg.sensor("imu") and changed.filter == cfg.filter
    filt, n = with_suggestion(cfg, Verdict("imu", "gyro_bias", "warn", "", "filter.standstill_s", "standstill_s = 0.5"))
    assert n == 1 and filt.filter.standstill_s == 0.5


@pytest.mark.parametrize("key, line, said", [
    ("sensors.imu.gyro_noise", "gyro_noise = 0.002 and more", "not a TOML line"),
    ("sensors.nowhere.gyro_noise", "gyro_noise = 0.002", "no sensor named 'nowhere'"),
    ("sensors.imu.gyro_noise", "gyro_noise = \"loud\"", "gyro_noise"),
    ("sensors.imu.no_such_key", "no_such_key = 1", "no_such_key"),
])
def test_a_line_that_does_not_apply_is_a_config_error(key: str, line: str, said: str) -> None:
    with pytest.raises(ConfigError, match=said):
        with_suggestion(robot_config(), Verdict("imu", "x", "warn", "", key, line))


def test_the_doctor_command_prints_the_replayed_effect(drive, tmp_path: Path, capsys) -> None:
    write_ros2_bag(tmp_path / "bag", drive)
    cfg = tmp_path / "robot.toml"
    cfg.write_text(robot_config_text(imu="gyro_noise = 0.02"))
    assert main(["doctor", str(tmp_path / "bag"), "--config", str(cfg)]) == 0
    out = capsys.readouterr().out
    assert "gyro_noise = 0.00" in out and "(replayed: likelihood +" in out, out
    assert main(["replay", str(tmp_path / "bag"), "--config", str(cfg), "--advice-budget-s", "0"]) == 0
    out = capsys.readouterr().out
    assert "gyro_noise = 0.00" in out and "replayed" not in out, out
    assert main(["replay", str(tmp_path / "bag"), "--config", str(cfg), "--advice-budget-s", "-1"]) == 2
    assert "--advice-budget-s" in capsys.readouterr().err


def test_a_line_that_turns_a_heading_nothing_measures_is_shown_as_unjudged_not_refused() -> None:
    """A two-D robot whose IMU kept its yaw through an 8 s logging gap in which it turned 0.9 rad, its orientation
    not used: the line that lets that yaw turn the heading moves the estimate, but no update measures a heading
    (the gyro drives it, nothing absolute), so the likelihood cannot tell. The proof says so, with how far the
    final pose moved, and the line is printed as the doctor's advice, not as refused."""
    samples = [s for s in simulate(SimConfig(duration=20.0)) if not 1004.0 <= s.stamp < 1012.0]  # stamps from 1000 s
    cfg = robot_config(orientation="off", filt="two_d_mode = true")
    line = Verdict("imu", "heading_across_gaps", "warn", "planted", "sensors.imu.orientation",
                   'orientation = "roll_pitch"\nyaw_across_gaps = true')
    (v,) = prove_advice(cfg, samples, [line])
    assert v.proof is not None and v.proof.tried and not v.proof.advised and not v.proof.judged, v.proof
    turned = float(v.proof.effect.split(" m and ")[1].split(" deg")[0])
    assert turned > 30.0 and "the replay cannot judge it" in v.proof.effect, v.proof  # ~0.9 rad turned in
    text = format_verdicts([v])
    assert "       -> in the [[sensors]] table" in text and "not advised" not in text, text


def test_an_advised_noise_that_leaves_its_channel_still_high_says_so():
    """A noise read off the innovations of a filter that trusted the sensor more is not yet the noise of the
    one that trusts it less (its innovations grow as it follows the sensor less where the sensor errs slowly):
    the proof says when the channel's whole-run NIS verdict is still the one the line was meant to mend, so
    the user knows a next round is coming (the F1/10 orientation: 49 -> 7.4 -> 2.2 -> ok over three rounds),
    and says nothing once it is mended; a line that leaves its channel no nearer 1 per dof says its gain is the
    other updates' (the F1/10's gyro_noise: gyro_bias 9.5 -> 14.8 per dof, likelihood +9,325 from the rest).
    Records of 200 scalar updates whose NIS is 9, 4 and 1."""
    from fusiond.core.diagnostics import DiagnosticsRecord
    from fusiond.tune.advice import _still

    def records(nis: float) -> list[DiagnosticsRecord]:
        return [DiagnosticsRecord(100.0 + 0.1 * k, "imu", ["roll"], [0.01], [0.01**2 / nis], nis, 1, False,
                                  channel="orientation") for k in range(200)]

    v = Verdict("imu", "orientation", "problem", "NIS high", "sensors.imu.orientation_noise",
                "orientation_noise = [0.01, 0.01, 1.0]")
    assert "imu/orientation still reads NIS high with it: paste it" in _still(v, records(9.0), records(4.0))
    assert "no nearer 1 with it" in _still(v, records(4.0), records(9.0))
    assert _still(v, records(9.0), records(1.0)) == ""
    assert _still(v, records(1.0), records(1.0)) == ""  # nothing to mend


def test_a_clock_line_that_brings_dropped_samples_back_is_not_judged_by_the_runs_own_updates():
    """The IMU stamped 1000 s behind and first in the recording: the filter follows the wheels' clock (the
    odometry's is the filter's) and drops the IMU. The line that corrects the IMU's clock fuses it again; the
    likelihood over the run's own updates (the wheels', without the IMU's) cannot weigh that, so the line is the
    doctor's, not 'not advised' on a score that lacks the IMU's terms."""
    from tests.support import sim_gps
    from tests.support.sim_faults import shift_stamps

    samples = [s for s in sim_gps.simulate(sim_gps.World(duration=30.0, gps_rate=1.0)) if s.sensor != "gps"]
    start = samples[0].stamp + 0.5
    samples = shift_stamps([s for s in samples if s.sensor == "imu" or s.stamp >= start], "imu", -1000.0)
    cfg = robot_config()
    result = run_samples(samples, cfg)
    clock = [v for v in result.verdicts() if v.channel == "time"]
    (v,) = prove_advice(cfg, samples, clock, base_applied=result.applied)
    assert v.proof is not None and not v.proof.judged and not v.proof.refuted, v.proof
    assert "samples of imu the run as configured dropped" in v.proof.effect, v.proof
    # without the run's counts its updates say the same: the IMU's orientation updates, applied again
    (blind,) = prove_advice(cfg, samples, clock)
    assert blind.proof is not None and not blind.proof.judged, blind.proof
    assert "more imu/orientation updates the run as configured gated or only learned from" in blind.proof.effect


def test_a_line_that_measures_every_update_otherwise_is_not_judged_by_them() -> None:
    """Absolute yaw without GPS, the only updates the IMU's orientation: the line to take only roll and pitch
    from it changes every update's dof, so none is left to compare. The proof says so, not "likelihood +0 ...
    not advised", and the line is printed as the doctor's advice."""
    samples = simulate(SimConfig(duration=30.0, standstill=2.0, imu_yaw_offset=0.4, imu_yaw_wander=0.3))
    cfg = robot_config(orientation="absolute", odom='twist_measured = [true, false, false, false, false, false]')  # no wheel yaw rate
    line = Verdict("imu", "orientation", "problem", "planted", "sensors.imu.orientation", 'orientation = "roll_pitch"')
    records: list = []
    base = run_samples(samples, cfg, records=records)
    assert {(r.sensor, r.channel) for r in records} <= {("imu", "orientation"), ("imu", "gyro_bias")}
    (v,) = prove_advice(cfg, samples, [line], base_records=records, base_final=base.final, base_applied=base.applied)
    assert v.proof is not None and v.proof.tried and not v.proof.advised and not v.proof.judged, v.proof
    assert "none is left to compare" in v.proof.effect, v.proof
    text = format_verdicts([v])
    assert "       -> in the [[sensors]] table" in text and "not advised" not in text, text


def test_the_replayed_nis_is_named_for_the_updates_it_is_of() -> None:
    """A line on the wheels (angular_velocity on the IMU, say, judged on the IMU's updates) whose sensor has no
    scored update of its own: the NIS figure quoted is all scored updates', and named so, not the wheels'."""
    from fusiond.tune.advice import _effect
    from fusiond.tune.likelihood import Score

    before = Score(100.0, 50, 50, 0, 0, {"": 0.58, "imu": 0.58})
    after = Score(90.0, 50, 50, 0, 0, {"": 0.46, "imu": 0.46})
    wheel = Verdict("wheel", "heading", "problem", "planted", "sensors.imu.angular_velocity", "angular_velocity = true")
    text = _effect(before, after, wheel, 0, [], [])
    assert text == "likelihood +10, the scored updates' NIS/dof 0.58 -> 0.46", text
    imu = Verdict("imu", "heading", "problem", "planted", "sensors.imu.angular_velocity", "angular_velocity = true")
    assert _effect(before, after, imu, 0, [], []) == "likelihood +10, imu's NIS/dof 0.58 -> 0.46"


def test_a_clock_line_is_judged_sample_by_sample_and_advised_when_it_fits():
    """A car at 10 m/s whose GPS stamps its fixes 0.25 s after their epoch (stamped on arrival): each fix is
    fused 2.5 m along the road from where it was taken. The doctor's clock line shifts every fix's stamp, so
    every GPS update of its replay has another stamp than the run's: paired by stamp, all of them read as
    missing, charged at the gate, and the line that restores the track was 'not advised' (likelihood -1000s).
    Paired by their samples, the replay is judged by what it does to those updates: advised."""
    from tests.support import sim_gps
    from tests.support.sim_faults import shift_stamps

    w = sim_gps.World(duration=60.0, speed=10.0, gps_rate=10.0, gps_sigma=0.3)
    samples = shift_stamps(sim_gps.simulate(w), "gps", 0.25)
    cfg = robot_config(gps="datum = [48.137, 11.575, 520.0]")
    result = run_samples(samples, cfg)
    clock = [v for v in result.verdicts() if v.sensor == "gps" and v.channel == "time" and v.suggestion]
    assert clock, [v.message for v in result.verdicts()]
    (v,) = prove_advice(cfg, samples, clock, base_records=None, base_applied=result.applied)
    assert "stamp_offset_s = -0.2" in v.suggestion, v.suggestion
    assert v.proof is not None and v.proof.judged and v.proof.advised, v.proof


def test_a_line_that_makes_the_gyro_drive_the_prediction_is_the_doctors_not_the_likelihoods() -> None:
    """The wheels' yaw rate 0.02 rad/s off on a straight road, the gyro not fused: the doctor's line fuses it.
    That changes what drives the prediction, which the run's own updates cannot score: the IMU's orientation
    updates, their noise stated ten times too small (0.002 for 0.02 rad), scored it at -6,442, and the problem
    was lowered to a warning the replay "contradicts". A loss is no verdict on a change of what is fused: the
    line is printed as the doctor's, and the problem stays one."""
    from tests.support.core_samples import make_config
    from tests.support.sim import SimConfig, simulate

    samples = simulate(SimConfig(duration=60.0, turn_amplitude=0.0, speed=5.0, standstill=3.0,
                                 gyro_bias=(0.0, 0.0, 0.004), wheel_yaw_offset=0.02, orientation_sigma=0.02))
    cfg = make_config(gyro=False, extra_imu="orientation_noise = [0.002, 0.002, 0.002]")
    result = run_samples(samples, cfg)
    line = [v for v in result.verdicts() if v.suggestion == "angular_velocity = true"]
    assert line, [v.message for v in result.verdicts()]
    (v,) = prove_advice(cfg, samples, line, base_final=result.final, base_applied=result.applied)
    assert v.level == "problem" and v.proof is not None and not v.proof.judged and not v.proof.refuted, v.proof
    assert "likelihood -" in v.proof.effect and "drive the prediction" in v.proof.effect, v.proof
    assert "not advised" not in format_verdicts([v])


def test_a_change_that_applies_the_updates_a_lost_run_gated_or_learned_from_is_not_judged_by_them() -> None:
    """The run as configured lost its GPS (a twist in the wrong frame): of 576 fixes, 59 gated and 517 only learned
    from. A change that applies 566 of them is not scored on the lost run's terms (gate charges, and what it did not
    score): on the highway car they read -2,388 for the line that takes it from 42 m to 1.5 m. A few more applied,
    against the terms the run is scored on, is judged as any change."""
    from fusiond.core.diagnostics import DiagnosticsRecord
    from fusiond.tune.advice import _updates_back

    def fixes(applied: int, gated: int, learning: int) -> list[DiagnosticsRecord]:
        kinds = [(False, False)] * applied + [(True, False)] * gated + [(False, True)] * learning
        return [DiagnosticsRecord(100.0 + 0.1 * k, "gps", ["east", "north"], [0.0, 0.0], [1.0, 1.0], 1.0, 2, rejected,
                                  channel="position", learning=lrn) for k, (rejected, lrn) in enumerate(kinds)]

    assert _updates_back(fixes(0, 59, 517), fixes(566, 0, 10), scored=1100) == "566 more gps/position updates"
    assert _updates_back(fixes(560, 6, 10), fixes(566, 0, 10), scored=1100) == ""
    assert _updates_back(fixes(2, 2, 10), fixes(6, 0, 10), scored=1500) == ""  # doubled, four of 1,500 terms


@pytest.mark.parametrize("proof, level, said", [
    (Proof(True, "likelihood +40"), "problem", ""),
    # judged, within its keys either way: not borne out
    (Proof(False, "likelihood -0"), "warn", "does not make the filter's predictions better by more than it adds"),
    (Proof(False, "likelihood -90", refuted=True), "warn", "makes the filter's predictions worse"),
    # the replay cannot judge it, or did not try: the check's evidence stands
    (Proof(False, "it changes none of the filter's updates", judged=False), "problem", ""),
    (Proof(True, "the 60 s budget ran out", tried=False), "problem", ""),
])
def test_a_problem_whose_line_the_replay_judged_and_did_not_advise_is_a_warning(proof, level, said):
    from fusiond.tune.advice import _with_proof

    v = _with_proof(Verdict("imu", "orientation", "problem", "the IMU's yaw drifts", "sensors.imu.orientation",
                            'orientation = "roll_pitch"'), proof)
    assert v.level == level and v.proof == proof and said in v.message, v
    assert ("so it is a warning, not a problem" in v.message) == (level == "warn")
