"""`fusiond tune` on simulated recordings whose noise is known, and through the real CLI.

The bounds come from the data, not from a run's output: a noise standard deviation fitted by
maximum likelihood from n independent scalar residuals has a relative standard error of
1/sqrt(2n) (the sample variance's chi-square spread), so a fit is held to three of those plus
the optimiser's own stopping width (``fit.XATOL`` in log-scale).
"""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import msgspec
import numpy as np
import pytest

from fusiond.config import load, loads
from fusiond.estimator.geodesy import EnuFrame, enu_to_geodetic
from fusiond.core.sensors import GpsSample, ImuSample
from fusiond.tune import dumps, tune
from fusiond.tune.fit import XATOL
from fusiond.tune.likelihood import Keyed, reference, replay_records, score

from tests.support.configs import robot_config
from tests.support.core_samples import plans_made
from tests.support.sim import SimConfig
from tests.support.sim import simulate as simulate_imu
from tests.support.sim_gps import World
from tests.support.sim_gps import simulate as simulate_gps

ROOT = Path(__file__).resolve().parents[2]
JACKAL = ROOT / "data" / "jackal_test2.bag"
SIGMAS = 3.0  # how many standard errors a fit may be off


def bound(n: int) -> float:
    """The relative error a fitted standard deviation may have with n scalar residuals."""
    return SIGMAS / math.sqrt(2.0 * n) + (math.exp(XATOL) - 1.0)


def row(result, name: str):
    return next(r for r in result.rows if r.param.name == name)


def fit_count(samples, result, kind: type) -> int:
    return sum(1 for s in samples if type(s) is kind and s.stamp <= result.split)


@pytest.fixture(scope="module")
def gps_recording():
    """60 s of a robot with 5 Hz fixes of 0.3 m white noise per axis, no wander."""
    return simulate_gps(World(duration=60.0, gps_rate=5.0, gps_sigma=0.3))


def test_tune_recovers_a_gps_noise_stated_four_times_too_large(gps_recording):
    # the simulated altitude does not wander, so the filter is told so (vertical_error_sigma = 0)
    cfg = robot_config(gps="position_noise = [1.2, 1.2, 1.2]\nvertical_error_sigma = 0.0")
    result = tune(gps_recording, cfg, keys=["gps.position_noise"], budget_s=300.0)
    fixes = fit_count(gps_recording, result, GpsSample)
    horizontal, vertical = row(result, "gps.position_noise.horizontal"), row(result, "gps.position_noise.vertical")
    assert horizontal.status == "tuned" and vertical.status == "tuned"
    for value in horizontal.after:
        assert abs(value / 0.3 - 1.0) < bound(2 * fixes), horizontal.after
    assert abs(vertical.after[0] / 0.3 - 1.0) < bound(fixes), vertical.after
    after = result.config.sensor("gps").position_noise
    assert after == (*horizontal.after, *vertical.after)
    # the held-back part agrees: its likelihood rose and its NIS per dof came to about 1
    assert result.heldback_after.neg_loglik < result.heldback_before.neg_loglik
    assert result.heldback_before.nis_per_dof["gps"] < 0.3 < 0.5 < result.heldback_after.nis_per_dof["gps"] < 1.5


def test_tune_recovers_an_imu_orientation_noise_and_leaves_what_nothing_observes():
    samples = simulate_imu(SimConfig(duration=30.0, orientation_sigma=0.002))
    cfg = robot_config(imu="orientation_noise = [0.008, 0.008, 0.008]")
    result = tune(samples, cfg, keys=["imu.orientation_noise", "wheel.twist_noise.linear"], budget_s=300.0)
    orientation = row(result, "imu.orientation_noise")
    n = 2 * fit_count(samples, result, ImuSample)  # roll and pitch of each message
    assert orientation.status == "tuned"
    for value in orientation.after:
        assert abs(value / 0.002 - 1.0) < bound(n), orientation.after
    # nothing in this recording observes position: the speed's noise cannot be told apart
    linear = row(result, "wheel.twist_noise.linear")
    assert linear.status == "not informed" and linear.after == linear.before
    assert result.config.sensor("wheel") == cfg.sensor("wheel")


def test_tune_refuses_a_value_the_held_back_part_contradicts(gps_recording):
    """The fixes' noise grows to the configured 1.2 m in the last 30 %: the fit part says 0.3 m, the
    held-back part says the config was right, so nothing may change."""
    cfg = robot_config(gps="position_noise = [1.2, 1.2, 1.2]\nvertical_error_sigma = 0.0")
    stamps = [s.stamp for s in gps_recording]
    split = min(stamps) + 0.7 * (max(stamps) - min(stamps))
    frame = EnuFrame(*World().datum)
    rng = np.random.default_rng(11)
    extra = math.sqrt(1.2**2 - 0.3**2)
    samples = []
    for s in gps_recording:
        if type(s) is GpsSample and s.stamp > split and s.status >= 0:
            e, n, u = frame.enu(s.latitude, s.longitude, s.altitude)
            lat, lon, alt = enu_to_geodetic(frame, *(np.array([e, n, u]) + rng.normal(0.0, extra, 3)))
            s = msgspec.structs.replace(s, latitude=lat, longitude=lon, altitude=alt)
        samples.append(s)
    result = tune(samples, cfg, keys=["gps.position_noise.horizontal"], budget_s=300.0)
    horizontal = row(result, "gps.position_noise.horizontal")
    assert horizontal.status == "refused", format_rows(result)
    assert "held-back" in horizontal.note
    assert result.config == cfg
    assert result.heldback_after.neg_loglik == result.heldback_before.neg_loglik


def format_rows(result) -> str:
    return "\n".join(f"{r.param.name} {r.before} -> {r.after} {r.status} {r.note}" for r in result.rows)


def test_a_replay_scored_on_its_own_terms_is_half_the_sum_of_log_det_and_nis():
    samples = simulate_imu(SimConfig(duration=5.0))
    cfg = robot_config()
    records = replay_records(cfg, samples)
    ref = reference(records, cfg)
    terms = [r for r in records if r.channel == "orientation" and not r.learning and not r.rejected]
    assert len(ref) == len(terms) > 0
    by_hand = 0.5 * sum(sum(math.log(v) for v in r.innovation_var) + r.nis for r in terms)
    got = score(records, ref)
    assert got.applied == len(terms) and got.rejected == got.missing == 0
    assert got.neg_loglik == pytest.approx(by_hand, rel=1e-12)
    # a replay that produces none of the terms pays each one's log det S and its capped NIS
    empty = score([], ref)
    assert empty.missing == len(ref) and empty.neg_loglik > got.neg_loglik


def test_records_keyed_once_score_and_reference_as_the_records_themselves():
    """The proof keys a replay's records once (``Keyed``) for the several references it scores them on: the same
    terms and the same score to the bit as the records themselves, on the whole run and on a held-back end, with
    records missing and slid; and the score is the module doc's sum where no record is left to stand in for a missing
    term."""
    samples = simulate_imu(SimConfig(duration=5.0))
    cfg = robot_config()
    records = replay_records(cfg, samples)
    end = records[len(records) // 2].stamp
    fewer = [r for i, r in enumerate(records) if i % 7]
    slid = [msgspec.structs.replace(r, stamp=r.stamp + 0.05) if i % 3 else r for i, r in enumerate(fewer)]
    for after in (-math.inf, end):
        ref = reference(records, cfg, after=after)
        assert len(ref) > 0 and reference(Keyed(records), cfg, after=after).terms == ref.terms
        for recs in (records, fewer, slid, []):
            assert score(Keyed(recs), ref) == score(recs, ref)
    ref = reference(records, cfg)  # every update a term: none left over to stand in for a missing one
    assert score(fewer, ref).missing > 0
    for recs in (records, fewer, []):
        assert score(recs, ref).neg_loglik == pytest.approx(_score_by_definition(recs, ref), rel=1e-12)


def test_the_checks_records_are_not_keyed_and_score_nothing():
    """A check moves no state (``CHECK_CHANNELS``: the wheels' yaw rate against the gyro): ``Keyed`` leaves its
    records out, and a replay's terms and score are the same with them as without them."""
    from fusiond.tune.likelihood import CHECK_CHANNELS

    samples = simulate_imu(SimConfig(duration=5.0))
    cfg = robot_config()
    records = replay_records(cfg, samples)
    updates = [r for r in records if r.channel not in CHECK_CHANNELS]
    assert len(updates) < len(records)  # the wheels' yaw-rate checks are among them
    keyed = Keyed(records)
    assert [r for _, r, _ in keyed.items] == updates
    ref = reference(records, cfg)
    assert reference(updates, cfg).terms == ref.terms
    assert score(keyed, ref) == score(updates, ref) == score(Keyed(updates), ref)


def _score_by_definition(records, ref) -> float:
    """-log L without pairing: each term found by its key, rejected or missing ones at their cap (the module doc);
    equal to ``score`` wherever no record slid."""
    by_key, seen = {}, {}
    for r in records:
        k = (r.sensor, r.channel, r.stamp)
        by_key[(*k, seen.get(k, 0))] = r
        seen[k] = seen.get(k, 0) + 1
    total = 0.0
    for key, (ld, cap, _) in ref.terms.items():
        r = by_key.get(key)
        if r is None:
            total += ld + cap
        elif r.rejected:
            total += sum(math.log(v) for v in r.innovation_var) + min(r.nis, cap)
        else:
            total += sum(math.log(v) for v in r.innovation_var) + r.nis
    return 0.5 * total


def test_an_update_whose_window_slid_is_scored_as_the_same_term_and_one_not_made_is_missing():
    """Windowed updates (the IMU's gravity tilt, every ~0.1 s) whose windows a parameter slides by a fraction of
    one: the same terms, scored on the replay's own innovations; none of them charged as missing. An update made
    more than the channel's median interval away stands in for the one not made (the count per channel is the
    reference's); one not made at all is missing, charged at its gate."""
    samples = simulate_imu(SimConfig(duration=5.0))
    cfg = robot_config()
    records = replay_records(cfg, samples)
    ref = reference(records, cfg)
    interval = ref.tolerance[("imu", "orientation")]
    assert interval > 0.0
    slid = [msgspec.structs.replace(r, stamp=r.stamp + 0.4 * interval) for r in records]
    exact, moved = score(records, ref), score(slid, ref)
    assert moved.missing == 0 and moved.neg_loglik == pytest.approx(exact.neg_loglik, rel=1e-12)
    terms = [i for i, r in enumerate(records) if r.channel == "orientation" and not r.learning]
    mid = terms[len(terms) // 2]
    far = [msgspec.structs.replace(r, stamp=r.stamp + 1.5 * interval) if i == mid else r for i, r in enumerate(records)]
    assert score(far, ref).missing == 0
    assert score(far, ref).neg_loglik == pytest.approx(exact.neg_loglik, rel=1e-12)  # its own innovation, moved
    fewer = [r for i, r in enumerate(records) if i != mid]
    assert score(fewer, ref).missing == 1 and score(fewer, ref).neg_loglik > exact.neg_loglik


@pytest.mark.parametrize("example", sorted((ROOT / "examples").glob("*.toml")) + [ROOT / "config.toml"],
                         ids=lambda p: p.name)
def test_the_written_config_loads_back_to_the_same_config(example):
    cfg = load(example)
    assert loads(dumps(cfg, {("filter", "process_noise"): "a comment"}, header="a header\nline two")) == cfg


@pytest.mark.parametrize("example", sorted((ROOT / "examples").glob("*.toml")) + [ROOT / "config.toml"],
                         ids=lambda p: p.name)
def test_the_tuned_keys_are_edited_into_the_users_own_file(example):
    """The user's file with its comments (``fusiond init`` explains each choice in them): a key it has is
    replaced on its line, a key it lacks is added to its table (a sensor's, or a top-level table the file
    may not have), each with its comment; every line the file had but the edited ones stays, and the text
    loads to the tuned config. A sensor added or removed is no edit: None (the whole config is written)."""
    import msgspec

    from fusiond.tune.toml_out import edited

    text = example.read_text()
    cfg = load(example)
    last = cfg.sensors[-1]
    noise = "gyro_noise" if hasattr(last, "gyro_noise") else "twist_noise" if hasattr(last, "twist_noise") else None
    sensors = list(cfg.sensors)
    if noise == "gyro_noise":
        sensors[-1] = msgspec.structs.replace(last, gyro_noise=0.00123)
    elif noise == "twist_noise":
        sensors[-1] = msgspec.structs.replace(last, twist_noise=[0.1, 0.1, 0.1, 0.2, 0.2, 0.2])
    tuned = msgspec.structs.replace(cfg, sensors=sensors,
                                    filter=msgspec.structs.replace(cfg.filter, gyro_bias_walk=3.25e-5))
    out = edited(text, cfg, tuned, {("filter", "gyro_bias_walk"): "fitted here"}, header="a header")
    assert out is not None and loads(out) == tuned
    assert out.startswith("# a header\n") and "gyro_bias_walk = 3.25e-05  # fitted here" in out
    kept = set(out.splitlines())
    edited_keys = ("gyro_bias_walk", noise or "-")
    assert all(line in kept for line in text.splitlines() if not line.lstrip().startswith(edited_keys))
    assert edited(text, cfg, msgspec.structs.replace(cfg, sensors=cfg.sensors[:-1])) is None


# --- through the real CLI --------------------------------------------------------------------------

def fusiond(*args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "fusiond", *args], capture_output=True, text=True, cwd=cwd,
                          timeout=600)


@pytest.mark.e2e
def test_tune_cli_writes_a_config_that_replay_accepts(tmp_path):
    out = tmp_path / "tuned.toml"
    done = fusiond("tune", str(JACKAL), "--config", "examples/jackal.toml", "--out", str(out),
                   "--keys", "imu.orientation_noise,filter.process_noise", "--budget-s", "30", "--quiet")
    assert done.returncode == 0, done.stderr
    assert "imu.orientation_noise" in done.stdout and "held-back" in done.stdout
    assert f"tuned config {out}" in done.stdout
    tuned = load(out)
    assert [s.name for s in tuned.sensors] == ["wheel", "imu"]
    replayed = fusiond("replay", str(JACKAL), "--config", str(out), "--tum", str(tmp_path / "t.tum"), "--quiet")
    assert replayed.returncode == 0, replayed.stderr
    assert (tmp_path / "t.tum").read_text().count("\n") > 100


@pytest.mark.e2e
def test_tune_cli_refuses_an_unknown_key_before_reading_the_bag(tmp_path):
    done = fusiond("tune", str(tmp_path / "missing.bag"), "--config", "examples/jackal.toml",
                   "--out", str(tmp_path / "t.toml"), "--keys", "imu.gyro_nosie")
    assert done.returncode == 2
    assert "unknown key 'imu.gyro_nosie'" in done.stderr and "imu.gyro_noise" in done.stderr
    assert "Traceback" not in done.stderr


@pytest.mark.e2e
def test_tune_cli_bad_inputs_exit_2_in_one_line(tmp_path):
    not_a_bag = tmp_path / "x.bag"
    not_a_bag.write_bytes(b"\x89PNG\r\n\x1a\n" + b"\0" * 64)
    done = fusiond("tune", str(not_a_bag), "--config", "examples/jackal.toml", "--out", str(tmp_path / "t.toml"))
    assert done.returncode == 2 and "Traceback" not in done.stderr and done.stderr.strip()
    done = fusiond("tune", str(JACKAL), "--config", "examples/jackal.toml", "--out", str(tmp_path))
    assert done.returncode == 2 and "is a directory" in done.stderr
    done = fusiond("tune", str(JACKAL), "--config", "examples/jackal.toml", "--out", str(tmp_path / "t.toml"),
                   "--budget-s", "0")
    assert done.returncode == 2 and "--budget-s" in done.stderr


def test_the_table_says_an_unstated_gps_noise_is_measured_and_the_default_only_its_bound():
    from fusiond.core.sensors.gps.tunables import noise_params

    fix = GpsSample("gps", 1.0, 48.1, 11.5, 520.0, 0, (0.0,) * 9, 0)  # covariance type UNKNOWN
    cfg = robot_config(gps="")
    gps = cfg.sensors[-1]
    horizontal, vertical = noise_params(gps, [fix, fix])
    assert horizontal.source == "unstated: measured, at most" and horizontal.start() == (2.5, 2.5)
    assert vertical.source == "messages (median)"  # the altitude keeps the default and its wander state
    off = noise_params(msgspec.structs.replace(gps, estimate_unknown_noise=False), [fix])
    assert off[0].source == "messages (median)"
    stated = msgspec.structs.replace(fix, position_covariance=(0.04, 0, 0, 0, 0.04, 0, 0, 0, 0.09), covariance_type=2)
    assert noise_params(gps, [stated])[0].source == "messages (median)"


def test_replays_side_by_side_tune_as_replays_in_turn(gps_recording, monkeypatch):
    """The probes, and each held-back check with its prediction of the held-back fixes, replayed in forked
    processes beside each other (``forked``): the same fit, table and config as all in this process."""
    import fusiond.tune.forked as forked

    cfg = robot_config(gps="position_noise = [1.2, 1.2, 1.2]\nvertical_error_sigma = 0.0",
                       imu="orientation_noise = [0.01, 0.01, 0.01]")
    keys = ["gps.position_noise", "imu.orientation_noise"]
    side_by_side = tune(gps_recording, cfg, keys=keys, budget_s=300.0)
    monkeypatch.setattr(forked, "workers_available", lambda: 1)
    in_turn = tune(gps_recording, cfg, keys=keys, budget_s=300.0)
    assert side_by_side.prediction_before is not None  # fixes were held back: their checks ran beside
    assert side_by_side.config == in_turn.config and side_by_side.evaluations == in_turn.evaluations
    assert [(r.param.name, r.after, r.status, r.note) for r in side_by_side.rows] == \
        [(r.param.name, r.after, r.status, r.note) for r in in_turn.rows]
    for field in ("fit_before", "fit_after", "heldback_before", "heldback_after", "prediction_before",
                  "prediction_after"):
        assert getattr(side_by_side, field) == getattr(in_turn, field), field


def test_replays_side_by_side_stop_at_the_bound_keeping_what_was_replayed(gps_recording):
    """``_Objective.many`` under a replay bound: the replays it starts are counted, cached and equal to
    the same points replayed in turn; the ones past the bound are not started, and the fit is told."""
    from fusiond.tune.fit import _Objective, _OutOfBudget, _Progress
    from fusiond.tune.params import select, tunable_params

    cfg = robot_config(gps="position_noise = [1.2, 1.2, 1.2]\nvertical_error_sigma = 0.0")
    samples = [s for s in gps_recording if s.stamp <= gps_recording[0].stamp + 20.0]
    params = [p for p in select(tunable_params(cfg, samples), ["gps.position_noise"]) if not p.skipped]
    points = [[0.3 * (k + 1)] + [0.0] * (len(params) - 1) for k in range(4)]
    side_by_side = _Objective(cfg, params, samples, math.inf, 3, _Progress(False, 0))
    side_by_side([0.0] * len(params))  # the reference replay
    with pytest.raises(_OutOfBudget):
        side_by_side.many(points)
    assert side_by_side.replays == 3 and side_by_side.stopped == "maxfev" and len(side_by_side.cache) == 3
    in_turn = _Objective(cfg, params, samples, math.inf, 10, _Progress(False, 0))
    in_turn([0.0] * len(params))
    for p in points[:2]:
        assert side_by_side.many([p]) == [in_turn(p)]  # a cached point costs no replay: no bound asked


def test_tune_says_the_doctors_problems_on_keys_it_does_not_fit_before_its_table():
    """The odom frame's twist configured as the body's (a problem the doctor names with twist_frame, which tune
    does not fit): tune fits the noise around it, and says first that the problem is to be fixed."""
    from tests.support.twist_frames import with_pose
    from tests.support.core_samples import make_config
    from fusiond.tune import format_table

    samples = with_pose(SimConfig(duration=60.0, turn_amplitude=0.6, speed=2.0), world=True)
    result = tune(samples, make_config(), maxfev=4, budget_s=60.0)
    (v,) = result.problems
    assert v.key == "sensors.wheel.twist_frame" and v.suggestion == 'twist_frame = "world"', v
    text = format_table(result)
    assert text.splitlines()[0].startswith("the doctor finds 1 problem") and 'twist_frame = "world"' in text, text
    clean = tune(with_pose(SimConfig(duration=60.0, turn_amplitude=0.6, speed=2.0), world=False), make_config(),
                 maxfev=4, budget_s=60.0)
    assert not [p for p in clean.problems if p.key == "sensors.wheel.twist_frame"], clean.problems


def test_a_doctor_line_stating_the_floor_the_messages_are_held_at_is_no_change(jackal_bag):
    """The Jackal's IMU with its gyro noise stated ten times too large: the orientation NIS reads low and the doctor
    suggests orientation_noise at its floor, the very noise the messages' covariances are floored to. Tuned, the
    gyro's noise comes down, and that line changes nothing: not written, not said to be tuned."""
    from fusiond.tune import read_samples

    text = (ROOT / "examples" / "jackal.toml").read_text()
    cfg = loads(text.replace("[[sensors]]\nname = \"imu\"", "[[sensors]]\nname = \"imu\"\ngyro_noise = 0.05", 1))
    assert cfg.sensor("imu").gyro_noise == 0.05 and cfg.sensor("imu").orientation_noise is None
    result = tune(read_samples([jackal_bag], cfg), cfg, keys=["imu.gyro_noise", "imu.orientation_noise"])
    rows = {r.param.name: r for r in result.rows}
    assert rows["imu.gyro_noise"].status == "tuned" and rows["imu.gyro_noise"].after < 0.01
    orientation = rows["imu.orientation_noise"]
    assert orientation.status != "tuned" and result.config.sensor("imu").orientation_noise is None, orientation


def test_a_fit_that_stops_at_its_own_limit_says_so():
    """An attitude process noise started far above what the recording supports (another filter's, carried over):
    the fit stops at 1/1000 of the start, its search's limit, not at a floor or an optimum, and the row says the
    recording asks for less still, so that the user tunes again rather than takes it as fitted. (No orientation
    update here: the doctor has no value of its own for it.)"""
    samples = simulate_gps(World(duration=60.0, gps_rate=5.0, gps_sigma=0.02))
    keys = ["filter.process_noise.attitude"]
    result = tune(samples, robot_config(gps="", filt="process_noise = [0.002, 200.0]", orientation="off"), keys=keys,
                  budget_s=300.0)
    r = row(result, keys[0])
    assert r.status == "tuned" and r.after == pytest.approx([0.2], rel=1e-6), r
    assert "at the fit's limit, 1/1000 of where it started" in r.note, r.note
    # from the default, inside its limits (the likelihood tells nothing below it apart): nothing of the kind is said
    ok = row(tune(samples, robot_config(gps="", orientation="off"), keys=keys, budget_s=300.0), keys[0])
    assert ok.status == "unchanged" and "fit's limit" not in ok.note, ok


def test_tune_plans_the_whole_recording_once(monkeypatch):
    """The doctor's replay of the whole recording and the held-back checks' replays share one snapshot plan
    (``likelihood.Plans``): the same samples with the same sensors' keys make the same plan."""
    samples = simulate_imu(SimConfig(duration=10.0, orientation_sigma=0.002))
    cfg = robot_config(imu="orientation_noise = [0.008, 0.008, 0.008]")
    made = plans_made(monkeypatch)
    result = tune(samples, cfg, keys=["imu.orientation_noise"], budget_s=300.0)
    assert row(result, "imu.orientation_noise").status == "tuned"
    assert made.count(len(samples)) == 1  # in this process; the forked replays plan in theirs
