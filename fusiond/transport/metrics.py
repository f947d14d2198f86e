"""Prometheus metrics (`[metrics] listen`): the health answer as `fusiond_*` families on `/metrics`.

Fleets watch services by scraping them; a fusion node that only answers a Zenoh query is
invisible to that. Every scrape builds its families from ONE health answer taken at that
moment (``HealthAnswer``, the same object the health queryable encodes), through a
prometheus-client collector on a registry of its own: nothing is counted twice, and a scrape
and a health query agree. Every series is labelled by ``namespace``; per-sensor ones by
``sensor``, per-channel ones by ``sensor`` and ``channel``, drops also by ``reason``.

The server is prometheus-client's own (a WSGI server on a thread); ``stop`` shuts it down.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from typing import Any

from .answer import HealthAnswer

__all__ = ["HealthCollector", "MetricsServer", "families", "STATUSES"]

STATUSES = ("ok", "starting", "degraded", "failed")
_BAD_VERDICTS = ("nis_high", "nis_low")


def families(a: HealthAnswer) -> list[Any]:
    """The metric families of one health answer."""
    from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, InfoMetricFamily

    ns = a.namespace
    out: list[Any] = []

    def gauge(name: str, doc: str, labels: tuple[str, ...] = ()) -> GaugeMetricFamily:
        fam = GaugeMetricFamily(f"fusiond_{name}", doc, labels=["namespace", *labels])
        out.append(fam)
        return fam

    def counter(name: str, doc: str, labels: tuple[str, ...] = ()) -> CounterMetricFamily:
        fam = CounterMetricFamily(f"fusiond_{name}", doc, labels=["namespace", *labels])
        out.append(fam)
        return fam

    info = InfoMetricFamily("fusiond_daemon", "the daemon answering: its Zenoh session id", labels=["namespace"])
    info.add_metric([ns], {"zid": a.zid})
    out.append(info)
    st = gauge("status", "1 for the daemon's health status, 0 for the others", ("status",))
    for s in STATUSES:
        st.add_metric([ns, s], 1.0 if a.status == s else 0.0)
    gauge("uptime_seconds", "seconds since the daemon started").add_metric([ns], a.uptime_s)
    counter("poses_published", "fused poses published").add_metric([ns], a.published)

    alive = gauge("sensor_alive", "1 while the sensor's samples arrive within its timeout", ("sensor",))
    rate = gauge("sensor_rate_hz", "observed rate of accepted samples (0 when silent)", ("sensor",))
    age = gauge("sensor_age_seconds", "seconds since the newest accepted sample (absent before the first)",
                ("sensor",))
    timeout = gauge("sensor_timeout_seconds", "silence after which the sensor is not alive", ("sensor",))
    received = counter("sensor_received", "payloads received", ("sensor",))
    applied = counter("sensor_applied", "samples fused", ("sensor",))
    late = counter("sensor_late", "samples fused at their own stamp from the history", ("sensor",))
    rejected = counter("sensor_rejected", "updates refused by the Mahalanobis gate", ("sensor",))
    dropped = counter("sensor_dropped", "samples dropped, by reason", ("sensor", "reason"))
    for name, s in a.sensors.items():
        alive.add_metric([ns, name], 1.0 if s.alive else 0.0)
        rate.add_metric([ns, name], s.rate_hz)
        if s.age_s is not None:
            age.add_metric([ns, name], s.age_s)
        timeout.add_metric([ns, name], s.timeout_s)
        received.add_metric([ns, name], s.received)
        applied.add_metric([ns, name], s.applied)
        late.add_metric([ns, name], s.late)
        rejected.add_metric([ns, name], s.rejected)
        for reason, n in sorted(s.dropped_by_reason.items()):
            dropped.add_metric([ns, name, reason], n)

    mean = gauge("nis_window_mean", "windowed NIS mean of a sensor channel", ("sensor", "channel"))
    lower = gauge("nis_lower_bound", "chi-square lower bound of that mean", ("sensor", "channel"))
    upper = gauge("nis_upper_bound", "chi-square upper bound of that mean", ("sensor", "channel"))
    out_of = gauge("nis_out_of_bounds", "1 when the channel's NIS verdict is nis_high or nis_low",
                   ("sensor", "channel", "verdict"))
    share = gauge("nis_rejected_share", "share of the window's updates the gate rejected (nis_high beyond a tenth)",
                  ("sensor", "channel"))
    updates = counter("channel_updates", "updates of a sensor channel", ("sensor", "channel"))
    for key, c in sorted(a.consistency.items()):
        sensor, _, channel = key.partition("/")
        labels = [ns, sensor, channel]
        m = c.get("nis_mean")
        if m is not None and math.isfinite(m):
            mean.add_metric(labels, m)
        bounds = c.get("nis_bounds")
        if bounds:
            lower.add_metric(labels, bounds[0])
            upper.add_metric(labels, bounds[1])
        verdict = str(c.get("verdict"))
        out_of.add_metric([*labels, verdict], 1.0 if verdict in _BAD_VERDICTS else 0.0)
        share.add_metric(labels, float(c.get("rejected_share", 0.0)))
        updates.add_metric(labels, c.get("updates", 0))

    f = a.filter
    gauge("filter_initialised", "1 once the filter has a state").add_metric([ns], float(f.initialised))
    gauge("filter_finite", "1 while the filter's state and covariance are finite").add_metric([ns], float(f.finite))
    gauge("filter_heading_known", "0 while a GPS-referenced heading is still unknown").add_metric(
        [ns], float(f.heading_known))
    gauge("filter_ready", "0 until the first sample is fused, and while the world frame waits for its absolute sensor").add_metric([ns], float(f.ready))
    if f.time is not None:
        gauge("filter_time_seconds", "message time of the newest estimate").add_metric([ns], f.time)
    counter("filter_covariance_resets", "non-finite covariances reset").add_metric([ns], f.covariance_resets)
    counter("filter_time_resets", "backwards time jumps that reset the filter").add_metric([ns], f.time_resets)

    if a.pose is not None:  # absent before the first published pose, as the health answer's null
        p = a.pose
        gauge("pose_stamp_seconds", "message time of the newest published pose").add_metric([ns], p.stamp)
        position = gauge("pose_position_meters", "the newest published pose's position in its frame", ("axis",))
        for axis, value in zip("xyz", p.position):
            position.add_metric([ns, axis], value)
        gauge("pose_yaw_radians", "the newest published pose's heading").add_metric([ns], p.yaw)
        # how sure the filter is: what an operator alerts on (a widening sigma is a robot the sensors lost)
        gauge("pose_sigma_xy_meters", "horizontal position std dev along its worst direction").add_metric(
            [ns], p.sigma_xy)
        gauge("pose_sigma_z_meters", "height std dev").add_metric([ns], p.sigma_z)
        gauge("pose_sigma_yaw_radians", "heading std dev (large while the heading is unknown)").add_metric(
            [ns], p.sigma_yaw)

    q = a.queue
    gauge("queue_depth", "samples waiting to be fused").add_metric([ns], q.depth)
    gauge("queue_capacity", "input queue capacity").add_metric([ns], q.capacity)

    if a.link_stats is not None:
        link = a.link_stats
        gauge("zenoh_link_up", "1 while at least one router or peer session is open").add_metric(
            [ns], 1.0 if link.state == "connected" else 0.0)
        gauge("zenoh_routers", "router sessions open").add_metric([ns], link.routers)
        gauge("zenoh_peers", "peer sessions open").add_metric([ns], link.peers)
        counter("zenoh_link_losses", "times the link was lost").add_metric([ns], link.losses)
        counter("zenoh_reconnections", "times the link came back after a loss").add_metric([ns], link.reconnections)
    return out


class HealthCollector:
    """A prometheus-client collector: each ``collect`` reads one health answer."""

    def __init__(self, read: Callable[[], HealthAnswer]) -> None:
        self._read = read

    def collect(self) -> Iterator[Any]:
        yield from families(self._read())

    def describe(self) -> list[Any]:
        return []  # the families depend on the config: no description at registration (no collect then)


class MetricsServer:
    """``/metrics`` on ``host:port`` (port 0: any free one, ``port`` then says which)."""

    def __init__(self, read: Callable[[], HealthAnswer], host: str, port: int) -> None:
        from prometheus_client import CollectorRegistry, start_http_server

        self.registry = CollectorRegistry(auto_describe=False)
        self.registry.register(HealthCollector(read))
        self._server, self._thread = start_http_server(port, addr=host, registry=self.registry)
        self.host = host
        self.port = int(self._server.server_address[1])

    def stop(self) -> None:
        self._server.shutdown()
        self._server.server_close()
        self._thread.join(2.0)
