"""The real recordings in ../shared/data (not in this repository) and the variants of them that
scripts/recording_variants.py writes: where they are, the marks that skip a test without them, and a variant
written to a test's own folder."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.support.scripts import load_script

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"

# The highway car's config as a new user writes it from the README (wheels, the gyro fused, the GPS with its
# defaults), for the tests that replay that recording or its variants
HIGHWAY_CONFIG = """
[[sensors]]
name = "wheel"
kind = "odom"
key = "odom"
twist_frame = "body"

[[sensors]]
name = "imu"
kind = "imu"
key = "imu"
orientation = "off"
angular_velocity = true

[[sensors]]
name = "gps"
kind = "gps"
key = "fix"
"""


def needs(recording: str, what: str) -> list:
    """The e2e mark and a skip naming ``recording`` (a folder or file of ../shared/data) and ``what`` it is."""
    return [pytest.mark.e2e,
            pytest.mark.skipif(not (DATA / recording).exists(), reason=f"needs ../shared/data/{recording} ({what})")]


def write_variant(name: str, out: Path) -> Path:
    """``scripts/recording_variants.py``'s variant ``name`` of its recording, written as the bag ``out``."""
    variants = load_script("recording_variants")
    v = next(v for v in variants.VARIANTS if v.name == name)
    variants.write_variant(DATA / v.recording, out, v)
    return out
