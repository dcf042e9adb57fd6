"""What the api returns: a run (``Run``), a verdict (``Validation``), a reference trace
checked (``ReferenceCheck``) and a benchmark (``BenchResult``), each with a ``repr``
that says in a screen how it came out."""
from __future__ import annotations

from dataclasses import dataclass as _dataclass, field as _field
from pathlib import Path
from typing import Iterable

import numpy as _np

from harness.api import inputs as _inputs
from harness.api.inputs import Signals
from harness.description import scene as scene_files


#: what a completed run whose energy balance fails is called (``Run.untrusted``, ``lever run``)
UNTRUSTED = "NOT TO BE TRUSTED"


@_dataclass
class Run:
    """One run: the result (times, traces, failure), the reference and the summary (what
    summary.json holds), and where the files went (``out``; None: none written).
    ``repr(run)`` (a notebook cell's output) says in a few lines how it ended and its
    main figures."""
    #: what the engine returned (``harness.engine.run.RunResult``)
    result: object
    #: the monolithic reference solution (None: not solved, ``reference=False``)
    reference: object | None
    #: what summary.json holds: statistics, error against the reference, energy balance
    #: (signals by their full names; a short one is taken where unambiguous)
    summary: dict
    #: where the files went (None: none written)
    out: Path | None = None
    #: the warnings and notes said about this run (also sent to ``notify``)
    notes: list[str] = _field(default_factory=list)
    #: the step latency's summary (``latency=True``; the tables are in ``out``)
    latency: list[str] | None = None

    def __post_init__(self):
        aliases = _driveline_aliases(self.result.scene)
        if isinstance(getattr(self.result, "traces", None), dict) and not isinstance(self.result.traces, Signals):
            self.result.traces = Signals(self.result.traces, aliases)
        for key in ("statistics", "error_vs_reference"):
            if isinstance(self.summary.get(key), dict):
                self.summary[key] = Signals(self.summary[key], aliases)

    @property
    def scene(self) -> scene_files.Scene:
        """The scene as run (with the overrides)."""
        return self.result.scene

    @property
    def times(self) -> _np.ndarray:
        """The communication points [s], one per row of the traces."""
        return self.result.times

    @property
    def traces(self) -> Signals:
        """The recorded signals by their names, ``component.variable`` (``coupling.tau2``):
        one array a signal, a value per time; a short name (``tau2``) is taken where only
        one signal ends with it."""
        return self.result.traces

    @property
    def ok(self) -> bool:
        """Whether the run reached its stop time without a failure and is to be trusted (an
        energy residual above 5 % of the work in says the traces are not the system's motion:
        ``untrusted`` says why, ``lever run`` prints NOT TO BE TRUSTED and exits 3)."""
        return self.result.ok and not self.untrusted

    @property
    def untrusted(self) -> str | None:
        """Why a completed run is not to be trusted, in a sentence (None: nothing says so)."""
        return self.summary.get("untrusted")

    @property
    def failure(self) -> str | None:
        """Why the run failed or was interrupted, in a sentence (None: it did not)."""
        return self.result.failure

    @property
    def outcome(self) -> str:
        """How the run ended: "ok"; "untrusted" (it reached its stop time, but its energy
        residual says the traces are not the system's motion: ``untrusted``); "interrupted"
        (Ctrl-C: what was computed is kept, marked so); "refused" (the FMUs refused the
        scene's values before the first step: the input is at fault, not the run); "failed"
        (part-way: the traces before the failure are kept)."""
        if self.result.interrupted:
            return "interrupted"
        if self.result.ok:
            return "untrusted" if self.untrusted else "ok"
        return "refused" if self.result.failure_stage == "initialisation" else "failed"

    def array(self, names: Iterable[str] | str | None = None) -> _np.ndarray:
        """The traces as one numpy structured array, ``time`` first (as fmpy's
        ``simulate_fmu`` returns): ``a["time"]``, ``a["coupling.tau2"]``; ``names``: only
        these signals (full or unambiguous short names; the fields are the full names)."""
        chosen = list(self.traces) if names is None else [self.traces.full_name(n)
                                                           for n in _inputs.names(names, "names")]
        return _np.rec.fromarrays([_np.asarray(self.times, float)]
                                  + [_np.asarray(self.traces[n], float) for n in chosen], names=["time"] + chosen)

    def __repr__(self) -> str:
        s = self.summary
        span = f"{self.times[0]:g} ... {self.times[-1]:g} s" if len(self.times) else "no rows"
        head = (f"Run({s.get('scene')}: {self.outcome.upper() if self.outcome != 'ok' else 'ok'}, master "
                f"{s.get('master')}, step {s.get('step_s', 0):g} s, {span}, {len(self.times)} rows x "
                f"{len(self.traces)} signals, wall time {s.get('wall_time_s') or 0:.2f} s")
        lines = [head]
        if self.failure:
            lines.append(f"  failure: {self.failure}")
        if self.untrusted:
            lines.append(f"  {UNTRUSTED}: {self.untrusted}")
        errors = s.get("error_vs_reference") or {}
        for name, stats in list((s.get("statistics") or {}).items())[:6]:
            if stats:
                error = errors.get(name)
                lines.append(f"  {name:16s} mean {stats['mean']:11.5g}  amplitude {stats['amplitude']:10.4g}"
                             + (f"  error vs reference {100 * error['rms_relative']:.2g} % RMS" if error else ""))
        if (balance := s.get("energy_balance")):
            lines.append(f"  energy residual {100 * balance['residual_relative']:.2g} % of the work in")
        tail = [f"{len(self.notes)} note{'s' if len(self.notes) != 1 else ''} in .notes"] if self.notes else []
        tail.append(f"files in {self.out}" if self.out else "no files written")
        lines.append("  " + "; ".join(tail) + ")")
        return "\n".join(lines)


def _driveline_aliases(scene) -> dict[str, str]:
    """A driveline's short names (``w1``, ``tau2``, ...) -> its signals; none for other scenes."""
    from harness.description import scene_kinds
    from harness.judges import metrics

    try:
        return metrics.signals(scene)
    except (scene_kinds.NotADriveline, KeyError, ValueError, AttributeError):
        return {}


@_dataclass(repr=False)
class Validation:
    """The verdict on one NAME (``lever validate NAME``): per signal (``findings.signals``),
    the problems that fail it (``findings.problems``), the span judged, and the result that
    was judged.  ``repr()`` says PASS or FAIL, the failing signals and the problems in a
    few lines."""
    #: what was judged: a reference's name or an FMU file
    name: str
    #: the verdict in detail (``harness.judges.validation.Findings``)
    findings: object
    #: the tolerance band per signal
    bands: dict
    #: the result judged (``.times``, ``.traces``, ``.how``)
    result: object
    #: the committed reference traces
    reference: object
    #: where validation.json and the plots went (None: none written)
    out: Path | None = None

    @property
    def passed(self) -> bool:
        """Whether every signal passes and nothing fails the whole result."""
        return self.findings.passed

    def __repr__(self) -> str:
        f = self.findings
        verdict = "PASS" if f.passed else "FAIL"
        span = f", judged {f.describe_span()}" if f.span else ""
        failed = [s for s in f.signals if not s.passed]
        lines = [f"Validation({self.name}: {verdict}{span}; {f.counted()}"]
        shown = [f"  FAIL {s.name}: {f.failure_line(s)}" for s in failed]
        lines += shown[:8]
        if len(failed) > 8:
            lines.append(f"  ... {len(failed) - 8} more failing signals in .findings.signals")
        lines += [f"  problem: {p}" for p in f.problems[:4]]
        if len(f.problems) > 4:
            lines.append(f"  ... {len(f.problems) - 4} more problems in .findings.problems")
        lines[-1] += f"; files in {self.out})" if self.out else ")"
        return "\n".join(lines)


@_dataclass
class ReferenceCheck:
    """One committed reference trace against what the project computes now."""
    name: str
    #: "current", "stale" (not current, left), "updated" (not current, rewritten) or
    #: "unavailable" (no reference can be computed: ``reason``)
    status: str
    problems: list[str] = _field(default_factory=list)
    #: per signal: ``signal``, ``max_change``, ``relative``, ``at_time``
    changes: list = _field(default_factory=list)
    reason: str = ""
    folder: Path | None = None


class BenchResult(dict):
    """What ``bench`` returns: the benchmark's result as a dict (``["claims"]``, ``["cases"]``,
    ``["summary"]``, ``["written"]``, ...); ``repr()`` says in a screen how many cases ran
    and failed, the claims' lines ``lever bench`` prints and where the files are."""

    def __repr__(self) -> str:
        cases = self.get("cases") or []
        failed = [c for c in cases if getattr(c, "failure", None)]
        lines = [f"BenchResult({self.get('scene')}: {len(cases) - len(failed)} of {len(cases)} cases ran"
                 + (f", {len(failed)} FAILED ({', '.join(c.label for c in failed[:4])}"
                    f"{', ...' if len(failed) > 4 else ''})" if failed else ", none failed")]
        summary = list(self.get("summary") or [])
        lines += summary[:14] + ([f"  ... {len(summary) - 14} more lines in ['summary']"] if len(summary) > 14 else [])
        written = self.get("written") or []
        lines.append(f"  written: {Path(written[0]).parent}/ ({', '.join(Path(w).name for w in written)}))"
                     if written else "  nothing written)")
        return "\n".join(lines)


#: the longest ``repr`` a value the api returns may have: a notebook cell's output on a screen
REPR_LIMIT = 3000


def brief(value, width: int = 70) -> str:
    """``value`` in a few words for a repr: a number or a short text as is, a collection by
    how many it holds, anything longer cut with an ellipsis."""
    text = str(value) if isinstance(value, Path) else repr(value)
    if len(text) <= width:
        return text
    if isinstance(value, dict):
        keys = ", ".join(map(str, list(value)[:4]))
        return f"{len(value)} entries ({keys}{', ...' if len(value) > 4 else ''})"
    if isinstance(value, (list, tuple, set)):
        return f"{len(value)} items"
    if isinstance(value, str) and "\n" in value:
        return f"a text of {value.count(chr(10)) + 1} lines"
    return text[:width - 3] + "..."


class Returned(dict):
    """What a study returns, as a dict (``result["agreement"]``, ...); its ``repr()`` says in
    a few lines what it holds, each key with its value in brief, not the whole of it."""

    def __repr__(self) -> str:
        lines = [f"{type(self).__name__}("] + [f"  {key!r}: {brief(value)}" for key, value in self.items()]
        return "\n".join(lines) + ")"


class ReturnedTuple(tuple):
    """What a command returns as a pair or triple (``text, path = api.study(...)``, ``outcomes,
    summary = api.bad_inputs()``): a tuple whose ``repr()`` gives each item in brief."""

    def __repr__(self) -> str:
        return f"{type(self).__name__}(" + ", ".join(brief(item) for item in self) + ")"


class StabilityMapResult(Returned):
    """What ``stability_map`` returns: ``["result"]`` (every case and its class,
    ``harness.studies.stabilitymap.StabilityMap``), ``["agreement"]`` (the prediction against
    what was observed), ``["written"]`` (the files); ``repr()`` says what ``lever stability``
    prints."""

    def __repr__(self) -> str:
        result, agreed = self.get("result"), self.get("agreement") or {}
        cases = len(getattr(result, "results", {}) or {})
        scene = getattr(getattr(result, "scene", None), "name", "?")
        lines = [f"StabilityMapResult({scene}: {cases} cases, {getattr(result, 'reused', 0)} of them from the case log"]
        if agreed.get("no_prediction"):
            lines.append(f"  {agreed['no_prediction']}")
            lines += [f"  {line}" for line in agreed.get("advice", [])[:12]]
        if agreed.get("explicit_rows"):
            lines.append(f"  explicit masters: predicted edge inside the observed bracket in "
                         f"{agreed['explicit_bracketed']} of {agreed['explicit_rows']} rows; observed/predicted "
                         f"median {agreed['explicit_ratio_median']:.3g}")
        by_master = list((agreed.get("by_master") or {}).items())
        lines += [f"  {m:24s} prediction agrees in {s['agree']}/{s['cases']} cases" for m, s in by_master[:12]]
        if len(by_master) > 12:
            lines.append(f"  ... {len(by_master) - 12} more masters in ['agreement']['by_master']")
        if agreed.get("mismatches"):
            lines.append(f"  {len(agreed['mismatches'])} cases disagree with the prediction: ['agreement']['mismatches']")
        written = self.get("written") or []
        lines.append(f"  written: {Path(written[0]).parent}/ ({', '.join(Path(w).name for w in written)}))"
                     if written else "  nothing written)")
        return "\n".join(lines)
