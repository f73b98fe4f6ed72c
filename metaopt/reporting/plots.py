"""Matplotlib figures of convergence curves (the paper's Figs. 4-5) and of several runs' bands.

Figures are built with matplotlib.figure.Figure (no pyplot, no display: headless anywhere) and
returned unsaved, so their data can be checked; save_figure writes them as small PNGs.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from metaopt.reporting.convergence import Band, Convergence
from metaopt.storage.whole_file import written_whole

#: Resolution of saved figures, dots per inch (6.4 x 4.8 in -> 640 x 480 px).
DPI = 100
#: The zoomed views scale their y axis to the curves from this fraction of the evaluations on:
#: the first, random candidates (robots that all fall, say) would flatten everything after.
FOCUS_FROM = 0.05
#: A minimized fitness whose positive values span more powers of ten than this gets a log axis.
DECADES = 2


def fitness_label(maximize: bool) -> str:
    """The y-axis label: fitness, and which way is better."""
    return f"fitness ({'higher' if maximize else 'lower'} is better)"


def convergence_figure(curves: Convergence, title: str, optimum: float | None = None) -> Figure:
    """Best so far and the trailing mean (failed evaluations excluded) against evaluations;
    below, the best so far alone, zoomed past the first random candidates.

    A minimized fitness that spans decades is drawn on a log axis; where the problem's optimum
    is known (benchmark functions), the lower panel shows best so far − optimum, on a log axis.
    """
    figure = Figure(figsize=(6.4, 6.4), layout="constrained")
    ax, zoom = figure.subplots(2, 1, sharex=True, height_ratios=(3, 2))
    excluded = "failed and screened" if curves.screened else "failed"
    ax.plot(
        curves.evaluations,
        curves.mean,
        color="tab:gray",
        lw=0.9,
        label=f"mean of the last {curves.window} evaluations ({excluded} excluded)",
    )
    ax.plot(curves.evaluations, curves.best, color="tab:red", lw=1.6, label="best so far")
    ax.set_ylabel(fitness_label(curves.maximize))
    lines, total = [title], len(curves.fitness)
    if curves.failed:
        lines.append(f"{curves.failed} of {total} evaluations failed")
    if curves.screened:
        lines.append(f"{curves.screened} of {total} evaluations screened (only a bound known)")
    ax.set_title("\n".join(lines), fontsize="medium")
    ax.legend(fontsize="small")
    ax.grid(alpha=0.3)
    if not curves.maximize and _spans_decades([curves.best, curves.mean]):
        ax.set_yscale("log")
    if not curves.maximize and optimum is not None:
        gap = curves.best - optimum
        zoom.plot(curves.evaluations, np.where(gap > 0, gap, np.nan), color="tab:red", lw=1.6)
        zoom.set_yscale("log")
        zoom.set_ylabel(f"best so far − optimum ({optimum:g})")
    else:
        zoom.plot(curves.evaluations, curves.best, color="tab:red", lw=1.6)
        if not curves.maximize and _spans_decades([curves.best]):
            zoom.set_yscale("log")
        else:
            _focus(zoom, [curves.best])
        zoom.set_ylabel("best so far (zoomed)")
    zoom.set_xlabel("evaluations")
    zoom.grid(alpha=0.3)
    return figure


def bands_figure(
    bands: dict[str, Band], maximize: bool, title: str, quantity: str = "best so far"
) -> Figure:
    """Per label, the median of ``quantity`` over runs with its interquartile band."""
    figure = Figure(figsize=(6.4, 4.2), layout="constrained")
    ax = figure.subplots()
    for label, band in bands.items():
        (line,) = ax.plot(band.evaluations, band.median, lw=1.6,
                          label=f"{label} ({band.runs} runs)")  # fmt: skip
        ax.fill_between(band.evaluations, band.lower, band.upper, color=line.get_color(),
                        alpha=0.2, lw=0)  # fmt: skip
    curves = [curve for band in bands.values() for curve in (band.lower, band.upper)]
    logarithmic = not maximize and _spans_decades(curves)
    if logarithmic:
        ax.set_yscale("log")
    else:
        # the medians and the better quartile: a worse quartile still among the first random
        # candidates (robots that all fall) would flatten every curve
        better = [band.upper if maximize else band.lower for band in bands.values()]
        _focus(ax, [*(band.median for band in bands.values()), *better])
    ax.set_xlabel("evaluations")
    ax.set_ylabel(f"{quantity}, {fitness_label(maximize)}")
    scale = (
        "log y axis"
        if logarithmic
        else f"y axis: medians, better quartile from {FOCUS_FROM:.0%} on"
    )
    ax.set_title(
        f"{title}\nmedian over runs, band: 25th to 75th percentile\n({scale})",
        fontsize="medium",
    )
    ax.legend(fontsize="small")
    ax.grid(alpha=0.3)
    return figure


def _spans_decades(curves: list[np.ndarray]) -> bool:
    """The curves' finite values are all positive and span more than DECADES powers of ten:
    on a linear axis everything past the first evaluations would look flat."""
    values = np.concatenate([np.asarray(curve, dtype=float) for curve in curves])
    values = values[np.isfinite(values)]
    return bool(values.size and values.min() > 0 and values.max() / values.min() > 10**DECADES)


def _focus(ax: Axes, curves: list[np.ndarray]) -> None:
    """Scale ax's y axis to the curves' finite values from FOCUS_FROM of their length on."""
    tails = [curve[int(len(curve) * FOCUS_FROM) :] for curve in curves]
    values = np.concatenate(tails) if tails else np.empty(0)
    values = values[np.isfinite(values)]
    if values.size == 0:
        return
    low, high = float(values.min()), float(values.max())
    pad = 0.05 * (high - low) or 0.05 * max(abs(high), 1e-12)
    ax.set_ylim(low - pad, high + pad)


def save_figure(figure: Figure, path: Path) -> Path:
    """Write figure as a PNG at DPI, whole or not at all; returns path."""
    with written_whole(path, binary=True) as handle:
        figure.savefig(handle, dpi=DPI, format="png")
    return path
