"""scripts/soak.py works (the real soak runs for minutes, outside CI): a ~10 s run, and its memory fit."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "scripts" / "soak.py"


def _soak_module():
    spec = importlib.util.spec_from_file_location("soak", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_memory_slope_flags_growth_and_not_noise():
    soak = _soak_module()
    minutes = [i / 12 for i in range(24)]  # 2 min sampled every 5 s
    flat = [80.0 + (0.3 if i % 2 else -0.3) for i in range(24)]
    growing = [80.0 + 3.0 * t for t in minutes]
    assert abs(soak.memory_slope(minutes, flat)) < 0.5
    assert soak.memory_slope(minutes, growing) == pytest.approx(3.0)
    assert soak.percentile([1.0, 2.0, 3.0, 4.0, 5.0], 50) == 3.0


# The memory threshold of the brief run, from what a leak would cost and what noise can do:
# - a leak worth catching keeps one sample-sized object per message (a decoded OdomSample with
#   its 36-float covariance is > 300 B): at 1 kHz IMU + 100 Hz odometry, 256 B per message is
#   1100 * 256 * 60 / 2**20 = 16.1 MiB/min;
# - the noise: the history (history_s = 1 s) and the queues are full after the 2 s warm-up; what
#   is left is the allocator taking one more 1 MiB pymalloc arena. A 1 MiB step in the middle of
#   the fit (8 samples, 1 s apart) has a least-squares slope of 1 / 5.25 MiB/s = 11.4 MiB/min.
# 16 MiB/min flags the first and passes the second.
SLOPE_THRESHOLD_MIB_PER_MIN = 16.0


def test_brief_run_threshold_separates_a_leak_from_an_arena_step():
    soak = _soak_module()
    minutes = [i / 60 for i in range(8)]  # the brief run's fit: 8 samples, 1 s apart
    leak = [70.0 + 1100 * 256 * 60 / 2**20 * t for t in minutes]
    arena = [70.0 + (1.0 if i >= 4 else 0.0) for i in range(8)]
    assert soak.memory_slope(minutes, leak) > SLOPE_THRESHOLD_MIB_PER_MIN
    assert soak.memory_slope(minutes, arena) < SLOPE_THRESHOLD_MIB_PER_MIN


@pytest.mark.e2e
def test_soak_script_runs_briefly(tmp_path):
    out = tmp_path / "soak.json"
    proc = subprocess.run([sys.executable, str(SCRIPT), "--minutes", "0.15", "--sample-s", "1", "--warmup-s", "2",
                           "--slope-threshold", str(SLOPE_THRESHOLD_MIB_PER_MIN), "--json", str(out), "--quiet"],
                          cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    data = json.loads(out.read_text())
    s = data["summary"]
    assert s["daemon_exit_code"] == 0
    assert s["slope_threshold_mib_per_min"] == SLOPE_THRESHOLD_MIB_PER_MIN
    assert s["slope_fit_samples"] >= 5
    assert s["rss_slope_mib_per_min"] < SLOPE_THRESHOLD_MIB_PER_MIN and s["memory"] == "flat"
    assert s["sent"]["imu"] > 1000 and s["sent"]["wheel"] > 100
    assert s["poses_matched"] > 0.9 * s["sent"]["wheel"]  # every odometry put gets its pose, matched by stamp
    assert s["latency_ms"]["p50"] > 0 and s["latency_ms"]["p99"] >= s["latency_ms"]["p50"]
    assert len(data["samples"]) >= 5 and all(x["rss_mib"] > 0 for x in data["samples"])
    assert "queue_full" in s and "RSS slope" in proc.stdout
