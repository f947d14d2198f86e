"""The package layout's contracts: public surfaces, one error hierarchy, reason codes in one module."""

from __future__ import annotations

import ast
import importlib
import re
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from fusiond import errors, reasons

PACKAGE = Path(__file__).resolve().parents[2] / "fusiond"


@pytest.mark.parametrize("name", ["fusiond.core", "fusiond.transport", "fusiond.replay", "fusiond.estimator",
                                  "fusiond.doctor"])
def test_each_package_declares_a_public_surface_that_resolves(name):
    pkg = importlib.import_module(name)
    assert pkg.__all__ and len(set(pkg.__all__)) == len(pkg.__all__)
    for n in pkg.__all__:
        assert getattr(pkg, n) is not None, n
    with pytest.raises(AttributeError):
        getattr(pkg, "no_such_name")


def test_every_error_is_a_fusiond_error_and_old_names_are_the_same_classes():
    from fusiond.config import ConfigError
    from fusiond.replay.bag import BagError
    from fusiond.codecs import DecodeError
    from fusiond.transport.session import SessionError

    for name in errors.__all__:
        assert issubclass(getattr(errors, name), errors.FusiondError), name
    assert ConfigError is errors.ConfigError and issubclass(ConfigError, ValueError)
    assert BagError is errors.BagError and issubclass(BagError, ValueError)
    assert issubclass(BagError, errors.ReplayError)
    assert SessionError is errors.SessionError and issubclass(SessionError, RuntimeError)
    assert issubclass(SessionError, errors.TransportError)
    assert issubclass(DecodeError, errors.CodecError) and issubclass(DecodeError, ValueError)


def test_an_estimate_before_any_sample_is_a_core_error():
    from fusiond.config import loads
    from fusiond.core import FusionCore

    core = FusionCore(loads('[[sensors]]\nname = "wheel"\nkind = "odom"\nkey = "odom"\n'))
    with pytest.raises(errors.CoreError, match="no sample has been fused yet"):
        core.estimate()
    with pytest.raises(errors.CoreError):
        core.pose()


def test_reason_codes_are_unique_and_each_has_a_meaning():
    codes = [v for k, v in vars(reasons).items() if k.isupper() and isinstance(v, str)]
    assert len(codes) == len(set(codes)) == len(reasons.MEANINGS)
    assert set(codes) == set(reasons.ALL)
    for code, meaning in reasons.MEANINGS.items():
        assert code == code.lower() and " " not in code
        assert meaning and "\n" not in meaning


def test_the_codecs_reasons_are_listed():
    from fusiond import codecs

    assert set(codecs.REASONS) <= set(reasons.ALL)


_REASON_CALLS = {"Rejected": 0, "_drop": 1, "on_dropped": 1}  # callee -> position of the reason argument


def test_no_reason_code_is_a_literal_outside_reasons_py():
    """Drops and rejections name their reason through fusiond.reasons, so that module is the whole list."""
    literal: list[str] = []
    for path in PACKAGE.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if not isinstance(node, ast.Call):
                continue
            f = node.func
            callee = f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else None
            pos = _REASON_CALLS.get(callee)
            if pos is None or len(node.args) <= pos:
                continue
            arg = node.args[pos]
            if isinstance(arg, ast.Constant) and isinstance(arg.value, str):
                literal.append(f"{path.relative_to(PACKAGE)}:{node.lineno} {callee}({arg.value!r})")
            for sub in ast.walk(arg):  # a conditional of two literals is still a literal
                if isinstance(sub, ast.IfExp) and any(isinstance(b, ast.Constant) for b in (sub.body, sub.orelse)):
                    literal.append(f"{path.relative_to(PACKAGE)}:{node.lineno} {callee}(...)")
    assert not literal, literal


# What a sensor's kind means is its descriptor's to say (core/sensors/kind.py): outside core/sensors/
# no module, the doctor's checks included, tests a kind by its config class or tag, nor reads an IMU's
# orientation mode as a string (``ImuSensor.fuses_yaw`` and its siblings name it).
_KIND_BRANCH = re.compile(r"kind *(==|!=|in) *|\.kind\b.*(==|in)|isinstance\([^)]*(Imu|Odom|Gps|Pose)(Config|Sensor|Model)"
                          r"|\.orientation *(==|!=|in\b|not in\b)")
_KIND_BRANCHES_KEPT: dict[str, int] = {}


def test_no_module_outside_the_sensor_kinds_branches_on_a_kind():
    found: dict[str, int] = {}
    for path in PACKAGE.rglob("*.py"):
        rel = path.relative_to(PACKAGE).as_posix()
        if rel.startswith("core/sensors/"):
            continue
        hits = sum(1 for line in path.read_text().splitlines() if _KIND_BRANCH.search(line))
        if hits:
            found[rel] = hits
    assert found == _KIND_BRANCHES_KEPT


# The pose's place in the state is the estimator's to know (fusiond/estimator/state.py POSITION, ATTITUDE,
# YAW_ROW, ...; ErrorStateEKF.position/attitude/yaw_variance): no bare index into a state or covariance.
_BARE_POSE_INDEX = re.compile(r"\b(x|x0|x1|P|Q)\[\d+(:\d+)?(, *\d+(:\d+)?)?\]|\.(x|P)\[\d|_covariance\(\[\d")


def _lines_matching(pattern: re.Pattern, skip: Callable[[str], bool]) -> list[str]:
    """``module:line: text`` of every line of the package that ``pattern`` finds, in the modules whose
    package-relative path ``skip`` does not exempt."""
    return [f"{rel}:{i}: {line.strip()}" for path in PACKAGE.rglob("*.py")
            if not skip(rel := path.relative_to(PACKAGE).as_posix())
            for i, line in enumerate(path.read_text().splitlines(), 1) if pattern.search(line)]


def _in_the_estimator(rel: str) -> bool:
    return rel.startswith("estimator/")


def test_no_bare_pose_index_outside_the_estimator():
    assert _lines_matching(_BARE_POSE_INDEX, _in_the_estimator) == []


# The estimator alone writes the state and its covariance (ErrorStateEKF's methods keep P symmetric and
# PSD, and tell the smoother's recorder): no assignment to a filter's x or P, whole or in part, elsewhere.
_STATE_WRITE = re.compile(r"\bekf\.(x|P)\b(\[[^\]]*\])?\s*([-+*/]?=)(?!=)")


def test_only_the_estimator_writes_the_state_and_its_covariance():
    assert _lines_matching(_STATE_WRITE, _in_the_estimator) == []


# The estimator's numerics run in the backend the filter was built with (fusiond/estimator/backend.py): the
# compiled module is reached through it alone, so no other module can switch or bypass it.
_KERNELS_IMPORT = re.compile(r"\b_kernels\b.*\bimport\b|\bimport\b.*\b_kernels\b")


def test_only_the_backend_imports_the_compiled_kernels():
    assert _lines_matching(_KERNELS_IMPORT, lambda rel: rel == "estimator/backend.py") == []
    backend = (PACKAGE / "estimator" / "backend.py").read_text()
    assert _KERNELS_IMPORT.search(backend)  # the pattern finds the one import there is
    assert "global " not in backend  # no process-wide switch: a backend is chosen per filter


def _printed(code: str) -> str:
    """What ``code`` prints, run in a fresh interpreter (what a module imports shows only in a new process)."""
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout


def test_the_kinds_never_import_the_outer_layers():
    """The registry, the kinds and the fusion core import nothing of transport, replay, the CLI, the tuner,
    the doctor, nor (until a decoder is asked for) the codecs and rosbags; the config's shared tables
    (``config_tables``) import nothing of fusiond at all."""
    code = ("import sys, fusiond.config_tables; a = {m for m in sys.modules if m.startswith('fusiond.')}; "
            "import fusiond.core.sensors.registry, fusiond.core.fusion; "
            "b = {m for m in sys.modules if m.split('.')[1:2] in (['transport'], ['replay'], ['cli'], ['tune'], "
            "['codecs'], ['doctor']) or m.startswith('rosbags')}; print(sorted(a), sorted(b))")
    out = _printed(code)
    assert out.strip() == "['fusiond.config_tables'] []"


def test_a_kinds_codec_is_imported_when_a_decoder_is_asked_for():
    """The pose's wire formats live in its package (``pose/codec.py``, a ``KindCodec``): loading the kinds
    and the core imports neither it nor the codecs; asking the kind for a decoder imports both."""
    code = (
        "import sys, fusiond.core.sensors.registry as r, fusiond.core.fusion\n"
        "def seen(): return ['fusiond.core.sensors.pose.codec' in sys.modules, 'fusiond.codecs' in sys.modules]\n"
        "before = seen()\n"
        "from fusiond.config import loads\n"
        "cfg = loads('[[sensors]]\\nname = \"wheel\"\\nkind = \"odom\"\\nkey = \"odom\"\\n'\n"
        "            '[[sensors]]\\nname = \"mocap\"\\nkind = \"pose\"\\nkey = \"mocap\"\\nencoding = \"json\"\\n')\n"
        "r.kind_of(cfg.sensor('mocap')).decoder(cfg.sensor('mocap'))\n"
        "print(before, seen())\n")
    out = _printed(code)
    assert out.strip() == "[False, False] [True, True]"


def test_no_codecs_module_imports_the_core():
    """``fusiond/codecs`` is a floor below the core: no module of it imports ``fusiond.core`` (nor ``..core``),
    at load or inside a function, since the kinds' ``codec`` modules import it and any such import would close
    a circle. Finding a kind's codec by its name or its sample's type is ``core/sensors/formats.py``'s."""
    upward = sorted(f"{path.relative_to(PACKAGE).as_posix()}: {m}" for path in (PACKAGE / "codecs").rglob("*.py")
                    for m in _imported_modules(path) if m == "fusiond.core" or m.startswith("fusiond.core."))
    assert upward == []
    # what this reads sees an import inside a function, relative: SensorKind.decoder's of the codecs
    assert "fusiond.codecs.decoders" in _imported_modules(PACKAGE / "core" / "sensors" / "kind.py")


def test_the_codecs_load_without_the_core_and_each_kind_answers_for_its_codec():
    """Loading the codecs imports nothing of the core: every built-in kind's sample and wire formats (ROS
    converter, JSON / msgpack Struct, encoder, struct fast path) live in its own package
    (``core/sensors/<kind>/sample.py``, ``codec.py``), found through its descriptor, by its name or its
    sample's type (``core/sensors/formats.py``)."""
    code = ("import sys, fusiond.codecs as c\n"
            "[getattr(c, name) for name in c.__all__ if name != 'TYPESTORE']\n"  # every module of the package
            "print(sorted({m.split('.')[1] for m in sys.modules if m.startswith('fusiond.')}))")
    out = _printed(code)
    assert out.strip() == "['codecs', 'errors', 'lazy_exports', 'samples']"
    from fusiond.core.sensors import codec_named, codec_of, kind_named

    for name in ("odom", "imu", "gps", "pose"):  # the built-in kinds
        kind = kind_named(name)
        codec = kind.codec()
        assert codec is codec_named(name) and codec.sample_type is kind.sample_type
        assert codec.ros_types == kind.ros_types and kind.from_ros() is codec.from_ros
        assert codec_of(codec.zero) is codec
        assert kind.codec.__func__.__module__.startswith(f"fusiond.core.sensors.{name}.")
        assert kind.sample_type.__module__ == f"fusiond.core.sensors.{name}.sample"
        assert codec.from_ros.__module__ == f"fusiond.core.sensors.{name}.codec"
        if codec.repeated is not None:  # its struct fast path is its own too
            assert codec.repeated[1].__module__ == f"fusiond.core.sensors.{name}.codec"
        if codec.tail is not None:
            assert codec.tail[1].__module__ == f"fusiond.core.sensors.{name}.codec"


def test_the_config_stands_above_the_kinds_it_assembles():
    """A kind's table subclasses the shared ``SensorTable`` and its model reads ``FilterConfig`` from
    ``config_tables``; ``config``, which decodes a whole document as the registered kinds' tables,
    imports the kinds. No module under core/sensors/ imports ``config``: no import runs back up."""
    upward = sorted(path.relative_to(PACKAGE).as_posix() for path in (PACKAGE / "core" / "sensors").rglob("*.py")
                    if any(m == "fusiond.config" or m.startswith("fusiond.config.") for m in _imported_modules(path)))
    assert upward == []
    assert "fusiond.core.sensors" in _imported_modules(PACKAGE / "config.py")


def _imported_modules(path: Path) -> set[str]:
    """The fusiond modules ``path`` imports, relative imports resolved (``from ..doctor import X`` in
    fusiond/replay/run.py is fusiond.doctor)."""
    package = ["fusiond", *path.relative_to(PACKAGE).parent.parts]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = package[:len(package) - node.level + 1] if node.level else []
            module = ".".join(base + ([node.module] if node.module else []))
            found.add(module)
            found.update(f"{module}.{a.name}" for a in node.names)
    return {m for m in found if m == "fusiond" or m.startswith("fusiond.")}


# The doctor is a floor above the fusion core: it reads the core's diagnostics and the samples, and
# only the commands that show its verdicts read it.
_DOCTOR_READERS = {"monitor.py", "replay/read_ahead.py", "replay/run.py", "tune/advice.py", "tune/doctor_values.py"}


def test_the_core_never_imports_the_doctor_and_only_its_readers_do():
    readers = set()
    for path in PACKAGE.rglob("*.py"):
        rel = path.relative_to(PACKAGE).as_posix()
        if rel.startswith("doctor/"):
            continue
        if any(m == "fusiond.doctor" or m.startswith("fusiond.doctor.") for m in _imported_modules(path)):
            readers.add(rel)
    assert not {r for r in readers if r.startswith("core/")}
    assert readers == _DOCTOR_READERS


def test_each_doctor_check_holds_its_own_thresholds():
    """A check's thresholds are module constants beside it (``doctor/checks/<check>.py``, each with where it
    comes from): no check module imports a constant from another check module."""
    crossing = []
    for path in (PACKAGE / "doctor" / "checks").glob("*.py"):
        package = ["fusiond", *path.relative_to(PACKAGE).parent.parts]
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.ImportFrom):
                continue
            base = package[:len(package) - node.level + 1] if node.level else []
            module = ".".join(base + ([node.module] if node.module else []))
            names = [a.name for a in node.names if a.name.isupper()]
            if module.startswith("fusiond.doctor.checks") and names:
                crossing.append(f"{path.name}: {module} {names}")
    assert crossing == []
    assert not (PACKAGE / "doctor" / "thresholds.py").exists()  # no module of loose thresholds


def test_a_kind_registers_under_its_tables_tag_and_an_unknown_tag_names_the_known_ones():
    from fusiond.config import SensorTable
    from fusiond.core.sensors import SensorKind, kind_named, register

    class Tagged(SensorTable, tag="tagged"):
        pass

    class Misnamed(SensorKind):
        name = "other"
        config_type = Tagged

    with pytest.raises(ValueError, match="its config table Tagged is tagged 'tagged'"):
        register(Misnamed())
    with pytest.raises(ValueError, match=r"unknown sensor kind 'tagged', expected one of \[") as err:
        kind_named("tagged")
    # the built-in kinds among them (a package installed here may add its own: discovery looked)
    assert all(f"'{k}'" in str(err.value) for k in ("gps", "imu", "odom", "pose")), err.value


def test_no_merge_conflict_markers_in_the_tree():
    """A conflict left in a docstring or a document still imports and renders: only a search finds it."""
    root = PACKAGE.parent
    markers = re.compile(r"^(<{7} |>{7} )")
    found = [f"{path.relative_to(root)}:{i}" for pattern in ("*.py", "*.md", "*.toml", "*.c", "*.sh")
             for path in root.rglob(pattern) if ".venv" not in path.parts and "build" not in path.parts
             for i, line in enumerate(path.read_text(errors="replace").splitlines(), 1) if markers.match(line)]
    assert found == []
