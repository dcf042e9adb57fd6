"""The explicit masters: each step uses only values known at its start (zero-order hold,
Gauss-Seidel's order, extrapolated or mid-step-predicted inputs); no rollback."""
from __future__ import annotations

import ctypes
import math
from collections import deque

from harness.engine.masters.base import Master
from harness.engine.system import System


class JacobiMaster(Master):
    """All components step in parallel on the inputs of ``t`` (zero-order hold), then
    the outputs of ``t + h`` are propagated."""

    name = "jacobi"
    order = 1
    description = "parallel steps, inputs held from the start of the step (zero-order hold)"

    def _step_impl(self, t, h):
        system = self.system
        system.step_with(self._steps, t, h)
        system.propagate()


class GaussSeidelMaster(Master):
    """Stateful components step one after the other; after each, its new outputs are
    propagated (through the coupling, evaluated on the shafts' current states) before
    the next one steps."""

    name = "gauss-seidel"
    order = 1
    description = "sequential steps, each shaft sees the coupling on the latest states"

    def _step_impl(self, t, h):
        system = self.system
        components = system.components
        for name in system.stateful:
            components[name].do_step(t, h)
            system.propagate([name])
        self._step_feedthrough(t, h)


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
    means, slopes, ends = [], [], []
    for j, xj in enumerate(nodes):
        basis = [1.0]                                   # coefficients of L_j, lowest power first
        for m, xm in enumerate(nodes):
            if m != j:
                scale = 1.0 / (xj - xm)
                shifted = [0.0] + basis                 # x * L
                basis = [(shifted[k] - xm * (basis[k] if k < len(basis) else 0.0)) * scale
                         for k in range(len(shifted))]
        means.append(sum(c / (k + 1) for k, c in enumerate(basis)))
        slopes.append(12.0 * sum(c * (1.0 / (k + 2) - 0.5 / (k + 1)) for k, c in enumerate(basis)))
        ends.append(sum(basis))
    return means, slopes, ends


def lagrange_weights(nodes, x: float) -> list[float]:
    """Weights of the values at ``nodes`` in the interpolating polynomial's value at ``x``."""
    return [math.prod((x - m) / (n - m) for m in nodes if m != n) for n in nodes]


class ExtrapolatingJacobiMaster(JacobiMaster):
    """Jacobi, but each stateful component's inputs are extrapolated from the last
    ``degree + 1`` communication points instead of held.  Where the component declares
    a derivative input (a shaft's ``tau_rate``) it gets the ramp that matches the
    extrapolating polynomial's mean and first moment over the step (first-order hold),
    otherwise the mean, held.  Order ``degree + 1`` with the ramp, at most 2 without;
    the first steps use the history there is."""

    degree = 1
    options = {"ramp": True}

    def __init__(self, system: System, step: float, **options):
        super().__init__(system, step, **options)
        self.coupled_inputs = self._coupled_inputs()
        rates = self._rate_inputs(self.coupled_inputs) if self.ramp else [None] * len(self.coupled_inputs)
        # One write per component: the inputs and, after them, their rates.
        self._held = []
        for (target, vrs, values), rate in zip(self.coupled_inputs, rates):
            n = len(values)
            if rate is None:
                self._held.append((target, vrs, (ctypes.c_double * n)(), n, False))
            else:
                both = (ctypes.c_uint * (2 * n))(*vrs, *rate[0])
                self._held.append((target, both, (ctypes.c_double * (2 * n))(), n, True))
        # The last ``degree`` communication points before the current one.
        self.history: deque = deque(maxlen=self.degree)
        self._weights_cache: dict = {}
        self._can_roll_back = all(system.components[n].description.coSimulation.canGetAndSetFMUstate
                                  for n in system.stateful)
        self._held_plan = system.held_plan({target.name for target, _, _ in self.coupled_inputs})
        # The held inputs' writes compiled once, as a propagation that reads nothing.
        self._sends = system.send_plan([(target, vrs, values) for target, vrs, values, _, _ in self._held])

    def _hold(self, t, h, points, predict: bool = True):
        """Write the inputs for the step ``[t, t + h]`` from the polynomial through
        ``points`` (``[(time, values per input)]``); return its values at ``t + h``
        (``None`` unless ``predict``)."""
        weights = self._weights([p[0] for p in points], t, h)
        ends = [] if predict else None
        k = -1
        for _, _, values, n, ramped in self._held:
            k += 1
            column = [p[1][k] for p in points]       # this component's inputs at each point
            component_ends = []
            for i in range(n):
                mean = change = end = 0.0
                for (w_mean, w_slope, w_end), inputs in zip(weights, column):
                    u = inputs[i]
                    mean += w_mean * u
                    change += w_slope * u         # slope * h
                    end += w_end * u
                if ramped:
                    values[i] = mean - 0.5 * change
                    values[n + i] = change / h
                else:
                    values[i] = mean
                component_ends.append(end)
            if predict:
                ends.append(component_ends)
        self.system.propagate_with(self._sends)
        return ends

    def _weights(self, times, t, h):
        key = tuple([round((x - t) / h, 9) for x in times])
        weights = self._weights_cache.get(key)
        if weights is None:
            if len(self._weights_cache) > 32:      # variable steps: do not grow without bound
                self._weights_cache.clear()
            weights = self._weights_cache[key] = list(zip(*extrapolation_weights(times, t, h)))
        return weights

    def _starting(self) -> bool:
        """Whether the history is still too short for the full degree and the stateful
        components can roll back to make up for it."""
        return len(self.history) < self.degree and self._can_roll_back

    def _step_impl(self, t, h):
        start = [list(values) for _, _, values in self.coupled_inputs]
        points = [*self.history, (t, start)]
        if self._starting():
            self._start_step(t, h, points)
        else:
            self._hold(t, h, points, predict=False)
            system = self.system
            system.step_with(self._steps, t, h)
            # The shafts' torques are written by the next _hold: only fill the buffers.
            system.propagate_with(self._held_plan)
            self._inputs_unsent = True
        self.history.append((t, start))

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
                through = points + [(t + h, [list(values) for _, _, values in self.coupled_inputs])]
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
        # Per source and feedthrough target: the buffer indices of each input's Taylor terms.
        self._predictions = []
        predicted = {}
        for source in system.stateful:
            values = system.buffers[source][1]
            names = system.exposed[source]
            for target, vrs, target_values, positions in system.writes[source]:
                if target.name not in system.feedthrough:
                    continue
                terms = [[system.index[(source, v)] for v in chains[(source, names[i])]] for i in positions]
                self._predictions.append((values, target_values, terms))
                predicted.setdefault(target, []).append(source)
        # Each feedthrough target's predicted inputs sent in one call (its buffer's runs)
        self._sends = [(target, vrs, target_values) for target, sources in predicted.items()
                       for vrs, target_values in system.input_spans(target.name, sources)]

    def _predict(self, dt):
        """Write the outputs predicted ``dt`` ahead to the feedthrough components' inputs
        and propagate the coupling torques they give to the stateful components."""
        factors = (1.0, dt, dt * dt / 2.0, dt * dt * dt / 6.0)
        for values, target_values, terms in self._predictions:
            for k, indices in enumerate(terms):
                target_values[k] = sum(f * values[i] for f, i in zip(factors, indices))
        for target, vrs, target_values in self._sends:
            target.write(vrs, target_values)
        self.system.propagate(self._feedthrough)

    def _step_impl(self, t, h):
        self._predict(0.5 * h)
        super()._step_impl(t, h)
