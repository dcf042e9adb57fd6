"""The explicit masters: each step uses only values known at its start (zero-order hold,
Gauss-Seidel's order, extrapolated or mid-step-predicted inputs); no rollback."""
from __future__ import annotations

import ctypes
import math
from collections import deque
from dataclasses import dataclass
from typing import Any, Callable

from harness.description.fmu_description import time_derivatives
from harness.engine.masters.base import Master
from harness.engine.component import Component
from harness.engine.straight_line import Source, add_steps, add_visits, elements_of
from harness.engine.system import Inputs, System


@dataclass(frozen=True, slots=True)
class HeldInputs:
    """A component's coupled inputs as an extrapolating master writes them over a step:
    ``values`` at ``vrs``, the ``n`` inputs first and, where ``ramped``, their declared
    time derivatives after them (rate, then higher ones)."""
    component: Component
    vrs: Any
    values: Any
    n: int
    ramped: bool


class JacobiMaster(Master):
    """All components step in parallel on the inputs of ``t`` (zero-order hold), then
    the outputs of ``t + h`` are propagated."""

    name = "jacobi"
    order = 1
    description = "parallel steps, inputs held from the start of the step (zero-order hold)"
    reads_recorded = True       # the step's function reads them last (``_compile_step``)

    def __init__(self, system: System, step: float, **options):
        super().__init__(system, step, **options)
        self._compile_step()

    def _compile_step(self):
        """The step, the propagation after it and the reads of the recorded outputs that
        depend on the inputs it wrote, as one function (``System.runner``); made again by a
        master that exposes outputs (the propagation reads them too)."""
        system = self.system
        self._step_and_propagate = system.runner(system.propagation_plan + system.dependent_reads, self._steps)

    def _step_impl(self, t, h):
        self._step_and_propagate(t, h)


class GaussSeidelMaster(Master):
    """Stateful components step one after the other; after each, its new outputs are
    propagated (through the coupling, evaluated on the shafts' current states) before
    the next one steps."""

    name = "gauss-seidel"
    order = 1
    description = "sequential steps, each shaft sees the coupling on the latest states"
    reads_recorded = True       # the whole step's function reads them last

    def __init__(self, system: System, step: float, **options):
        super().__init__(system, step, **options)
        # the whole step as one function (``harness.engine.straight_line``)
        source = Source("gauss-seidel step", "t, h")
        for name in system.stateful:
            add_steps(source, system.step_plan([name]))
            add_visits(source, system.partial_plan([name]))
        add_steps(source, self._feedthrough_steps)
        add_visits(source, system.dependent_reads)
        self._whole_step = source.function()

    def _step_impl(self, t, h):
        self._whole_step(t, h)


def _lagrange_basis(nodes) -> list[list[float]]:
    """For each node ``x_j``: the coefficients (lowest power first) of the Lagrange basis
    polynomial ``L_j`` (1 at ``x_j``, 0 at the other nodes), the product of
    ``(x - x_m) / (x_j - x_m)`` over the other nodes in their order, multiplied out term
    by term.  Two and three nodes (the extrapolating masters' degrees 1 and 2) unrolled:
    the same operations in the same order, fewer Python steps (an adaptive master makes
    new weights on every step)."""
    if len(nodes) == 3:
        x0, x1, x2 = nodes
        return [_basis_3(x0, x1, x2), _basis_3(x1, x0, x2), _basis_3(x2, x0, x1)]
    if len(nodes) == 2:
        x0, x1 = nodes
        return [_basis_2(x0, x1), _basis_2(x1, x0)]
    return _lagrange_product(nodes)


def _lagrange_product(nodes) -> list[list[float]]:
    """``_lagrange_basis`` for any number of nodes, one factor at a time."""
    bases = []
    for j, xj in enumerate(nodes):
        basis = [1.0]
        for m, xm in enumerate(nodes):
            if m != j:
                scale = 1.0 / (xj - xm)
                shifted = [0.0] + basis                 # x * L
                basis = [(shifted[k] - xm * (basis[k] if k < len(basis) else 0.0)) * scale
                         for k in range(len(shifted))]
        bases.append(basis)
    return bases


def _basis_2(xj, a):
    """``_lagrange_basis``'s loop for the node ``xj`` and one other, ``a``."""
    scale = 1.0 / (xj - a)
    return [(0.0 - a * 1.0) * scale, (1.0 - a * 0.0) * scale]


def _basis_3(xj, a, b):
    """``_lagrange_basis``'s loop for the node ``xj`` and two others, ``a`` then ``b``."""
    scale = 1.0 / (xj - a)
    c0, c1 = (0.0 - a * 1.0) * scale, (1.0 - a * 0.0) * scale
    scale = 1.0 / (xj - b)
    return [(0.0 - b * c0) * scale, (c0 - b * c1) * scale, (c1 - b * 0.0) * scale]


#: the first moment about the step's middle of ``x^k`` over [0, 1]: 1/(k + 2) - 1/2 (k + 1)
_FIRST_MOMENTS = tuple(1.0 / (k + 2) - 0.5 / (k + 1) for k in range(8))


def extrapolation_weights(past_times, t: float, h: float) -> tuple[list, list, list]:
    """Weights ``(m_j, r_j, e_j)`` over past values ``u(t_j)`` of the polynomial ``p``
    through them: ``sum_j m_j u(t_j)`` is the mean of ``p`` over ``[t, t + h]``,
    ``sum_j r_j u(t_j) / h`` the slope of its best linear fit there (the ramp with the same
    mean and first moment) and ``sum_j e_j u(t_j)`` its value at ``t + h``.

    A shaft sees the torque's mean over the step in its speed and the first moment in
    its angle; with a held torque only the mean can match (for uniform steps the
    Adams-Bashforth weights: degree 1: -1/2, 3/2; degree 2: 5/12, -16/12, 23/12).
    Pure Python over the Lagrange basis: this runs on every step of an adaptive master."""
    nodes = [(x - t) / h for x in past_times]          # <= 0, scaled to the step
    if len(nodes) == 3:
        return _extrapolation_weights_3(*nodes)
    moments = _FIRST_MOMENTS if len(nodes) <= len(_FIRST_MOMENTS) else \
        tuple(1.0 / (k + 2) - 0.5 / (k + 1) for k in range(len(nodes)))
    means, slopes, ends = [], [], []
    for basis in _lagrange_basis(nodes):
        # each sum from 0.0, lowest power first
        mean = slope = end = 0.0
        for k, c in enumerate(basis):
            mean += c / (k + 1)
            slope += c * moments[k]
            end += c
        means.append(mean)
        slopes.append(12.0 * slope)
        ends.append(end)
    return means, slopes, ends


def _extrapolation_weights_3(x0, x1, x2) -> tuple[list, list, list]:
    """``extrapolation_weights``' sums for three nodes (the quadratic's, on every step of an
    adaptive master), unrolled: the same operations in the same order."""
    m0, m1, m2 = _FIRST_MOMENTS[:3]
    means, slopes, ends = [], [], []
    for c0, c1, c2 in (_basis_3(x0, x1, x2), _basis_3(x1, x0, x2), _basis_3(x2, x0, x1)):
        means.append(0.0 + c0 / 1 + c1 / 2 + c2 / 3)
        slopes.append(12.0 * (0.0 + c0 * m0 + c1 * m1 + c2 * m2))
        ends.append(0.0 + c0 + c1 + c2)
    return means, slopes, ends


def derivative_weights(times, scale: float) -> tuple[list, list]:
    """Weights ``(d1_j, d2_j)`` over values ``u(t_j)`` at ``times`` (the last one ``t``)
    such that ``sum_j d1_j u(t_j) / scale`` and ``sum_j d2_j u(t_j) / scale^2`` are the
    first and second derivatives at ``t`` of the polynomial through them (uniform steps
    of ``scale``, degree 2: 1/2, -2, 3/2 and 1, -2, 1)."""
    t = times[-1]
    bases = _lagrange_basis([(x - t) / scale for x in times])
    return ([basis[1] if len(basis) > 1 else 0.0 for basis in bases],
            [2.0 * basis[2] if len(basis) > 2 else 0.0 for basis in bases])


def lagrange_weights(nodes, x: float) -> list[float]:
    """Weights of the values at ``nodes`` in the interpolating polynomial's value at ``x``."""
    return [math.prod((x - m) / (n - m) for m in nodes if m != n) for n in nodes]


def snapshot_of(buffers) -> Callable[[], list[list[float]]]:
    """A function that copies ``buffers`` (ctypes arrays) into lists of floats, read through
    their memoryviews as the compiled steps read them (``straight_line.elements_of``): for
    one- and two-value buffers (a driveline's coupling torques) without a loop, which costs
    most of it."""
    views = [elements_of(values) for values in buffers]
    if all(len(values) == 1 for values in views):
        if len(views) == 2:
            a, b = views
            return lambda: [[a[0]], [b[0]]]
        return lambda: [[values[0]] for values in views]
    return lambda: [list(values) for values in views]


class ExtrapolatingJacobiMaster(JacobiMaster):
    """Jacobi, but each stateful component's inputs are extrapolated from the last
    ``degree + 1`` communication points instead of held.  Where the component declares
    a derivative input (a shaft's ``tau_rate``) it gets the ramp that matches the
    extrapolating polynomial's mean and first moment over the step (first-order hold),
    otherwise the mean, held.  Order ``degree + 1`` with the ramp, at most 2 without;
    the first steps use the history there is.

    Where a component declares the polynomial's derivatives up to its degree as inputs
    (a shaft's ``tau_rate`` and ``tau_accel``), the polynomial is sent whole at the end of
    each step instead - the torque the coupling gives now, its slope and curvature, which
    the shaft reduces to the same ramp - in the same call that makes the shaft's
    acceleration consistent for recording: no write before the next step (11 FMI calls a
    step on a driveline, against 13).  Components without them (a foreign FMU) get the
    hold before each step, as before."""

    degree = 1
    options = {"ramp": True}
    reads_recorded = False      # but the steady step's function does (``_steady_step``)
    #: a step after the start-up is one compiled function where it can be (``_steady_step``);
    #: a subclass with a ``_step_impl`` of its own says False
    steady_steps = True

    def __init__(self, system: System, step: float, **options):
        super().__init__(system, step, **options)
        self.coupled_inputs = self._coupled_inputs()
        chains = self._derivative_inputs(self.coupled_inputs) if self.ramp else [[] for _ in self.coupled_inputs]
        # One write per component: the inputs and, after them, their derivatives (the
        # hold gives rates and sets any higher ones to 0).
        self._held = []
        for inputs, chain in zip(self.coupled_inputs, chains):
            n = len(inputs.values)
            if not chain:
                self._held.append(HeldInputs(inputs.component, inputs.vrs, (ctypes.c_double * n)(), n, False))
            else:
                every = (ctypes.c_uint * (n * (1 + len(chain))))(*inputs.vrs,
                                                                 *(vr for vrs_k in chain for vr in vrs_k))
                self._held.append(HeldInputs(inputs.component, every, (ctypes.c_double * len(every))(), n, True))
        # The components whose inputs get the polynomial whole at the end of each step (see
        # the class); the others (a foreign FMU without the derivative inputs) the hold.
        ahead = [k for k, chain in enumerate(chains) if len(chain) >= self.degree]
        self._rest = tuple(k for k in range(len(self._held)) if k not in ahead)
        self._ahead = tuple(ahead)
        self.sends_ahead = bool(ahead)
        self._ahead_after = None        # the history point after which it was last sent
        # The last ``degree`` communication points before the current one.
        self.history: deque = deque(maxlen=self.degree)
        self._weights_cache: dict = {}
        self._can_roll_back = all(system.components[n].description.coSimulation.canGetAndSetFMUstate
                                  for n in system.stateful)
        self._held_plan = system.held_plan({inputs.component.name for inputs in self.coupled_inputs})
        # The held inputs' writes compiled once, as propagations that read nothing: all of
        # them, those sent ahead, the rest.
        writes = [Inputs(held.component, held.vrs, held.values) for held in self._held]
        self._sends = system.send_plan(writes)
        self._sends_ahead = system.send_plan([writes[k] for k in self._ahead])
        self._sends_rest = system.send_plan([writes[k] for k in self._rest])
        # The per-step work, flattened once: the live input buffers (copied into the
        # history), and for each input sent ahead (component k, input i) its held buffer,
        # the live one, n, and whether it takes a second derivative.
        self._live = tuple(inputs.values for inputs in self.coupled_inputs)
        self._ahead_inputs = tuple((k, i, self._held[k].values, self._live[k], self._held[k].n,
                                    len(self._held[k].values) > 2 * self._held[k].n)
                                   for k in self._ahead for i in range(self._held[k].n))
        # For each held input (component k, input i), those not sent ahead apart: its held
        # buffer, n, whether ramped, and the slots of its higher derivatives (set to 0).
        self._held_inputs = tuple((k, i, held.values, held.n, held.ramped,
                                   tuple(range(2 * held.n + i, len(held.values), held.n)))
                                  for k, held in enumerate(self._held) for i in range(held.n))
        self._rest_inputs = tuple(each for each in self._held_inputs if each[0] in self._rest)
        self._ahead_curved = any(each[5] for each in self._ahead_inputs)
        self.snapshot = snapshot_of(self._live)
        self._step_held = system.runner(self._held_plan, self._steps)
        # The holds by number of points, prediction and part (``_hold``) and the end-of-step
        # writes by number of weights (``_send_ahead``): made here for the counts a run meets
        # (a history of at most ``degree`` points and the point now), so that no step pays
        # for compiling one; any other made when first met.
        self._holders: dict[tuple, Callable] = {
            (points, predict, rest_only): self._holder(points, predict, rest_only)
            for points in range(1, self.degree + 2) for predict in (True, False)
            for rest_only in ((False, True) if self._rest else (False,))}
        self._ahead_writers: dict[int, Callable] = {
            points + 1: self._ahead_writer(points) for points in range(1, self.degree + 1)} if self.sends_ahead else {}
        # The derivative weights the last step used and the scaled nodes of their key:
        # a fixed step's next pattern is recognised without rounding (``_derivatives``).
        self._last_derivatives = None
        # Where every component takes the polynomial whole, a step after the start-up is one
        # function (``_steady_step``) that also reads the recorded outputs itself.
        if self.steady_steps and self.sends_ahead and not self._rest:
            self.reads_recorded = True
            self._whole_step = self._steady_step()
        else:
            self._whole_step = self._general_step

    def _derivative_inputs(self, inputs) -> list[list]:
        """For each ``Inputs`` of ``inputs``: the value references of their declared time
        derivatives (``fmu_description.time_derivatives``), first, second, ... as far as every
        input of the component has one (``[]`` where one has none)."""
        out = []
        for each in inputs:
            variables = each.component.variables
            rate_of = {variables[of].valueReference: variables[name].valueReference
                       for name, of in time_derivatives(each.component.description).items()
                       if variables[name].causality == "input"}
            chain, current = [], list(each.vrs)
            while all(vr in rate_of for vr in current) and len(chain) < 3:
                current = [rate_of[vr] for vr in current]
                chain.append(current)
            out.append(chain)
        return out

    def _hold(self, t, h, points, predict: bool = True, rest_only: bool = False):
        """Write the inputs for the step ``[t, t + h]`` from the polynomial through
        ``points`` (``[(time, values per input)]``); return its values at ``t + h``
        (``None`` unless ``predict``).  ``rest_only``: only the components whose inputs
        were not sent ahead."""
        weights = self._weights([p[0] for p in points], t, h)
        key = (len(weights), predict, rest_only)
        holder = self._holders.get(key)
        if holder is None:
            holder = self._holders[key] = self._holder(*key)
        return holder(weights, [p[1] for p in points], h)

    def _holder(self, points: int, predict: bool, rest_only: bool) -> Callable:
        """``_hold``'s writes and sends through ``points`` communication points as one
        function (``harness.engine.straight_line``) of the weights, the points' values and
        ``h``; it returns the polynomial's values at the step's end (by component) where
        ``predict``, else None.  Per input each sum from 0.0 over the points in their order,
        what a loop over them makes."""
        source = Source(f"hold through {points} points", "weights, pasts, h")
        source.line(", ".join(f"(m{j}, r{j}, e{j})" for j in range(points)) + ", = weights")
        source.line(", ".join(f"past{j}" for j in range(points)) + ", = pasts")
        ends = []
        for k, i, values, n, ramped, higher in (self._rest_inputs if rest_only else self._held_inputs):
            held = source.elements(values, "held")
            for j in range(points):
                source.line(f"u{j} = past{j}[{k}][{i}]")
            mean = "0.0" + "".join(f" + m{j} * u{j}" for j in range(points))
            if ramped:
                source.line(f"mean = {mean}")
                source.line("change = 0.0" + "".join(f" + r{j} * u{j}" for j in range(points)) + "       # slope * h")
                source.line(f"{held}[{i}] = mean - 0.5 * change")
                source.line(f"{held}[{n + i}] = change / h")
                for j in higher:
                    source.line(f"{held}[{j}] = 0.0           # higher derivatives: the ramp is all")
            else:
                source.line(f"{held}[{i}] = {mean}")
            if predict:
                if i == 0:
                    ends.append([])
                ends[-1].append(f"end{k}_{i}")
                source.line(f"end{k}_{i} = 0.0" + "".join(f" + e{j} * u{j}" for j in range(points)))
        add_visits(source, self._sends_rest if rest_only else self._sends)
        source.line("return [" + ", ".join("[" + ", ".join(group) + "]" for group in ends) + "]" if predict
                    else "return None")
        return source.function()

    def _send_ahead(self, t_end):
        """Write each component's inputs at ``t_end`` (the step just made's end, where the
        coupling's torques are in the input buffers) and the derivatives there of the
        polynomial through the history and them: what the next step holds."""
        history = self.history
        scale = t_end - history[-1][0]
        first, second = self._derivatives(history, t_end, scale)
        writer = self._ahead_writers.get(len(first))
        if writer is None:
            writer = self._ahead_writers[len(first)] = self._ahead_writer(len(first) - 1)
        writer(history, first, second, scale, scale * scale)
        self._ahead_after = history[-1]
        # what was not sent ahead is still only in the buffers
        self._inputs_unsent = bool(self._rest)

    def _ahead_writer(self, points: int) -> Callable:
        """``_send_ahead``'s writes and sends through ``points`` past communication points
        and the inputs now, as one function (``harness.engine.straight_line``) of the history,
        the weights, ``scale`` and its square.  Per input, each sum from 0.0 over the past
        points in their order and then the value now: what a loop over them makes."""
        source = Source(f"send ahead through {points + 1} points", "history, first, second, scale, squared")
        if points:
            source.line(", ".join(f"(_, past{j})" for j in range(points)) + ", = history")
        source.line(", ".join(f"f{j}" for j in range(points + 1)) + ", = first")
        if self._ahead_curved:
            source.line(", ".join(f"s{j}" for j in range(points + 1)) + ", = second")
        self._add_ahead_writes(source, points)
        return source.function()

    def _add_ahead_writes(self, source: Source, points: int):
        """The lines of ``_ahead_writer``'s writes and sends, in ``source`` (past values
        ``past0`` ..., weights ``f0`` ... and ``s0`` ..., ``scale`` and ``squared`` bound)."""
        for k, i, values, now, n, higher in self._ahead_inputs:
            held, live = source.elements(values, "held"), source.elements(now, "live")
            source.line(f"u = {live}[{i}]")
            source.line(f"{held}[{i}] = u")
            source.line(f"{held}[{n + i}] = (0.0 + " + "".join(f"f{j} * past{j}[{k}][{i}] + " for j in range(points))
                        + f"f{points} * u) / scale")
            if higher:
                source.line(f"{held}[{2 * n + i}] = (0.0 + "
                            + "".join(f"s{j} * past{j}[{k}][{i}] + " for j in range(points))
                            + f"s{points} * u) / squared")
        add_visits(source, self._sends_ahead)

    def _derivatives(self, history, t_end, scale):
        """The derivative weights at ``t_end`` through the history's times and it, cached by
        the pattern of the times scaled to ``scale`` (see ``_cached``).  A pattern whose
        scaled nodes lie within 1e-10 of the last one's key rounds to that key (the key's
        9 digits leave 5e-10 either side), so a fixed step finds its weights without
        rounding the nodes again."""
        last = self._last_derivatives
        if last is not None:
            nodes = last[0]
            count = len(nodes)
            if count == len(history):
                # the loop for one and two points (jacobi-linear's and jacobi-quadratic's
                # fixed step) unrolled
                if count == 2:
                    (n0, n1), (p0, p1) = nodes, history
                    if abs((p0[0] - t_end) / scale - n0) < 1e-10 and abs((p1[0] - t_end) / scale - n1) < 1e-10:
                        return last[1]
                elif count == 1:
                    if abs((history[0][0] - t_end) / scale - nodes[0]) < 1e-10:
                        return last[1]
                else:
                    for point, node in zip(history, nodes):
                        if not abs((point[0] - t_end) / scale - node) < 1e-10:
                            break
                    else:
                        return last[1]
        times = [p[0] for p in history] + [t_end]
        key = tuple([round((x - t_end) / scale, 9) for x in times])
        weights = self._cached(("d",) + key, lambda: derivative_weights(times, scale))
        self._last_derivatives = (key[:-1], weights)
        return weights

    def restore_states(self, states, t):
        super().restore_states(states, t)
        self._ahead_after = None        # the inputs sent ahead belong to another state

    def _weights(self, times, t, h):
        return self._cached(tuple([round((x - t) / h, 9) for x in times]),
                            lambda: list(zip(*extrapolation_weights(times, t, h))))

    def _cached(self, key, compute):
        """Weights by the pattern of the points' times, scaled to the step (to 9 digits: a
        fixed step's patterns repeat although its times carry rounding)."""
        weights = self._weights_cache.get(key)
        if weights is None:
            if len(self._weights_cache) > 32:      # variable steps: do not grow without bound
                self._weights_cache.clear()
                self._last_derivatives = None     # its weights are recomputed as the cache would
            weights = self._weights_cache[key] = compute()
        return weights

    def _step_impl(self, t, h):
        self._whole_step(t, h)

    def _steady_step(self) -> Callable:
        """``_general_step`` and the reads of the recorded outputs after it as one function
        (``harness.engine.straight_line``) of ``(t, h)``, for a master whose components all take
        the polynomial whole.  A step after the start-up - the history full, its newest point
        the one the inputs were sent ahead after, the last derivative weights matching the
        times - is made here, call for call and operation for operation as ``_general_step``,
        ``_send_ahead`` and ``_derivatives`` make it; any other goes to ``_general_step``."""
        points = self.degree
        source = Source(f"steady step through {points + 1} points", "t, h")
        master = source.name(self, "master")
        general = source.name(self._general_step, "general")
        source.line(f"history = {master}.history")
        source.line(f"after = {master}._ahead_after")
        source.line(f"if after is None or len(history) != {points} or history[-1] is not after:")
        source.line(f"    return {general}(t, h)")
        # the snapshot (``snapshot_of``): each input buffer's values as a list
        source.line("start = [" + ", ".join(
            "[" + ", ".join(f"{source.elements(values, 'live')}[{i}]" for i in range(len(values))) + "]"
            for values in self._live) + "]")
        source.line(f"{master}._ahead_after = None")
        add_steps(source, self._steps)
        add_visits(source, self._held_plan)
        source.line("history.append((t, start))")
        # ``_send_ahead`` at the step's end, ``_derivatives``' test of the last weights unrolled
        source.line("t_end = t + h")
        source.line(", ".join(f"(t{j}, past{j})" for j in range(points)) + ", = history")
        source.line(f"scale = t_end - t{points - 1}")        # the newest point's time: t
        source.line(f"last = {master}._last_derivatives")
        source.line("weights = None")
        source.line("if last is not None:")
        source.line("    nodes = last[0]")
        source.line(f"    if len(nodes) == {points}:")
        source.line("        " + ", ".join(f"n{j}" for j in range(points)) + ", = nodes")
        source.line("        if " + " and ".join(f"abs((t{j} - t_end) / scale - n{j}) < 1e-10"
                                                 for j in range(points)) + ":")
        source.line("            weights = last[1]")
        source.line("if weights is None:")
        source.line(f"    weights = {master}._derivatives(history, t_end, scale)")
        source.line(", ".join(f"f{j}" for j in range(points + 1)) + ", = weights[0]")
        if self._ahead_curved:
            source.line(", ".join(f"s{j}" for j in range(points + 1)) + ", = weights[1]")
            source.line("squared = scale * scale")
        self._add_ahead_writes(source, points)
        source.line(f"{master}._ahead_after = history[-1]")
        add_visits(source, self.system.dependent_reads)
        source.line(f"{master}._inputs_unsent = False")
        return source.function()

    def _general_step(self, t, h):
        """A step of this family, whatever the history (a start-up, inputs not sent ahead, a
        restored state); with ``reads_recorded`` it reads the recorded outputs after it too,
        as ``Master.step`` does otherwise."""
        start = self.snapshot()
        history = self.history
        # While the history is too short for the full degree and the stateful components
        # can roll back, a start-up step makes up for it.
        if len(history) < self.degree and self._can_roll_back:
            self._start_step(t, h, [*history, (t, start)])
        else:
            # Sent ahead after the last step - unless something (a restored state, a
            # history set from outside) came in between.
            after = self._ahead_after
            ahead = after is not None and bool(history) and history[-1] is after
            if not ahead or self._rest:
                self._hold(t, h, [*history, (t, start)], predict=False, rest_only=ahead)
            self._ahead_after = None
            # The shafts' torques are written before the next step: only fill the buffers.
            self._step_held(t, h)
            self._inputs_unsent = True
        history.append((t, start))
        if self.sends_ahead and (len(history) >= self.degree or not self._can_roll_back):   # not starting
            self._send_ahead(t + h)
        if self.reads_recorded and self.system.has_dependent_outputs:
            self.system.refresh_dependent(send=self._inputs_unsent)
            self._inputs_unsent = False

    def _start_step(self, t, h, points):
        """A start-up step of the master's order although the history is short: step
        with what extrapolation there is, then roll back and step again with the
        polynomial that also passes through the torques found at the end of the step,
        ``degree + 1`` times over (each pass gains an order)."""
        states = self.save_states()
        try:
            through = points
            for iteration in range(self.degree + 2):
                if iteration:
                    self.restore_states(states, t)
                    self.n_iterations += 1
                self._hold(t, h, through)
                self._step_stateful(t, h)
                self.system.propagate()
                through = points + [(t + h, self.snapshot())]
        finally:
            self._free_states(states)
        self._step_feedthrough(t, h)


class LinearExtrapolationMaster(ExtrapolatingJacobiMaster):
    name = "jacobi-linear"
    order = 2
    degree = 1
    description = "Jacobi with linear extrapolation of the coupling torques (ramped over the step)"


class QuadraticExtrapolationMaster(ExtrapolatingJacobiMaster):
    """Order 3 with the ramp.  Without it (``ramp=False``, or shafts with no derivative
    input) order 2: a held torque matches the mean but not the first moment."""

    name = "jacobi-quadratic"
    order = 3
    degree = 2
    description = "Jacobi with quadratic extrapolation of the coupling torques (ramped over the step)"


class MidpointPredictionMaster(JacobiMaster):
    """Jacobi, but the torque each shaft holds over the step is the coupling evaluated on
    the states *predicted at mid-step*: every connected output of a stateful component is
    extrapolated by its Taylor series, from the time derivatives its model description
    declares (``phi -> w -> a`` for a shaft).  The midpoint rule then approximates the
    torque's mean over the step with a tenth of the error of Adams-Bashforth
    extrapolation (h^2/24 against 5h^2/12), for one more coupling evaluation per step.
    Order 2 (a held torque cannot match its first moment, see the quadratic master)."""

    name = "jacobi-midpoint"
    order = 2
    description = "Jacobi with the coupling evaluated on the shafts' states predicted at mid-step"

    def __init__(self, system: System, step: float, **options):
        super().__init__(system, step, **options)
        scene = system.scene
        chains = {}
        for c in scene.connections:
            if c.source in system.stateful and c.target in system.feedthrough:
                chains[(c.source, c.output)] = system.derivative_chain(c.source, c.output)
        system.expose([f"{source}.{v}" for (source, _), chain in chains.items() for v in chain[1:]])
        system.propagate()       # fill the buffers of the newly exposed outputs
        # Per predicted input: its buffer, its position there, the source's output buffer and
        # the indices there of its Taylor terms (the output, then its derivatives).
        taylor = []
        predicted = {}
        for source in system.stateful:
            values = system.buffers[source][1]
            names = system.exposed[source]
            for share in system.writes[source]:
                if share.component.name not in system.feedthrough:
                    continue
                taylor += [(share.values, k, values, tuple(system.index[(source, v)] for v in chains[(source, names[i])]))
                           for k, i in enumerate(share.positions)]
                predicted.setdefault(share.component, []).append(source)
        self._taylor = tuple(taylor)
        # Each feedthrough target's predicted inputs sent in one call (its buffer's runs),
        # then the propagation from the feedthrough components: one plan, compiled once
        self._sends = system.send_plan([span for target, sources in predicted.items()
                                        for span in system.input_spans(target.name, sources)])
        self._from_feedthrough = system.partial_plan(self._feedthrough)
        self._predicted_plan = self._sends + self._from_feedthrough
        self._predict = self._prediction()
        self._compile_step()            # the propagation now reads the exposed derivatives too

    def _prediction(self) -> Callable:
        """``_predict(dt)``: write the outputs predicted ``dt`` ahead to the feedthrough
        components' inputs and propagate the coupling torques they give to the stateful
        components; one function (``harness.engine.straight_line``).  Each Taylor sum as
        sum() makes it: from 0.0, lowest term first."""
        source = Source("predict", "dt")
        factors = ("1.0", "dt", "f2", "f3")
        source.line("f2 = dt * dt / 2.0")
        if any(len(indices) > 3 for *_, indices in self._taylor):
            source.line("f3 = dt * dt * dt / 6.0")
        for target_values, k, values, indices in self._taylor:
            # a shaft's angle (phi, w, a) and speed (w, a): the value's factor 1.0 left out, as exact
            terms = [f"{source.elements(values, 'outputs')}[{i}]" if j == 0 else
                     f"{factors[j]} * {source.elements(values, 'outputs')}[{i}]" for j, i in enumerate(indices)]
            source.line(f"{source.elements(target_values, 'inputs')}[{k}] = 0.0 + " + " + ".join(terms))
        add_visits(source, self._predicted_plan)
        return source.function()

    def _step_impl(self, t, h):
        self._predict(0.5 * h)
        self._step_and_propagate(t, h)
