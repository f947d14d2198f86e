"""`fusiond replay --report DIR`: a small HTML page a user opens in a browser.

Trajectory and NIS figure, innovation traces with their predicted 2-sigma band,
the doctor's verdicts and the replay summary. Plain HTML with PNG images: no
scripts, no network, it opens from a file:// URL anywhere.
"""

from __future__ import annotations

import html
import math
from pathlib import Path

import numpy as np

from .plot import break_gaps, plot_replay, run_start
from .run import ReplayResult, summary


# An innovation panel is scaled to its bulk, not to its extremes: one outlier (a fix 50 m off) or the
# 2-sigma band of the first updates (S huge before the state has converged) would flatten every other
# update into a line at zero. The panel spans the larger of the 99th percentile of |innovation| and the
# 95th of the band, times a margin; what lies beyond is marked at the panel's edge, with its count.
INNOVATION_PERCENTILE = 99.0
BAND_PERCENTILE = 95.0
LIMIT_MARGIN = 1.25


def innovation_limits(y: np.ndarray, band: np.ndarray) -> tuple[float, float] | None:
    """Symmetric y-limits of one innovation panel from robust percentiles of |y| and of the 2-sigma band
    (NaN rows, the gap breaks, left out); None when there is nothing finite to scale to."""
    y = np.abs(np.asarray(y, dtype=float))
    band = np.abs(np.asarray(band, dtype=float))
    y, band = y[np.isfinite(y)], band[np.isfinite(band)]
    parts = [np.percentile(y, INNOVATION_PERCENTILE)] if len(y) else []
    parts += [np.percentile(band, BAND_PERCENTILE)] if len(band) else []
    lim = LIMIT_MARGIN * max(parts, default=0.0)
    if not lim > 0.0 or not math.isfinite(lim):
        return None
    return -lim, lim


def plot_innovations(result: ReplayResult, path: Path) -> bool:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    chans = sorted(result.trace.innovations.items())
    rows = sum(len(comps) for _, (comps, data) in chans if data)
    if rows == 0:
        return False
    fig, axes = plt.subplots(rows, 1, figsize=(11, 1.9 * rows + 0.6), sharex=True, squeeze=False)
    k = 0
    t0 = run_start(result)
    for name, (comps, data) in chans:
        if not data:
            continue
        t, y, sd = break_gaps(np.array([d[0] for d in data]) - t0, np.array([d[1] for d in data], dtype=float),
                              np.sqrt(np.array([d[2] for d in data], dtype=float)))
        for i, comp in enumerate(comps):
            ax = axes[k, 0]
            ax.fill_between(t, -2 * sd[:, i], 2 * sd[:, i], color="tab:green", alpha=0.2, label="±2σ predicted (S)")
            ax.plot(t, y[:, i], lw=0.8, color="tab:blue", label="innovation")
            limits = innovation_limits(y[:, i], 2 * sd[:, i])
            if limits is not None:
                ax.set_ylim(*limits)
                beyond = np.abs(np.nan_to_num(y[:, i])) > limits[1]
                if beyond.any():  # off the scale: marked at the edge it went past, and counted
                    edge = np.sign(y[beyond, i]) * limits[1] * 0.97
                    ax.scatter(t[beyond], edge, marker="|", s=30, color="tab:red", zorder=3,
                               label="beyond the scale")
                    ax.text(0.005, 0.95, f"{int(beyond.sum())} beyond ±{limits[1]:.3g}", transform=ax.transAxes,
                            fontsize=7, va="top", color="tab:red")
            ax.set_ylabel(f"{name}\n{comp}", fontsize=8)
            ax.grid(alpha=0.3)
            if k == 0:
                ax.legend(loc="upper right", fontsize=7, ncol=2)
            k += 1
    axes[-1, 0].set_xlabel(f"time since the start [s] (stamp {t0:.3f})")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return True


def write_report(result: ReplayResult, directory: Path, title: str, evaluation: str | None = None) -> Path:
    """``evaluation``: the `--reference` table (format_evaluation), shown beside the doctor."""
    directory.mkdir(parents=True, exist_ok=True)
    plot_replay(result, directory / "overview.png", title=title)
    has_innov = plot_innovations(result, directory / "innovations.png")
    verdicts = result.verdicts()
    rows = "\n".join(
        f'<tr class="{v.level}"><td>{html.escape(v.level)}</td><td>{html.escape(v.sensor)}/{html.escape(v.channel)}'
        f"</td><td>{html.escape(v.message)}</td><td><code>{html.escape(v.key)}</code>"
        + (f"<br><code>{html.escape(v.suggestion)}</code>" if v.suggestion else "")
        + (f"<br>{'replayed' if v.proof.tried else 'not replayed'}: {html.escape(v.proof.effect)}"
           f"{'' if v.proof.advised or not v.proof.judged else '; not advised'}" if v.proof is not None else "") + "</td></tr>"
        for v in verdicts
    )
    cons = "\n".join(
        f"<tr><td>{html.escape(name)}</td><td>{c['updates']}</td><td>{c['rejected']}</td>"
        f"<td>{'-' if c['nis_mean'] is None else format(c['nis_mean'], '.3f')}</td>"
        f"<td>{'-' if not c['nis_bounds'] else '[{:.2f}, {:.2f}]'.format(*c['nis_bounds'])}</td>"
        f"<td>{html.escape(c['verdict'])}</td><td>{html.escape(c['now_note'])}</td></tr>"
        for name, c in result.doctor.channel_summaries().items()
    )
    innov = '<h2>Innovations</h2>\n<img src="innovations.png" alt="innovation traces">' if has_innov else ""
    page = f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>fusiond replay: {html.escape(title)}</title>
<style>
body {{ font-family: sans-serif; margin: 2em; max-width: 1200px; }}
img {{ max-width: 100%; border: 1px solid #ddd; }}
table {{ border-collapse: collapse; margin: 1em 0; }} td, th {{ border: 1px solid #ccc; padding: 4px 8px; }}
tr.problem td {{ background: #fdd; }} tr.warn td {{ background: #ffd; }} tr.ok td {{ background: #dfd; }}
pre {{ background: #f6f6f6; padding: 1em; overflow-x: auto; }}
</style></head>
<body>
<h1>fusiond replay: {html.escape(title)}</h1>
<h2>Doctor</h2>
<table id="verdicts"><tr><th>level</th><th>sensor/channel</th><th>verdict</th><th>config key</th></tr>
{rows}
</table>
{"" if evaluation is None else '<h2>Against the reference</h2>' + chr(10) + '<pre id="evaluation">' + html.escape(evaluation) + '</pre>'}
<h2>Trajectory and NIS</h2>
<img src="overview.png" alt="trajectory and NIS per sensor channel">
{innov}
<h2>NIS consistency (whole run; chi-square bounds for its update count)</h2>
<table><tr><th>channel</th><th>updates</th><th>rejected</th><th>mean NIS</th><th>bounds</th><th>verdict</th>
<th>latest window</th></tr>
{cons}
</table>
<h2>Summary</h2>
<pre>{html.escape(summary(result))}</pre>
</body></html>
"""
    index = directory / "index.html"
    index.write_text(page)
    return index
