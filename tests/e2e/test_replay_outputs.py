"""The replay's files are written in blocks at the end (TUM) or in ~1 MiB blocks (diagnostics):
byte for byte what the per-message forms give: one TUM line per published pose, one JSON line
per diagnostics record, in order, none lost at a block boundary."""

from __future__ import annotations

from pathlib import Path

import msgspec
import pytest

from fusiond.config import load
from fusiond.errors import ReplayError
from fusiond.core.fusion import FusionCore
from fusiond.replay.bag import open_bag_samples
from fusiond.replay.run import replay, tum_line

ROOT = Path(__file__).resolve().parents[2]


def test_tum_and_diagnostics_files_hold_every_pose_and_record_in_order(jackal_bag: Path, tmp_path: Path) -> None:
    cfg = load(ROOT / "examples/jackal.toml")
    tum, diag = tmp_path / "out.tum", tmp_path / "out.jsonl"
    result = replay([jackal_bag], cfg, tum=tum, diagnostics=diag, keep_trace=False, progress=False)

    # the same samples through a core of their own, each output formatted the moment it exists
    core = FusionCore(cfg)
    lines: list[str] = []
    records: list[bytes] = []
    with open_bag_samples([jackal_bag], cfg.sensors) as bag:
        for sample in bag:
            step = core.ingest(sample)
            if step.publish:
                lines.append(tum_line(*core.pose()))
            records.extend(msgspec.json.encode(r) + b"\n" for r in step.records)

    assert result.poses == len(lines) == 3060  # one pose per odometry message of the bag
    assert tum.read_text() == "".join(lines)
    written = diag.read_bytes()
    assert len(written) > 1 << 20  # more than one block: the block boundary is crossed
    assert written == b"".join(records)


def test_a_replay_without_the_doctor_writes_the_same_files_and_says_it_has_no_verdicts(jackal_bag: Path,
                                                                                        tmp_path: Path) -> None:
    """`fusiond replay --quiet` (no summary, plot or report to judge for) skips the doctor: the
    fusion and its files do not depend on it."""
    cfg = load(ROOT / "examples/jackal.toml")
    with_doctor, without = tmp_path / "a.tum", tmp_path / "b.tum"
    full = replay([jackal_bag], cfg, tum=with_doctor, keep_trace=False, progress=False)
    lean = replay([jackal_bag], cfg, tum=without, keep_trace=False, progress=False, doctor=False)
    assert without.read_text() == with_doctor.read_text() and lean.poses == full.poses > 0
    assert full.verdicts() and lean.doctor is None
    with pytest.raises(ReplayError, match="without the doctor"):
        lean.verdicts()


def test_a_run_that_publishes_nothing_says_why_instead_of_a_final_pose() -> None:
    """A GPS that never gives a fix (all dropped, or a topic the live robot never publishes):
    everything is fused but no pose is published. The summary must not print a "final pose" that
    was never published; it says what the filter waits for."""
    from fusiond.replay.run import run_samples, summary
    from fusiond.core.sensors import ImuSample, OdomSample

    from tests.support.configs import robot_config

    cov6 = tuple(1e-4 if i % 7 == 0 else 0.0 for i in range(36))
    cov3 = (1e-4, 0.0, 0.0, 0.0, 1e-4, 0.0, 0.0, 0.0, 1e-4)
    samples = []
    for k in range(100):
        t = 10.0 + 0.02 * k
        samples.append(OdomSample("wheel", t, (0.5, 0.0, 0.0), (0.0, 0.0, 0.0), cov6))
        samples.append(ImuSample("imu", t + 0.001, (0.0, 0.0, 0.0, 1.0), cov3, (0.0, 0.0, 0.0), cov3))
    result = run_samples(samples, robot_config(gps="datum = [48.137, 11.575, 520.0]"))
    assert result.poses == 0 and result.final is not None  # fused, not published
    text = summary(result)
    assert "final pose" not in text
    assert "no pose published: waiting for the first GPS fix from 'gps'" in text
    assert "estimated   wheel_scale=1.0000" in text  # on by default beside a GPS, nothing learned yet
