"""The adaptive masters: error-controlled communication steps (rolled back and retried
shorter when the error estimate exceeds the tolerance)."""
from __future__ import annotations

import math
from collections import deque
from typing import Callable

from harness.engine.masters.base import MasterFailure
from harness.engine.masters.explicit import ExtrapolatingJacobiMaster, lagrange_weights
from harness.engine.masters.iterative import TrapezoidalNewtonMaster
from harness.engine.system import System


class StepControl:
    """Error-controlled step size, shared by the adaptive masters: a step whose error
    estimate (relative to ``tolerance``) exceeds 1 is rolled back and retried shorter,
    and a PI controller (Gustafsson's gains) proposes the next one.  ``ESTIMATE_ORDER``
    is the power of ``h`` the estimate scales with."""

    adaptive = True
    SAFETY, GROWTH, SHRINK = 0.8, 3.0, 0.2
    ESTIMATE_ORDER = 2
    #: (low, high): an accepted step whose proposed change factor lies within keeps its
    #: size, where ``_keeps_step()`` says so
    KEEP: tuple[float, float] | None = None

    def _keeps_step(self) -> bool:
        return True

    def _init_control(self):
        if not (isinstance(self.tolerance, (int, float)) and 0.0 < self.tolerance < 1.0):
            raise ValueError(f"option 'tolerance' = {self.tolerance!r} is outside its allowed range (0, 1) "
                             "(relative torque error)")
        self.max_step = float(self.max_step) if self.max_step else (self.t_end - self.t) / 50.0
        self.h = min(self.h, self.max_step)
        self._previous_error = 1.0
        self._scale = 0.0

    def _clip(self, t, h):
        h = min(h, self.h)
        if self.t_end - (t + h) < 0.25 * h:        # do not leave a sliver before the end
            h = self.t_end - t
        return h

    def _controlled_step(self, t, h, attempt):
        """Step from ``t`` with ``attempt(h, states)`` (it steps the stateful components
        and returns ``(error, result)``) until the error is within tolerance or ``h`` at
        ``min_step``; propose the next step.  Returns ``(h, error, result)``."""
        states = self.save_states()
        try:
            while True:
                error, result = attempt(h, states)
                if error <= 1.0 or h <= self.min_step:
                    break
                self.restore_states(states, t)
                self.n_rejected += 1
                shrink = max(self.SHRINK, self.SAFETY * error ** (-1.0 / self.ESTIMATE_ORDER))
                h = max(self.min_step, h * shrink)
                self.system.propagate()            # the buffers back to the start of the step
        finally:
            self._free_states(states)
        k = self.ESTIMATE_ORDER
        bounded = max(error, 1e-10)
        factor = self.SAFETY * bounded ** (-0.3 / k) * (self._previous_error / bounded) ** (0.4 / k)
        self._previous_error = bounded
        if self.KEEP is not None and self.KEEP[0] <= factor <= self.KEEP[1] and self._keeps_step():
            factor = 1.0
        self.h = min(self.max_step, h * min(self.GROWTH, max(self.SHRINK, factor)))
        return h, error, result


class AdaptiveTrapezoidalMaster(StepControl, TrapezoidalNewtonMaster):
    """``trapezoidal-newton`` with the step chosen by an error estimate, for stiff
    couplings.

    Predictor-corrector estimate on the coupling torques at the end of the step: the
    converged ones against the quadratic through the last three communication points,
    extrapolated.  The trapezoidal coupling's local error is ``h^3/12`` times the
    torque's third derivative and the extrapolation's ``prod(t + h - t_j)/6`` times the
    same, so the local error is the fraction ``r / (1 + r)`` of their difference with
    ``r = h^3 / (2 prod(t + h - t_j))`` (1/13 for equal steps).  Relative to the torque
    scale (the largest coupling torque so far) it is compared with ``tolerance``; a step
    above it is rolled back and retried shorter, and a PI controller proposes the next.
    Short steps where the stiff mode rings, long ones (h * omega_n >> 1) where the motion
    is smooth: the trapezoidal coupling is stable at any step.  Where the stiff mode is
    unresolved the step changes seldom and by little (see ``KEEP``, ``UNRESOLVED``).

    The Newton iteration stops at ``iteration_tolerance`` relative to the same scale
    (default: a tenth of ``tolerance``: the iteration error stays below the step's own),
    starting from the torques the extrapolated end-of-step torques give, with interface
    Jacobians from ``InterfaceJacobian`` as the step size changes."""

    name = "adaptive-trapezoidal"
    description = "trapezoidal coupling (Newton, rollback) with error-controlled steps, for stiff couplings"
    options = {"tolerance": 1e-3, "iteration_tolerance": None, "max_iterations": 30, "min_step": 1e-8,
               "max_step": None}
    ESTIMATE_ORDER = 3
    START_FRACTION = 0.5    # while fewer than three points are known: a cautious share of the difference
    # Each change of the step shifts the trapezoidal coupling's small forced-response
    # error, which excites the stiff mode, and at h * omega_n > 1 the scheme does not damp
    # it: the unresolved mode rings on and the error estimate sees it.  So the step changes
    # seldom and little.  It grows by at most 10 % (shrinks by at most half) at a time; with
    # the usual factor 3 the stiff scene rang on at about 990 rad/s with 200 times the
    # reference's amplitude there.  And where the mode is unresolved, an accepted step is
    # kept while the controller's proposal lies within KEEP (RADAU5 keeps its step within
    # 1.0-1.2 to save factorisations): no small cuts while within tolerance, no small gains.
    # Changing it at every step kept the stiff scene near h * omega_n = 2.6 in a cycle of
    # 10 % rises and drops, with 10-35 % more steps for the same error (three load seeds);
    # keeping it also where the mode is resolved cost 10 % more steps there.  A wider upper
    # bound (1.5) makes steps that must grow back by decades after an event creep (55 times
    # the steps on kavz685_step_tiny_inertia, where this rule halves them).
    GROWTH, SHRINK = 1.1, 0.5
    KEEP = (0.6, 1.2)
    # The interface Jacobian says how resolved the stiff mode is without knowing the
    # models: the trapezoidal G(u) moves the end torques by about (h * omega_n)^2 / 4 per
    # unit of held torque (a spring c between inertias: c h^2 / (4 I_red)), so a row sum
    # of |dG/du| above 1/4 means h * omega_n above about 1.
    UNRESOLVED = 0.25

    def _keeps_step(self) -> bool:
        jacobian = self._jacobian
        return jacobian is not None and max(sum(abs(x) for x in row) for row in jacobian) >= self.UNRESOLVED

    def __init__(self, system: System, step: float, **options):
        super().__init__(system, step, **options)
        self._init_control()
        if self.iteration_tolerance is None:
            self.iteration_tolerance = 0.1 * self.tolerance
        self._ends: deque = deque(maxlen=2)     # (time, torques) at the last communication points before t

    def _step_impl(self, t, h):
        start = self.current_inputs()
        self._scale = max(self._scale, max(abs(x) for x in start))
        points = list(self._ends) + [(t, start)]
        times = [p[0] for p in points]
        full = len(points) == 3

        def attempt(h, states):
            weights = lagrange_weights(times, t + h)
            predicted = [sum(w * p[1][i] for w, p in zip(weights, points)) for i in range(len(start))]
            try:      # from the held torques that the extrapolated end-of-step torques give
                u = self._solve(t, h, states, start, self.iteration_tolerance,
                                [0.5 * (a + b) for a, b in zip(start, predicted)])
            except MasterFailure:
                if h <= self.min_step:
                    raise
                return 1.0 / self.SHRINK ** 3, None      # not converged: shrink hard and retry
            end = self.current_inputs()                 # tau(t + h) with the converged torques
            if full:
                r = h ** 3 / (2.0 * math.prod(t + h - x for x in times))
                fraction = r / (1.0 + r)
            else:
                fraction = self.START_FRACTION
            scale = max(self._scale, max(abs(x) for x in end)) or 1.0
            difference = max(abs(a - b) for a, b in zip(end, predicted))
            return fraction * difference / (self.tolerance * scale), u

        h, _, _ = self._controlled_step(t, self._clip(t, h), attempt)
        self._ends.append((t, start))
        self._send_end_torques()
        self._step_feedthrough(t, h)
        return h


# -- adaptive step size ----------------------------------------------------------------------------

class AdaptiveMaster(StepControl, ExtrapolatingJacobiMaster):
    """``jacobi-quadratic`` (ramped quadratic extrapolation of the coupling torques, over
    variable steps) with the step chosen by an error estimate.

    Predictor-corrector estimate (Milne's device): the extrapolating polynomial's value at
    the end of the step against the torque the coupling actually gives there.  For
    degree ``d`` the error of the mean over the step is a fixed fraction of that
    difference (``MEAN_FRACTION``, from the polynomial error term); relative to the torque
    scale (the largest coupling torque so far) it is compared with ``tolerance``.  A step
    above tolerance is rolled back (full FMU states) and retried shorter; the next step
    comes from a PI controller (Gustafsson's gains).  While the history is short the
    degree is lower, so the start-up transient is taken with short steps.

    The power-bond energy residual at the coupling - what OSP's ECCO controls - is
    accumulated as a diagnostic (``bond_energy_residual_J``): the work the shafts received
    minus what the torques found at both ends of each step account for (trapezoidal rule).
    """

    name = "adaptive"
    order = 3
    degree = 2
    description = "ramped quadratic extrapolation with error-controlled steps (predictor-corrector, PI)"
    options = {"tolerance": 1e-3, "min_step": 1e-8, "max_step": None, "ramp": True}

    steady_steps = False        # every step is its own (``_step_impl``), none compiled whole
    MEAN_FRACTION = (0.5, 5.0 / 12.0, 3.0 / 8.0)   # by degree: mean error / end-point error
    ESTIMATE_ORDER = 3

    def __init__(self, system: System, step: float, **options):
        super().__init__(system, step, **options)
        self._init_control()
        self._speeds = self._bond_speeds()
        self._read_speeds = _reader(self._speeds)
        self.bond_energy_residual = 0.0
        # an attempt's steps and the propagation after them, one function (``System.runner``)
        self._attempt_step = system.runner(system.propagation_plan, self._stateful_steps)

    def _bond_speeds(self):
        """For each coupled input (a torque on a shaft), the speed at the same port: the
        component's exposed output in rad/s, if it has one."""
        system = self.system
        speeds = []
        for inputs in self.coupled_inputs:
            target = inputs.component
            candidates = [v for v in system.exposed[target.name] if _unit(target, v) == "rad/s"]
            index = system.index[(target.name, candidates[0])] if candidates else None
            speeds.append((system.buffers[target.name][1], index))
        return speeds

    def counters(self) -> dict:
        return {**super().counters(), "bond_energy_residual_J": self.bond_energy_residual}

    def _step_impl(self, t, h):
        snapshot = self.snapshot
        start = snapshot()
        speeds = self._read_speeds()
        points = list(self.history) + [(t, start)]
        fraction = self.MEAN_FRACTION[len(points) - 1]

        def attempt(h, states):
            predicted = self._hold(t, h, points)
            self._attempt_step(t, h)
            end = snapshot()
            # the largest torque so far and the largest miss, as max() finds them (the first
            # of equals kept, a NaN only where it comes first), without generator frames
            scale = self._scale
            for torques in start + end:
                for x in torques:
                    if abs(x) > scale:
                        scale = abs(x)
            self._scale = scale
            difference = None
            for ps, es in zip(predicted, end):
                for p, e in zip(ps, es):
                    miss = abs(p - e)
                    if difference is None or miss > difference:
                        difference = miss
            return fraction * difference / (self.tolerance * (self._scale or 1.0)), end

        h, error, end = self._controlled_step(t, self._clip(t, h), attempt)
        if error > 1.0:
            raise MasterFailure(f"{self.name}: the step size fell to its minimum {self.min_step:.3g} s at "
                                f"t = {t:.9g} s with the error estimate still {error:.3g} times the tolerance "
                                f"{self.tolerance:g}; the coupling torque changes too fast for this tolerance")
        # ECCO's power-bond residual: work given (held means) against work accounted for.
        end_speeds = self._read_speeds()
        for held, ss, es, w0, w1 in zip(self._held, start, end, speeds, end_speeds):
            values, n, ramped = held.values, held.n, held.ramped
            for i in range(n):
                mean = values[i] + (0.5 * values[n + i] * h if ramped else 0.0)
                self.bond_energy_residual += h * (mean - 0.5 * (ss[i] + es[i])) * 0.5 * (w0 + w1)
        self.history.append((t, start))
        self._step_feedthrough(t, h)
        return h


def _reader(speeds) -> Callable[[], list[float]]:
    """A function that reads the bond speeds ``[(buffer, index or None)]``: the value at
    each index, 0.0 where there is none; two speeds (a driveline's shafts) unrolled."""
    if len(speeds) == 2 and all(i is not None for _, i in speeds):
        (a, i), (b, j) = speeds
        return lambda: [a[i], b[j]]
    return lambda: [values[i] if i is not None else 0.0 for values, i in speeds]


def _unit(component, name):
    variable = component.variable(name)
    return variable.unit or (variable.declaredType.unit if variable.declaredType is not None else None)
