"""Co-simulation masters: how a system of FMUs is stepped from one communication point
to the next.

Like scipy's ``OdeSolver``, one base class states the contract and keeps the books, and
each master implements one step in ``_step_impl``:

* ``step(h)`` advances the system from ``t`` to ``t + h`` and leaves it *consistent*
  at the new time: every connected input holds its source's current output, so a
  recorder can read any exposed value.  It raises ``FmuCallError`` (from the component
  that failed) and otherwise returns nothing.
* Counters: ``n_steps``, ``n_rollbacks``, ``n_iterations``; ``fmu_calls`` counts the
  FMI calls on the hot path (read, write, doStep) of all components.
* ``order``: the global convergence order the master promises on smooth problems
  (the tests check it against the monolithic reference).

Masters know nothing of the models: only the system's stateful components (no direct
feedthrough, stepped in scene order) and its propagation.
"""
from __future__ import annotations

from collections import deque

import numpy as np

from .system import System


class Master:
    name = "abstract"
    order = 0
    description = ""

    def __init__(self, system: System, step: float):
        if not step > 0.0:
            raise ValueError(f"communication step must be > 0, got {step}")
        self.system = system
        self.h = float(step)
        self.t = system.scene.experiment.start
        self.n_steps = 0
        self.n_rollbacks = 0
        self.n_iterations = 0

    @property
    def fmu_calls(self) -> int:
        return self.system.fmu_calls

    def step(self, h: float | None = None, t_next: float | None = None):
        """Advance by ``h`` (default: the master's step).  ``t_next`` may give the
        target time exactly, to avoid accumulating rounding in ``t``."""
        h = self.h if h is None else h
        target = self.t + h if t_next is None else t_next
        self._step_impl(self.t, target - self.t)
        self.t = target
        self.n_steps += 1

    def _step_impl(self, t: float, h: float):
        raise NotImplementedError

    def counters(self) -> dict:
        return {"steps": self.n_steps, "fmu_calls": self.fmu_calls, "rollbacks": self.n_rollbacks,
                "iterations": self.n_iterations}


class JacobiMaster(Master):
    """All components step in parallel on the inputs of ``t`` (zero-order hold), then
    the outputs of ``t + h`` are propagated."""

    name = "jacobi"
    order = 1
    description = "parallel steps, inputs held from the start of the step (zero-order hold)"

    def _step_impl(self, t, h):
        system = self.system
        for component in system.components.values():
            component.do_step(t, h)
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
        for name in system.order:
            if name in system.feedthrough:
                components[name].do_step(t, h)


def extrapolation_weights(past_times, t: float, h: float) -> np.ndarray:
    """Weights ``w_j`` such that ``sum_j w_j u(t_j)`` is the mean over ``[t, t + h]`` of
    the polynomial through the points ``(t_j, u(t_j))``.

    A shaft FMU holds its input torque over a step, so what matters is the torque's
    mean over the step; for uniform steps these are the Adams-Bashforth weights
    (degree 1: -1/2, 3/2; degree 2: 5/12, -16/12, 23/12), one order above the degree."""
    nodes = (np.asarray(past_times, dtype=float) - t) / h          # <= 0, scaled to the step
    degree = len(nodes) - 1
    vandermonde = nodes[:, None] ** np.arange(degree + 1)[None, :]
    means = 1.0 / np.arange(1, degree + 2)                         # mean of x^k over [0, 1]
    return np.linalg.solve(vandermonde.T, means)


class ExtrapolatingJacobiMaster(JacobiMaster):
    """Jacobi, but each stateful component's inputs are extrapolated from the last
    ``degree + 1`` communication points instead of held: the value held over the step
    is the mean of the extrapolating polynomial over it.  Order ``degree + 1`` on smooth
    problems; the first steps use the history there is."""

    degree = 1

    def __init__(self, system: System, step: float):
        super().__init__(system, step)
        # The input buffers of stateful components, as the last propagation left them.
        self._inputs = [(target, vrs, values) for writes in system.writes.values()
                        for target, vrs, values, _ in writes if target.name in system.stateful]
        self._history: deque = deque(maxlen=self.degree + 1)
        self._weights_cache: dict = {}

    def _step_impl(self, t, h):
        self._history.append((t, [list(values) for _, _, values in self._inputs]))
        if len(self._history) > 1:
            times = [entry[0] for entry in self._history]
            key = tuple(round((x - t) / h, 9) for x in times)
            weights = self._weights_cache.get(key)
            if weights is None:
                weights = self._weights_cache.setdefault(key, extrapolation_weights(times, t, h).tolist())
            for k, (target, vrs, values) in enumerate(self._inputs):
                for i in range(len(values)):
                    values[i] = sum(w * entry[1][k][i] for w, entry in zip(weights, self._history))
                target.write(vrs, values)
        super()._step_impl(t, h)


class LinearExtrapolationMaster(ExtrapolatingJacobiMaster):
    name = "jacobi-linear"
    order = 2
    degree = 1
    description = "Jacobi with linear extrapolation of the coupling torques (mean over the step)"


class QuadraticExtrapolationMaster(ExtrapolatingJacobiMaster):
    """Order 2, not 3: a shaft holds its input over the step, so its speed sees the
    torque's mean (third order here) but its angle sees the torque's first moment, which
    a held value matches only to second order.  Beating that needs input derivatives
    (fmi2SetRealInputDerivatives), which pythonfmu FMUs do not support."""

    name = "jacobi-quadratic"
    order = 2
    degree = 2
    description = "Jacobi with quadratic extrapolation of the coupling torques (mean over the step)"


MASTERS = {cls.name: cls for cls in (JacobiMaster, GaussSeidelMaster, LinearExtrapolationMaster,
                                     QuadraticExtrapolationMaster)}


def make(name: str, system: System, step: float) -> Master:
    try:
        return MASTERS[name](system, step)
    except KeyError:
        raise ValueError(f"unknown master '{name}' (known: {', '.join(MASTERS)})") from None
