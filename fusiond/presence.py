"""Is a daemon there? What a remote tool may say of a daemon from what it knows now.

A daemon killed with SIGKILL sends nothing more: its last health answer still reads `ok`,
and a tool that shows it reads a crashed robot as a healthy one. Two facts say a daemon is
gone: its liveliness token (Zenoh withdraws it when the daemon's session ends, at once for a
closed socket, within the lease for a host that vanished), and the age of its newest health
answer. A tool's own link says whether it can know anything at all.

State, first rule that holds:
- `disconnected`: the tool has no Zenoh link (its router is gone): nothing about any daemon is known.
- `lost`: the token is gone, or no health answer for `stale_s` (since: when it went, or the
  last answer), or none at all `stale_s` after the daemon was found.
- `waiting`: found, its first answer not in yet.
- otherwise the status of its current health answer (`ok`, `degraded`, `starting`, `failed`).
Only the last case is `current`: a tool shows a health answer then and never otherwise.

Pure logic with the times passed in (monotonic for ages, wall for the `since` shown).
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Presence", "PresenceState", "LINK_LOST", "TOKEN_GONE", "rank", "withdrawn"]

TOKEN_GONE = "liveliness token gone (the daemon stopped, or its link to the router is down)"
LINK_LOST = "this monitor has no Zenoh link (its router or peers are gone)"


@dataclass(frozen=True)
class PresenceState:
    status: str  # disconnected | lost | waiting | the health status
    since: float | None  # wall time the state began (lost, disconnected), else None
    reason: str | None  # why it is not the health status
    health_age_s: float | None  # age of the newest health answer
    current: bool  # the health answer may be shown as the daemon's state


class Presence:
    """One daemon's token and answers, as a remote tool saw them (not thread-safe: the caller locks)."""

    def __init__(self) -> None:
        self.token: bool | None = None  # None: never seen by the liveliness subscriber
        self.token_wall: float | None = None  # wall time of the token's last change
        self.found: float | None = None  # monotonic time the daemon was first (or again) found
        self.found_wall: float | None = None
        self.answer: float | None = None  # monotonic time of the newest health answer
        self.answer_wall: float | None = None
        self.link_lost_wall: float | None = None

    def token_up(self, now: float, wall: float) -> None:
        if self.token is not True:
            self.token_wall = wall
            self.found, self.found_wall = now, wall
        self.token = True

    def token_down(self, wall: float) -> None:
        if self.token is not False:
            self.token_wall = wall
        self.token = False

    def answered(self, now: float, wall: float) -> None:
        self.answer, self.answer_wall = now, wall
        if self.found is None:
            self.found, self.found_wall = now, wall

    def state(self, now: float, wall: float, stale_s: float, link_up: bool, health: dict | None) -> PresenceState:
        age = None if self.answer is None else max(now - self.answer, 0.0)
        if not link_up:
            if self.link_lost_wall is None:
                self.link_lost_wall = wall
            return PresenceState("disconnected", self.link_lost_wall, LINK_LOST, age, False)
        self.link_lost_wall = None
        if self.token is False:
            return PresenceState("lost", self.token_wall, TOKEN_GONE, age, False)
        if age is not None and (self.found is None or self.answer >= self.found):
            if age > stale_s:
                return PresenceState("lost", self.answer_wall, f"no health answer for {age:.1f} s", age, False)
            status = str((health or {}).get("status", "?"))
            return PresenceState(status, None, None, age, True)
        waited = 0.0 if self.found is None else now - self.found
        if waited > stale_s:
            return PresenceState("lost", self.found_wall, f"no health answer in {waited:.1f} s since it was found",
                                 age, False)
        return PresenceState("waiting", None, "waiting for its first health answer", age, False)


def rank(status: str) -> int:
    """Worst first: lost and disconnected, failed, the states short of ok, ok."""
    return {"lost": 0, "disconnected": 0, "failed": 1, "degraded": 2, "starting": 2, "waiting": 2}.get(
        status, 3 if status == "ok" else 1)



def withdrawn(sample: object) -> bool:
    """A liveliness subscriber's sample says the token went (a DELETE), not that it came (a PUT)."""
    import zenoh

    put = zenoh.SampleKind.PUT
    return put != getattr(sample, "kind")
