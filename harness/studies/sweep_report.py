"""The report of a parameter sweep (``harness.studies.sweep``): sweep.json, sweep.md and a plot
an axis, the cases' numbers under the traces' signal names, the monograph's reported points
set beside the model's."""
from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np

from harness.description import scene as scenes
from harness.formats import plotting
from harness.judges import metrics
from harness.paths import DATA
from harness.studies.sweep_axes import Axis
from harness.studies.sweep_trends import NOT_JUDGED


#: a key or a word of the monograph's index: A_w1, mean_tau2 (1 the drive, 2 the driven shaft), unevenness_1
_INDEXED = re.compile(r"\b(?:(A|mean)_(w|a|tau)([12])|unevenness_([12]))\b")


def signal_key(key: str, names: dict) -> str:
    """``key`` (or every such word of a text) under the traces' signal names: ``A_w1`` ->
    ``A_engine.w``, ``mean_tau2`` -> ``mean_coupling.tau2``, ``unevenness_2`` ->
    ``unevenness_load.w`` (``names``: ``metrics.signals`` of the scene); other keys as they are."""
    def named(m):
        if m.group(4):
            return f"unevenness_{names['w' + m.group(4)]}"
        return f"{m.group(1)}_{names[m.group(2) + m.group(3)]}"
    return _INDEXED.sub(named, key)


def published(report: dict, names: dict) -> dict:
    """The report as written and returned: each case's amplitudes, means and unevenness,
    the trends' quantities and numbers under the traces' signal names (``signal_key``);
    the differences (``dA_tau``) and the shafts' common means (``mean_w``) keep theirs."""
    cases = [{**c, "result": {signal_key(k, names): v for k, v in c["result"].items()}} for c in report["cases"]]
    trends_named = [{**t, "holds_for": [signal_key(q, names) for q in t["holds_for"]],
                     "numbers": signal_key(t["numbers"], names)} for t in report["trends"]]
    differences = {f"dA_{q}": signal_key(f"A_{q}2 - A_{q}1", names) for q in ("w", "a", "tau")}
    return {**report, "differences": differences, "cases": cases, "trends": trends_named}



def write(out: Path, axes: list[Axis], report: dict, names: dict | None = None) -> dict:
    """sweep.json, sweep.md and a plot an axis of ``report`` (its cases by the monograph's
    index) to ``out``; returns the report as ``published`` under the signals' ``names``
    (default: ``metrics.signals`` of the report's scene)."""
    names = names or metrics.signals(scenes.load(report["scene"]))
    out.mkdir(parents=True, exist_ok=True)
    public = published(report, names)
    (out / "sweep.json").write_text(json.dumps(public, indent=2, default=str))
    results = report["cases"]
    failed = [r for r in results if r["result"].get("status") != "ok"]
    amplitudes = ("A_w1", "A_w2", "A_a1", "A_a2", "A_tau1", "A_tau2")
    lines = [f"# Parameter sweep of the {report['scene']} scene against the monograph's figures", "",
             "Amplitudes A = (max - min)/2 and means after the start-up transient of the drive shaft's "
             f"({names['w1']}, {names['a1']}, {names['tau1']}) and the driven shaft's ({names['w2']}, {names['a2']}, "
             f"{names['tau2']}) signals; dA = A driven - A drive (the monograph's difference, e.g. dA_tau = "
             f"{public['differences']['dA_tau']}).  Each axis varies one quantity at the "
             "conditions of the figure it mirrors.", "", "## Trends (docs/physics.md#what-the-monograph-reports)", "",
             "| trend | reproduced | numbers |", "|---|---|---|"]
    for t in public["trends"]:
        verdict = {"yes": "yes", "partly": "partly: " + ", ".join(t["holds_for"]), "no": "**no**",
                   NOT_JUDGED: NOT_JUDGED}[t["reproduced"]]
        lines.append(f"| {t['trend']} | {verdict} | {_cell(t['numbers'])} |")
    for axis in axes:
        rows = [r for r in results if r["axis"] == axis.name]
        lines += ["", f"## {axis.name} (Fig. {axis.figure}): {axis.quantity}", "", axis.note, "",
                  f"![{axis.name}](sweep_{axis.name}.png)", "",
                  "| value | " + " | ".join(signal_key(k, names).replace("_", " ", 1) for k in amplitudes)
                  + " | mean speed | mean torque | status |",
                  "|---|---|---|---|---|---|---|---|---|---|"]
        for r in rows:
            res = r["result"]
            if res.get("status") == "ok":
                cells = " | ".join(f"{res[k]:.4g}" for k in amplitudes + ("mean_w", "mean_tau"))
                lines.append(f"| {r['x']:g} | {cells} | ok |")
            else:
                lines.append(f"| {r['x']:g} |" + " - |" * 8 + f" failed: {_cell(res.get('error'))} "
                             f"({_cell(res.get('where'))}) |")
        reported = dict(axis.reported)
        if axis.name == "stiffness_measured":
            reported.update(measured_amplitudes())
        if reported:
            lines += ["", "Reported by the monograph: " + "; ".join(
                f"{signal_key(k, names)} " + ", ".join(f"{x:g} -> {_range(v)}" for x, v in pts)
                for k, pts in reported.items())]
            compared = against_monograph(rows, reported)
            if compared:
                lines += ["", "The model beside the monograph (its cases interpolated at the printed points):", ""]
                lines += [f"- {comparison_sentence(c)}" for c in compared]
        _plot(out / f"sweep_{axis.name}.png", axis, rows, reported)
    if failed:
        lines += ["", "## Failed cases", ""] + [f"- {r['axis']} = {r['x']:g}: {_cell(r['result'].get('error'))} "
                                                f"({_cell(r['result'].get('where'))})" for r in failed]
    (out / "sweep.md").write_text("\n".join(lines) + "\n")
    return public


def _cell(text) -> str:
    """``text`` on one line for a Markdown table cell: its lines joined (a multi-line
    error would end the table), pipes escaped."""
    return " ".join(line.strip() for line in str(text).splitlines() if line.strip()).replace("|", "\\|")


def _range(v) -> str:
    return f"{v[0]:g}-{v[1]:g}" if isinstance(v, (tuple, list)) else f"{v:g}"


#: each column of a sweep's plot: the quantity, its label, its unit
PLOT_COLUMNS = (("w", "speed", "rad/s"), ("a", "acceleration", "rad/s^2"), ("tau", "torque", "N*m"))


def _reported_value(v) -> float:
    """A printed value, or the middle of a printed range."""
    return 0.5 * (v[0] + v[1]) if isinstance(v, (tuple, list)) else float(v)


def against_monograph(rows: list[dict], reported: dict) -> list[dict]:
    """The model against each reported amplitude series it can be set beside: per key
    (``A_w1``, ``dA_tau``, ...), the printed values, the model's at the same points (its
    cases interpolated, points outside them left out), how many times larger the printed
    ones are, and whether their signs agree."""
    ok = sorted((r for r in rows if r["result"].get("status") == "ok"), key=lambda r: r["x"])
    x = np.array([r["x"] for r in ok], dtype=float)
    out = []
    for q, label, unit in PLOT_COLUMNS:
        for key in (f"A_{q}1", f"A_{q}2", f"dA_{q}"):
            points = [(px, _reported_value(v)) for px, v in reported.get(key) or ()
                      if len(x) >= 2 and x[0] <= px <= x[-1] or len(x) == 1 and px == x[0]]
            if not points:
                continue
            model = np.interp([px for px, _ in points], x, [r["result"][key] for r in ok])
            printed = np.array([v for _, v in points])
            ratios = np.abs(printed) / np.maximum(np.abs(model), 1e-300)
            out.append({"key": key, "quantity": label, "unit": unit, "x": [px for px, _ in points],
                        "printed": printed.tolist(), "model": model.tolist(),
                        "ratio": (float(ratios.min()), float(ratios.max())),
                        "opposite_sign_at": [px for (px, _), a, b in zip(points, printed, model)
                                             if np.sign(a) != np.sign(b)]})
    return out


def comparison_sentence(c: dict) -> str:
    """One comparison of ``against_monograph`` in words, e.g. 'dA torque: the monograph
    +11 -> +56 N*m, the model -0.16 -> -2.1 N*m: 17-27x larger, of opposite sign'."""
    def series(values):
        return " -> ".join(f"{v:+.3g}" if c["key"].startswith("dA") else f"{v:.3g}" for v in values)

    size = _times(c) + " the model's"
    sign = _sign_words(c)
    name = c["key"].split("_")[0] + " " + c["quantity"] + {"1": " drive", "2": " driven"}.get(c["key"][-1], "")
    return (f"{name}: the monograph {series(c['printed'])} {c['unit']}, the model {series(c['model'])} {c['unit']} "
            f"(at {', '.join(f'{x:g}' for x in c['x'])}): {size}{sign}")


#: printed and model values further apart than this factor share a logarithmic axis
#: (symmetric-logarithmic for differences, which change sign), so both can be read
LOG_RATIO = 10.0


def _scale_for(ax, values) -> None:
    """A logarithmic y-axis when ``values`` span more than ``LOG_RATIO`` or change sign
    (symmetric-logarithmic when any is negative), so that the model and the monograph are
    each readable on one axes."""
    v = np.abs(np.asarray([x for x in values if np.isfinite(x)], dtype=float))
    v = v[v > 0]
    if not len(v):
        return
    changes_sign = min(values) < 0 < max(values)
    if v.max() / v.min() < LOG_RATIO and not changes_sign:
        return
    if min(values) > 0:
        ax.set_yscale("log")
    else:
        # the linear part around 0 a decade below the smallest value, on a power of ten: its
        # ticks (-1, 0, 1 of that power) then stand a decade's height apart, not on each other
        ax.set_yscale("symlog", linthresh=float(10.0 ** np.floor(np.log10(v.min()))), linscale=1.0)
    ax.autoscale_view()
    ax.margins(y=0.12)
    if min(values) > 0:
        plotting.log_ticks(ax.yaxis)
    else:
        from matplotlib import ticker

        ax.yaxis.set_major_formatter(ticker.FuncFormatter(lambda y, _: f"{y:g}"))      # -10 -1 0 1 10


def _plot(path: Path, axis: Axis, rows: list[dict], reported: dict):
    """One column per quantity (and the means for the load and inertia axes): the model's
    amplitudes and its dA = A2 - A1, the monograph's points (crosses) on the same axes -
    logarithmic where they are a decade or more apart - and each panel's comparison in
    words (how many times the model's, and a sign that differs)."""
    plt = plotting.pyplot()
    ok = sorted((r for r in rows if r["result"].get("status") == "ok"), key=lambda r: r["x"])
    x = np.array([r["x"] for r in ok])
    value = lambda key: [r["result"][key] for r in ok]  # noqa: E731
    columns = list(PLOT_COLUMNS) + ([("mean", "mean", "")] if axis.name in ("load", "inertia") else [])
    comparisons = {c["key"]: c for c in against_monograph(rows, reported)}
    fig, grid = plt.subplots(2, len(columns), figsize=(4.6 * len(columns), 6.6), squeeze=False,
                             sharex=True, layout="constrained")
    for col, (q, label, unit) in enumerate(columns):
        top, middle = grid[0, col], grid[1, col]
        if q == "mean":
            top.plot(x, value("mean_w"), "-o", color="tab:purple", label="model mean w")
            top.set_ylabel("mean speed [rad/s]")
            middle.plot(x, value("mean_tau"), "-o", color="tab:brown", label="model mean torque")
            middle.set_ylabel("mean torque [N*m]")
            _overlay(top, reported.get("mean_w"), "reported mean w", "k")
            _overlay(middle, reported.get("mean_tau"), "reported mean torque", "k")
            continue
        for i, style, color in ((1, "-o", "C0"), (2, "--s", "C1")):
            top.plot(x, value(f"A_{q}{i}"), style, color=color, label=f"model {('drive', 'driven')[i - 1]}")
        _overlay(top, reported.get(f"A_{q}1"), "monograph drive", "C0")
        _overlay(top, reported.get(f"A_{q}2"), "monograph driven", "C1")
        top.set_ylabel(f"{label} amplitude A [{unit}]")
        middle.plot(x, value(f"dA_{q}"), "-o", color="tab:green", label="model dA = A2 - A1")
        _overlay(middle, reported.get(f"dA_{q}"), "monograph dA", "tab:green")
        middle.axhline(0, color="0.6", lw=0.8)
        middle.set_ylabel(f"dA {label} [{unit}]")
        for ax, keys in ((top, (f"A_{q}1", f"A_{q}2")), (middle, (f"dA_{q}",))):
            shown = [v for k in keys for v in value(k)] + [_reported_value(v) for k in keys
                                                           for _, v in reported.get(k) or ()]
            _scale_for(ax, shown)
            said = [comparisons[k] for k in keys if k in comparisons]
            if said:
                # above the panel, not on it: a box on the data hid the points it spoke of
                ax.set_title("\n".join(_panel_note(c) for c in said), fontsize=7.5, loc="left")
    for axes_row in grid:
        for ax in axes_row:
            ax.grid(alpha=0.3)
            if ax.axison and not ax.has_data():
                ax.text(0.5, 0.5, f"no case ran ({len(rows)} failed)", transform=ax.transAxes, ha="center",
                        va="center", color="0.5")
    for row in grid:
        plotting.row_legend(row, fontsize=7)
    for ax in grid[-1]:
        ax.set_xlabel(axis.quantity)
    fig.suptitle(f"{axis.name} (Fig. {axis.figure}): {axis.note}" + ("" if not comparisons else
                 "\nthe monograph's points (x) on the model's axes"), fontsize=9)
    plotting.save_png(fig, path, dpi=100)
    plt.close(fig)


def _panel_note(c: dict) -> str:
    """A panel's comparison, short: 'monograph dA = 17-27x the model's, opposite sign'."""
    which = {"1": " drive", "2": " driven"}.get(c["key"][-1], "")
    return (f"monograph{which} {c['key'].split('_')[0]} = {_times(c)} the model's"
            + _sign_words(c))


def _times(c: dict) -> str:
    """How many times the model's the printed values are: '26x', '3.1-11x', '17-140x'."""
    low, high = (f"{r:.2g}" if r < 100 else f"{r:.0f}" for r in c["ratio"])
    return f"{low}x" if low == high else f"{low}-{high}x"


def _sign_words(c: dict) -> str:
    """', of opposite sign' (everywhere), ', of opposite sign at 35', or nothing."""
    at = c["opposite_sign_at"]
    if not at:
        return ""
    return ", of opposite sign" + ("" if len(at) == len(c["x"]) else " at " + ", ".join(f"{x:g}" for x in at))


def _overlay(ax, points, label, color):
    if not points:
        return
    for i, (x, v) in enumerate(points):
        if isinstance(v, (tuple, list)):
            ax.errorbar([x], [0.5 * (v[0] + v[1])], yerr=[[0.5 * (v[1] - v[0])]], fmt="x", color=color,
                        capsize=3, label=label if i == 0 else None)
        else:
            ax.plot([x], [v], "x", color=color, ms=9, mew=2, label=label if i == 0 else None)


def measured_amplitudes() -> dict:
    """A of the measured mean drive and driven torque curves per grade, from the data
    files (for the Fig. 4.8 overlay): {"A_tau1": [(c, A)], "A_tau2": [...]}."""
    from harness.studies.measured import amplitude, pair_tables

    pairs, _ = pair_tables([DATA / "monograph"])
    out = {"A_tau1": [], "A_tau2": []}
    for drive, driven in pairs:
        if drive.stiffness:
            out["A_tau1"].append((drive.stiffness, amplitude(drive.mean_curve)))
            out["A_tau2"].append((drive.stiffness, amplitude(driven.mean_curve)))
    return out
