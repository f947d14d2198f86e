"""The recording `fusiond tune` fits: the configured sensors' samples, read once into memory.

Read through the replay's own machinery (``open_bag_samples``: only the configured sensors'
topics are ever opened; ``check_topics``: the same errors and warnings as ``replay``), then
replayed from memory once per evaluation.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

from ..config import Config
from ..errors import BagError
from ..replay.bag import open_bag_samples
from ..replay.run import check_topics


def read_samples(paths: Sequence[Path | str], cfg: Config, warn: Callable[[str], None] | None = None,
                 allow_missing: bool = True) -> list:
    """The configured sensors' samples of the bags, in bag order. BagError (a ReplayError) for a bag
    that cannot be replayed as configured, or one without a single sample of them (or, unless
    ``allow_missing``, without a configured sensor's topic)."""
    with open_bag_samples([Path(p) for p in paths], cfg.sensors) as bag:
        check_topics(bag, cfg, warn, allow_missing)
        samples = list(bag)
    if not samples:
        raise BagError(f"{', '.join(str(p) for p in paths)}: no message of a configured sensor could be read")
    return samples


# the share of a recording tune fits; the rest (its last 30 %) is held back to validate on, by tune and by the
# doctor's proofs alike: a change that predicts the run's end worse is not kept, however it does before
FIT_FRACTION = 0.7


def split_stamp(samples: Sequence[object], fraction: float = FIT_FRACTION) -> float:
    """The stamp ``fraction`` of the way through the recording (by stamp, not by message count)."""
    stamps = [s.stamp for s in samples]  # type: ignore[attr-defined]
    lo, hi = min(stamps), max(stamps)
    return lo + fraction * (hi - lo)


__all__ = ["FIT_FRACTION", "read_samples", "split_stamp"]
