"""`fusiond monitor --fleet`: one line per daemon, worst first.

An operator with ten robots wants to see which one needs looking at, not ten tables. Each
row is what the monitor knows of a daemon now (``presence.py``): its status (`lost` and
`disconnected` first, then `failed`, the states short of `ok`, `ok`), its link, the channel
whose windowed NIS is furthest outside its chi-square bounds (from the daemon's own health
answer), its drops and the age of its health answer. A lost daemon shows no figures.
"""

from __future__ import annotations

import math
import time
from typing import Any

from .presence import rank

# the colour of a daemon's status, in the fleet table and in the one robot's monitor alike
STATUS_STYLE = {"ok": "green", "degraded": "yellow", "starting": "yellow", "waiting": "yellow", "failed": "red",
                "lost": "bold red", "disconnected": "bold red"}

__all__ = ["STATUS_STYLE", "fleet_rows", "fleet_lines", "render_fleet", "worst_channel"]


def worst_channel(consistency: dict[str, dict[str, Any]]) -> dict | None:
    """The channel whose NIS mean is furthest outside (or nearest the edge of) its bounds, with that
    ratio (> 1: outside); None without a judged channel."""
    worst, score = None, -math.inf
    for key, c in consistency.items():
        mean, bounds = c.get("nis_mean"), c.get("nis_bounds")
        if mean is None or not bounds or not math.isfinite(mean) or bounds[0] <= 0 or mean <= 0:
            continue
        s = max(mean / bounds[1], bounds[0] / mean)
        if s > score:
            worst, score = {"channel": key, "nis_mean": mean, "nis_bounds": list(bounds),
                            "verdict": c.get("verdict"), "outside": s}, s
    return worst


def fleet_rows(snapshots: list[dict]) -> list[dict]:
    """One summary per daemon snapshot (``Monitor.snapshot``), worst first."""
    rows = []
    for snap in snapshots:
        health = (snap.get("health") or {}) if snap.get("current", True) else {}
        sensors = health.get("sensors") or {}
        rows.append({
            "daemon": snap["daemon"], "namespace": snap.get("namespace"), "zid": snap.get("zid"),
            "status": snap["status"], "since": snap.get("since"), "reason": snap.get("reason"),
            "link": snap.get("link"), "health_age_s": snap.get("health_age_s") if health else None,
            "worst_nis": worst_channel(health.get("consistency") or {}) if health else None,
            "dropped": sum(int(s.get("dropped") or 0) for s in sensors.values()) if health else None,
            "sensors_alive": f"{sum(bool(s.get('alive')) for s in sensors.values())}/{len(sensors)}" if health
            else None,
            "published": health.get("published") if health else None,
        })
    rows.sort(key=lambda r: (rank(r["status"]), -((r["worst_nis"] or {}).get("outside") or 0.0), r["daemon"]))
    return rows


def _nis(w: dict | None) -> str:
    if w is None:
        return "-"
    lo, hi = w["nis_bounds"]
    return f"{w['channel']} {w['nis_mean']:.2f} [{lo:.2f}, {hi:.2f}] {w['verdict']}"


def _age(v: float | None) -> str:
    return "-" if v is None else f"{v:.1f}s"


def _since(r: dict) -> str:
    if r["since"] is None:
        return r["reason"] or ""
    return f"since {time.strftime('%H:%M:%S', time.localtime(r['since']))}: {r['reason']}"


def fleet_lines(rows: list[dict], wall: float) -> list[str]:
    """Plain lines (a pipe, a log file): one per daemon, worst first."""
    stamp = time.strftime("%H:%M:%S", time.localtime(wall))
    out = []
    for r in rows:
        if r["reason"]:
            out.append(f"{stamp} {r['daemon']:<16} {r['status']:<12} {_since(r)}")
        else:
            out.append(f"{stamp} {r['daemon']:<16} {r['status']:<12} link={r['link'] or '-'} "
                       f"sensors={r['sensors_alive']} nis={_nis(r['worst_nis'])} dropped={r['dropped']} "
                       f"age={_age(r['health_age_s'])}")
    return out


def render_fleet(rows: list[dict]):
    """A rich table of the rows."""
    from rich.table import Table
    from rich.text import Text

    t = Table(show_header=True, header_style="bold", box=None)
    for col in ("daemon", "status", "link", "sensors", "worst NIS", "dropped", "age", ""):
        t.add_column(col)
    for r in rows:
        t.add_row(r["daemon"], Text(r["status"], style=STATUS_STYLE.get(r["status"], "")), r["link"] or "-",
                  r["sensors_alive"] or "-", _nis(r["worst_nis"]), "-" if r["dropped"] is None else str(r["dropped"]),
                  _age(r["health_age_s"]), _since(r) if r["reason"] else "")
    return t
