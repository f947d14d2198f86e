"""The Zenoh side: session setup, the daemon, `fusiond play`, rmw_zenoh interop, the latency bench.

Imports `fusiond.codecs` for wire formats and never `fusiond.replay` (the player takes an
open bag from its caller). Submodules are imported by name; none is imported here, so that
a tool pays only for what it uses.
"""

__all__ = ["bench_latency", "daemon", "player", "rmw_zenoh", "session"]
