"""Regenerate tests/data/jackal_pin.json after a deliberate behaviour change.

Run from the repository root: `.venv/bin/python tests/data/regen_jackal_pin.py [BAG]`
(BAG defaults to data/jackal_test2.bag). Commit the new pin on its own,
saying in the message which change moved the estimates and why.
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from tests.conftest import JACKAL_BAG  # noqa: E402
from tests.support.jackal_pin import write  # noqa: E402

if __name__ == "__main__":
    bag = Path(sys.argv[1]) if len(sys.argv) > 1 else JACKAL_BAG
    print(f"wrote {write(bag)}")
