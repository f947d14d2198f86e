"""Replay figure: fused trajectory against raw wheel odometry, and NIS per channel.

matplotlib is imported here only, when a plot is asked for, so that replay
without --plot does not pay for it at start-up.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.diagnostics import chi2_ppf
from .run import ReplayResult


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
    if tr.raw_odom:
        raw = np.array(tr.raw_odom)
        ax.plot(raw[:, 1], raw[:, 2], color="0.6", lw=1.2, label="wheel odometry (raw)")
    if tr.fused:
        fused = np.array(tr.fused)
        ax.plot(fused[:, 1], fused[:, 2], color="tab:blue", lw=1.6, label="fusiond")
        ax.plot(fused[0, 1], fused[0, 2], "go", label="start")
        ax.plot(fused[-1, 1], fused[-1, 2], "rs", label="end")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    ax.set_title(title or "trajectory")

    window = result.core.cfg.filter.nis_window
    conf = result.core.cfg.filter.nis_confidence
    for i, name in enumerate(channels):
        data = np.array(tr.nis[name], dtype=float)
        t, nis, dof, rej = data[:, 0], data[:, 1], int(data[-1, 2]), data[:, 3] > 0
        a = fig.add_subplot(gs[1 + i, :])
        a.semilogy(t[~rej], np.maximum(nis[~rej], 1e-6), ".", ms=2, color="tab:blue", alpha=0.35, label="NIS")
        if rej.any():
            a.semilogy(t[rej], np.maximum(nis[rej], 1e-6), "x", ms=4, color="tab:red", label="rejected / slip")
        finite = np.where(np.isfinite(nis), nis, np.nan)
        a.semilogy(t, _windowed_mean(finite, window), color="k", lw=1.2, label=f"mean over {window}")
        lo = chi2_ppf((1 - conf) / 2, window * dof) / window
        hi = chi2_ppf(1 - (1 - conf) / 2, window * dof) / window
        a.axhspan(lo, hi, color="tab:green", alpha=0.15, label=f"{int(conf * 100)}% bounds (dof {dof})")
        a.set_ylabel(name, fontsize=8)
        a.grid(alpha=0.3, which="both")
        a.legend(loc="upper right", fontsize=7, ncol=4)
    if channels:
        a.set_xlabel("stamp [s]")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
