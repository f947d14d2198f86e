"""A whole-run figure of a statistic that notes its samples and folds them in chunks.

The doctor's statistics are fed at every message of a replay, so they only note what they are
given and fold it into their sums a chunk at a time (``_settle``). Every figure they expose must
fold what is still pending before it is read, whichever is read first: a ``Settled`` attribute
does that, so no reader can see a sum that lacks the newest samples.
"""

from __future__ import annotations

from typing import Any

__all__ = ["Settled"]


class Settled:
    """``owner.<attr>`` (or its element ``index``) read after ``owner._settle()``."""

    def __init__(self, attr: str, index: int | None = None) -> None:
        self.attr = attr
        self.index = index

    def __get__(self, owner: Any, kind: type | None = None) -> Any:
        if owner is None:
            return self
        owner._settle()
        value = getattr(owner, self.attr)
        return value if self.index is None else value[self.index]
