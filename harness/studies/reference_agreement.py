"""Does the reference made from the FMUs (``harness.judges.fmu_reference``) measure a run's
error as the monolithic reference does?  On scenes where both exist, every master at two
steps (the adaptive and Model Exchange ones at two tolerances) is judged against the
monolithic reference, the converged Model Exchange one and the extrapolated co-simulation
one; the table gives each error figure (the largest relative RMS error of the scene's
judged signals) and the ratio to the monolithic one.  A row is judged where the error is
above ``MARGIN`` times both made references' own error estimates: there the ratio must lie
within ``AGREEMENT``.  ``lever study reference-agreement`` prints the table
(docs/how-to/measure-your-own-error.md quotes it)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from harness.description import plan as plans
from harness.description import scene as scenes
from harness.engine import masters as master_family
from harness.engine.run import simulate
from harness.engine.system import CO_SIMULATION
from harness.judges import fmu_reference
from harness.judges.solution import ReferenceUnavailable
from harness.paths import FMUS

SCENES = ("kavz685", "kavz685_stiff", "freewheel_rectifier")
#: the span the study runs (a made reference of a 10 s scene at a quarter of a 50 us step is
#: millions of steps): the first STOP seconds of each scene
STOP = 1.0
#: the two errors agree when their ratio lies within [1 / AGREEMENT, AGREEMENT] ...
AGREEMENT = 1.5
#: ... where the error is above MARGIN times the made reference's own error estimate
MARGIN = 100.0
MADE = ("model-exchange", "extrapolated")
#: (tolerance, tolerance) of the masters that take one instead of a step
TOLERANCES = (1e-3, 1e-5)


@dataclass
class Row:
    scene: str
    master: str
    setting: str
    #: source -> error figure (None: no reference of that source, or the run failed)
    figures: dict = field(default_factory=dict)
    #: source -> the made reference's own error figure
    own: dict = field(default_factory=dict)
    failure: str | None = None

    def ratio(self, source: str) -> float | None:
        a, b = self.figures.get(source), self.figures.get("monolithic")
        return a / b if a is not None and b else None

    def verdict(self, source: str) -> str:
        ratio, own = self.ratio(source), self.own.get(source)
        if ratio is None or own is None:
            return "-"
        if self.figures["monolithic"] <= MARGIN * own:
            return "not judged"
        return "agrees" if 1 / AGREEMENT <= ratio <= AGREEMENT else "DISAGREES"


def settings(plan: plans.Plan, master: str) -> list[tuple[str, float, dict]]:
    """A master's two settings on a scene: its step and twice it, or two tolerances."""
    cls = master_family.master_class(master)
    h = plan.experiment.step
    if cls.adaptive or cls.interface != CO_SIMULATION:
        return [(f"tol {tol:g}", h, {"tolerance": tol}) for tol in TOLERANCES]
    return [(f"h {step:g} s", step, {}) for step in (2 * h, h)]


def rows_of(scene_name: str, stop: float = STOP, masters=None, fmu_dir=FMUS) -> tuple[list[Row], dict]:
    """Every master's rows on ``scene_name`` cut to ``stop`` s, and a description of each made
    reference (source -> its quality, or why there is none)."""
    spec = scenes.load(scene_name)
    if stop is not None and stop < spec.experiment.stop:
        spec = spec.with_overrides([f"experiment.stop={stop}"])
    plan = plans.check(spec, fmu_dir=fmu_dir)
    rows, described = [], {}
    for master in masters or master_family.MASTERS:
        for setting, step, options in settings(plan, master):
            row = Row(spec.name, master, setting)
            rows.append(row)
            result = simulate(plan, master, step, options=options)
            if not result.ok:
                row.failure = result.failure
                continue
            for source in ("monolithic", *MADE):
                try:
                    ref = fmu_reference.reference(plan, result.times, source=source)
                except ReferenceUnavailable as error:
                    described.setdefault(source, f"none: {error}")
                    continue
                judged = fmu_reference.judge(spec, result.times, result.traces, ref)
                row.figures[source] = judged.figure
                if source != "monolithic":
                    row.own[source] = judged.reference_figure
                    described.setdefault(source, fmu_reference.quality(ref, judged.reference_figure))
                else:
                    described.setdefault(source, ref.method)
    return rows, described


def _pct(x):
    return "-" if x is None else f"{100 * x:.3g} %"


def markdown(tables: list[tuple[str, list[Row], dict]], stop: float = STOP) -> str:
    lines = ["# The made references against the monolithic one", "",
             f"Each scene's first {stop:g} s; every master at two steps (two tolerances for those that take one). "
             "Error figure: the largest relative RMS error of the scene's judged signals (the driveline's speeds "
             "and torques, the rectifier's main signals).  Ratio: the error against the made reference over the "
             f"error against the monolithic one; judged where the error is above {MARGIN:g}x the made reference's "
             f"own error estimate, where it must lie within {AGREEMENT:g}x.", ""]
    verdicts = []
    for scene, rows, described in tables:
        lines += [f"## {scene}", ""]
        for source in ("monolithic", *MADE):
            lines.append(f"* {fmu_reference.SOURCES[source]}: {described.get(source, 'not made (no run to judge)')}")
        lines += ["", "| master | setting | vs monolithic | vs Model Exchange | ratio | verdict | vs extrapolated | "
                  "ratio | verdict |", "|---|---|---|---|---|---|---|---|---|"]
        for r in rows:
            if r.failure:
                lines.append(f"| {r.master} | {r.setting} | run failed: {r.failure[:120]} | | | | | | |")
                continue
            cells = [_pct(r.figures.get("monolithic"))]
            for source in MADE:
                ratio = r.ratio(source)
                verdicts.append(r.verdict(source))
                cells += [_pct(r.figures.get(source)), "-" if ratio is None else f"{ratio:.4f}", r.verdict(source)]
            lines.append(f"| {r.master} | {r.setting} | " + " | ".join(cells) + " |")
        lines.append("")
    lines.append(f"Judged rows: {verdicts.count('agrees')} agree, {verdicts.count('DISAGREES')} disagree; "
                 f"{verdicts.count('not judged')} not judged (error within {MARGIN:g}x the reference's own).")
    return "\n".join(lines)


def study(names=SCENES, stop: float = STOP, masters=None) -> str:
    return markdown([(name, *rows_of(name, stop, masters)) for name in names], stop)


def agreement(rows: list[Row]) -> list[str]:
    """The rows that disagree, as ``"scene master setting source: ratio"`` (empty: all agree)."""
    return [f"{r.scene} {r.master} {r.setting} {s}: {r.ratio(s):.3f}" for r in rows for s in MADE
            if r.verdict(s) == "DISAGREES"]


if __name__ == "__main__":
    print(study())
