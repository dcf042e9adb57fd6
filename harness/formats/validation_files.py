"""What ``lever validate`` writes: ``validation.json``, the result as the cross-check names
it, and a plot per failing signal - with the units of each signal and the reference drawn from
its own (dense) samples."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from harness.formats.reference_traces import ReferenceTraces, Result, Traces, write_csv

def write_validation(out: Path, findings, bands: dict, result: Result, reference: ReferenceTraces,
                     write_result: bool = True, plots: bool = True) -> list[Path]:
    """``validation.json``, the result as ``<NAME>_out.csv`` (cross-check naming; unless
    ``write_result`` is false) and one plot per failing signal with its band (unless ``plots``
    is false), in ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    for stale in out.glob("*.png"):
        stale.unlink()
    if findings.KIND == "lever":                    # the engineer's verdict (harness.judges.verdict)
        return write_verdict(out, findings, result, reference, write_result, plots)
    written = _write_result_and_json(out, findings, result, reference, write_result)
    if plots and len(result.times):
        for signal in findings.signals:
            if not signal.passed:
                written.append(plot_signal(out, reference, result, signal, bands[signal.name], findings.tolerance))
    return written


def write_verdict(out: Path, verdict, result: Result, reference: ReferenceTraces, write_result: bool = True,
                  plots: bool = True) -> list[Path]:
    """``write_validation`` for the engineer's verdict: ``validation.json`` (every check, the
    tolerances and their sources, the power), the result, and a plot per failing signal
    (unless ``plots`` is false)."""
    written = _write_result_and_json(out, verdict, result, reference, write_result)
    if plots and len(result.times):
        written += [plot_verdict_signal(out, reference, result, s, verdict) for s in verdict.signals if not s.passed]
    return written


def _write_result_and_json(out: Path, judged, result: Result, reference: ReferenceTraces,
                           write_result: bool) -> list[Path]:
    """What every verdict writes: the result's recorded outputs (``<name>_out.csv``, unless
    the result came from a file) and ``validation.json`` (the verdict's ``to_dict`` and how
    the result was made)."""
    import json

    written = []
    if write_result and len(result.times):
        path = out / f"{reference.name}_out.csv"
        write_csv(path, Traces(result.times, {n: result.traces[n] for n in reference.outputs.signals
                                             if n in result.traces}))
        written.append(path)
    summary = judged.to_dict()
    summary["run"] = {"how": result.how, "failure": result.failure}
    path = out / "validation.json"
    path.write_text(json.dumps(summary, indent=2, default=float))
    written.append(path)
    return written


def plot_verdict_signal(out: Path, reference: ReferenceTraces, result: Result, signal, verdict) -> Path:
    """One failing signal: the reference, its tube over the judged window and the result over
    the whole span above; below, the window's last revolutions (its last tenth without a
    shaft), where a changed mean, ripple or phase shows - or, when only a tube fails, the
    revolutions about its sample farthest beyond it."""
    from harness.formats import plotting

    plt = plotting.pyplot()
    t_ref, y_ref = reference.outputs.times, np.asarray(reference.outputs.signals[signal.name], dtype=float)
    t, y = result.times, np.asarray(result.traces[signal.column], dtype=float)
    start, stop = verdict.window or verdict.transient       # the steady window, or a start-up-only span
    inside = (t_ref >= start) & (t_ref <= stop)
    width = signal.power.band if signal.power else 0.0
    close = (2 * 2 * math.pi / verdict.rotation) if verdict.rotation else 0.1 * (stop - start)
    tubes = [c for c in signal.failed if c.at is not None]
    if tubes and len(tubes) == len(signal.failed):
        farthest = tubes[0].at
        zoom = (max(t_ref[0], farthest - 0.5 * close), min(t_ref[-1], farthest + 0.5 * close))
        zoom_title = f"about the sample farthest beyond the {tubes[0].quantity}, t = {farthest:.4g} s"
    else:
        zoom = (max(start, stop - close), stop)
        zoom_title = f"the judged window's last {zoom[1] - zoom[0]:.3g} s"
    fig, axes = plt.subplots(2, 1, figsize=(11, 7), layout="constrained")
    for ax, (low, high) in zip(axes, ((t_ref[0], t_ref[-1]), zoom)):
        ax.fill_between(t_ref[inside], y_ref[inside] - width, y_ref[inside] + width, color="tab:green", alpha=0.25,
                        lw=0, label=f"tube +-{width:.3g} (judged window)")
        ax.plot(t_ref, y_ref, color="tab:green", lw=1.0, label=f"reference ({len(t_ref)} samples)")
        ax.plot(t, y, color="tab:blue", lw=0.8, marker="." if len(t) < 3000 else None, ms=2, label="result")
        ax.set_xlim(low, high)
        shown = np.concatenate([y_ref[(t_ref >= low) & (t_ref <= high)], y[(t >= low) & (t <= high)]])
        shown = shown[np.isfinite(shown)]
        if shown.size and shown.max() > shown.min():
            pad = 0.05 * (shown.max() - shown.min())
            ax.set_ylim(shown.min() - pad - width, shown.max() + pad + width)
        ax.set_xlabel("time [s]")
        ax.set_ylabel(f"{signal.name} [{signal.unit}]" if signal.unit else f"{signal.name} (unit not known)")
        ax.grid(alpha=0.3)
    plotting.legend_outside(axes[0])
    failed = ", ".join(c.quantity for c in signal.failed)
    axes[0].set_title(f"{reference.name}: {signal.name} FAILS on {failed} (validation.json has the figures)",
                      fontsize=9)
    axes[1].set_title(zoom_title, fontsize=9)
    path = out / f"{signal.name}.png"
    plotting.save_png(fig, path, dpi=110)
    plt.close(fig)
    return path


def _finite_limits(*arrays) -> tuple[float, float] | None:
    """The smallest and largest finite value of ``arrays``; None when there is none."""
    values = np.concatenate([np.asarray(a, dtype=float).ravel() for a in arrays])
    values = values[np.isfinite(values)]
    return (float(values.min()), float(values.max())) if values.size else None


def plot_signal(out: Path, reference: ReferenceTraces, result: Result, finding, band, tolerance) -> Path:
    """The reference, its band, the result and the samples outside the band: the whole span
    above, a close-up around the first sample outside below."""
    from harness.formats import plotting

    plt = plotting.pyplot()
    t_ref, y_ref = reference.outputs.times, reference.outputs.signals[finding.name]
    column = next(c for c in (finding.name,) + tuple(k for k in result.traces if k.endswith("." + finding.name))
                  if c in result.traces)
    t, y = result.times, result.traces[column]
    first = finding.outside_times[0] if finding.outside_times else finding.max_error_time
    span = t_ref[-1] - t_ref[0]
    half = max(0.025 * span, 10 * float(np.median(np.diff(t_ref)))) if len(t_ref) > 1 else 1.0
    # no sample compared (the result's times miss the reference's): no close-up, and the
    # whole plot over both spans, from their finite values only
    windows = (None, (first - half, first + half) if math.isfinite(first) else None)
    fig, axes = plt.subplots(2 if windows[1] else 1, 1, figsize=(11, 7 if windows[1] else 4), squeeze=False,
                             layout="constrained")
    axes = axes[:, 0]
    for ax, window in zip(axes, windows):
        ax.fill_between(band.t, band.low, band.high, color="tab:green", alpha=0.25, lw=0,
                        label=f"band ({tolerance.name}: +-{band.width:.3g})")
        ax.plot(t_ref, y_ref, color="tab:green", lw=1.0, label="reference")
        ax.plot(t, y, color="tab:blue", lw=0.8, label="result")
        if finding.outside_times:
            times = np.array(finding.outside_times)
            ax.plot(times, np.interp(times, t, y), "x", color="tab:red", ms=5, label="outside the band")
        if window:
            window = (max(window[0], t_ref[0]), min(window[1], t_ref[-1]))
            ax.set_xlim(*window)
            inside = (t_ref >= window[0]) & (t_ref <= window[1])
            shown = np.concatenate([band.low[(band.t >= window[0]) & (band.t <= window[1])],
                                    band.high[(band.t >= window[0]) & (band.t <= window[1])],
                                    y[(t >= window[0]) & (t <= window[1])], y_ref[inside]])
            shown = shown[np.isfinite(shown)]
            if shown.size:
                pad = 0.05 * (shown.max() - shown.min() or 1.0)
                ax.set_ylim(shown.min() - pad, shown.max() + pad)
            ax.set_title(f"close-up at t = {first:.4g} s", fontsize=9)
        else:
            x = _finite_limits(t_ref, t)
            y_limits = _finite_limits(band.low, band.high, y_ref, y)
            if x and x[1] > x[0]:
                ax.set_xlim(*x)
            if y_limits and y_limits[1] > y_limits[0]:
                pad = 0.05 * (y_limits[1] - y_limits[0])
                ax.set_ylim(y_limits[0] - pad, y_limits[1] + pad)
        ax.set_xlabel("time [s]")
        ax.set_ylabel(finding.name)
        ax.grid(alpha=0.3)
    plotting.legend_outside(axes[0])
    axes[0].set_title(f"{reference.name}: {finding.name} - {finding.problem}", fontsize=9)
    path = out / f"{finding.name}.png"
    plotting.save_png(fig, path, dpi=110)
    plt.close(fig)
    return path
