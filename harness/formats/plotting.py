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
#: two curves drawn on one axes where both must be told apart (errors of the drive and the
#: driven side): blue and red, not two neighbours of the colour cycle (green over blue)
PAIR_COLOURS = ("C0", "C3")


def pyplot():
    """matplotlib's pyplot on the file-only backend (no display needed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_png(fig, path, dpi: int = 110) -> None:
    """``fig`` written to ``path`` as a PNG at ``dpi``, pixel for pixel what
    ``fig.savefig(path, dpi=dpi)`` writes, drawn once: savefig draws a figure with a layout
    engine twice (a pass that places the axes and renders nothing, then the picture), a
    fifth of the time of a run's plots; here the layout is placed and the picture drawn."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    if not isinstance(fig.canvas, FigureCanvasAgg):     # a figure of another backend: its own way
        fig.savefig(path, dpi=dpi)
        return
    fig.set_dpi(dpi)
    engine = fig.get_layout_engine()
    if engine is not None:
        engine.execute(fig)
        fig.set_layout_engine("none")       # placed: the draw keeps the axes where they are
    fig.canvas.print_png(path)


def legend_outside(ax, fontsize: float = 8, **options) -> None:
    """The axes' legend to the right of the axes, where it covers no data (nothing when
    nothing is labelled).  The figure must leave room: ``constrained`` layout does."""
    handles, labels = ax.get_legend_handles_labels()
    if handles:
        ax.legend(handles, labels, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0,
                  fontsize=fontsize, **options)


def legend_above(ax, fontsize: float = 8) -> None:
    """The axes' legend in one row above the axes, for a plot whose labels are long beside
    a wide axes: the axes keep the figure's width."""
    handles, labels = ax.get_legend_handles_labels()
    if handles:
        ax.legend(handles, labels, loc="lower left", bbox_to_anchor=(0.0, 1.01), borderaxespad=0.0,
                  ncol=len(handles), fontsize=fontsize, frameon=False)


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


def log_ticks(axis, wide: float = 3.5) -> None:
    """A logarithmic axis labelled in plain numbers at 1, 2 and 5 of each decade (every digit
    within less than a decade, 1 alone over more than ``wide`` decades), the minor ticks
    unlabelled: matplotlib's own labels of a short log range put '2x10^-1' at every minor
    tick, running into each other."""
    from matplotlib import ticker

    low, high = axis.get_view_interval()
    decades = np.log10(max(high, 1e-300) / max(low, 1e-300)) if low > 0 else np.inf
    subs = tuple(range(1, 10)) if decades < 1.0 else (1.0, 2.0, 5.0) if decades <= wide else (1.0,)
    axis.set_major_locator(ticker.LogLocator(base=10.0, subs=subs))
    axis.set_major_formatter(ticker.FuncFormatter(lambda v, _: f"{v:g}"))
    axis.set_minor_formatter(ticker.NullFormatter())


def mark_transient(ax, start: float, end: float) -> None:
    """Shade the start-up transient ``start ... end``, left out of the report's figures."""
    if end > start:
        ax.axvspan(start, end, color=TRANSIENT_SHADE, zorder=0, label="start-up transient (not judged)")


#: a panel's curve is drawn as its envelope (max and min over slices of the window) when it
#: turns more often than this, about the pixels across the panel: a line that turns at every
#: pixel is a solid band (KAVZ-685's a1 turns ~500 times in 8 s and reads as a line; its a2,
#: ~1,000 times, was a band)
DENSE_TURNS = 800
#: slices of a window's envelope: about one per pixel of an 11-inch figure's wide column
ENVELOPE_SLICES = 500
#: the detail beside a judged window: this many periods of its strongest frequency
DETAIL_PERIODS = 3
#: an overview leaves off a start-up that overshoots the judged values this many times
#: their own range on both sides
IMPULSE_FACTOR = 4.0


def turns(values) -> int:
    """How often a curve changes direction: how dense its line is drawn."""
    d = np.diff(np.asarray(values, dtype=float))
    d = d[d != 0.0]
    return int(np.count_nonzero(np.diff(np.sign(d))))


def envelope(t, values, slices: int = ENVELOPE_SLICES):
    """``(t, low, high)``: the min and max of ``values`` over ``slices`` equal slices of the
    samples, at each slice's middle time - the band a dense line fills, drawn as a shape."""
    t = np.asarray(t, dtype=float)
    v = np.asarray(values, dtype=float)
    edges = np.linspace(0, len(v), min(slices, len(v)) + 1).astype(int)
    parts = [slice(a, b) for a, b in zip(edges[:-1], edges[1:]) if b > a]
    return (np.array([0.5 * (t[s][0] + t[s][-1]) for s in parts]), np.array([v[s].min() for s in parts]),
            np.array([v[s].max() for s in parts]))


def trace(ax, t, values, color, label: str, lw: float = 0.6) -> bool:
    """``values`` over ``t`` on ``ax``: as a line where its turns can be seen, else as its
    envelope (filled, outlined, labelled as one).  True when the envelope was drawn."""
    if turns(values) <= DENSE_TURNS:
        ax.plot(t, values, "-", color=color, lw=lw, label=label)
        return False
    tm, low, high = envelope(t, values)
    ax.fill_between(tm, low, high, color=color, alpha=0.3, lw=0.0)
    ax.plot(tm, low, "-", color=color, lw=0.5)
    ax.plot(tm, high, "-", color=color, lw=0.5, label=f"{label} (envelope)")
    return True


def detail_span(t, values) -> float:
    """A time span that shows ``DETAIL_PERIODS`` periods of the strongest frequency of
    ``values`` (the mean left out), within a fortieth and a quarter of the window."""
    t = np.asarray(t, dtype=float)
    window = float(t[-1] - t[0])
    v = np.asarray(values, dtype=float)
    span = window / 16.0
    if len(v) >= 16 and window > 0:
        power = np.abs(np.fft.rfft(v - v.mean()))
        frequency = np.fft.rfftfreq(len(v), window / (len(v) - 1))
        if len(power) > 1 and power[1:].max() > 0:
            span = DETAIL_PERIODS / frequency[1 + int(np.argmax(power[1:]))]
    return float(np.clip(span, window / 40.0, window / 4.0))


def impulse_limits(whole, judged):
    """The overview's y-range when the start-up is an impulse (it overshoots the judged
    values by ``IMPULSE_FACTOR`` times their range on both sides, as an acceleration does
    at a step): the judged range widened by that factor; None when the start-up is shown
    whole (a rise from rest to the running level, as speeds and torques have)."""
    whole = whole[np.isfinite(whole)]
    judged = judged[np.isfinite(judged)]
    if not len(whole) or not len(judged):
        return None
    low, high = float(judged.min()), float(judged.max())
    span = high - low
    reach = IMPULSE_FACTOR * span
    if span <= 0 or not (whole.max() > high + reach and whole.min() < low - reach):
        return None
    return low - 0.5 * reach, high + 0.5 * reach


def time_view(t, series: list[tuple[str, np.ndarray]], ylabel: str, unit: str, transient: float, title: str,
              difference: tuple[str, np.ndarray] | None = None):
    """A figure of quantities over time as a report judges them: the whole run of each
    series in its own panel, on one scale (the transient shaded; an impulse at the start
    left off the scale and its peaks named), then
    each series alone over the judged window t >= start + ``transient``, zoomed to it,
    with its mean and its max and min (amplitude A = (max - min)/2, as the report states
    it), and ``difference`` (label, values) over that window when given (two curves that
    lie on each other differ where the eye cannot see).  Beside each judged panel, the last
    few periods at the same scale: the wave's shape, which a window of hundreds of periods
    (drawn as its envelope) cannot show."""
    plt = pyplot()
    t = np.asarray(t, dtype=float)
    judged = t >= t[0] + transient
    if judged.sum() < 2:
        judged = np.ones_like(t, dtype=bool)
    rows = 1 + len(series) + (difference is not None)
    fig = plt.figure(figsize=(12, 1.2 + 2.1 * rows), layout="constrained")
    grid = fig.add_gridspec(rows, 2, width_ratios=(3.2, 1.0))
    # the whole run of each series in its own panel, side by side on one scale: drive and
    # driven torque (or speed) are close, and drawn on one axes one hid the other
    whole_row = grid[0, :].subgridspec(1, len(series), wspace=0.02)
    whole = np.concatenate([np.asarray(v, dtype=float) for _, v in series])
    limits = impulse_limits(whole, np.concatenate([np.asarray(v, dtype=float)[judged] for _, v in series]))
    overviews = []
    for i, (label, values) in enumerate(series):
        overview = fig.add_subplot(whole_row[0, i], sharey=overviews[0] if overviews else None)
        overview.plot(t, values, "-", color=f"C{i}", lw=0.7)
        mark_transient(overview, t[0], t[0] + transient)
        overview.set_title(f"whole run: {label}", fontsize=9, loc="left")
        overview.grid(alpha=0.3)
        if overviews:
            overview.tick_params(labelleft=False)
        overviews.append(overview)
    overviews[0].set_ylabel(f"{ylabel} [{unit}]")
    if limits is not None:
        overviews[0].set_ylim(*limits)
        overviews[-1].text(0.99, 0.97, f"start-up peaks off the scale: max {np.nanmax(whole):.4g}, "
                           f"min {np.nanmin(whole):.4g} {unit}", transform=overviews[-1].transAxes, ha="right",
                           va="top", fontsize=8, bbox={"facecolor": "white", "edgecolor": "0.7", "alpha": 0.9})
    if transient > 0:
        overviews[-1].legend(*overviews[-1].get_legend_handles_labels(), loc="upper left", bbox_to_anchor=(1.02, 1.0),
                             borderaxespad=0.0, fontsize=8)
    tj = t[judged]
    panels = [(f"C{i}", label, np.asarray(values, dtype=float)[judged], f"{label} [{unit}]")
              for i, (label, values) in enumerate(series)]
    if difference is not None:
        panels.append(("C3", difference[0], np.asarray(difference[1], dtype=float)[judged], f"difference [{unit}]"))
    span = detail_span(tj, panels[0][2])
    near = tj >= tj[-1] - span
    near[-2:] = True            # a run of a few samples: the detail still spans two of them
    axes, details = [], []
    for row, (color, label, v, axis_label) in enumerate(panels, start=1):
        ax = fig.add_subplot(grid[row, 0], sharex=axes[0] if axes else None)
        detail = fig.add_subplot(grid[row, 1], sharey=ax, sharex=details[0] if details else None)
        trace(ax, tj, v, color, label)
        detail.plot(tj[near], v[near], "-", color=color, lw=0.8)
        if difference is not None and row == len(panels):
            for a in (ax, detail):
                a.axhline(0.0, color="0.6", lw=0.8)
            zoom(ax, v, [0.0])
        else:
            mean, high, low = float(np.mean(v)), float(np.max(v)), float(np.min(v))
            for a in (ax, detail):
                a.axhline(mean, color="k", ls="--", lw=0.8)
                for level in (high, low):
                    a.axhline(level, color="0.4", ls=":", lw=0.8)
            ax.plot([], [], "k--", lw=0.8, label=f"mean {mean:.4g}")
            ax.plot([], [], ":", color="0.4", lw=0.8, label=f"max, min: A = {0.5 * (high - low):.4g}")
            zoom(ax, v)
        ax.set_ylabel(axis_label)
        detail.tick_params(labelleft=False)
        for a in (ax, detail):
            a.grid(alpha=0.3)
        axes.append(ax)
        details.append(detail)
    for ax, detail in zip(axes, details):
        handles, labels = ax.get_legend_handles_labels()
        if handles:
            detail.legend(handles, labels, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0, fontsize=8)
    axes[0].set_xlim(tj[0], tj[-1])
    details[0].set_xlim(tj[near][0], tj[-1])
    axes[0].set_title(f"judged window t >= {t[0] + transient:g} s, each zoomed to its values", fontsize=9, loc="left")
    details[0].set_title(f"its last {span:.3g} s", fontsize=9, loc="left")
    axes[-1].set_xlabel("time [s]")
    details[-1].set_xlabel("time [s]")
    fig.suptitle(title)
    return fig


__all__ = ["PAIR_COLOURS", "pyplot", "save_png", "legend_outside", "legend_above", "row_legend", "zoom", "mark_transient", "log_ticks", "turns",
           "envelope", "trace", "detail_span", "impulse_limits", "time_view"]
