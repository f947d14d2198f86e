"""`fusiond bench`'s yardsticks are what they claim: the tight step is the estimator's model, the
synthetic bag replays cleanly. (No timing is asserted; `fusiond bench` reports the numbers.)"""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchmarks import bench
from fusiond.config import load
from fusiond.core.fusion import FusionCore
from fusiond.estimator import predict
from fusiond.estimator import observations as obs
from fusiond.replay.bag import open_bag_samples

ROOT = bench.Path(bench.__file__).resolve().parents[1]


def test_tight_step_runs_the_estimators_model():
    """300 steps of the yardstick and of fusiond's estimator (bench_estimator's step) from the same
    start with the same inputs. The yardstick's two shortcuts bound the difference: Jr(w dt) ~ I
    (|w dt| = 2 mrad: the bias columns of F are off by |w dt| / 2 = 1e-3 relative) and the small-tilt
    H (tilt ~1 mrad: 1e-6 relative). The bias columns only couple the small bias variance (1e-4 *
    dt^2 per step) into attitude, so P's pose diagonal agrees to well within 1e-3 relative, the
    pose to within 1e-6 m / 1e-6 rad over 1.5 m of travel."""
    step = bench.tight_step()
    m = bench.estimator_model()
    layout, ekf = m.layout, m.ekf
    for _ in range(300):
        step()
        x, F, Q = predict(layout, ekf.x, m.u, 0.01, m.noise, m.ws)
        ekf.propagate(x, F, Q)
        y, H, R = obs.orientation(layout, ekf.x, (0.001, -0.002, 0.0), m.cov, (0, 1))
        ekf.update(y, H, R, mask=m.mask)
    st = dict(zip(step.__code__.co_freevars, (c.cell_contents for c in step.__closure__)))["st"]
    assert math.dist(st["p"], ekf.x[0:3]) < 1e-6
    assert abs(abs(float(np.dot(st["q"], ekf.x[3:7]))) - 1.0) < 1e-12  # cos(angle/2): angle < 3e-6 rad
    np.testing.assert_allclose(np.diag(st["P"])[:6], np.diag(ekf.P)[:6], rtol=1e-3)
    assert math.dist(st["p"], (0.0, 0.0, 0.0)) > 1.0  # it did travel


def test_synthetic_bag_replays_every_message(tmp_path):
    cfg = load(ROOT / "examples" / "jackal.toml")
    odom = "/" + cfg.sensors[0].key
    imu = "/" + cfg.sensors[1].key
    path = bench.write_synthetic_bag(tmp_path / "synthetic", odom, imu, messages=301)
    core = FusionCore(cfg)
    with open_bag_samples([path], cfg.sensors) as samples:
        n = sum(1 for s in samples if core.ingest(s).accepted)
    assert n == 301
    assert [st.applied for st in core.stats] == [101, 200]  # 50 Hz odometry, 100 Hz IMU: 1 + 2 per 20 ms
    # 2 s of a 1 m/s circle of radius 5 m (0.2 rad/s): the chord from the start, 2 r sin(0.2 rad)
    assert math.dist(core.pose()[1][0:3].tolist(), (0.0, 0.0, 0.0)) == pytest.approx(
        2 * 5.0 * math.sin(0.2 * 2.0 / 2), abs=0.05)


def test_targets_are_ratios_of_the_same_run():
    result = {"estimator": {"predict_update_us": 30.0}, "yardstick": {"tight_numpy_step_us": 20.0},
              "replay": {"replay_vs_rosbags": 0.4},
              "process": {"fusiond_replay_s": 2.0, "fusiond_replay_cpu_s": 1.5, "bare_numpy_script_s": 1.6,
                          "bare_numpy_script_cpu_s": 1.0}}
    t = bench.targets(result)
    assert t["estimator_step_vs_tight_numpy (<=1.5)"] == pytest.approx(1.5)
    assert t["replay_in_process_vs_rosbags_decode (>=0.5)"] == pytest.approx(0.4)
    assert t["replay_process_vs_bare_jackal_wall (<=1.0)"] == pytest.approx(1.25)
    assert t["replay_process_vs_bare_jackal_cpu (<=1.0)"] == pytest.approx(1.5)
    assert not any("synthetic" in k for k in t)
    result["latency"] = {"cpu_ratio": 2.1}
    t = bench.targets(result)
    assert t["daemon_cpu_vs_bare_subscriber (<=2.0)"] == pytest.approx(2.1)
    lines = bench.format_table({"targets": t}).splitlines()
    said = {line.split()[1]: line.split()[-1] for line in lines}
    assert said == {"estimator_step_vs_tight_numpy": "met", "replay_in_process_vs_rosbags_decode": "missed",
                    "replay_process_vs_bare_jackal_wall": "missed", "replay_process_vs_bare_jackal_cpu": "missed",
                    "daemon_cpu_vs_bare_subscriber": "missed"}


def test_process_benchmark_runs_fusiond_byte_compiled_as_installed():
    """`bench_process` compiles the package first, as pip does on install: every module of fusiond
    then has a cached bytecode file that CPython accepts for its current source."""
    import importlib.util
    from pathlib import Path

    import fusiond

    bench._compile_package()
    package = Path(fusiond.__file__).resolve().parent
    sources = sorted(package.rglob("*.py"))
    assert len(sources) > 40
    for src in sources:
        cached = Path(importlib.util.cache_from_source(str(src)))
        assert cached.is_file(), src
        # the header's source mtime and size are what the import system checks before using it
        header = cached.read_bytes()[8:16]
        stat = src.stat()
        assert int.from_bytes(header[:4], "little") == int(stat.st_mtime) & 0xFFFFFFFF
        assert int.from_bytes(header[4:], "little") == stat.st_size & 0xFFFFFFFF


def test_replay_split_adds_up_and_counts_the_same_messages(jackal_bag):
    """The in-process split is of one bag: rosbags decodes the configured topics' messages, the
    replay fuses the same number; the core-free bound is the replay's rate without the core's share."""
    cfg = load(ROOT / "examples" / "jackal.toml")
    r = bench.bench_replay(jackal_bag, cfg, repeat=1)
    with open_bag_samples([jackal_bag], cfg.sensors) as b:
        assert r["messages"] == sum(1 for _ in b)
    assert r["replay_vs_rosbags"] == pytest.approx(r["rosbags_us_per_msg"] / r["replay_us_per_msg"])
    free = r["replay_us_per_msg"] - r["core_us_per_msg"]
    if free > 0:
        assert r["replay_vs_rosbags_core_free"] == pytest.approx(r["rosbags_us_per_msg"] / free)
    assert r["replay_no_doctor_vs_rosbags"] == pytest.approx(r["rosbags_us_per_msg"] / r["no_doctor_us_per_msg"])
