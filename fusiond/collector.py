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

The young collections themselves are spaced out too (YOUNG): every container a replay keeps (its
records, the history's events, the snapshot plan's keys, the proof's term keys) counts towards the
next one, and each walks the survivors since the last. A replay makes no cyclic garbage worth
collecting sooner (its steps and records hold no cycles), and the young generation stays bounded
(YOUNG containers, ten MB at most).

A command that replays a recording (``fusiond replay``, ``doctor``, ``tune``...) spaces them out from its start
(``for_a_recording``), its imports included: modules live as long as the process, and none of their objects
is garbage. Measured over a whole `fusiond replay` of each shared recording with its example config
(``gc.callbacks``): at the interpreter's 700, the collector ran 120 to 250 young and 10 to 22 middle
collections, 14 to 29 ms of a 0.5 to 0.8 s replay; at YOUNG, the eight of the interpreter's own start,
2 ms.
"""

from __future__ import annotations

import gc
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["YOUNG", "for_a_recording", "skips_the_caller"]

YOUNG = 100_000  # containers allocated (net) between two young collections during a replay


def for_a_recording() -> None:
    """Young collections YOUNG apart from here on, for a process that is to replay a recording (module doc);
    forked children (the read-ahead, the advice's and tune's replays) inherit it."""
    thresholds = gc.get_threshold()
    gc.set_threshold(max(YOUNG, thresholds[0]), *thresholds[1:])


@contextmanager
def skips_the_caller() -> Iterator[None]:
    """Freeze what is alive now for the block, and hand it back after, with young collections YOUNG
    apart meanwhile; a caller that froze objects itself keeps its own freeze and thresholds (nothing is
    changed here then)."""
    if gc.get_freeze_count():
        yield
        return
    gc.freeze()
    thresholds = gc.get_threshold()
    gc.set_threshold(max(YOUNG, thresholds[0]), *thresholds[1:])
    try:
        yield
    finally:
        gc.set_threshold(*thresholds)
        gc.unfreeze()
