"""The highway car with its wheels' yaw rate read 0.05 rad/s high (``scripts/recording_variants.py``'s
``comma_wz_offset``), configured as a user who has not fused the gyro, with one fix in ten: the wheels drive the
heading between fixes, and on a road that hardly turns no scale can be fitted. The doctor names the wheels'
offset and says to fuse the gyro (not the GPS's noise, which the bent track makes look understated); the line,
pasted, mends the track against the reference. Skipped without the recording."""

from __future__ import annotations

import json
from pathlib import Path

from fusiond.cli import main

from tests.support.recordings import HIGHWAY_CONFIG, needs, write_variant

pytestmark = needs("comma2k19_ex1", "the highway car")

CONFIG = HIGHWAY_CONFIG.replace("angular_velocity = true", "angular_velocity = {gyro}")


def _world(bag: Path, gyro: str, tmp: Path) -> float:
    """The world error over the run with one fix in ten fused (scored at the other nine)."""
    config, out = tmp / f"gyro_{gyro}.toml", tmp / f"gyro_{gyro}.json"
    config.write_text(CONFIG.format(gyro=gyro))
    assert main(["replay", str(bag), "--config", str(config), "--reference", "/ground_truth", "--fuse-every", "10",
                 "--quiet", "--evaluation", str(out)]) == 0
    scores = json.loads(out.read_text())["scores"]
    world = next(s["world_h"] for s in scores if s["segment"] == "all" and s["method"] == "fusiond")
    return world


def test_a_wheel_yaw_offset_on_a_straight_road_is_named_and_fusing_the_gyro_mends_it(tmp_path, capsys):
    bag = write_variant("comma_wz_offset", tmp_path / "comma_wz_offset")
    config = tmp_path / "user.toml"
    config.write_text(CONFIG.format(gyro="false"))
    assert main(["doctor", str(bag), "--config", str(config)]) == 0
    out = capsys.readouterr().out
    line = next(s for s in out.splitlines() if "wheel/heading:" in s)
    assert line.startswith("doctor PROBLEM") and "hardly turns" in line and "[sensors.imu.angular_velocity]" in line
    assert 'angular_velocity = true' in out[out.index("wheel/heading:"):]
    world_off, world_on = _world(bag, "false", tmp_path), _world(bag, "true", tmp_path)
    assert world_on < 0.5 * world_off, (world_off, world_on)
