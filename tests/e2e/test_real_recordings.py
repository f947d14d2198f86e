"""The real recordings in ../shared/data: on every scored segment of the acceptance cases, fusiond is
not worse than the best plain baseline beyond the reference's own noise (scripts/real_recordings.py
states how each is derived). Skipped without the recordings."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT.parent / "shared" / "data"

pytestmark = [
    pytest.mark.e2e,
    pytest.mark.skipif(not (DATA / "comma2k19_ex1").exists() or not (DATA / "f110_ds2").exists(),
                       reason=f"the real recordings are not in {DATA} (see docs/RESULTS.md)"),
]


def _bench():
    spec = importlib.util.spec_from_file_location("real_recordings", ROOT / "scripts" / "real_recordings.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


def test_fusiond_never_loses_to_a_plain_baseline_beyond_the_reference_noise() -> None:
    rows = [r for r in _bench().rows(DATA) if r.case.acceptance]
    assert rows
    lost = [(r.case.what, r.segment, r.ours, r.best, r.noise) for r in rows if r.verdict in ("NO", "-")]
    assert not lost, lost


def test_the_advice_replayed_beside_the_scoring_prints_what_it_prints_in_turn(capsys, monkeypatch) -> None:
    """`replay --reference` with advice: the advice's replay runs in a forked process beside the scoring
    (neither reads the other); the printed summary, verdicts, proof and scores are those of one after the
    other in the process."""
    import fusiond.tune.forked as forked
    from fusiond.cli import main

    argv = ["replay", str(DATA / "comma2k19_ex1"), "--config", str(ROOT / "examples" / "comma2k19.toml"),
            "--reference", "/ground_truth"]
    assert main(argv) == 0
    beside = capsys.readouterr().out
    monkeypatch.setattr(forked, "workers_available", lambda: 1)
    assert main(argv) == 0
    in_turn = capsys.readouterr().out
    assert "(replayed: likelihood" in beside and "reference   /ground_truth" in beside and "aligned m" in beside
    drop_rate = lambda text: [line for line in text.splitlines() if "msg/s" not in line]  # noqa: E731
    assert drop_rate(beside) == drop_rate(in_turn)
