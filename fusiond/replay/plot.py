"""Replay figure: fused trajectory (with the GPS fixes, or the raw wheel odometry), and NIS per channel.

With a GPS the world frame is ENU at the datum (or the first fix): the fused track
and the fixes are drawn there, together; the raw wheel odometry lives in its own
frame and is left out then. Time axes are seconds from the start of the run (bags
stamped in Unix time would otherwise read +1.43e9), and lines break at gaps in the
data instead of drawing straight across them.

matplotlib is imported here only, when a plot is asked for, so that replay
without --plot does not pay for it at start-up.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.sensors.registry import kind_of
from ..core.diagnostics import chi2_ppf
from .run import ReplayResult


GAP_MIN_S = 1.0  # a pause in a trace this long (and 10 typical periods) is a gap: the line breaks there


def break_gaps(t: np.ndarray, *columns: np.ndarray) -> tuple[np.ndarray, ...]:
    """t and columns with a NaN row inserted wherever consecutive stamps are further apart than a gap."""
    if len(t) < 3:
        return (t, *columns)
    dt = np.diff(t)
    typical = float(np.median(dt[dt > 0])) if (dt > 0).any() else 0.0
    gaps = np.nonzero(dt > max(GAP_MIN_S, 10.0 * typical))[0]
    if not len(gaps):
        return (t, *columns)
    out = [np.insert(t.astype(float), gaps + 1, np.nan)]
    for c in columns:
        out.append(np.insert(c.astype(float), gaps + 1, np.nan, axis=0))
    return tuple(out)


def run_start(result: ReplayResult) -> float:
    """The first stamp of the run: time axes count from here."""
    tr = result.trace
    firsts = [tr.fused[0][0]] if tr.fused else []
    firsts += [v[0][0] for v in tr.nis.values() if v]
    return min(firsts) if firsts else 0.0


def _windowed_mean(values: np.ndarray, n: int) -> np.ndarray:
    if len(values) < n:
        return np.full(len(values), np.nan)
    c = np.cumsum(np.insert(values, 0, 0.0))
    out = np.full(len(values), np.nan)
    out[n - 1 :] = (c[n:] - c[:-n]) / n
    return out


def plot_replay(result: ReplayResult, path: Path, title: str = "") -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tr = result.trace
    channels = sorted(tr.nis)
    rows = 1 + len(channels)
    fig = plt.figure(figsize=(11, 4.5 + 2.6 * len(channels)))
    gs = fig.add_gridspec(rows, 2, height_ratios=[3.2] + [1.6] * len(channels))

    ax = fig.add_subplot(gs[0, :])
    t0 = run_start(result)
    has_gps = any(kind_of(s).geodetic for s in result.core.cfg.sensors)
    series = result.doctor.series()
    if has_gps:
        if series.gps_t:
            ax.plot(series.gps_e, series.gps_n, ".", ms=3, color="tab:orange", alpha=0.7, label="GPS fixes")
    elif tr.raw_odom:
        raw = np.array(tr.raw_odom)
        _, rx, ry = break_gaps(raw[:, 0], raw[:, 1], raw[:, 2])
        ax.plot(rx, ry, color="0.6", lw=1.2, label="wheel odometry (raw)")
    if tr.fused:
        fused = np.array(tr.fused)
        _, fx, fy = break_gaps(fused[:, 0], fused[:, 1], fused[:, 2])
        ax.plot(fx, fy, color="tab:blue", lw=1.6, label="fusiond")
    if result.smoothed is not None and len(result.smoothed):  # replay --smooth: the track after the fact beside it
        sm = np.asarray(result.smoothed).reshape(-1, 8)
        _, sx, sy = break_gaps(sm[:, 0], sm[:, 1], sm[:, 2])
        ax.plot(sx, sy, color="tab:purple", lw=1.0, ls="--", label="fusiond smoothed")
    if tr.fused:
        ax.plot(fused[0, 1], fused[0, 2], "go", label="start")
        ax.plot(fused[-1, 1], fused[-1, 2], "rs", label="end")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("east [m] (ENU at the datum)" if has_gps else "x [m]")
    ax.set_ylabel("north [m]" if has_gps else "y [m]")
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    ax.set_title(title or "trajectory")

    window = result.core.cfg.filter.nis_window
    conf = result.core.cfg.filter.nis_confidence
    for i, name in enumerate(channels):
        data = np.array(tr.nis[name], dtype=float)
        t, nis, dof, rej = data[:, 0] - t0, data[:, 1], int(data[-1, 2]), data[:, 3] > 0
        a = fig.add_subplot(gs[1 + i, :])
        a.semilogy(t[~rej], np.maximum(nis[~rej], 1e-6), ".", ms=2, color="tab:blue", alpha=0.35, label="NIS")
        if rej.any():
            a.semilogy(t[rej], np.maximum(nis[rej], 1e-6), "x", ms=4, color="tab:red", label="rejected / slip")
        finite = np.where(np.isfinite(nis), nis, np.nan)
        tb, mb = break_gaps(t, _windowed_mean(finite, window))
        a.semilogy(tb, mb, color="k", lw=1.2, label=f"mean over {window}")
        lo = chi2_ppf((1 - conf) / 2, window * dof) / window
        hi = chi2_ppf(1 - (1 - conf) / 2, window * dof) / window
        a.axhspan(lo, hi, color="tab:green", alpha=0.15, label=f"{int(conf * 100)}% bounds (dof {dof})")
        a.set_ylabel(name, fontsize=8)
        a.grid(alpha=0.3, which="both")
        a.legend(loc="upper right", fontsize=7, ncol=4)
    if channels:
        a.set_xlabel(f"time since the start [s] (stamp {t0:.3f})")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
