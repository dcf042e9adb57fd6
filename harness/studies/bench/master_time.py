"""The master's own time, measured directly: runs of a case with every FMI call timed
(``simulate(wrap_calls=...)``), the time outside the calls being the master's - its
arithmetic, its Python, the recording and the guard.

A difference of two noisy medians (a run's time less the calls priced in other loops) can
come out at 2 % or 47 % for the same case; here the calls of the very run are timed, and
what the timing itself adds is taken off by calibration:

* a timed call's interval holds the call and the timer's own latency ``inside`` (an empty
  interval, measured);
* the rest of the wrapper's cost, ``outside``, falls outside the intervals, in what would
  otherwise count as the master's: a loop of wrapped calls of a cheap callee, less the time
  in their intervals and less the loop's own;
* the run tells an observer of each step (to take the stepping loop's calls alone): its
  no-op call's cost is taken off too.

So, each step, ``master = its time - its intervals - calls * outside - observer`` and
``in_calls = its intervals - calls * inside``.  A step many times the median's was
interrupted (another process's turn: a per-call processor clock would cost microseconds a
read) and is set aside; of several runs the least master time a step (what is left of
interruptions only adds).  ``trusted`` says whether the figure
can be quoted, and where not, why: runs that disagree, or a correction as large as what
it corrects."""
from __future__ import annotations

import statistics as stats
import time as clock
from dataclasses import dataclass, field
from pathlib import Path

from harness.engine import masters as master_family
from harness.engine.component import STATE_CALLS
from harness.engine.run import simulate
from harness.engine.system import CO_SIMULATION
from harness.paths import FMUS

#: the largest spread (median over least) of the runs' master times a quoted figure allows
MAX_SPREAD = 0.25
#: the largest share of the raw master time the timing's correction may take
MAX_CORRECTION = 0.5
#: the largest share of steps set aside as interrupted (``kept_steps``) a quoted figure allows
#: (on a busy machine the share grows with the step's length: 6-8 % of 200 us steps and
#: 11-14 % of 400 us ones at a load of 12 on 2 processors)
MAX_DROPPED = 0.2
#: a step more than this many times the median step's time was interrupted
OUTLIER = 4.0
#: how many arguments each kind of call takes (the wrapper matches it: no ``*args``)
ARITY = {"get": 4, "set": 4, "step": 4, "state": 2}
#: the kind each wrapped call is counted as (``Component.wrap_calls`` names the three state calls)
COUNTED_AS = {"get": "get", "set": "set", "step": "step", **dict.fromkeys(STATE_CALLS, "state")}


class CallTimer:
    """Wraps FMI calls (``wrap(component, kind, function)``, for ``simulate(wrap_calls=...)``)
    so that each call's interval is added to ``spent[component][kind]`` and to ``total``,
    and counted in ``made`` and ``calls``; as the run's observer it marks each step's end
    (``marks``: the time, the intervals so far, the calls so far), so that the stepping
    loop's calls are taken alone and each step's parts are known."""

    def __init__(self, timer=clock.perf_counter):
        self.timer = timer
        self.spent: dict[str, dict[str, list]] = {}
        self.made: dict[str, dict[str, list]] = {}
        self.total, self.calls = [0.0], [0]
        self.marks: list[tuple[float, float, int]] = []
        self.window = None

    def wrap(self, component: str, kind: str, function):
        kind = COUNTED_AS[kind]
        account = self.spent.setdefault(component, {}).setdefault(kind, [0.0])
        count = self.made.setdefault(component, {}).setdefault(kind, [0])
        return _timed(function, self.timer, account, count, self.total, self.calls, ARITY[kind])

    # the run's observer
    def started(self, t):
        for kinds in (*self.spent.values(), *self.made.values()):
            for cell in kinds.values():
                cell[0] = 0
        self.total[0], self.calls[0] = 0.0, 0
        self.window = None
        self.marks = [(self.timer(), 0.0, 0)]

    def stepped(self, n, t):
        self.marks.append((self.timer(), self.total[0], self.calls[0]))

    def ended(self):
        self.window = ({name: {kind: cell[0] for kind, cell in kinds.items()} for name, kinds in self.spent.items()},
                       {name: {kind: cell[0] for kind, cell in kinds.items()} for name, kinds in self.made.items()})


def _timed(function, timer, account: list, count: list, total: list, calls: list, arity: int):
    """``function`` timed; the hot path's calls take four arguments, the state calls two
    (wrapped through the four-argument shape; the calibration times the same shapes)."""
    if arity == 2:
        four = _timed(lambda a, b, c, d: function(a, b), timer, account, count, total, calls, 4)
        return lambda a, b: four(a, b, None, None)

    def timed(a, b, c, d):
        started = timer()
        status = function(a, b, c, d)
        spent = timer() - started
        account[0] += spent
        total[0] += spent
        count[0] += 1
        calls[0] += 1
        return status
    return timed


def _cheap(a, b, c=None, d=None):
    return 0


def calibrate(timer=clock.perf_counter, n: int = 2000, repeats: int = 51) -> dict:
    """What the timing adds, seconds a call (least of ``repeats`` loops of ``n``, short
    loops: on a busy machine most of them run uninterrupted, and the least is one): for each
    arity ``inside``, the timer's latency within an interval (an empty one), and
    ``outside``, the rest of the wrapper's cost - a loop of wrapped calls less the time in
    their intervals and less the loop's own; and ``observer``, the mark a run makes at
    each step."""
    def loop_alone():
        started = timer()
        for _ in range(n):
            pass
        return timer() - started

    found = {}
    for arity in (4, 2):
        account = [0.0]
        wrapped = _timed(_cheap, timer, account, [0], [0.0], [0], arity)
        outside_s = inside_s = empty_loop = float("inf")
        for _ in range(repeats):
            # each least on its own: a difference's least would take the other's noise
            empty_loop = min(empty_loop, loop_alone())
            account[0] = 0.0
            started = timer()
            if arity == 4:
                for _ in range(n):
                    wrapped(None, None, None, None)
            else:
                for _ in range(n):
                    wrapped(None, None)
            outside_s = min(outside_s, timer() - started - account[0])
            empty = [0.0]
            for _ in range(n):
                began = timer()
                empty[0] += timer() - began
            inside_s = min(inside_s, empty[0])
        found[arity] = {"inside": inside_s / n, "outside": max(0.0, (outside_s - empty_loop) / n)}
    observer, bare_s, called_s = CallTimer(timer), float("inf"), float("inf")
    for _ in range(repeats):
        observer.marks = []
        bare_s = min(bare_s, loop_alone())
        started = timer()
        for k in range(n):
            observer.stepped(k, 0.0)
        called_s = min(called_s, timer() - started)
    found["observer"] = max(0.0, (called_s - bare_s) / n)
    return found


@dataclass
class MasterTime:
    """A case's time split, measured directly (``measure``), per run: the master's seconds
    a step ``masters``, the calls' ``in_calls``, the timing's cost taken off
    ``corrections`` and the share of steps ``dropped`` as interrupted; ``calls``
    component -> kind -> count and ``in_call`` component -> kind -> seconds (whole run) of
    the run with the least master time; its ``steps`` and FMI ``fmu_calls``."""
    master: str
    step: float
    tolerance: float | None
    masters: list = field(default_factory=list)
    in_calls: list = field(default_factory=list)
    corrections: list = field(default_factory=list)
    dropped: list = field(default_factory=list)
    calls: dict = field(default_factory=dict)
    in_call: dict = field(default_factory=dict)
    steps: int = 0
    fmu_calls: int = 0
    calibration: dict = field(default_factory=dict)
    failure: str | None = None

    @property
    def best(self) -> int:
        return min(range(len(self.masters)), key=self.masters.__getitem__)

    @property
    def per_step(self) -> float:
        """The master's seconds a step (the least of the runs)."""
        return self.masters[self.best]

    @property
    def share(self) -> float:
        """The master's share of its run's time (the run with the least master time)."""
        k = self.best
        return self.masters[k] / (self.masters[k] + self.in_calls[k])

    @property
    def spread(self) -> float:
        """The runs' median master time over the least, less 1."""
        return stats.median(self.masters) / self.per_step - 1.0

    @property
    def problems(self) -> list[str]:
        """Why the figure cannot be quoted (empty: it can)."""
        if self.failure:
            return [self.failure]
        out = []
        if len(self.masters) < 2:
            out.append("a single run: its spread is unknown")
        if self.per_step <= 0:
            out.append(f"the master's time came out at {1e6 * self.per_step:.2f} us a step, not above zero "
                       "(the timing's correction exceeds what it corrects)")
            return out
        if len(self.masters) >= 2 and self.spread > MAX_SPREAD:
            out.append(f"the runs' master times spread {100 * self.spread:.0f} % (median over least; "
                       f"at most {100 * MAX_SPREAD:.0f} % quoted)")
        k = self.best
        if self.dropped[k] > MAX_DROPPED:
            out.append(f"{100 * self.dropped[k]:.0f} % of the steps were interrupted (at most "
                       f"{100 * MAX_DROPPED:.0f} % set aside)")
        correction = self.corrections[k]
        if correction > MAX_CORRECTION * (self.per_step + correction):
            out.append(f"the timing's own cost taken off ({1e6 * correction:.2f} us a step) is "
                       f"{100 * correction / (self.per_step + correction):.0f} % of the raw master time "
                       f"(at most {100 * MAX_CORRECTION:.0f} % quoted)")
        return out

    @property
    def trusted(self) -> bool:
        return not self.problems

    def summary(self) -> dict:
        """What a benchmark case keeps (plain data): the master's and the calls' seconds a
        step and the master's share (the run with the least master time), the runs' master
        times, their spread and the steps set aside, why the figure cannot be quoted, and
        the calls by component and kind with the seconds spent in them."""
        if self.failure or not self.masters:
            return {"problems": self.problems or ["no timed run"]}
        k = self.best
        return {"master_per_step_s": self.per_step, "in_calls_per_step_s": self.in_calls[k], "share": self.share,
                "runs_master_per_step_s": list(self.masters), "spread": self.spread, "dropped": self.dropped[k],
                "correction_per_step_s": self.corrections[k], "problems": self.problems, "steps": self.steps,
                "calls": self.calls, "in_call_s": self.in_call}


def step_parts(marks: list[tuple[float, float, int]], calibration: dict, state_calls: int = 0):
    """Each step's master and call time from a run's ``marks`` (``CallTimer``), less what
    the timing adds (``calibrate``): ``(masters, in_calls, corrections)`` a step.  The
    calls are taken as four-argument ones; ``state_calls`` of the run's calls were
    two-argument ones (spread evenly over the steps)."""
    four, two, observer = calibration[4], calibration[2], calibration["observer"]
    steps = len(marks) - 1
    extra = (state_calls / steps) * (two["outside"] - four["outside"]) if steps else 0.0
    extra_inside = (state_calls / steps) * (two["inside"] - four["inside"]) if steps else 0.0
    masters, in_calls, corrections = [], [], []
    for (t0, in0, n0), (t1, in1, n1) in zip(marks, marks[1:]):
        calls = n1 - n0
        correction = observer + calls * four["outside"] + extra
        masters.append((t1 - t0) - (in1 - in0) - correction)
        in_calls.append((in1 - in0) - calls * four["inside"] - extra_inside)
        corrections.append(correction)
    return masters, in_calls, corrections


def uninterrupted(totals: list) -> list[int]:
    """The steps not interrupted, of steps that took ``totals`` seconds: those within
    ``OUTLIER`` times the median step's (another process's turn on the processor, a page
    fault or a collection of the garbage lands in a few steps and makes them many times as
    long)."""
    if not totals:
        return []
    limit = OUTLIER * stats.median(totals)
    return [k for k, total in enumerate(totals) if total <= limit]


def kept_steps(masters: list, in_calls: list) -> list[int]:
    """The steps not interrupted (``uninterrupted``), each step's whole time its master's
    and its calls' time."""
    return uninterrupted([m + c for m, c in zip(masters, in_calls)])


def measure(scene, master: str, step: float, options: dict | None = None, fmu_dir: Path = FMUS,
            runs: int = 3, tolerance: float | None = None, calibration: dict | None = None,
            timer=clock.perf_counter) -> MasterTime:
    """``runs`` runs of ``master`` at ``step`` on ``scene`` with every FMI call timed: the
    master's own time a step, directly (see the module).  A Model Exchange master's calls
    are not a co-simulation component's: its ``failure`` says so, and a failed run's."""
    result = MasterTime(master, step, tolerance)
    if master_family.master_class(master).interface != CO_SIMULATION:
        result.failure = f"{master} integrates the FMUs in Model Exchange: its calls are not timed one by one"
        return result
    given = calibration
    for _ in range(runs):
        # calibrated just before each run where not given: the machine's pace drifts (a
        # busy sibling core makes every call half as slow again)
        calibration = given or calibrate(timer)
        timing = CallTimer(timer)
        run = simulate(scene, master, step, fmu_dir, options=options, observer=timing, wrap_calls=timing.wrap)
        if not run.ok:
            result.failure = f"{master} failed in a timed run: {run.failure}"
            return result
        spent, made = timing.window
        state_calls = sum(kinds.get("state", 0) for kinds in made.values())
        masters, in_calls, corrections = step_parts(timing.marks, calibration, state_calls)
        kept = kept_steps(masters, in_calls)
        if not kept:
            result.failure = f"{master}: no step to time"
            return result
        result.masters.append(sum(masters[k] for k in kept) / len(kept))
        result.in_calls.append(sum(in_calls[k] for k in kept) / len(kept))
        result.corrections.append(sum(corrections[k] for k in kept) / len(kept))
        result.dropped.append(1.0 - len(kept) / len(masters))
        if result.masters[-1] == min(result.masters):
            result.calibration = calibration
            result.calls, result.steps, result.fmu_calls = made, len(masters), int(run.counters.get("fmu_calls", 0))
            result.in_call = {name: {kind: max(0.0, s - made[name][kind] * calibration[ARITY[kind]]["inside"])
                                     for kind, s in kinds.items()} for name, kinds in spent.items()}
    return result


def split(timed: dict, twins: dict[str, dict[str, float]], wall: float) -> tuple[dict | None, str | None]:
    """A run of ``wall`` seconds split by ``timed`` (``MasterTime.summary()``): ``master``
    its measured share, ``crossing`` the calls priced at the do-nothing twins' (component
    -> kind -> seconds a call), ``slave`` the rest of the time in the calls; and why not
    (``None`` and the reason): the figure is not to be quoted (``timed["problems"]``), a
    call kind made has no twin price, or the twins' prices come to more than the time
    measured in those calls (the prices and the runs saw different machines) by enough to
    move a share by half a percentage point (the shares are given to the percent); by less
    (a few state calls of a start-up, priced apart), those calls count as crossing alone.
    Every kind is judged alike: the twins cross by the FMUs' own path (``do_nothing_twins``:
    behind the same native entry, a set kept and a read answered there as ours are)."""
    if timed.get("problems"):
        return None, "; ".join(timed["problems"])
    crossing = excess = 0.0
    worst = None
    for name, kinds in timed["calls"].items():
        for kind, count in kinds.items():
            if not count:
                continue
            if kind not in twins.get(name, {}):
                return None, f"{name}'s {kind} calls have no do-nothing price"
            priced, measured = count * twins[name][kind], timed["in_call_s"][name][kind]
            if priced > measured:
                if worst is None or priced - measured > worst[0]:
                    worst = (priced - measured,
                             f"{name}'s {kind} calls priced at the do-nothing twins' ({1e6 * priced / count:.1f} us "
                             f"a call) come to more than the time measured in them ({1e6 * measured / count:.1f} us)")
                excess += priced - measured
                priced = measured
            crossing += priced
    master, in_calls = timed["master_per_step_s"], timed["in_calls_per_step_s"]
    crossing = min(crossing / timed["steps"], in_calls)
    per_step = master + in_calls
    if excess and excess / timed["steps"] >= 0.005 * per_step:
        return None, worst[1]
    return {"crossing": wall * crossing / per_step, "slave": wall * (in_calls - crossing) / per_step,
            "master": wall * master / per_step}, None
