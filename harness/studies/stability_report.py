"""The stability map's files (``lever stability``): stability.md (the agreement, the edges
table, a class matrix), stability.csv (every case with its predicted spectral radius) and
stability_map.png (a panel a master, observed classes with the predicted edges over them),
from a ``harness.studies.stabilitymap.StabilityMap``.  A map without prediction (no linear
model: ``StabilityMap.no_prediction`` says why) gets the same files with that sentence first,
its predicted columns "not predicted", its edges observed only and the advice its runs give."""
from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from harness.judges import metrics, stability
from harness.paths import FMUS
from harness.studies.cases import FAILED
from harness.studies.stabilitymap import (ENERGY_DRIFT, EXPLICIT, GROWTH_DIVERGENT, GROWTH_DRIFT, STATUSES,
                                          StabilityMap, agreement, predicted_growth, predicted_radius, unstable)

#: what a map without prediction writes where a prediction would be
NOT_PREDICTED = "not predicted"
#: and where a figure of the linear model (omega_n, zeta, h*omega_n) would be
UNKNOWN = "unknown"


def write(out: Path, result: StabilityMap, fmu_dir: Path = FMUS, plots: bool = True) -> list[Path]:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    agreed = agreement(result, fmu_dir)
    predicted = result.model is not None
    paths = [_write_csv(out / "stability.csv", result, fmu_dir),
             (_write_markdown if predicted else _write_observed_markdown)(out / "stability.md", result, agreed)]
    if plots:
        paths.append((_plot if predicted else _plot_observed)(out / "stability_map.png", result))
    return paths


def _write_csv(path: Path, result: StabilityMap, fmu_dir) -> Path:
    fields = ["master", "stiffness", "damping", "h_omega", "steps", "omega_n", "zeta", "step_s", "predicted_rho",
              "predicted_growth", "predicted_edge", "class", "growth", "energy_residual", "steps_planned", "steps_done", "wall_s", "why"]
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, fields)
        writer.writeheader()
        for case in sorted(result.results, key=lambda c: (c.master, c.stiffness, -c.damping, c.h_omega or c.step)):
            r = result.results[case]
            if result.model is None:
                row = {"master": case.master, "stiffness": case.stiffness, "damping": case.damping,
                       "h_omega": UNKNOWN, "steps": case.steps, "omega_n": UNKNOWN, "zeta": UNKNOWN,
                       "step_s": case.step, "predicted_rho": NOT_PREDICTED, "predicted_growth": NOT_PREDICTED,
                       "predicted_edge": NOT_PREDICTED}
            else:
                model = result.model.with_coupling(case.stiffness, case.damping)
                rho = predicted_radius(result.model, case, fmu_dir)
                row = {"master": case.master, "stiffness": case.stiffness, "damping": case.damping,
                       "h_omega": case.h_omega, "steps": case.steps,
                       "omega_n": model.omega_n, "zeta": model.zeta, "step_s": model.step_for(case.h_omega),
                       "predicted_rho": rho, "predicted_growth": predicted_growth(rho, case.steps),
                       "predicted_edge": result.edges.get(case.row)}
            if r.get("status") == FAILED:
                row.update({"class": "failed", "why": f"{r['error']} ({r['where']})"})
            else:
                row.update({k: r.get(k) for k in ("class", "growth", "energy_residual", "steps_planned", "steps_done",
                                                   "wall_s", "why")})
            writer.writerow(row)
    return path


SYMBOL = {"stable": "S", "energy-drifting": "E", "divergent": "X", "failed": "!"}


def _fmt(x, digits=3):
    return "-" if x is None else f"{x:.{digits}g}"


def summary_table(result: StabilityMap, agreed: dict) -> list[str]:
    """The edges table: one row per master and coupling, predicted against observed."""
    lines = ["| master | c [N*m/rad] | b [N*m*s/rad] | zeta | predicted edge h*w_n | observed: last stable | "
             "first unstable | observed/predicted |", "|---|---|---|---|---|---|---|---|"]
    for r in agreed["edge_rows"]:
        lines.append(f"| {r['master']} | {r['stiffness']:.4g} | {r['damping']:.3g} | {r['zeta']:.3g} | "
                     f"{_fmt(r['predicted_edge']) if r['predicted_edge'] is not None else 'none <= 100'} | "
                     f"{_fmt(r['last_stable'])} | {_fmt(r['first_unstable']) if r['first_unstable'] else 'none'} | "
                     f"{_fmt(r['ratio'])} |")
    return lines


def _write_markdown(path: Path, result: StabilityMap, agreed: dict) -> Path:
    plan, model = result.plan, result.model
    lines = [f"# Stability map: {result.scene.name}", "",
             f"Linearised two-inertia model: I1 = {model.drive_inertia:g}, I2 = {model.driven_inertia:g} kg*m^2, "
             f"K1 = {model.engine_slope:g} N*m*s/rad, U12 = 1 (harness/stability.py states the linearisation). "
             f"Scene coupling: c = {model.stiffness:g} N*m/rad, b = {model.damping:g} N*m*s/rad: "
             f"omega_n = {model.omega_n:.4g} rad/s, zeta = {model.zeta:.3g}."
             + (f"  Measured, not read from the scene: {model.uncertainty()}." if model.measured else ""), "",
             f"Sweep: c in {', '.join(f'{c:.4g}' for c in plan.stiffnesses)} N*m/rad; b in "
             f"{', '.join(f'{b:.3g}' for b in plan.dampings)} N*m*s/rad; h*omega_n in "
             f"{', '.join(f'{x:g}' for x in plan.h_omegas)}" + (" plus 0.9 and 1.1 (where growth is slow: up to 2) times each predicted edge" if plan.refine else "")
             + f"; masters {', '.join(plan.masters)}.  Each case runs max({plan.min_steps}, {plan.periods:g} periods) "
             f"steps (at most {plan.max_steps}).  {len(result.results)} cases: " + _counts(result)
             + f" ({result.reused} reused from the case log; {result.wall_s:.0f} s).", "",
             _classes_text(result) + "  Compared with the prediction, a case is *unstable* when divergent or growing "
             f"(> {GROWTH_DRIFT:g}x); the predicted edge is where the spectral radius of the master's one-step map "
             "crosses 1.", ""]
    lines += ["## Agreement", ""]
    if agreed["explicit_rows"]:
        low, high = agreed["explicit_ratio_range"]
        lines.append(f"Explicit masters ({', '.join(m for m in EXPLICIT if m in plan.masters)}): the predicted edge "
                     f"lies between the last observed stable and the first observed unstable h*omega_n in "
                     f"**{agreed['explicit_bracketed']} of {agreed['explicit_rows']}** (master, c, b) rows with both "
                     f"observed; observed edge (geometric mean of the bracket) / predicted: median "
                     f"{agreed['explicit_ratio_median']:.3g}, range {low:.3g} ... {high:.3g}.  The brackets leave out "
                     f"the {agreed['inconclusive']} inconclusive runs: spectral radius above 1 but a predicted growth "
                     f"over the run below {GROWTH_DRIFT:g}x, which no run of that length can show.")
    if agreed["rate_ratio_median"] is not None:
        low, high = agreed["rate_ratio_range"]
        lines.append("")
        lines.append(f"Growth rates, in the {len(agreed['rates'])} cases that grew measurably (> {GROWTH_DRIFT:g}x) "
                     "and ran to the end: the observed growth per step, ln(growth) / (3/4 steps), over the predicted "
                     f"ln(spectral radius): median {agreed['rate_ratio_median']:.3g}, range {low:.3g} ... {high:.3g}.")
    lines.append("")
    lines.append("Case by case, predicted to grow visibly (spectral radius^(3/4 steps) > "
                 f"{GROWTH_DRIFT:g}) against observed unstable:")
    lines.append("")
    lines.append("| master | cases | agree |")
    lines.append("|---|---|---|")
    for m in plan.masters:
        s = agreed["by_master"].get(m)
        if s:
            lines.append(f"| {m} | {s['cases']} | {s['agree']} ({100 * s['agree'] / s['cases']:.0f} %) |")
    lines.append("")
    implicit = [m for m in plan.masters if m not in EXPLICIT]
    for m in implicit:
        bad = [(c, r) for c, r in result.results.items() if c.master == m and r.get("status") != FAILED and unstable(r)]
        edges = sorted({e for (mm, _, _), e in result.edges.items() if mm == m and e is not None})
        predicted = (f"predicted edge (its iteration stops converging) at h*omega_n = "
                     f"{', '.join(f'{e:.3g}' for e in edges)}" if edges else "predicted stable at every swept step")
        if bad:
            where = ", ".join(f"c={c.stiffness:.3g} b={c.damping:.3g} x={c.h_omega:g}" for c, _ in sorted(
                bad, key=lambda item: (item[0].stiffness, item[0].damping, item[0].h_omega))[:8])
            lines.append(f"- {m}: {predicted}; observed unstable in {len(bad)} cases ({where}"
                         + (", ..." if len(bad) > 8 else "") + ")")
        else:
            lines.append(f"- {m}: {predicted}; observed stable (not growing) in every swept case")
    if agreed["mismatches"]:
        lines += ["", "Cases where prediction and observation differ:", "",
                  "| master | c | b | h*omega_n | steps | predicted rho | predicted growth | observed | growth | "
                  "h*omega_n / predicted edge |",
                  "|---|---|---|---|---|---|---|---|---|---|"]
        for mm in sorted(agreed["mismatches"], key=lambda m: (m["case"].master, m["case"].stiffness,
                                                               -m["case"].damping, m["case"].h_omega)):
            c = mm["case"]
            lines.append(f"| {c.master} | {c.stiffness:.4g} | {c.damping:.3g} | {c.h_omega:g} | {c.steps} | "
                         f"{mm['rho']:.6g} | {_fmt(mm['predicted_growth'])} | {mm['observed']} | {_fmt(mm['growth'])} | "
                         f"{_fmt(mm['x_over_edge'])} |")
    lines += ["", "## Edges", ""] + summary_table(result, agreed)
    lines += ["", "## Cases", "",
              "S stable, E energy-drifting, X divergent, ! failed (the case raised); columns h*omega_n "
              "(refinement points in stability.csv).", ""]
    xs = plan.h_omegas
    at = {(*case.row, case.h_omega): r for case, r in result.results.items()}
    lines.append("| master | c | b | zeta | " + " | ".join(f"{x:g}" for x in xs) + " |")
    lines.append("|---|---|---|---|" + "---|" * len(xs))
    for m in plan.masters:
        for c in plan.stiffnesses:
            for b in plan.dampings:
                cells = []
                for x in xs:
                    r = at.get((m, c, b, x))
                    cells.append(_symbol(r))
                zeta = result.model.with_coupling(c, b).zeta
                lines.append(f"| {m} | {c:.4g} | {b:.3g} | {zeta:.3g} | " + " | ".join(cells) + " |")
    path.write_text("\n".join(lines + _failed_lines(result)) + "\n")
    return path


def _symbol(r: dict | None) -> str:
    """A case's letter in the markdown's class matrix (blank: not run)."""
    return " " if r is None else SYMBOL["failed" if r.get("status") == FAILED else r["class"]]


def _failed_lines(result: StabilityMap) -> list[str]:
    """The markdown's list of the cases that failed (raised, or their run could not start)."""
    failed = [(c, r) for c, r in result.results.items() if r.get("status") == FAILED]
    if not failed:
        return []
    return ["", "## Cases that raised or could not start", ""] + [f"- {c.key}: {r['error']} ({r['where']})"
                                                                  for c, r in failed]


def _classes_text(result: StabilityMap) -> str:
    """The criteria of the classes, for the markdown."""
    return ("Classes: **divergent** - the run failed (non-finite value, an FMU refused a value, the coupling "
            f"iteration did not converge) or the amplitude of the coupling torque "
            f"{metrics.signals(result.scene)['tau2']} grew > {GROWTH_DIVERGENT:g}x "
            "from the first quarter of the run to the last; **energy-drifting** - amplitude grew > "
            f"{GROWTH_DRIFT:g}x, or the energy residual exceeds {100 * ENERGY_DRIFT:g} % of the engine's work; "
            "**stable** - neither.")


def _counts(result: StabilityMap) -> str:
    counts = {}
    for r in result.results.values():
        key = "failed" if r.get("status") == FAILED else r["class"]
        counts[key] = counts.get(key, 0) + 1
    return ", ".join(f"{counts[k]} {k}" for k in (*STATUSES, "failed") if k in counts)


def _write_observed_markdown(path: Path, result: StabilityMap, agreed: dict) -> Path:
    """stability.md of a map without prediction: why first, then what the runs showed."""
    plan = result.plan
    lines = [f"# Stability map: {result.scene.name} (observed runs only)", "", f"**{result.no_prediction}**", "",
             f"Sweep: c in {', '.join(f'{c:.4g}' for c in plan.stiffnesses)} N*m/rad; b in "
             f"{', '.join(f'{b:.3g}' for b in plan.dampings)} N*m*s/rad; steps: the scene's h = {plan.scene_step:g} s "
             f"times {', '.join(f'{r:g}' for r in plan.step_ratios)}, scaled by sqrt({plan.scene_stiffness:.4g} / c) "
             "(the coupling mode's frequency goes as sqrt(c): each stiffness's row covers the same range of "
             f"h*omega_n, whatever the inertias); masters {', '.join(plan.masters)}.  Each case runs as many coupling "
             f"periods as the scene's own run ({plan.scene_steps} steps at ratio 1), at least {plan.min_steps} and at "
             f"most {plan.max_steps} steps.  {len(result.results)} cases: {_counts(result)} ({result.reused} reused "
             f"from the case log; {result.wall_s:.0f} s).", "",
             _classes_text(result) + "  A case is *unstable* when divergent or growing "
             f"(> {GROWTH_DRIFT:g}x).", "",
             "## Advice from the observed runs only", "",
             "Not predicted: the largest step each master was seen stable at, below its first unstable case; a step "
             "between two swept ones, or a longer run, may differ.", ""]
    lines += [f"- {line}" for line in agreed["advice"]]
    lines += ["", "## Edges", "",
              "| master | c [N*m/rad] | b [N*m*s/rad] | predicted edge | observed: last stable h [s] | "
              "first unstable h [s] | S/E/X/! |", "|---|---|---|---|---|---|---|"]
    for r in agreed["observed_rows"]:
        classes = "/".join(str(r["classes"].get(k, 0)) for k in (*STATUSES, FAILED))
        lines.append(f"| {r['master']} | {r['stiffness']:.4g} | {r['damping']:.3g} | {NOT_PREDICTED} | "
                     f"{_fmt(r['last_stable_step'])} | "
                     f"{_fmt(r['first_unstable_step']) if r['first_unstable_step'] else 'none'} | {classes} |")
    lines += ["", "## Cases", "",
              "S stable, E energy-drifting, X divergent, ! failed (the case raised, or its run could not start); "
              "columns: the step's ratio to "
              "the scene's, at the scene's stiffness (the step of each case in stability.csv).", ""]
    ratios = plan.step_ratios
    lines.append("| master | c | b | h [s] | " + " | ".join(f"{r:g}" for r in ratios) + " |")
    lines.append("|---|---|---|---|" + "---|" * len(ratios))
    for m in plan.masters:
        for c in plan.stiffnesses:
            for b in plan.dampings:
                row = plan.observed_cases(m, c, b)
                cells = []
                for case in row:
                    r = result.results.get(case)
                    cells.append(_symbol(r))
                lines.append(f"| {m} | {c:.4g} | {b:.3g} | {row[0].step:.3g} ... {row[-1].step:.3g} | "
                             + " | ".join(cells) + " |")
    path.write_text("\n".join(lines + _failed_lines(result)) + "\n")
    return path


COLOURS = {"stable": "#2e7d32", "energy-drifting": "#f9a825", "divergent": "#c62828", "failed": "#616161"}


def edge_curves(result: StabilityMap, master: str, points: int = 9, fmu_dir: Path = FMUS) -> list:
    """Predicted edge against zeta for each swept stiffness (damping from 0 to the
    largest swept): ``[(c, zetas, edges)]``."""
    curves = []
    b_max = max(result.plan.dampings) or 1.0
    for c in result.plan.stiffnesses:
        zetas, edges = [], []
        for b in np.linspace(0.0, b_max, points):
            model = result.model.with_coupling(c, b)
            edge = stability.stability_edge(model, master, fmu_dir)
            if edge is not None:
                zetas.append(model.zeta)
                edges.append(edge)
        if edges:
            curves.append((c, zetas, edges))
    return curves


def legend_classes(statuses) -> list[str]:
    """The classes a map's legend names: those its cases hold, in ``COLOURS``' order (no
    "failed" entry when nothing failed)."""
    return [k for k in COLOURS if k in set(statuses)]


def _panels(masters: list, panel_height: float, margin: float):
    """``(pyplot, figure, axes)``: one panel a master, three to a row (no blank panels
    beside one), sharing their axes."""
    from harness.formats import plotting

    plt = plotting.pyplot()
    ncols = min(3, len(masters))
    nrows = math.ceil(len(masters) / ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(max(5.2 * ncols, 7.5), panel_height * nrows + margin),
                             squeeze=False, sharex=True, sharey=True, layout="constrained")
    return plt, fig, axes


def _cases_on(ax, result: StabilityMap, master: str, where) -> set:
    """Each case of ``master`` as a square of its class's colour at ``where(case)``; the
    classes drawn."""
    statuses = set()
    for case, r in result.results.items():
        if case.master != master:
            continue
        status = "failed" if r.get("status") == FAILED else r["class"]
        statuses.add(status)
        ax.scatter(*where(case), s=70, marker="s", color=COLOURS[status], edgecolors="none", alpha=0.85)
    return statuses


def _plot(path: Path, result: StabilityMap) -> Path:
    from matplotlib.lines import Line2D

    from harness.formats import plotting

    masters = result.plan.masters
    plt, fig, axes = _panels(masters, 4.2, 0.6)
    ncols = axes.shape[1]
    statuses = set()
    zetas = [result.model.with_coupling(c.stiffness, c.damping).zeta for c in result.results]
    for ax, master in zip(axes.flat, masters):
        statuses |= _cases_on(ax, result, master, lambda case: (
            case.h_omega, result.model.with_coupling(case.stiffness, case.damping).zeta))
        for (m, c, b), edge in result.edges.items():
            if m == master and edge is not None:
                ax.plot(edge, result.model.with_coupling(c, b).zeta, marker="|", color="k", ms=16, mew=1.6)
        for c, zs, es in edge_curves(result, master):
            ax.plot(es, zs, "k-", lw=0.9, alpha=0.7)
            # above the curve's top end, clear of the case markers on its row
            ax.annotate(f"c={c:.0e}" if c >= 1e4 else f"c={c:.4g}", (es[-1], zs[-1]), xytext=(0, 9),
                        textcoords="offset points", ha="center", va="bottom", fontsize=7,
                        bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.85})
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(master, fontsize=10)
        ax.grid(True, which="both", alpha=0.2)
    for ax in axes[-1]:
        ax.set_xlabel("h * omega_n")
    for ax in axes[:, 0]:
        ax.set_ylabel("damping ratio zeta")
    for ax in list(axes.flat)[len(masters):]:
        ax.axis("off")
    if zetas:
        axes[0, 0].set_ylim(min(zetas) / 1.5, max(zetas) * 1.5)
    for ax in list(axes.flat)[:len(masters)]:
        plotting.log_ticks(ax.xaxis)
        plotting.log_ticks(ax.yaxis)
    handles = [Line2D([], [], marker="s", ls="", color=COLOURS[k], label=k) for k in legend_classes(statuses)]
    handles.append(Line2D([], [], color="k", lw=0.9, marker="|", ms=10,
                          label="predicted edge (|: swept coupling; line: per stiffness, damping varied)"))
    fig.legend(handles=handles, loc="outside lower center", ncol=len(handles) if ncols > 1 else 2, fontsize=8,
               frameon=False)
    fig.suptitle(f"Stability map: {result.scene.name} (observed classes; lines: linear analysis)", fontsize=11)
    plotting.save_png(fig, path, dpi=110)
    plt.close(fig)
    return path


def _plot_observed(path: Path, result: StabilityMap) -> Path:
    """stability_map.png of a map without prediction: a panel a master, the observed class
    of each case over its step and its coupling, and why there are no edges."""
    import textwrap

    from matplotlib.lines import Line2D

    from harness.formats import plotting

    masters = result.plan.masters
    rows = [(c, b) for c in result.plan.stiffnesses for b in result.plan.dampings]
    plt, fig, axes = _panels(masters, 0.3 * len(rows) + 2.6, 1.2)
    statuses = set()
    for ax, master in zip(axes.flat, masters):
        statuses |= _cases_on(ax, result, master, lambda case: (case.step, rows.index(case.row[1:])))
        ax.set_xscale("log")
        ax.set_title(master, fontsize=10)
        ax.grid(True, which="both", alpha=0.2)
    for ax in axes[-1]:
        ax.set_xlabel("communication step h [s]")
    for ax in axes[:, 0]:
        ax.set_yticks(range(len(rows)), [f"c={c:.4g}, b={b:.3g}" for c, b in rows], fontsize=8)
        ax.set_ylim(-0.6, len(rows) - 0.4)
    for ax in list(axes.flat)[len(masters):]:
        ax.axis("off")
    for ax in list(axes.flat)[:len(masters)]:
        plotting.log_ticks(ax.xaxis, wide=2.0)       # steps in s are long labels: 1, 2, 5 crowd over 3 decades
    handles = [Line2D([], [], marker="s", ls="", color=COLOURS[k], label=k) for k in legend_classes(statuses)]
    fig.legend(handles=handles, loc="outside lower center", ncol=max(1, len(handles)), fontsize=8, frameon=False)
    fig.suptitle(f"Stability map: {result.scene.name} (observed classes only; edges not predicted)\n"
                 + textwrap.fill(result.no_prediction, 110), fontsize=9)
    plotting.save_png(fig, path, dpi=110)
    plt.close(fig)
    return path
