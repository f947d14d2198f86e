"""The health answer as it goes on the wire: the health report, who answers, and its link.

In a fleet every answer must name its robot: `fusiond health --key '*/fusiond/health'`
prints one line per daemon, and a line that does not say which robot it is tells an operator
nothing. So the answer is the report (``health.HealthReport``, every field as before) followed
by the daemon's Zenoh ``namespace`` and ``zid``, its ``link`` (`connected`, `disconnected`, or `listening`: a peer
that dials nothing) and the link's figures (``link_stats``: sessions open, losses, reconnections; ``link.py``). Built here, by
the transport, because the report is pure logic with no session; the metrics endpoint
(``metrics.py``) reads the same answer, so a scrape and a query agree.
"""

from __future__ import annotations

import msgspec

from ..health import HealthReport
from .link import LinkHealth

__all__ = ["HealthAnswer", "answer", "encode_answer"]


class HealthAnswer(HealthReport, kw_only=True):
    """``HealthReport``'s fields, then who answers: a decoder of the report alone reads it as before."""

    namespace: str = ""  # the daemon's Zenoh namespace ("" when it has none)
    zid: str = ""  # its Zenoh session id (a restarted daemon has a new one)
    link: str = ""  # "connected" (a router or peer session open), "disconnected", or "listening" (dials nothing)
    link_stats: LinkHealth | None = None  # that link's sessions, losses and reconnections


def answer(report: HealthReport, namespace: str, zid: str, link: LinkHealth | None) -> HealthAnswer:
    """The report with the daemon's identity and link."""
    fields = {f: getattr(report, f) for f in report.__struct_fields__}
    return HealthAnswer(**fields, namespace=namespace, zid=zid, link=link.state if link is not None else "",
                        link_stats=link)


_encoder = msgspec.json.Encoder()


def encode_answer(a: HealthAnswer) -> bytes:
    return _encoder.encode(a)
