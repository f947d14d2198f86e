"""Fixtures and options shared by every test tier.

The tests are in tiers, one directory each, by subject:

- ``tests/unit``: the maths, the estimator and its kernels, codecs and bags, config, logs, layout, and
  small core units (history, health, diagnostics, TF tree, state file);
- ``tests/sensors``: the sensor models and the fusion core's behaviour on simulated robots (GPS, IMU,
  odometry, pose, time jumps, gaps, two_d_mode, ...);
- ``tests/doctor``: the doctor's verdicts, the advice it pastes, ``fusiond tune`` and ``calibrate-imu``;
- ``tests/e2e``: the daemon and Zenoh on loopback, the CLI end to end, replays of real bags and
  recordings, deploy, benchmarks, soak.

``tests/support`` holds the helpers (simulations, configs, reference encoders, daemon and session
helpers); a test module imports helpers from ``tests.support`` only, never from another test module.
Test data stays in ``tests/data`` (and the Jackal bag in the repository's ``data/``).
``--fast`` (below) selects by module name, whatever the tier.
"""

from __future__ import annotations

from pathlib import Path

import pytest

# the helpers hold asserts of their own (tests.support.verdicts): rewrite them as pytest does in test modules
pytest.register_assert_rewrite("tests.support")

# --- the fast tier (`scripts/test.sh --fast`, under a minute on 2 cores) ---------------------------
#
# The modules that pin the maths, the sensor models, the core's behaviour, the codecs, the config and
# the evaluation, without simulations of minutes nor processes nor Zenoh: what a developer runs on
# every change. The whole suite (CI) adds the simulated recordings, the doctor, the daemon end to end.
FAST_MODULES = frozenset({
    "test_estimator_math", "test_estimator_fast_paths", "test_kernels", "test_layout", "test_history_ring",
    "test_written_out", "test_replay_collector", "test_snapshot_plan",
    "test_codecs", "test_config_truth", "test_logs", "test_thread_state",
    "test_time_jumps", "test_fusion_core", "test_sensor_models", "test_evaluate", "test_health",
    "test_diagnostics", "test_gps_blocks", "test_continuous_odom", "test_odom_rate", "test_world_twist",
    "test_two_d_mode", "test_bag", "test_trajectory_pin", "test_standstill_bias", "test_tf_tree", "test_state_file",
    "test_toy_kind", "test_cli_parser", "test_kind_questions", "test_doctor_median", "test_smoother",
    "test_smoother_core", "test_fixed_lag", "test_lag_window", "test_doctor_order", "test_forked", "test_simplex",
    "test_read_ahead",
})


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--fast", action="store_true", help="only the fast tier (tests/conftest.py FAST_MODULES)")


def pytest_ignore_collect(collection_path: Path, config: pytest.Config) -> bool | None:
    """--fast: a test module outside the tier is not imported at all (collecting every module took ~7 s of the
    tier's minute, for the 900 tests it then deselected)."""
    if (config.getoption("--fast") and collection_path.suffix == ".py" and collection_path.name.startswith("test_")
            and collection_path.stem not in FAST_MODULES):
        return True
    return None


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if not config.getoption("--fast"):
        return
    keep = [i for i in items if i.path.stem in FAST_MODULES
            and i.get_closest_marker("e2e") is None and i.get_closest_marker("long_sim") is None]
    config.hook.pytest_deselected(items=[i for i in items if i not in keep])
    items[:] = keep


# --- the estimator's backends (fusiond/estimator/backend.py) -----------------------------------------

@pytest.fixture(scope="session", params=["numpy", "compiled"])
def backend(request):
    """Each estimator backend in turn: a test that takes it passes on the Python reference and on the
    compiled kernels (skipped where they were not built)."""
    from fusiond.estimator.backend import COMPILED, PYTHON

    if request.param == "numpy":
        return PYTHON
    if COMPILED is None:
        pytest.skip("fusiond.estimator._kernels not built (no C compiler at install)")
    return COMPILED


# --- bag fixtures (codecs / replay.bag tests) ------------------------------------------

# robot_localization's test bag 2 (BSD, data/LICENSE.robot_localization), shipped in the repo so
# that the Jackal tests always run.
JACKAL_BAG = Path(__file__).resolve().parents[1] / "data" / "jackal_test2.bag"


@pytest.fixture(scope="session")
def jackal_bag() -> Path:
    """The real Jackal ROS 1 bag (data/jackal_test2.bag in the repo)."""
    if not JACKAL_BAG.is_file():
        pytest.fail(f"the in-repo Jackal bag is missing: {JACKAL_BAG}")
    return JACKAL_BAG


# --- reliability observations (tests/e2e/test_reliability.py, tests/e2e/test_security.py) -----------
#
# The reliability tests record what they fed the daemon and what they observed into one
# JSON file in pytest's session temp dir. With FUSIOND_WRITE_RELIABILITY=1 the session end
# renders docs/RELIABILITY.md from it (scripts/reliability_table.py), so that table is
# produced by the test suite, never written by hand.

import json as _json
import os as _os
import platform as _platform
import time as _time

RELIABILITY_ENV = "FUSIOND_WRITE_RELIABILITY"
_reliability_path: list[Path] = []


class ReliabilityLog:
    """Rows of the reliability table; every record rewrites the JSON file (nothing lost if a test dies)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.rows: list[dict] = []

    def record(self, *, group: str, sensor: str, input: str, expected: str, observed: str, passed: bool,
               crashed: bool = False, non_finite: bool = False, test: str = "") -> None:
        self.rows.append({"group": group, "sensor": sensor, "input": input, "expected": expected,
                          "observed": observed, "passed": bool(passed), "crashed": bool(crashed),
                          "non_finite": bool(non_finite), "test": test})
        self.path.write_text(_json.dumps({"created": _time.strftime("%Y-%m-%d %H:%M:%S"),
                                          "machine": f"{_platform.machine()}, {_os.cpu_count()} CPUs",
                                          "rows": self.rows}, indent=1))


@pytest.fixture(scope="session")
def reliability_log(tmp_path_factory) -> ReliabilityLog:
    path = tmp_path_factory.getbasetemp() / "reliability.json"
    _reliability_path.append(path)
    return ReliabilityLog(path)


def pytest_sessionfinish(session, exitstatus):
    if _os.environ.get(RELIABILITY_ENV) != "1" or not _reliability_path or not _reliability_path[0].is_file():
        return
    import importlib.util

    root = Path(__file__).resolve().parents[1]
    spec = importlib.util.spec_from_file_location("reliability_table", root / "scripts" / "reliability_table.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    out = module.render_file(_reliability_path[0], root / "docs" / "RELIABILITY.md")
    print(f"\nreliability table written to {out}")
