"""Running a scene: instantiate its system, step it with a master, record what the scene
asks for.  A failed run keeps every row recorded before the failure and says what went
wrong, where and when (``RunResult.failure``)."""
from __future__ import annotations

import math
import re
import time as clock
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from harness.description import plan as plans
from harness.description import scene as scenes
from harness.engine import masters as master_family
from harness.engine.component import FmuCallError
from harness.engine.guard import Diverged, Guard
from harness.engine import interrupt
from harness.engine.interrupt import Interrupted
from harness.engine.straight_line import elements_of
from harness.paths import FMUS
from harness.engine.system import System


@dataclass
class RunResult:
    scene: scenes.Scene
    master: str
    step: float
    times: np.ndarray
    traces: dict[str, np.ndarray]
    wall_time: float
    counters: dict = field(default_factory=dict)
    failure: str | None = None
    #: where a failed run stopped: "initialisation" (the inputs were refused), "stepping",
    #: or "interrupted" (Ctrl-C: the rows up to the last whole step are kept)
    failure_stage: str | None = None
    #: a failed run's diagnosis: kind (bound, non-finite, fmu-error, master), component,
    #: fmu, variable, value, bound, time, master, step, step_index (see harness.engine.guard)
    diagnosis: dict | None = None
    #: findings of the checks made before the run (the stability advisor)
    warnings: list[str] = field(default_factory=list)
    #: a streamed run (``simulate(stream=...)``): what it wrote and kept (harness.engine.traces)
    stream: dict | None = None
    #: inputs no connection drives and the scene gives no value (``Plan.unconnected``):
    #: held at their start values; named in the run's output and report
    unconnected_inputs: list[str] = field(default_factory=list)
    #: the master's options in effect (its defaults filled in: a tolerance, iterations, ...)
    options: dict = field(default_factory=dict)
    #: connections not checked for dimension, a side declaring no unit (``Plan.unchecked``)
    unchecked_connections: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return self.failure is None

    @property
    def interrupted(self) -> bool:
        return self.failure_stage == "interrupted"


class Recorder:
    """Preallocated rows of the recorded variables, filled from the system's buffers:
    one copy of the system's output block a step (through memoryviews: a slice copied in
    C, without numpy's indexing), checked for non-finite values in blocks (a non-finite
    row is found and reported with its time)."""

    CHECK_EVERY = 256

    def __init__(self, system: System, names: list[str], n_rows: int, stream=None):
        self.names = names
        # Streaming (harness.engine.traces.TraceStream): hold one chunk, hand it on when full.
        self.stream = stream
        if stream is not None:
            from harness.engine.traces import CHUNK
            n_rows = min(n_rows, CHUNK)
        # Record the system's whole output block (every component's buffer, a superset of
        # the names) in one copy a step; pick the names at the end.
        self._columns = {}
        offset = 0
        for comp, (_, values) in system.buffers.items():
            for var, i in ((v, system.index[(comp, v)]) for v in system.exposed[comp]):
                self._columns[f"{comp}.{var}"] = offset + i
            offset += len(values)
        self._block = elements_of(system.output_block)
        self._width = offset
        missing = [n for n in names if n not in self._columns]
        if missing:
            raise KeyError(f"not exposed by the system: {', '.join(missing)}")
        self._selected = [self._columns[n] for n in names]      # the recorded names' columns
        self.count = 0
        self._checked = 0
        self._allocate(n_rows)

    def _allocate(self, n_rows: int, kept: int = 0):
        """Rows for ``n_rows`` steps, the first ``kept`` of the present ones copied over; the
        flat views ``record`` writes through."""
        times, rows = np.empty(n_rows), np.empty((n_rows, self._width))
        if kept:
            times[:kept], rows[:kept] = self.times[:kept], self.rows[:kept]
        self.times, self.rows = times, rows
        self._time_items = memoryview(times)
        self._row_items = memoryview(rows.reshape(-1))

    def record(self, t: float):
        count = self.count
        if count == len(self.times):
            if self.stream is not None:
                self._hand_on()
            else:                               # a variable-step run: grow
                self._allocate(2 * count, count)
            count = self.count
        width = self._width
        self._row_items[count * width:(count + 1) * width] = self._block
        self._time_items[count] = t
        self.count = count = count + 1
        if count - self._checked >= self.CHECK_EVERY:
            self.check()

    def check(self):
        """Raise ``Diverged`` at the first non-finite recorded value since the last check
        (the rows up to it are kept)."""
        block = self.rows[self._checked:self.count, self._selected]
        finite = np.isfinite(block)
        if not finite.all():
            first = int(np.argmin(finite.all(axis=1)))
            row = self._checked + first
            bad = [n for n, ok in zip(self.names, finite[first]) if not ok]
            self.count = row + 1
            raise Diverged(f"non-finite value of {', '.join(bad)} at t = {self.times[row]:.6g} s")
        self._checked = self.count

    def _hand_on(self, checked: bool = True):
        """Pass the rows held so far to the stream (checked first, unless they are the
        last rows of a run that already failed) and start a new chunk."""
        if checked:
            self.check()
        self.stream.append(self.times[:self.count], self.rows[:self.count][:, self._selected])
        self.count = self._checked = 0

    def traces(self) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        if self.stream is not None:       # the rows since the last chunk (a failed run's included)
            self._hand_on(checked=False)
            self.stream.close()
            return self.stream.traces()
        n = self.count
        return self.times[:n].copy(), {name: self.rows[:n, self._columns[name]].copy() for name in self.names}


def simulate(scene: scenes.Scene | plans.Plan, master: str | None = None, step: float | None = None,
             fmu_dir: Path = FMUS, progress: bool = False, options: dict | None = None,
             stream: Path | None = None, keep_partial: bool = False, observer=None,
             wrap_calls=None) -> RunResult:
    """Run ``scene`` with ``master`` (default: the scene's) at communication step ``step``
    (for an adaptive master: its first step); ``options`` go to the master, over what the
    scene states for its own master (``experiment.tolerance``).  ``scene`` is
    a checked ``harness.description.plan.Plan`` (its FMUs where it found them) or a scene,
    checked here once with its FMUs in ``fmu_dir``.  The stability
    advice is not computed here: whoever shows it (``lever run``) asks
    ``harness.judges.stability.run_advice`` and may keep it in ``RunResult.warnings``.  ``stream``: a trace CSV
    written while the run goes, the result keeping every k-th row (harness.engine.traces).

    Ctrl-C stops the run at the next step boundary (harness.engine.interrupt): with
    ``keep_partial`` the result holds the rows computed until then, marked interrupted;
    without, ``Interrupted`` is raised once the FMUs are freed.

    ``observer`` (e.g. ``harness.engine.observers.StepTimer``) is told when the stepping
    starts (``started(t)``), after every whole step (``stepped(n, t)``, the step recorded
    and checked) and when it ends (``ended()``); without one the loop pays one test a step.
    ``wrap_calls`` goes to the ``System`` (every FMI call wrapped, e.g. timed)."""
    with interrupt.deferred():
        result = _simulate(scene, master, step, fmu_dir, progress, options, stream, observer, wrap_calls)
    if result.interrupted and not keep_partial:
        raise Interrupted(result.diagnosis["time"])
    return result


def _simulate(subject, master, step, fmu_dir, progress, options, stream, observer=None,
              wrap_calls=None) -> RunResult:
    scene = subject.scene if isinstance(subject, plans.Plan) else subject
    e = scene.experiment
    master = master or e.master
    step = float(step or e.step)
    master_family.check(master)     # an unknown master is said before the scene's findings
    options = {**master_family.stated_options(master, e), **(options or {})}
    plan = subject if isinstance(subject, plans.Plan) else plans.check(scene, fmu_dir=fmu_dir)
    names = list(plan.recorded)
    # refuses an unsound scene (SceneInvalid) first, and for a Model Exchange master an FMU
    # without that interface (NoModelExchange), before any FMU is instantiated
    system = System(plan, record=names, interface=master_family.master_class(master).interface,
                    wrap_calls=wrap_calls)
    n_steps = max(1, math.ceil((e.stop - e.start) / step - 1e-9))
    failure = stage = diagnosis = None
    recorder = driver = bar = calls_before = None
    started = stepping = clock.perf_counter()
    try:
        system.initialize()
        guard = Guard(system, master, step)     # before the master: it may expose outputs
        driver = master_family.make(master, system, step, **options)
        guard.watch()                           # the master may have re-planned the buffers
        recorder = Recorder(system, names, n_steps + 1, stream=_stream(stream, plan, names, n_steps + 1))
        recorder.record(e.start)
        interrupt.check(e.start)
        bar = _progress(e.stop - e.start, scene.name, master) if progress else None
        calls_before = system.calls_by_kind()
        interrupt.phase("stepping")
        if observer is not None:
            observer.started(driver.t)
        stepping = clock.perf_counter()
        if driver.adaptive:
            while driver.t < e.stop - 1e-12 * max(1.0, abs(e.stop)):
                # the step that reaches the stop aims at it exactly (t + (stop - t) may not)
                if driver.h >= e.stop - driver.t:
                    driver.step(t_next=e.stop)
                else:
                    driver.step(driver.h)
                recorder.record(driver.t)
                guard.check(driver.t, driver.n_steps)
                if observer is not None:
                    observer.stepped(driver.n_steps, driver.t)
                if interrupt.requested():
                    raise Interrupted(driver.t)
                if bar is not None:
                    bar.update(driver.t - bar.n)
        else:
            # Targets from the step count, not by summing steps: no drift in t.  The last
            # is the stop time itself: start + n*step can miss it by an ulp (0.03 + 5*0.001
            # is 0.034999999999999996).
            stride = 500 if bar is not None else n_steps + 1
            step_to, record, check, start, stop = driver.step, recorder.record, guard.check, e.start, e.stop
            for n in range(1, n_steps + 1):
                step_to(t_next=stop if n == n_steps else min(start + n * step, stop))
                record(driver.t)
                check(driver.t, n)
                if observer is not None:
                    observer.stepped(n, driver.t)
                if interrupt.requested():
                    raise Interrupted(driver.t)
                if n % stride == 0:
                    bar.update(driver.t - bar.n)
        recorder.check()
        if bar is not None:
            bar.close()
    except (FmuCallError, Diverged, master_family.MasterFailure) as error:
        stage = "stepping" if driver else "initialisation"
        refused = scene.components.get(getattr(error, "component", None))
        failure = ((f"FMU {refused.fmu} refused a call: " if refused else "")
                   + f"{error} (master {master}, step {step:g} s"
                   + (f", after {driver.n_steps} steps" if driver else ", during initialisation") + ")")
        diagnosis = _diagnosis(error, scene, master, step, driver)
    except Interrupted as error:
        # Ctrl-C between two steps: what was computed stands; not the FMUs' failure.
        at = error.time if error.time is not None else (driver.t if driver else e.start)
        stage = "interrupted"
        failure = (f"interrupted at t = {at:.6g} s (master {master}, step {step:g} s"
                   + (f", after {driver.n_steps} steps)" if driver else ", during initialisation)"))
        diagnosis = {"kind": "interrupted", "master": master, "step": step, "time": at,
                     "step_index": driver.n_steps if driver else 0, "message": failure}
        if bar is not None:
            bar.close()
    finally:
        ended = clock.perf_counter()
        if observer is not None:
            observer.ended()
        counters = driver.counters() if driver else {"fmu_calls": system.fmu_calls}
        counters["setup_time"] = stepping - started
        if calls_before is not None:    # the stepping loop's FMI calls by component and kind
            counters["calls_by_kind"] = {name: {kind: n - calls_before[name][kind] for kind, n in by_kind.items()}
                                         for name, by_kind in system.calls_by_kind().items()}
        system.free()
    times, traces = recorder.traces() if recorder else (np.empty(0), {n: np.empty(0) for n in names})
    # wall_time: the stepping loop (master, FMU calls, recording), not instantiation.
    in_effect = {key: getattr(driver, key, default) if driver else options.get(key, default)
                 for key, default in master_family.master_class(master).options.items()}
    return RunResult(scene, master, step, times, traces, ended - stepping, counters, failure, stage, diagnosis,
                     [], recorder.stream.report() if recorder and recorder.stream else None, list(plan.unconnected),
                     in_effect, list(plan.unchecked))


def _diagnosis(error: Exception, scene: scenes.Scene, master: str, step: float, driver) -> dict:
    """What a failed run reports in ``RunResult.diagnosis``: the guard's own, or one
    built from an FMU's refusal (its log names the variable) or a master's failure."""
    if isinstance(error, Diverged) and error.diagnosis:
        return dict(error.diagnosis)
    out = {"kind": "master", "master": master, "step": step,
           "step_index": (driver.n_steps + 1) if driver else 0,
           "time": driver.t if driver else None, "message": str(error)}
    if isinstance(error, Diverged):
        out["kind"] = "non-finite"
    elif isinstance(error, FmuCallError):
        named = re.search(r"(?:parameter|variable) '(\w+)'", " ".join(error.messages))
        spec = scene.components.get(error.component)
        out.update(kind="fmu-error", component=error.component, fmu=spec.fmu if spec else None,
                   variable=named.group(1) if named else None, call=error.call, time=error.time,
                   fmu_messages=error.messages)
    return out


def _stream(path: Path | None, plan: plans.Plan, names: list[str], rows: int):
    if path is None:
        return None
    from harness.engine.traces import TraceStream, integrals_for
    return TraceStream(path, names, rows, integrate=integrals_for(plan))


def _progress(span: float, scene: str, master: str):
    from tqdm import tqdm
    return tqdm(total=span, desc=f"{scene} [{master}]", unit="s", unit_scale=False, leave=False,
                mininterval=0.5, bar_format="{l_bar}{bar}| {n:.3g}/{total:.3g} s simulated [{elapsed}<{remaining}]")


def trace_memory(plan: plans.Plan, step: float | None = None) -> tuple[int, int]:
    """``(bytes, rows)``: what holding a run's traces in memory takes, estimated before it
    runs: the recorder's rows (every connected and recorded output, and the time), the
    recorded traces copied out of them, and the block the trace file is written from."""
    e = plan.experiment
    rows = max(1, math.ceil((e.stop - e.start) / float(step or e.step) - 1e-9)) + 1
    names = plan.recorded
    columns = len(set(names) | {f"{c.source}.{c.output}" for c in plan.connections})
    return 8 * rows * (columns + 2 * len(names) + 2), rows


def available_memory() -> int | None:
    """Bytes of memory the system can give a process now (Linux: MemAvailable); None
    where it cannot be told."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None
