from __future__ import annotations

from pathlib import Path

import pytest

# --- bag fixtures (codecs / replay.bag tests) ------------------------------------------

JACKAL_BAG = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "jackal_test2.bag"


@pytest.fixture(scope="session")
def jackal_bag() -> Path:
    """The real Jackal ROS 1 bag of DESIGN.md (dev data, kept beside the repo)."""
    if not JACKAL_BAG.is_file():
        pytest.skip(f"dev bag not found at {JACKAL_BAG}")
    return JACKAL_BAG
