"""A replay (and the advice's proof) freezes the objects that were alive before it (the collector walks only what the replay
allocates) and hands them back after, spacing the young collections out meanwhile; a caller's own freeze is left as it is."""

from __future__ import annotations

import gc
from pathlib import Path

from fusiond.collector import YOUNG
from fusiond.config import load
from fusiond.replay import run

ROOT = Path(__file__).resolve().parents[2]


def test_a_replay_freezes_what_existed_and_unfreezes_it_after(jackal_bag: Path, monkeypatch) -> None:
    cfg = load(ROOT / "examples" / "jackal.toml")
    seen: list[int] = []
    young: list[int] = []
    thresholds = gc.get_threshold()
    real_feed = run.Runner.feed

    def feed(self, sample, keep: bool = True) -> None:
        if not seen:
            seen.append(gc.get_freeze_count())
            young.append(gc.get_threshold()[0])
        real_feed(self, sample, keep)

    monkeypatch.setattr(run.Runner, "feed", feed)
    assert gc.get_freeze_count() == 0
    kept_before = [[]]  # a tracked container alive before the replay: frozen during it
    run.replay([jackal_bag], cfg, keep_trace=False, progress=False, doctor=False)
    assert seen and seen[0] > 0  # frozen while the samples were fused
    assert gc.get_freeze_count() == 0  # and handed back to the collector
    assert gc.is_tracked(kept_before)
    assert young == [max(YOUNG, thresholds[0])]  # young collections spaced out while fusing ...
    assert gc.get_threshold() == thresholds  # ... and the caller's thresholds back after


def test_a_callers_freeze_is_left_to_the_caller(jackal_bag: Path) -> None:
    cfg = load(ROOT / "examples" / "jackal.toml")
    gc.freeze()
    try:
        assert gc.get_freeze_count() > 0
        run.replay([jackal_bag], cfg, keep_trace=False, progress=False, doctor=False)
        assert gc.get_freeze_count() > 0  # not unfrozen by the replay (only freed objects leave the count)
    finally:
        gc.unfreeze()


def test_the_advice_is_proven_with_the_recordings_replay_frozen(jackal_bag: Path, monkeypatch) -> None:
    from fusiond.tune import advice

    cfg = load(ROOT / "examples" / "jackal_rl.toml")
    fused: list = []
    records: list = []

    def keep(samples):
        for s in samples:
            fused.append(s)
            yield s

    result = run.replay([jackal_bag], cfg, keep_trace=False, progress=False, through=keep, records=records)
    verdicts = result.verdicts()
    assert any(v.suggestion for v in verdicts)  # the wheel/heading problem's paste line
    seen: list[int] = []
    real = advice.replay_records

    def replay_records(*args):
        seen.append(gc.get_freeze_count())
        return real(*args)

    monkeypatch.setattr(advice, "replay_records", replay_records)
    advice.prove_advice(cfg, fused, verdicts, 60.0, records)
    assert seen and all(n > 0 for n in seen)
    assert gc.get_freeze_count() == 0
