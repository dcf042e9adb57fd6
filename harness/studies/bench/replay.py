"""The floor of a master's own run: the FMI calls the run made, recorded with their
arguments, then replayed in a bare loop with nothing else.

The FMU-call floor (``floors.call_floor``) is one step of zero-order-hold calls; a master
that extrapolates its inputs sends the shafts a torque slope (and they do more work in
their physics for it), and a master that evaluates the coupling at a midpoint makes more
calls: measured against that floor, our FMUs' extra work would count as the harness's.
This floor is the master's own calls instead:

* ``record`` runs the master once with every raw call wrapped (``simulate(wrap_calls=...)``)
  and keeps, in order, each call's component and kind with its arguments: the value
  references each fmi2GetReal reads, the values each fmi2SetReal sends (copied), each
  fmi2DoStep's t, h and flag, and the state calls (fmi2GetFMUstate, fmi2SetFMUstate,
  fmi2FreeFMUstate) by the state they name; and, where the stepping ends, every real
  variable of each FMU (``Recording.final``);
* ``Replay`` instantiates the scene's FMUs afresh, initialises them as a run does
  (``System.initialize``), makes untimed the calls the master made before its stepping
  loop, then times the stepping loop's calls, each with its recorded arguments, in one
  loop that only checks each call's status.  Each FMU does exactly the work it did in the
  run; a state the run saved is saved in the replay at the same call, and each later
  call that named it in the run names the replay's own;
* ``Replay.check`` reads every real variable again after the timed calls: bit for bit
  what the run left, or the replay was not the run's (``ReplayDiverged``);
* ``SideBySide`` times a run and the replay of its calls in turns: the run steps
  ``CHUNK_STEPS`` steps, then the replay makes the calls of those steps on its own FMUs,
  and so on, each turn timed.  A shared machine's speed changes over tenths of a second
  and more (a neighbour's load), by up to twice: two whole runs timed one after the other
  saw different machines, a turn of a few milliseconds and the next the same one (a run
  over its replay timed whole spread from -30 % to +95 % on a shared two-core machine;
  in turns, the same repeats lay within a few per cent of each other).

A long run is recorded for its first ``MAX_CALLS`` calls at most, in whole steps
(``Recording.span_steps`` of ``Recording.steps``): the floor of such a run is that span's
replay scaled by the steps, which a fixed-step master's steps of equal work justify.
"""
from __future__ import annotations

import ctypes
import time as clock
from dataclasses import dataclass, field
from pathlib import Path

from harness.description import plan as plans
from harness.engine import interrupt
from harness.engine.component import STATE_CALLS
from harness.engine.run import simulate
from harness.engine.system import System
from harness.paths import FMUS
from harness.studies.bench.floors import CALL_KINDS
from harness.studies.bench.master_time import COUNTED_AS

#: calls recorded at most (about 160 bytes a call kept, more while replayed): a run longer
#: than this is recorded and replayed for a span of its first whole steps
MAX_CALLS = 500_000

#: the types of the variables the check reads (FMI 2.0, FMI 3.0)
REAL_TYPES = ("Real", "Float64")

#: steps of a run timed in one turn of ``SideBySide`` before the replay makes their calls
#: (a few milliseconds of work: the machine does not change within it, and the run's
#: caches, cold after the replay's turn, are warm again within a step)
CHUNK_STEPS = 25

GET, SET, STEP, GET_STATE, SET_STATE, FREE_STATE = range(6)
_KINDS = {"get": GET, "set": SET, "step": STEP, **dict(zip(STATE_CALLS, (GET_STATE, SET_STATE, FREE_STATE)))}


class ReplayDiverged(RuntimeError):
    """The replay did not do what the run did (a call refused, a variable ending otherwise)."""


@dataclass
class Recording:
    """A run's FMI calls (``record``): ``calls`` in order, each ``(component index, kind,
    arguments...)``, value references by their number in ``value_references``; ``plan``
    the checked scene (its FMUs), ``record`` the outputs the run recorded; ``components``
    the scene's component names (in the order the indices count); ``start`` the index of the stepping loop's first call (those before
    are the master's set-up); ``steps`` the run's steps and ``span_steps`` the steps
    recorded (fewer where the run passed ``MAX_CALLS``); ``final`` every real variable of
    each component where the recording ends (component -> (value references, values)),
    and ``calls_by_kind`` the recorded stepping calls by component and kind."""
    plan: object
    record: list
    components: list
    calls: list = field(default_factory=list)
    value_references: list = field(default_factory=list)
    start: int = 0
    steps: int = 0
    span_steps: int = 0
    #: for each recorded step, the index in ``calls`` just after its last call
    step_ends: list = field(default_factory=list)
    final: dict = field(default_factory=dict)
    calls_by_kind: dict = field(default_factory=dict)
    failure: str | None = None

    @property
    def whole(self) -> bool:
        """Whether every step of the run is recorded."""
        return self.span_steps == self.steps


class _Recorder:
    """``wrap`` for ``simulate(wrap_calls=...)`` and the run's observer: each call kept
    (see ``Recording``), until a step ends beyond ``limit`` calls."""

    def __init__(self, recording: Recording, descriptions: dict, limit: int):
        self.recording = recording
        self.calls = recording.calls
        self.index = {name: k for k, name in enumerate(recording.components)}
        self.descriptions = descriptions
        self.limit = limit
        self.on = [True]
        self.handles, self.readers = {}, {}
        self.vrs: dict[bytes, int] = {}

    def _vrs(self, vrs, n: int) -> int:
        """The number of a set of value references in ``Recording.value_references`` (one
        ctypes array each; a call keeps the number, so that the recorded calls hold plain
        values only, which the garbage collector stops visiting)."""
        key = ctypes.string_at(vrs, n * ctypes.sizeof(ctypes.c_uint))
        kept = self.vrs.get(key)
        if kept is None:
            kept = self.vrs[key] = len(self.recording.value_references)
            self.recording.value_references.append((ctypes.c_uint * n).from_buffer_copy(key))
        return kept

    def wrap(self, component: str, kind: str, function):
        k, on, calls = self.index[component], self.on, self.calls
        code = _KINDS[kind]
        if code == GET:
            self.readers[component] = function

            def get(handle, vrs, n, values):
                if on[0]:
                    self.handles[component] = handle
                    calls.append((k, GET, self._vrs(vrs, n.value)))
                return function(handle, vrs, n, values)
            return get
        if code == SET:
            def set_(handle, vrs, n, values):
                if on[0]:
                    count = n.value
                    calls.append((k, SET, self._vrs(vrs, count),
                                  ctypes.string_at(values, count * ctypes.sizeof(ctypes.c_double))))
                return function(handle, vrs, n, values)
            return set_
        if code == STEP:
            def step(handle, t, h, flag):
                if on[0]:
                    self.handles[component] = handle
                    calls.append((k, STEP, float(t), float(h), int(flag)))
                return function(handle, t, h, flag)
            return step

        # the state calls: recorded by the address of the state they name (the address a
        # get wrote, read after it)
        def state(handle, pointer):
            if not on[0]:
                return function(handle, pointer)
            if code == SET_STATE:
                calls.append((k, code, pointer.value))
                return function(handle, pointer)
            if code == FREE_STATE:
                calls.append((k, code, pointer._obj.value))
                return function(handle, pointer)
            status = function(handle, pointer)
            calls.append((k, code, pointer._obj.value))
            return status
        return state

    # the run's observer
    def started(self, t):
        self.recording.start = len(self.calls)

    def stepped(self, n, t):
        self.recording.steps = n
        if self.on[0]:
            self.recording.span_steps = n
            self.recording.step_ends.append(len(self.calls))
            if len(self.calls) - self.recording.start >= self.limit:
                self._end()

    def ended(self):
        if self.on[0]:
            self._end()

    def _end(self):
        """The recording ends here: every real variable of each component read (the
        unwrapped calls, not recorded)."""
        self.on[0] = False
        self.recording.final = final_values(self.recording.components, self.descriptions, self.readers,
                                            self.handles)


def _real_variables(description) -> list[int]:
    return [v.valueReference for v in description.modelVariables
            if v.type in REAL_TYPES and v.causality in ("input", "output", "local")]


def final_values(components: list[str], descriptions: dict, readers: dict, handles: dict) -> dict:
    """Component -> (value references, values) of every real input, output and local
    variable, read with ``readers[component]`` (a raw fmi2GetReal) on ``handles``."""
    found = {}
    for name in components:
        vrs = _real_variables(descriptions[name])
        if not vrs or name not in handles:
            continue
        refs = (ctypes.c_uint * len(vrs))(*vrs)
        values = (ctypes.c_double * len(vrs))()
        status = readers[name](handles[name], refs, ctypes.c_size_t(len(vrs)), values)
        if status > 1:
            raise ReplayDiverged(f"{name}: fmi2GetReal of its real variables returned status {status}")
        found[name] = (tuple(vrs), bytes(values))
    return found


def record(scene, master: str, step: float, options: dict | None = None, fmu_dir: Path = FMUS,
           limit: int = MAX_CALLS) -> Recording:
    """One run of ``master`` at ``step`` with every FMI call recorded (see the module);
    ``failure`` says why a run failed (nothing to replay then)."""
    plan = scene if isinstance(scene, plans.Plan) else plans.check(scene, fmu_dir=fmu_dir)
    names = list(plan.scene.components)
    recording = Recording(plan, list(plan.recorded), names)
    descriptions = {name: plan.descriptions[spec.fmu] for name, spec in plan.scene.components.items()}
    recorder = _Recorder(recording, descriptions, limit)
    run = simulate(plan, master, step, fmu_dir, options=options, observer=recorder, wrap_calls=recorder.wrap)
    if not run.ok:
        recording.failure = f"{master} failed in the recorded run: {run.failure}"
        recording.calls.clear()
        return recording
    counted = {name: dict.fromkeys(CALL_KINDS, 0) for name in names}
    counted_as = {code: COUNTED_AS[kind] for kind, code in _KINDS.items()}
    for call in recording.calls[recording.start:]:
        counted[names[call[0]]][counted_as[call[1]]] += 1
    recording.calls_by_kind = counted
    return recording


def _two(function, handle, pointer, _):
    """A state call (two arguments) in the replay's loop of four."""
    return function(handle, pointer)


class Replay:
    """The recorded calls on a fresh instance of the scene's FMUs (see the module): made
    ready (instantiated, initialised, the master's set-up calls made), then its loop made
    once - whole (``timed()``) or in turns with a run (``SideBySide``) - then ``check()``;
    ``free()`` in any case."""

    def __init__(self, recording: Recording):
        if recording.failure:
            raise ReplayDiverged(recording.failure)
        self.recording = recording
        self.system = System(recording.plan, record=recording.record)
        try:
            self.system.initialize()
            self.components = [self.system.components[name] for name in recording.components]
            self._follow_initialization()
            self.slots: dict[int, ctypes.c_void_p] = {}
            self.held: list[tuple] = []          # (component, state) saved and not yet freed
            self.scratch: dict[tuple[int, int], object] = {}
            set_up = self._compiled(recording.calls[self.initialized:recording.start])
            self.loop = self._compiled(recording.calls[recording.start:])
            self._run(set_up)
        except BaseException:
            self.free()
            raise

    def _follow_initialization(self):
        """The replay's ``initialize()`` made the calls the run's did (the same code on the
        same scene): the recording's first calls, which are skipped - checked by count."""
        made = {c.name: (c.gets, c.sets, c.steps, c.state_calls) for c in self.components}
        self.initialized = sum(sum(counts) for counts in made.values())
        recorded = {name: [0, 0, 0, 0] for name in self.recording.components}
        for call in self.recording.calls[:self.initialized]:
            recorded[self.recording.components[call[0]]][min(call[1], 3)] += 1
        if self.initialized > self.recording.start or any(tuple(recorded[n]) != made[n] for n in made):
            raise ReplayDiverged("the recording does not begin with the calls of the system's initialisation "
                                 f"(recorded {recorded}, made {made})")

    def _compiled(self, calls) -> list[tuple]:
        """``(function, a, b, c, d)`` of each call, its arguments as ctypes objects made now."""
        out = []
        raws = [c.raw for c in self.components]
        value_references = self.recording.value_references
        for call in calls:
            k, code = call[0], call[1]
            raw, component = raws[k], self.components[k]
            if code == GET:
                vrs = value_references[call[2]]
                buffer = self.scratch.get((k, call[2]))
                if buffer is None:
                    buffer = self.scratch[(k, call[2])] = (ctypes.c_double * len(vrs))()
                out.append((raw.get_real, raw.handle, vrs, raw.count(len(vrs)), buffer))
            elif code == SET:
                vrs = value_references[call[2]]
                out.append((raw.set_real, raw.handle, vrs, raw.count(len(vrs)),
                            (ctypes.c_double * len(vrs)).from_buffer_copy(call[3])))
            elif code == STEP:
                out.append((raw.do_step, raw.handle, call[2], call[3], call[4]))
            elif code == GET_STATE:
                slot = self.slots[call[2]] = ctypes.c_void_p()
                self.held.append((component, slot))
                out.append((_two, component.raw_state_calls[0], raw.handle, ctypes.byref(slot), None))
            else:
                slot = self.slots.get(call[2])
                if slot is None:
                    raise ReplayDiverged(f"{component.name}: a state call names a state the run never saved")
                if code == SET_STATE:
                    out.append((_two, component.raw_state_calls[1], raw.handle, slot, None))
                else:
                    del self.slots[call[2]]
                    self.held = [(c, s) for c, s in self.held if s is not slot]
                    out.append((_two, component.raw_state_calls[2], raw.handle, ctypes.byref(slot), None))
        return out

    @staticmethod
    def _run(loop: list[tuple]):
        for n, (function, a, b, c, d) in enumerate(loop):
            status = function(a, b, c, d)
            if status > 1:
                raise ReplayDiverged(f"call {n} of the replay returned status {status}")

    def timed(self, timer=clock.perf_counter) -> float:
        """Seconds the stepping loop's calls take, replayed in a bare loop (the status of
        each checked, as a run checks it)."""
        loop = self.loop
        started = timer()
        for function, a, b, c, d in loop:
            if function(a, b, c, d) > 1:
                break
        else:
            return timer() - started
        raise ReplayDiverged(f"a replayed call ({getattr(function, '__name__', function)!s}) returned an error "
                             "status the run's did not")

    def check(self):
        """Every real variable of each FMU bit for bit what the run left where the
        recording ended; ``ReplayDiverged`` names the first that is not."""
        final = self.recording.final
        now = final_values(self.recording.components,
                           {c.name: c.description for c in self.components},
                           {c.name: c.raw.get_real for c in self.components},
                           {c.name: c.raw.handle for c in self.components})
        for name, (vrs, values) in final.items():
            if now.get(name) != (vrs, values):
                got = (ctypes.c_double * len(vrs)).from_buffer_copy(now[name][1])
                want = (ctypes.c_double * len(vrs)).from_buffer_copy(values)
                size = ctypes.sizeof(ctypes.c_double)
                first = next(k for k in range(len(vrs))       # the bits, a NaN's too
                             if now[name][1][k * size:(k + 1) * size] != values[k * size:(k + 1) * size])
                variable = next(v.name for v in self.components[self.recording.components.index(name)]
                                .description.modelVariables if v.valueReference == vrs[first]
                                and v.type in REAL_TYPES)
                raise ReplayDiverged(f"{name}.{variable} ends at {got[first]!r} in the replay, "
                                     f"{want[first]!r} in the run")

    def free(self):
        system = getattr(self, "system", None)
        if system is None:
            return
        for component, slot in getattr(self, "held", []):
            if slot.value:
                try:
                    component.free_state(slot)
                except Exception:  # noqa: BLE001 - freeing goes on; the instance frees the rest
                    pass
        self.held = []
        system.free()
        self.system = None


class SideBySide:
    """A run's observer (``simulate(observer=...)``) that times the run and the replay of
    its own calls in turns (see the module): after every ``chunk`` steps of the run the
    calls those steps made are made on ``replay``'s FMUs, and each turn is timed apart.
    ``run_s`` and ``replay_s``: the seconds of the turns, over ``steps`` of the run's steps
    (the recorded span's, where the recording ended before the run).  The run's turns hold
    this observer's call after each step (a call and a test, a fraction of a microsecond):
    counted against the run, never for it."""

    def __init__(self, replay: Replay, chunk: int = CHUNK_STEPS, timer=clock.perf_counter):
        recording = replay.recording
        ends = recording.step_ends
        if len(ends) != recording.span_steps:
            raise ReplayDiverged("the recording has no step boundaries for its span (recorded by another version)")
        # the step a turn ends after -> the replay's calls of its steps
        last_steps = [*range(chunk, len(ends) + 1, chunk)] + ([len(ends)] if len(ends) % chunk else [])
        self.turns, first = {}, 0
        for n in last_steps:
            end = ends[n - 1] - recording.start
            self.turns[n] = replay.loop[first:end]
            first = end
        self.run_s = self.replay_s = 0.0
        self.steps = 0
        self._timer = timer
        self._mark = 0.0

    def started(self, t):
        self._mark = self._timer()

    def stepped(self, n, t):
        calls = self.turns.get(n)
        if calls is None:
            return
        timer = self._timer
        ended = timer()
        for function, a, b, c, d in calls:
            if function(a, b, c, d) > 1:
                raise ReplayDiverged(f"a replayed call ({getattr(function, '__name__', function)!s}) in the "
                                     f"steps up to {n} returned an error status the run's did not")
        replayed = timer()
        self.run_s += ended - self._mark
        self.replay_s += replayed - ended
        self.steps = n
        self._mark = timer()

    def ended(self):
        pass


class OwnCallsFloor:
    """The floor of a master's case in the benchmark: its run recorded once (runs are
    deterministic: every run of the case makes these calls), then each ``__call__`` one
    more run of the master with the replay of its calls side by side (``SideBySide``):
    ``(run, replay)`` seconds, each over the recorded steps, scaled to the whole run (see
    the module) - or None once a replay failed or differed from the run, ``problem``
    saying why."""

    def __init__(self, scene, master: str, step: float, options: dict | None = None, fmu_dir: Path = FMUS,
                 limit: int = MAX_CALLS):
        self.recording = record(scene, master, step, options, fmu_dir, limit)
        self.problem = self.recording.failure
        self.master, self.step, self.options, self.fmu_dir = master, step, options, fmu_dir

    def __call__(self) -> tuple[float, float] | None:
        if self.problem:
            return None
        r = self.recording
        try:
            replay = Replay(r)
            try:
                turns = SideBySide(replay)
                run = simulate(r.plan, self.master, self.step, self.fmu_dir, options=self.options, observer=turns)
                interrupt.check()
                if not run.ok or turns.steps != r.span_steps:
                    raise ReplayDiverged(f"the run side by side with the replay did not make the recorded run's "
                                         f"steps ({run.failure or f'{turns.steps} of {r.span_steps}'})")
                replay.check()
            finally:
                replay.free()
        except ReplayDiverged as error:
            self.problem = f"the replay of the run's calls is not the run's: {error}"
            r.calls.clear()
            return None
        scale = r.steps / r.span_steps
        return turns.run_s * scale, turns.replay_s * scale

    def summary(self) -> dict:
        """What the case keeps: the calls replayed, the steps they span of the run's, the
        state calls among them, and why the floor is not measured (None: it is)."""
        r = self.recording
        stepping = r.calls_by_kind
        return {"calls": sum(sum(kinds.values()) for kinds in stepping.values()),
                "state_calls": sum(kinds["state"] for kinds in stepping.values()),
                "steps": r.steps, "span_steps": r.span_steps, "problem": self.problem}
