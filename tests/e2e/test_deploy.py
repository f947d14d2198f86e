"""The Dockerfile and the systemd unit, checked without Docker or systemd.

The Dockerfile's steps are replayed: its COPY instructions into a scratch
context, its `pip install` line built (wheel, no network) and resolved with
`pip install --dry-run` (network; skipped without it), and its CMD and
HEALTHCHECK parsed by fusiond's own command line.
"""

from __future__ import annotations

import json
import shlex
import shutil
import socket
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from fusiond.cli import build_parser
from fusiond.config import load

ROOT = Path(__file__).resolve().parents[2]


def instructions(path: Path) -> list[tuple[str, str]]:
    """(INSTRUCTION, arguments) with continuation lines joined and comments dropped."""
    out: list[tuple[str, str]] = []
    pending = ""
    for line in path.read_text().splitlines():
        stripped = line.strip()
        if not pending and (not stripped or stripped.startswith("#")):
            continue
        if stripped.endswith("\\"):
            pending += stripped[:-1] + " "
            continue
        full = pending + stripped
        pending = ""
        word, _, rest = full.partition(" ")
        out.append((word.upper(), rest.strip()))
    return out


def exec_form(text: str) -> list[str]:
    return json.loads(text) if text.startswith("[") else shlex.split(text)


DOCKERFILE = instructions(ROOT / "Dockerfile")


def first(name: str) -> str:
    return next(args for word, args in DOCKERFILE if word == name)


def test_dockerfile_contract():
    assert first("FROM").startswith("python:3.11-slim")
    user = [args for word, args in DOCKERFILE if word == "USER"]
    assert user and user[-1] not in ("root", "0")
    words = [w for w, _ in DOCKERFILE]
    assert words.index("USER") < words.index("CMD")
    assert exec_form(first("CMD")) == ["fusiond", "run", "--config", "/etc/fusiond/config.toml"]
    health = first("HEALTHCHECK")
    options, _, command = health.partition(" CMD ")
    assert "--interval=" in options and "--timeout=" in options
    argv = exec_form(command.strip())
    assert argv[:2] == ["fusiond", "health"]
    args = build_parser().parse_args(argv[1:])  # the CLI accepts exactly this command line
    assert args.config == "/etc/fusiond/config.toml" and args.timeout < 8
    run = build_parser().parse_args(exec_form(first("CMD"))[1:])
    assert run.func.__module__ == "fusiond.cli.run"


def _replay_copies(ctx: Path, root: Path) -> None:
    """Each COPY of the Dockerfile, relative destinations under WORKDIR (= ctx), absolute under `root`."""
    for word, args in DOCKERFILE:
        if word != "COPY":
            continue
        *sources, dest = shlex.split(args)
        assert not any(s.startswith("--") for s in sources), "COPY flags are not emulated"
        target = root / dest.lstrip("/") if dest.startswith("/") else ctx / dest
        for src in sources:
            path = ROOT / src
            assert path.exists(), f"Dockerfile copies {src}, which is not in the repository"
            if path.is_dir():
                shutil.copytree(path, target, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
            elif dest.endswith("/"):
                target.mkdir(parents=True, exist_ok=True)
                shutil.copy2(path, target / path.name)
            else:
                target.parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(path, target)


def _pip_install_args() -> list[str]:
    for word, args in DOCKERFILE:
        if word == "RUN" and "pip install" in args:
            for part in args.split("&&"):
                argv = shlex.split(part)
                if argv[:2] == ["pip", "install"]:
                    return argv[2:]
    raise AssertionError("no `pip install` in the Dockerfile")


def _online(host: str = "pypi.org") -> bool:
    try:
        with socket.create_connection((host, 443), timeout=3):
            return True
    except OSError:
        return False


def test_dockerfile_install_steps_without_docker(tmp_path):
    ctx, root = tmp_path / "opt" / "fusiond", tmp_path / "root"
    ctx.mkdir(parents=True)
    _replay_copies(ctx, root)
    cfg = load(root / "etc/fusiond/config.toml")  # the image's default config is valid
    assert cfg.zenoh.listen, "the HEALTHCHECK dials the config's listen endpoint"
    args = _pip_install_args()
    assert "." in args

    # the package builds from exactly what was copied: with build isolation as `docker build` does
    # (it fetches setuptools), or offline with the local build tools when they can
    online = _online()
    wheels = tmp_path / "wheels"
    isolation = [] if online else ["--no-build-isolation"]
    proc = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", *isolation, "--quiet",
                           "-w", str(wheels), "."], cwd=ctx, capture_output=True, text=True, timeout=120)
    if proc.returncode != 0 and not online:
        pytest.skip("offline, and the local build tools cannot build the wheel without network")
    assert proc.returncode == 0, proc.stderr
    (wheel,) = wheels.glob("fusiond-*.whl")
    with zipfile.ZipFile(wheel) as z:
        names = set(z.namelist())
        entry_points = next(z.read(n).decode() for n in names if n.endswith("entry_points.txt"))
    assert "fusiond = fusiond.cli:run" in entry_points
    for module in ("cli/__init__.py", "cli/run.py", "health.py", "transport/daemon.py", "transport/player.py",
                   "transport/session.py", "core/fusion.py", "estimator/ekf.py"):
        assert f"fusiond/{module}" in names
    assert not any(n.startswith("benchmarks/") for n in names)  # the benchmarks stay in the source tree
    if shutil.which("gcc") or shutil.which("cc"):  # the compiled kernels are built where a compiler is
        assert any(n.startswith("fusiond/estimator/_kernels.") and n.endswith((".so", ".pyd")) for n in names)

    # and pip resolves the Dockerfile's install line, dependencies included, as `docker build` would
    if not online:
        pytest.skip("no network: dependency resolution of the Dockerfile's pip install not checked")
    report = tmp_path / "report.json"
    proc = subprocess.run([sys.executable, "-m", "pip", "install", "--dry-run", "--ignore-installed", "--quiet",
                           "--report", str(report), *args], cwd=ctx, capture_output=True, text=True, timeout=180)
    if proc.returncode != 0 and ("Could not fetch" in proc.stderr or "connection" in proc.stderr.lower()):
        pytest.skip(f"package index unreachable: {proc.stderr.strip().splitlines()[-1]}")
    assert proc.returncode == 0, proc.stderr
    installed = {item["metadata"]["name"].lower() for item in json.loads(report.read_text())["install"]}
    assert {"fusiond", "eclipse-zenoh", "numpy", "msgspec", "structlog", "rosbags", "matplotlib", "rich"} <= installed
    assert "pytest" not in installed  # the image gets the runtime only, not the test extra


def test_systemd_unit_runs_the_daemon_cleanly():
    text = (ROOT / "deploy" / "fusiond.service").read_text()
    keys = dict(line.split("=", 1) for line in text.splitlines() if "=" in line and not line.startswith("#"))
    argv = shlex.split(keys["ExecStart"])
    assert Path(argv[0]).name == "fusiond" and argv[1] == "run"
    assert build_parser().parse_args(argv[1:]).config == "/etc/fusiond/config.toml"
    assert keys["KillSignal"] == "SIGTERM" and keys["RestartPreventExitStatus"] == "2"
    assert keys.get("DynamicUser") == "yes" or keys.get("User") not in (None, "root")
