"""What every plot of the project shares: legends beside the data (never on it), a view
zoomed to the values it shows, the start-up transient marked, and time views that show
the judged window at a readable scale.

A report states means and amplitudes after the start-up transient; a plot over the whole
run is scaled by the start-up (0-120 N*m for a +-6 N*m ripple), so the time figures have
an overview of the whole run and, below it, the judged window zoomed to its own values.
"""
from __future__ import annotations

import numpy as np

#: the face colour of the start-up transient in an overview
TRANSIENT_SHADE = "0.88"


def pyplot():
    """matplotlib's pyplot on the file-only backend (no display needed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def legend_outside(ax, fontsize: float = 8, **options) -> None:
    """The axes' legend to the right of the axes, where it covers no data (nothing when
    nothing is labelled).  The figure must leave room: ``constrained`` layout does."""
    handles, labels = ax.get_legend_handles_labels()
    if handles:
        ax.legend(handles, labels, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0,
                  fontsize=fontsize, **options)


def row_legend(axes, fontsize: float = 8) -> None:
    """One legend for a row of axes that share their kinds of line, to the right of the
    row's last axes: every label of the row, once."""
    seen = {}
    for ax in axes:
        for handle, label in zip(*ax.get_legend_handles_labels()):
            seen.setdefault(label, handle)
    if seen:
        axes[-1].legend(list(seen.values()), list(seen), loc="upper left", bbox_to_anchor=(1.01, 1.0),
                        borderaxespad=0.0, fontsize=fontsize)


def zoom(ax, *series, pad: float = 0.08) -> None:
    """The y-range of ``ax`` set to the finite values of ``series`` with ``pad`` of their
    range above and below (a flat series gets a range around its value)."""
    values = np.concatenate([np.asarray(s, dtype=float).ravel() for s in series]) if series else np.empty(0)
    values = values[np.isfinite(values)]
    if not len(values):
        return
    low, high = float(values.min()), float(values.max())
    span = high - low or max(abs(high) * 1e-3, 1e-12)
    ax.set_ylim(low - pad * span, high + pad * span)


def mark_transient(ax, start: float, end: float) -> None:
    """Shade the start-up transient ``start ... end``, left out of the report's figures."""
    if end > start:
        ax.axvspan(start, end, color=TRANSIENT_SHADE, zorder=0, label="start-up transient (not judged)")


def time_view(t, series: list[tuple[str, np.ndarray]], ylabel: str, unit: str, transient: float, title: str,
              difference: tuple[str, np.ndarray] | None = None):
    """A figure of quantities over time as a report judges them: the whole run (the
    transient shaded), then each series alone over the judged window t >= start +
    ``transient``, zoomed to it, with its mean and its max and min (amplitude A = (max -
    min)/2, as the report states it), and ``difference`` (label, values) over that window
    when given (two curves that lie on each other differ where the eye cannot see)."""
    plt = pyplot()
    t = np.asarray(t, dtype=float)
    judged = t >= t[0] + transient
    if judged.sum() < 2:
        judged = np.ones_like(t, dtype=bool)
    rows = 1 + len(series) + (difference is not None)
    fig, axes = plt.subplots(rows, 1, figsize=(11, 1.2 + 2.1 * rows), squeeze=False, layout="constrained")
    axes = axes[:, 0]
    overview = axes[0]
    for label, values in series:
        overview.plot(t, values, "-", lw=0.7, label=label)
    mark_transient(overview, t[0], t[0] + transient)
    overview.set_ylabel(f"{ylabel} [{unit}]")
    overview.set_title("whole run", fontsize=9, loc="left")
    tj = t[judged]
    for ax, (color, (label, values)) in zip(axes[1:], enumerate(series)):
        v = np.asarray(values, dtype=float)[judged]
        mean, high, low = float(np.mean(v)), float(np.max(v)), float(np.min(v))
        ax.plot(tj, v, "-", color=f"C{color}", lw=0.6, label=label)
        ax.axhline(mean, color="k", ls="--", lw=0.8, label=f"mean {mean:.4g}")
        for level in (high, low):
            ax.axhline(level, color="0.4", ls=":", lw=0.8)
        ax.plot([], [], ":", color="0.4", lw=0.8, label=f"max, min: A = {0.5 * (high - low):.4g}")
        zoom(ax, v)
        ax.set_ylabel(f"{label} [{unit}]")
    if difference is not None:
        label, values = difference
        ax = axes[-1]
        d = np.asarray(values, dtype=float)[judged]
        ax.plot(tj, d, "-", color="C3", lw=0.6, label=label)
        ax.axhline(0.0, color="0.6", lw=0.8)
        zoom(ax, d, [0.0])
        ax.set_ylabel(f"difference [{unit}]")
    axes[1].set_title(f"judged window t >= {t[0] + transient:g} s, each zoomed to its values", fontsize=9, loc="left")
    for ax in axes:
        ax.grid(alpha=0.3)
        legend_outside(ax)
    for ax in axes[2:]:
        ax.sharex(axes[1])
    axes[1].set_xlim(tj[0], tj[-1])
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(title)
    return fig


__all__ = ["pyplot", "legend_outside", "row_legend", "zoom", "mark_transient", "time_view"]
