"""The garbage collector during a replay: it looks only at what the replay allocates.

A replay keeps what its doctor and its history hold for a while, and every 700 surviving containers
start a collection; now and then one of those is a full collection, which walks every tracked object
of the process: the imports (numpy, rosbags, zenoh: about 100,000 objects) and the caller's data.
Measured on the Jackal bag: one such collection took 33 ms of a 480 ms replay, and whether one fell
inside a replay decided most of its run-to-run spread. The replays that prove the doctor's advice
come after the recording's own, whose records and doctor series are alive then too: on the highway
car's recording a full collection inside the proof walked them for 45-70 ms. None of those objects is
garbage the replay makes, so they are frozen (``gc.freeze``) for its duration and handed back after
(``gc.unfreeze``).
"""

from __future__ import annotations

import gc
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["skips_the_caller"]


@contextmanager
def skips_the_caller() -> Iterator[None]:
    """Freeze what is alive now for the block, and hand it back after; a caller that froze objects itself
    keeps its own freeze (nothing is frozen or unfrozen here then)."""
    if gc.get_freeze_count():
        yield
        return
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()
