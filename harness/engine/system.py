"""A scene's FMUs instantiated and wired: the object masters step.

Values flow along the scene's connections by *propagation*: components are visited in
an order where every component with direct feedthrough (its outputs depend on its
inputs, as its model description declares) comes after the components feeding it; each
visited component's outputs are read in one call, and each target's inputs are set in
one call once the last of its sources has been read (one fmi2SetReal per target, not
one per source).  ``propagate(sources)`` re-propagates only downstream of the given
components (what a Gauss-Seidel master needs after stepping one shaft).

Only the scene's components are instantiated, and only the outputs that are connected
or recorded are ever read.
"""
from __future__ import annotations

import ctypes
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from harness.description import plan as plans
from harness.description import scene as scenes
from harness.description.fmu_description import time_derivatives
# the formats layer (SSP, OSP, the container, the peers) finds these here too
from harness.engine.component import Component, step_call
from harness.engine.fmi3_component import open_component
from harness.engine.interface import CoSimComponent
from harness.engine.straight_line import straight_line
from harness.paths import FMUS


# -- the compiled records a propagation runs ---------------------------------------------------------
# Read by name, a field found by what it is rather than where it sits; slotted, as a slot is
# the quickest attribute Python reads (a named tuple's field takes about twice as long).

@dataclass(frozen=True, slots=True)
class Inputs:
    """Inputs of ``component``: their value references ``vrs`` and ``values``, ctypes
    arrays (a whole input buffer or a view into part of it)."""
    component: Component
    vrs: Any
    values: Any


@dataclass(frozen=True, slots=True)
class Share:
    """A source's share of ``component``'s input buffer: the inputs at ``vrs`` whose
    ``values`` come from the source's exposed outputs at ``positions`` (indices into the
    source's output buffer, in the order of the inputs)."""
    component: Component
    vrs: Any
    values: Any
    positions: list[int]


@dataclass(frozen=True, slots=True)
class Send:
    """One fmi2SetReal of a propagation: ``n`` inputs of ``component`` at ``vrs`` set to
    ``values`` (views into its input buffer), the raw call and handle looked up once."""
    component: Component
    set_real: Callable
    handle: Any
    vrs: Any
    n: Any
    values: Any


@dataclass(frozen=True, slots=True)
class Copy:
    """Outputs copied into a target's input buffer ``values``: ``values[k] = outputs[i]``
    for each ``(k, i)`` of ``pairs``."""
    values: Any
    pairs: tuple[tuple[int, int], ...]


@dataclass(frozen=True, slots=True)
class Visit:
    """A component's part of a compiled propagation plan: its outputs read in one call
    (``get_real`` None where it has none to read; ``n`` as the raw call takes it) into
    ``values``, copied into its targets' input buffers, then the ``sends`` it completes
    (where it is the last of a target's sources in the plan).  ``component`` None in a
    plan that only sends."""
    component: Component | None
    get_real: Callable | None
    handle: Any
    vrs: Any
    n: Any
    values: Any
    copies: tuple[Copy, ...]
    sends: tuple[Send, ...]


@dataclass(frozen=True, slots=True)
class StepCall:
    """A component's fmi2DoStep, the raw call and handle looked up once (``step_plan``)."""
    component: Component
    do_step: Callable
    handle: Any


@dataclass(frozen=True, slots=True)
class FloorPlan:
    """The FMI calls of one communication step and nothing else (``System.floor_step``):
    each component's fmi2DoStep (a ``step_plan``), one full propagation, and the re-reads
    of the outputs that depend on inputs."""
    steps: tuple[StepCall, ...]
    propagation: list[Visit]
    rereads: list[Visit]


#: the FMI interface a system instantiates its FMUs in (``System(interface=...)``)
CO_SIMULATION, MODEL_EXCHANGE = "co-simulation", "model exchange"


class SceneInvalid(ValueError):
    def __init__(self, scene_name: str, findings: list[str]):
        self.findings = findings
        super().__init__(f"scene '{scene_name}' is not valid:\n  - " + "\n  - ".join(findings))


def feedthrough_components(scene: scenes.Scene, descriptions: dict) -> set[str]:
    """Components (name -> model description) with direct feedthrough that matters: a
    *connected* output depends on inputs (a shaft's acceleration depends on its torque,
    but nothing is wired from it)."""
    connected = {(c.source, c.output) for c in scene.connections}
    return {name for name, md in descriptions.items()
            if any(_on_inputs(u) and (name, u.variable.name) in connected for u in md.outputs)}


def _on_inputs(unknown) -> bool:
    """Whether an output depends directly on an input (its dependencies also name states,
    for Model Exchange, which are no feedthrough)."""
    return any(d.causality == "input" for d in unknown.dependencies or ())


def dependency_order(scene: scenes.Scene, feedthrough: set[str]) -> list[str]:
    """Components without direct feedthrough first (scene order), then each feedthrough
    component after the components feeding it; an algebraic loop is a finding."""
    order = [n for n in scene.components if n not in feedthrough]
    pending = [n for n in scene.components if n in feedthrough]
    while pending:
        ready = [n for n in pending
                 if all(c.source in order or c.source not in feedthrough
                        for c in scene.connections if c.target == n)]
        if not ready:
            raise SceneInvalid(scene.name, [f"algebraic loop between direct-feedthrough components "
                                            f"{', '.join(pending)}"])
        order += ready
        pending = [n for n in pending if n not in ready]
    return order


class System:
    def __init__(self, plan: plans.Plan | scenes.Scene, fmu_dir: Path = FMUS, logging_on: bool = False,
                 record: list[str] | None = None, interface: str = CO_SIMULATION,
                 wrap_calls: Callable | None = None):
        """The system of a checked scene (``harness.description.plan``; a scene is checked
        here, its FMUs in ``fmu_dir``); ``SceneInvalid`` when the plan has refusals.
        ``interface``: the FMUs instantiated for co-simulation (the default) or for Model
        Exchange (``harness.engine.me_component``; ``NoModelExchange`` for an FMU without
        it, before any is instantiated).  ``wrap_calls(component, kind, function)``, where
        given, replaces each co-simulation component's FMI calls before any plan is
        compiled (``Component.wrap_calls``: the benchmark times every call so)."""
        if not isinstance(plan, plans.Plan):
            plan = plans.check(plan, fmu_dir=fmu_dir)
        self.plan = plan
        self.scene = scene = plan.scene
        self.record = list(scene.record if record is None else record)
        if plan.refusals:
            raise SceneInvalid(scene.name, list(plan.refusals))
        self.interface = interface
        kind = open_component
        if interface == MODEL_EXCHANGE:
            from harness.engine.me_component import ModelExchangeComponent, NoModelExchange
            newer = [name for name, spec in scene.components.items()
                     if plan.descriptions[spec.fmu].fmiVersion != "2.0"]
            if newer:
                raise NoModelExchange(
                    f"scene '{scene.name}': " + "; ".join(
                        f"component '{n}' (FMU {scene.components[n].fmu}) is FMI "
                        f"{plan.descriptions[scene.components[n].fmu].fmiVersion}" for n in newer)
                    + " - the Model Exchange master integrates FMI 2.0 Model Exchange FMUs")
            lacking = [name for name, spec in scene.components.items()
                       if plan.descriptions[spec.fmu].modelExchange is None]
            if lacking:
                raise NoModelExchange(
                    f"scene '{scene.name}': " + "; ".join(
                        f"component '{n}' (FMU {scene.components[n].fmu}) offers co-simulation only" for n in lacking)
                    + " - Model Exchange is needed to integrate the FMUs' equations together")
            kind = ModelExchangeComponent
        elif interface != CO_SIMULATION:
            raise ValueError(f"interface {interface!r}: one of {CO_SIMULATION!r}, {MODEL_EXCHANGE!r}")
        self.components: dict[str, CoSimComponent] = {}
        try:
            for name in scene.components:
                self.components[name] = kind(name, plan.paths[name], logging_on)
                if wrap_calls is not None:
                    if interface != CO_SIMULATION:
                        raise ValueError("wrap_calls: only co-simulation components' calls are wrapped")
                    self.components[name].wrap_calls(
                        lambda call_kind, function, name=name: wrap_calls(name, call_kind, function))
        except Exception:
            self.free()
            raise
        self.feedthrough = feedthrough_components(
            scene, {name: c.description for name, c in self.components.items()})
        # Stateful components in scene order: the order a Gauss-Seidel master steps them.
        self.stateful = [n for n in scene.components if n not in self.feedthrough]
        try:
            self._plan()
        except Exception:          # an algebraic loop refused: the instances go with it
            self.free()
            raise

    def derivative_chain(self, component: str, output: str) -> list[str]:
        """``[output, d/dt output, d2/dt2 output, ...]`` as far as the component's model
        description declares them (``fmu_description.time_derivatives``)."""
        of = {of: name for name, of in time_derivatives(self.components[component].description).items()}
        chain = [output]
        while chain[-1] in of and len(chain) < 4:
            chain.append(of[chain[-1]])
        return chain

    def expose(self, items: list[str]):
        """Also read the outputs ``component.variable`` on every propagation (for a master
        that needs more than the connections carry)."""
        new = [item for item in items if item not in self.record]
        if new:
            self.record += new
            self._plan()

    # -- wiring --------------------------------------------------------------------------------
    def _plan(self):
        scene = self.scene
        exposed = {name: [] for name in self.components}
        for c in scene.connections:
            if c.output not in exposed[c.source]:
                exposed[c.source].append(c.output)
        for item in self.record:
            comp, _, var = item.partition(".")
            if var not in exposed[comp] and self.components[comp].variable(var).causality == "output":
                exposed[comp].append(var)
        # Outputs that depend on inputs (model description) go last in each buffer, so that
        # reading them again after an input write reads them alone (see dependent_reads).
        self.input_dependent = {}
        for name, names in exposed.items():
            depends = {u.variable.name for u in self.components[name].description.outputs if _on_inputs(u)}
            exposed[name] = [v for v in names if v not in depends] + [v for v in names if v in depends]
            self.input_dependent[name] = [v for v in names if v in depends]
        self.exposed = exposed
        # Every component's output values are views into one block (in the order of
        # ``buffers``), so that a recorder copies a step's outputs in one go.
        self.buffers = {name: self.components[name].real_buffer(names) for name, names in exposed.items()}
        self.output_block = (ctypes.c_double * sum(len(names) for names in exposed.values()))()
        offset = 0
        for name, (vrs, _) in self.buffers.items():
            count = len(vrs)
            self.buffers[name] = (vrs, (ctypes.c_double * count).from_buffer(
                self.output_block, offset * ctypes.sizeof(ctypes.c_double)))
            offset += count
        self.index = {(name, var): i for name, names in exposed.items() for i, var in enumerate(names)}

        order = self.order = dependency_order(scene, self.feedthrough)

        # Each target's connected inputs in one buffer (sources in propagation order), so
        # that a propagation sets them in one call; each source's share is a view into it.
        incoming = {}
        for name in order:
            for c in scene.connections:
                if c.source == name:
                    incoming.setdefault(c.target, []).append(c)
        self.inputs = {}
        self._input_ranges = {}      # target -> {source: (first, count)} in the target's buffer
        for target, conns in incoming.items():
            self.inputs[target] = self.components[target].real_buffer([c.input for c in conns])
            ranges = {}
            for k, c in enumerate(conns):
                first, count = ranges.get(c.source, (k, 0))
                ranges[c.source] = (first, count + 1)
            self._input_ranges[target] = ranges
        # For each source: its share of each target's buffer and the copy map.
        self.writes = {}
        for name in order:
            writes = []
            for target, ranges in self._input_ranges.items():
                if name in ranges:
                    first, count = ranges[name]
                    vrs, values = self._views(target, first, count)
                    conns = incoming[target][first:first + count]
                    writes.append(Share(self.components[target], vrs, values,
                                        [self.index[(name, c.output)] for c in conns]))
            self.writes[name] = writes
        # Components downstream of each one (itself included), in propagation order.
        self.downstream = {}
        for name in order:
            reach = {name}
            for n in order:
                if n in self.feedthrough and any(c.source in reach and c.target == n for c in scene.connections):
                    reach.add(n)
            self.downstream[name] = [n for n in order if n in reach]

        self._compile()

    def _views(self, target: str, first: int, count: int):
        """(value references, values) of ``count`` inputs of ``target``'s buffer from
        ``first``: ctypes arrays sharing its memory."""
        vrs, values = self.inputs[target]
        return ((ctypes.c_uint * count).from_buffer(vrs, first * ctypes.sizeof(ctypes.c_uint)),
                (ctypes.c_double * count).from_buffer(values, first * ctypes.sizeof(ctypes.c_double)))

    def input_spans(self, target: str, sources) -> list[Inputs]:
        """``Inputs`` covering the inputs of ``target`` that come from ``sources``, as few
        adjacent runs of its buffer as there are (one where the sources' shares adjoin):
        what one fmi2SetReal each sends."""
        ranges = self._input_ranges[target]
        spans = sorted(ranges[s] for s in sources if s in ranges)
        runs = []
        for first, count in spans:
            if runs and first == runs[-1][0] + runs[-1][1]:
                runs[-1][1] += count
            else:
                runs.append([first, count])
        return [Inputs(self.components[target], *self._views(target, first, count)) for first, count in runs]

    def _compile_plan(self, names, held=frozenset()):
        """A propagation over the components ``names`` (in propagation order), flattened into
        raw calls, one ``Visit`` per component: its outputs read in one call, copied into its
        targets' input buffers, and then, where it is the last of a target's sources in the
        plan, that target's inputs from the plan's sources set in one call (targets in
        ``held`` are filled but not sent: see held_plan).  Every Python attribute lookup
        left for run time would show in the harness's overhead."""
        names = list(names)
        position = {n: k for k, n in enumerate(names)}
        plan = []
        for name in names:
            component = self.components[name]
            vrs, values = self.buffers[name]
            copies = tuple(Copy(share.values, tuple(enumerate(share.positions))) for share in self.writes[name])
            sends = []
            for target, ranges in self._input_ranges.items():
                mine = [s for s in ranges if s in position]
                if target in held or name not in mine or max(position[s] for s in mine) != position[name]:
                    continue
                t = self.components[target]
                sends += [Send(t, t.raw.set_real, t.raw.handle, span.vrs, t.raw.count(len(span.vrs)), span.values)
                          for span in self.input_spans(target, mine)]
            plan.append(Visit(component, component.raw.get_real if len(vrs) else None, component.raw.handle, vrs,
                              component.raw.count(len(vrs)), values, copies, tuple(sends)))
        return plan

    def _compile(self):
        # plans of the wiring replaced here: their functions go with them (see ``runner``)
        self._runners = {}
        self._full_plan = self._compile_plan(self.order)
        self._propagate_full = self.runner(self._full_plan)
        self._partial_plans = {}
        # Components without direct feedthrough whose exposed outputs still depend on their
        # inputs (a shaft's acceleration on its torque): propagation reads them before their
        # inputs are written, so such an output lags a step unless it is read again - it
        # alone: the others cannot have changed (the model description says so).
        dependent = [name for name in self.order if name not in self.feedthrough and self.input_dependent[name]]
        self.dependent_reads = [self._read(name, len(self.exposed[name]) - len(self.input_dependent[name]),
                                           len(self.input_dependent[name])) for name in dependent]
        # For masters whose last propagation only filled the buffers: first send the
        # connected inputs of those components from their buffers.
        self._dependent_sends = self.send_plan([Inputs(self.components[name], *self.inputs[name])
                                                for name in dependent if name in self.inputs])
        self.has_dependent_outputs = bool(dependent)
        self._refresh = self.runner(self.dependent_reads)
        self._send_and_refresh = self.runner(self._dependent_sends + self.dependent_reads)

    def _read(self, name: str, first: int, count: int, copies=(), sends=()) -> Visit:
        """A ``Visit`` reading ``count`` outputs of ``name``'s buffer from ``first`` (views
        sharing its memory), then ``copies`` and ``sends``."""
        component = self.components[name]
        vrs, values = self.buffers[name]
        return Visit(component, component.raw.get_real if count else None, component.raw.handle,
                     (ctypes.c_uint * count).from_buffer(vrs, first * ctypes.sizeof(ctypes.c_uint)),
                     component.raw.count(count),
                     (ctypes.c_double * count).from_buffer(values, first * ctypes.sizeof(ctypes.c_double)),
                     copies, sends)

    def connection_plan(self) -> tuple[list[Visit], list[Visit]]:
        """``(connections, rest)``: a full propagation that reads of each component without
        direct feedthrough only the outputs its connections carry (the head of its
        buffer, which ``_plan`` puts first), and the reads of the rest of those buffers
        (recorded outputs, the ones that depend on inputs among them), to run after it.
        For a master that evaluates the system at points where nothing is recorded (a
        right-hand side): a shaft's angle and speed are its states, the rest needs its
        model evaluated.  Run together they leave every buffer as ``propagate()`` and
        ``refresh_dependent()`` do."""
        connected = {}
        for c in self.scene.connections:
            connected.setdefault(c.source, set()).add(c.output)
        plan, rest = [], []
        for visit in self._full_plan:
            name = visit.component.name
            exposed = self.exposed[name]
            head = 0
            while head < len(exposed) and exposed[head] in connected.get(name, ()):
                head += 1
            if name in self.feedthrough or head == len(exposed) or \
                    any(i >= head for copy in visit.copies for _, i in copy.pairs):
                plan.append(visit)
                continue
            plan.append(self._read(name, 0, head, visit.copies, visit.sends))
            rest.append(self._read(name, head, len(exposed) - head))
        return plan, rest

    def send_plan(self, writes: list[Inputs]) -> list[Visit]:
        """A plan for ``propagate_with`` that reads nothing and sends each ``Inputs`` of
        ``writes`` in one fmi2SetReal (empty when there is nothing to send)."""
        sends = tuple(Send(w.component, w.component.raw.set_real, w.component.raw.handle, w.vrs,
                           w.component.raw.count(len(w.vrs)), w.values) for w in writes)
        return [Visit(None, None, None, None, 0, None, (), sends)] if sends else []

    def step_plan(self, names) -> tuple[StepCall, ...]:
        """The doStep calls of the components ``names``, compiled for ``step_with``."""
        return tuple(StepCall(c, c.raw.do_step, c.raw.handle) for c in (self.components[n] for n in names))

    @staticmethod
    def step_with(plan, t: float, h: float):
        """fmi2DoStep(t, h) on each component of a ``step_plan``, in its order; what
        ``Component.do_step`` does, without its per-call lookups."""
        for call in plan:
            component = call.component
            component.count("step")
            status = call.do_step(call.handle, t, h, 1)
            if status > 1:
                component.fail(step_call(t, h), status)
            component.time = t + h

    @property
    def propagation_plan(self):
        """The compiled full propagation (see ``_compile_plan``): what ``propagate()`` runs."""
        return self._full_plan

    def held_plan(self, held: set[str]):
        """A propagation plan that fills the input buffers of the components in ``held``
        but does not send them: for a master that writes those inputs itself before the
        next step (saves two FMI calls a step on a driveline)."""
        return self._compile_plan(self.order, frozenset(held))

    def runner(self, plan, steps=None) -> Callable:
        """``plan`` (a compiled propagation: ``_full_plan``, a partial one, ``held_plan``,
        ``send_plan``, or several added) as one function of straight-line calls
        (``harness.engine.straight_line``), made on the first request and kept while the
        wiring stands (until ``expose``); a plan is not changed once made.  With ``steps``
        (a ``step_plan``, also an empty one) the function takes ``(t, h)`` and makes those
        steps first."""
        return self._made((plan, steps), lambda: straight_line("plan", plan, steps))

    def _made(self, plans: tuple, make: Callable) -> Callable:
        """The function ``make()`` gives for the objects ``plans``, made once: kept by their
        ids with them (an id is not reused while its object lives)."""
        key = tuple(map(id, plans))
        made = self._runners.get(key)
        if made is None:
            made = self._runners[key] = (plans, make())
        return made[1]

    def propagate_with(self, plan):
        """Run a compiled propagation plan (``_full_plan``, a partial one, or ``held_plan``):
        its function (``runner``)."""
        self.runner(plan)()

    @staticmethod
    def interpret(plan):
        """Run a compiled propagation plan by walking its records: what its function
        (``runner``) does, kept as the reference the generated code is tested against."""
        for visit in plan:
            values = visit.values
            get_real = visit.get_real
            if get_real is not None:
                component = visit.component
                component.count("get")
                status = get_real(visit.handle, visit.vrs, visit.n, values)
                if status > 1:
                    component.fail("fmi2GetReal", status)
            for copy in visit.copies:
                target_values = copy.values
                for k, i in copy.pairs:
                    target_values[k] = values[i]
            for send in visit.sends:
                target = send.component
                target.count("set")
                status = send.set_real(send.handle, send.vrs, send.n, send.values)
                if status > 1:
                    target.fail("fmi2SetReal", status)

    def floor_plan(self) -> FloorPlan:
        """The calls ``floor_step`` makes, compiled (components in propagation order)."""
        return FloorPlan(self.step_plan(self.order), self._full_plan, self.dependent_reads)

    def floor_step(self, t: float, h: float, plan: FloorPlan | None = None):
        """One communication step of FMI calls and nothing else, made by the code every
        master's step runs: each component's fmi2DoStep, one full propagation (the
        copies carry the values, so the models run the scene's motion), and the re-reads of
        recorded outputs that depend on inputs.  What a master that does nothing else pays
        a step: the benchmark's FMU-call floor.  ``plan`` (default ``floor_plan()``) may
        carry raw calls wrapped, e.g. in timers."""
        if plan is None:
            plan = self._made((), self.floor_plan)          # one default plan while the wiring stands
        made = self._runners.get((id(plan),))
        run = made[1] if made is not None else self._made(
            (plan,), lambda: straight_line("floor step", plan.propagation + plan.rereads, plan.steps))
        run(t, h)

    def refresh_dependent(self, send: bool = False):
        """Read again the outputs that depend on inputs written since they were read (see
        ``dependent_reads``), after sending those inputs from their buffers first when
        ``send`` (the last propagation was a held plan)."""
        if send:
            self._send_and_refresh()
        else:
            self._refresh()

    def propagate(self, sources=None):
        """Read outputs and write them to connected inputs, in dependency order."""
        if sources is None:
            self._propagate_full()
        else:
            self.runner(self.partial_plan(sources))()

    def partial_plan(self, sources) -> list[Visit]:
        """The compiled propagation downstream of the components ``sources`` (what
        ``propagate(sources)`` runs), for ``propagate_with``; valid until ``expose``."""
        key = tuple(sources)
        plan = self._partial_plans.get(key)
        if plan is None:
            plan = self._partial_plans[key] = self._compile_plan(self._downstream_of(sources))
        return plan

    def _downstream_of(self, sources):
        if len(sources) == 1:
            return self.downstream[sources[0]]
        reach = set().union(*(self.downstream[s] for s in sources))
        return [n for n in self.order if n in reach]

    def value(self, component: str, output: str) -> float:
        vrs, values = self.buffers[component]
        return values[self.index[(component, output)]]

    # -- life cycle ------------------------------------------------------------------------------
    def initialize(self):
        e = self.scene.experiment
        for name, values in self.plan.start_values.items():
            self.components[name].set_parameters(dict(values))
        for c in self.components.values():
            c.initialize(e.start, e.stop)
        self.propagate()
        for c in self.components.values():
            c.exit_initialization()
        self.propagate()

    def calls_by_kind(self) -> dict[str, dict[str, int]]:
        """FMI calls made on the hot path so far, by component and kind (get, set, step, state;
        in Model Exchange also the kinds of ``harness.engine.me_component.ME_CALL_KINDS``)."""
        return {name: {"get": c.gets, "set": c.sets, "step": c.steps, "state": c.state_calls,
                       **getattr(c, "model_exchange_calls", {})}
                for name, c in self.components.items()}

    @property
    def fmu_calls(self) -> int:
        return sum(c.calls for c in self.components.values())

    def free(self):
        for c in self.components.values():
            c.free()
