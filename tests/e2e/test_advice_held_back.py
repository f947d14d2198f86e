"""A paste line the whole run likes and the run's end does not: the doctor's proof validates on the run's last
30 %, held back as tune validates (``tune/advice.py``), and does not advise it.

The F1/10 car started 60 s into its recording (``scripts/recording_variants.py``'s ``f110_off_start60``), its
IMU's roll and pitch fused with the noise the doctor's first round advised. Its orientation errs slowly (a race
car's lateral acceleration in an AHRS's tilt): a larger white noise keeps raising the whole run's likelihood of the
orientation's own innovations, round after round, while the filter, following the IMU less, predicts the end of the
run worse and tracks it worse against the reference (a new user pasting each round lost 0.07 m of segment a's
aligned error over three rounds). Skipped without the recording."""

from __future__ import annotations

import json
import re
from pathlib import Path


from fusiond.cli import main

from tests.support.recordings import needs, write_variant

pytestmark = needs("f110_ds2", "the F1/10 recording")

ROUND_ONE = """
[[sensors]]
name = "wheel"
kind = "odom"
key = "odom"
twist_frame = "body"
twist_measured = [true, true, true, false, false, false]

[[sensors]]
name = "imu"
kind = "imu"
key = "imu"
orientation = "roll_pitch"
angular_velocity = true
gyro_noise = 0.00305
orientation_noise = [0.0099, 0.0094, 1.0000]
"""


def _aligned(bag: Path, config: Path, out: Path) -> float:
    assert main(["replay", str(bag), "--config", str(config), "--reference", "/ground_truth", "--quiet",
                 "--evaluation", str(out)]) == 0
    scores = json.loads(out.read_text())["scores"]
    return next(s["aligned_h"] for s in scores if s["segment"] == "all" and s["method"] == "fusiond")


def test_a_line_that_predicts_the_runs_end_worse_is_not_advised(tmp_path, capsys):
    """The orientation verdict's next line raises the whole run's likelihood (more than its one key) but lowers
    the held-back part's: tried, not advised, the held-back figure given. Pasted anyway, the reference agrees:
    the aligned error over the run is worse with it."""
    bag = write_variant("f110_off_start60", tmp_path / "f110_off_start60")
    config = tmp_path / "round_one.toml"
    config.write_text(ROUND_ONE)
    assert main(["replay", str(bag), "--config", str(config)]) == 0
    out = capsys.readouterr().out
    block = out[out.index("imu/orientation:"):]
    block = block[:block.index("\ndoctor ")] if "\ndoctor " in block else block
    assert "tried in the" in block and "not advised" in block, block
    held = re.search(r"last 30 % \(held back, as tune validates\) likelihood (-\d+)", block)
    gain = re.search(r"\(likelihood \+(\d+)", block)
    assert held and gain and int(gain.group(1)) > 1, block
    line = re.search(r"orientation_noise = \[[^\]]+\]", block).group(0)
    pasted = tmp_path / "round_two.toml"
    pasted.write_text(ROUND_ONE.replace("orientation_noise = [0.0099, 0.0094, 1.0000]", line))
    assert _aligned(bag, pasted, tmp_path / "two.json") > _aligned(bag, config, tmp_path / "one.json")
