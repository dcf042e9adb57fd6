"""Co-simulation masters: how a system of FMUs is stepped from one communication point
to the next.

Like scipy's ``OdeSolver``, one base class states the contract and keeps the books, and
each master implements one step in ``_step_impl``:

* ``step(h)`` advances the system from ``t`` to ``t + h`` and leaves it *consistent*
  at the new time: every connected input holds its source's current output, so a
  recorder can read any exposed value.  It raises ``FmuCallError`` (from the component
  that failed) and otherwise returns nothing.
* Counters: ``n_steps`` (accepted steps), ``n_rollbacks``, ``n_iterations`` (coupled
  evaluations beyond the first in a step, including those for Jacobians), ``n_rejected``;
  ``fmu_calls`` counts the FMI calls on the hot path (read, write, doStep and the state
  calls) of all components.
* Variable steps: an ``adaptive`` master chooses its own step; ``step()`` without
  arguments takes the step it proposes (``h``), clipped to ``t_end``.
* A master that cannot make a step (an iteration that does not converge, a step size
  that underflows) raises ``MasterFailure`` saying where, when and why.
* ``order``: the global convergence order the master promises on smooth problems
  (the tests check it against the monolithic reference).

Masters know nothing of the models: only the system's stateful components (no direct
feedthrough, stepped in scene order) and its propagation.
"""
from __future__ import annotations

import ctypes
import math
from collections import deque

from .system import System


class MasterFailure(RuntimeError):
    """A master could not make a step; the system is left at the last accepted step."""


class Master:
    name = "abstract"
    order = 0
    description = ""
    adaptive = False
    #: options ``make`` accepts for this master, with their defaults
    options: dict = {}

    def __init__(self, system: System, step: float, **options):
        if not step > 0.0:
            raise ValueError(f"communication step must be > 0, got {step}")
        unknown = set(options) - set(self.options)
        if unknown:
            raise ValueError(f"master '{self.name}' takes no option {', '.join(sorted(unknown))}"
                             + (f" (it takes: {', '.join(self.options)})" if self.options else ""))
        for key, default in self.options.items():
            setattr(self, key, options.get(key, default))
        self.system = system
        self.h = float(step)
        self.t = system.scene.experiment.start
        self.t_end = system.scene.experiment.stop
        self.n_steps = 0
        self.n_rollbacks = 0
        self.n_iterations = 0
        self.n_rejected = 0
        self._stateful = [system.components[n] for n in system.stateful]
        self._feedthrough = [n for n in system.order if n in system.feedthrough]
        self._feedthrough_components = [system.components[n] for n in self._feedthrough]
        #: set by a step that left the coupled inputs in their buffers only (a held plan)
        self._inputs_unsent = False

    @property
    def fmu_calls(self) -> int:
        return self.system.fmu_calls

    def step(self, h: float | None = None, t_next: float | None = None):
        """Advance by ``h`` (default: the master's step).  ``t_next`` may give the
        target time exactly, to avoid accumulating rounding in ``t``."""
        h = self.h if h is None else h
        target = self.t + h if t_next is None else t_next
        taken = self._step_impl(self.t, target - self.t)
        if self.system.has_dependent_outputs:
            # recorded outputs that depend on inputs (a shaft's acceleration on its torque)
            # were read before the step's last inputs were written: read them with those
            self.system.refresh_dependent(send=self._inputs_unsent)
            self._inputs_unsent = False
        # An adaptive master may take less than it was offered; it returns what it took.
        self.t = target if taken is None else self.t + taken
        self.n_steps += 1

    def _step_impl(self, t: float, h: float):
        """Advance the system from ``t`` by ``h``; return ``None``, or the step actually
        taken if it is shorter (adaptive masters)."""
        raise NotImplementedError

    def counters(self) -> dict:
        return {"steps": self.n_steps, "fmu_calls": self.fmu_calls, "rollbacks": self.n_rollbacks,
                "iterations": self.n_iterations, "rejected": self.n_rejected}

    # -- shared helpers ------------------------------------------------------------------------
    def _coupled_inputs(self):
        """The input buffers of stateful components that propagation fills (the coupling
        torques), as the last propagation left them: ``[(component, vrs, values)]``."""
        system = self.system
        return [(target, vrs, values) for writes in system.writes.values()
                for target, vrs, values, _ in writes if target.name in system.stateful]

    def _rate_inputs(self, inputs):
        """For each ``(component, vrs, values)`` of ``inputs``: the buffer of the inputs
        declared as their time derivatives (FMI ``derivative`` attribute; a shaft's
        ``tau_rate``), or None where a component has none for one of them."""
        out = []
        for target, vrs, _ in inputs:
            rate_of = {v.derivative.valueReference: v.name for v in target.description.modelVariables
                       if v.derivative is not None and v.causality == "input"}
            names = [rate_of.get(vr) for vr in vrs]
            out.append(target.real_buffer(names) if all(names) else None)
        return out

    # Full FMU states of the stateful components, for masters that roll back.
    def _save_states(self) -> list:
        return [component.save_state() for component in self._stateful]

    def _restore_states(self, states, t):
        for component, state in zip(self._stateful, states):
            component.restore_state(state, t)
        self.n_rollbacks += 1

    def _free_states(self, states):
        for component, state in zip(self._stateful, states):
            component.free_state(state)

    def _step_stateful(self, t, h):
        for component in self._stateful:
            component.do_step(t, h)

    def _step_feedthrough(self, t, h):
        for component in self._feedthrough_components:
            component.do_step(t, h)


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


def _lagrange_weights(nodes, x: float) -> list[float]:
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
        self._inputs = self._coupled_inputs()
        rates = self._rate_inputs(self._inputs) if self.ramp else [None] * len(self._inputs)
        # One write per component: the inputs and, after them, their rates.
        self._held = []
        for (target, vrs, values), rate in zip(self._inputs, rates):
            n = len(values)
            if rate is None:
                self._held.append((target, vrs, (ctypes.c_double * n)(), n, False))
            else:
                both = (ctypes.c_uint * (2 * n))(*vrs, *rate[0])
                self._held.append((target, both, (ctypes.c_double * (2 * n))(), n, True))
        # The last ``degree`` communication points before the current one.
        self._history: deque = deque(maxlen=self.degree)
        self._weights_cache: dict = {}
        self._can_roll_back = all(system.components[n].description.coSimulation.canGetAndSetFMUstate
                                  for n in system.stateful)
        self._all_components = list(system.components.values())
        self._held_plan = system.held_plan({target.name for target, _, _ in self._inputs})

    def _hold(self, t, h, points):
        """Write the inputs for the step ``[t, t + h]`` from the polynomial through
        ``points`` (``[(time, values per input)]``); return its values at ``t + h``."""
        weights = self._weights([p[0] for p in points], t, h)
        ends = []
        for k, (target, vrs, values, n, ramped) in enumerate(self._held):
            component_ends = []
            for i in range(n):
                mean = change = end = 0.0
                for (w_mean, w_slope, w_end), point in zip(weights, points):
                    u = point[1][k][i]
                    mean += w_mean * u
                    change += w_slope * u         # slope * h
                    end += w_end * u
                if ramped:
                    values[i] = mean - 0.5 * change
                    values[n + i] = change / h
                else:
                    values[i] = mean
                component_ends.append(end)
            target.write(vrs, values)
            ends.append(component_ends)
        return ends

    def _weights(self, times, t, h):
        key = tuple(round((x - t) / h, 9) for x in times)
        weights = self._weights_cache.get(key)
        if weights is None:
            if len(self._weights_cache) > 32:      # variable steps: do not grow without bound
                self._weights_cache.clear()
            weights = self._weights_cache[key] = list(zip(*extrapolation_weights(times, t, h)))
        return weights

    def _starting(self) -> bool:
        """Whether the history is still too short for the full degree and the stateful
        components can roll back to make up for it."""
        return len(self._history) < self.degree and self._can_roll_back

    def _step_impl(self, t, h):
        start = [list(values) for _, _, values in self._inputs]
        points = list(self._history) + [(t, start)]
        if self._starting():
            self._start_step(t, h, points)
        else:
            self._hold(t, h, points)
            for component in self._all_components:
                component.do_step(t, h)
            # The shafts' torques are written by the next _hold: only fill the buffers.
            self.system.propagate_with(self._held_plan)
            self._inputs_unsent = True
        self._history.append((t, start))

    def _start_step(self, t, h, points):
        """A start-up step of the master's order although the history is short: step
        with what extrapolation there is, then roll back and step again with the
        polynomial that also passes through the torques found at the end of the step,
        ``degree + 1`` times over (each pass gains an order)."""
        states = self._save_states()
        try:
            through = points
            for iteration in range(self.degree + 2):
                if iteration:
                    self._restore_states(states, t)
                    self.n_iterations += 1
                self._hold(t, h, through)
                self._step_stateful(t, h)
                self.system.propagate()
                through = points + [(t + h, [list(values) for _, _, values in self._inputs])]
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
        for source in system.stateful:
            values = system.buffers[source][1]
            names = system.exposed[source]
            for target, vrs, target_values, positions in system.writes[source]:
                if target.name not in system.feedthrough:
                    continue
                terms = [[system.index[(source, v)] for v in chains[(source, names[i])]] for i in positions]
                self._predictions.append((values, target, vrs, target_values, terms))

    def _predict(self, dt):
        """Write the outputs predicted ``dt`` ahead to the feedthrough components' inputs
        and propagate the coupling torques they give to the stateful components."""
        factors = (1.0, dt, dt * dt / 2.0, dt * dt * dt / 6.0)
        for values, target, vrs, target_values, terms in self._predictions:
            for k, indices in enumerate(terms):
                target_values[k] = sum(f * values[i] for f, i in zip(factors, indices))
            target.write(vrs, target_values)
        self.system.propagate(self._feedthrough)

    def _step_impl(self, t, h):
        self._predict(0.5 * h)
        super()._step_impl(t, h)


# -- iterative coupling with rollback ------------------------------------------------------------

def _solve_linear(matrix, rhs) -> list[float]:
    """``x`` with ``matrix @ x = rhs`` (nested lists), by Gaussian elimination with partial
    pivoting.  Plain Python: a driveline couples two or three torques, and at that size
    numpy's call overhead is ten times the arithmetic (this runs on every step of an
    iterating master)."""
    n = len(rhs)
    rows = [list(row) + [b] for row, b in zip(matrix, rhs)]
    for k in range(n):
        pivot = max(range(k, n), key=lambda i: abs(rows[i][k]))
        rows[k], rows[pivot] = rows[pivot], rows[k]
        head = rows[k]
        if head[k] == 0.0:
            raise ZeroDivisionError("singular interface matrix")
        for row in rows[k + 1:]:
            factor = row[k] / head[k]
            if factor:
                for j in range(k, n + 1):
                    row[j] -= factor * head[j]
    x = [0.0] * n
    for k in range(n - 1, -1, -1):
        row = rows[k]
        x[k] = (row[n] - sum(row[j] * x[j] for j in range(k + 1, n))) / row[k]
    return x


class InterfaceJacobian:
    """The interface Jacobian ``dG/du`` of a coupling iteration as a function of the
    step ``h``, from finite-difference Jacobians taken at earlier steps.

    A shaft holding a torque ``u`` over ``h`` ends with its angle moved by ``h^2 / (2 I)``
    and its speed by ``h / I`` per unit of ``u``; a coupling linear in angles and speeds
    then gives ``dG/du = A h + B h^2`` exactly.  Two Jacobians at different steps fix
    ``A`` and ``B``, so a step-size controller that changes ``h`` every step needs no new
    finite differences while the model serves (a shaft's own damping and a nonlinear
    coupling make it approximate; Newton's iteration and Broyden's updates absorb that).
    With one Jacobian only the step it was taken at is served.  Matrices are nested
    lists (see ``_solve_linear``)."""

    SAME_STEP = 0.02     # relative: steps closer than this are the same for the model
    DISTINCT = 0.3       # relative: two samples this far apart make a well-posed fit

    def __init__(self):
        self._samples: list[tuple[float, list]] = []   # the newest last
        self._fit = None                               # (A, B)

    def add(self, h: float, jacobian):
        self._samples = [(x, j) for x, j in self._samples if abs(x - h) > self.SAME_STEP * h][-1:]
        self._samples.append((h, [[float(v) for v in row] for row in jacobian]))
        self._fit = None
        if len(self._samples) == 2:
            (h1, j1), (h2, j2) = self._samples
            if abs(h1 - h2) > self.DISTINCT * max(h1, h2):
                determinant = h1 * h2 * (h2 - h1)
                self._fit = ([[(x1 * h2 * h2 - x2 * h1 * h1) / determinant for x1, x2 in zip(r1, r2)]
                              for r1, r2 in zip(j1, j2)],
                             [[(x2 * h1 - x1 * h2) / determinant for x1, x2 in zip(r1, r2)]
                              for r1, r2 in zip(j1, j2)])

    def at(self, h: float) -> list | None:
        if self._fit is not None:
            a, b = self._fit
            hh = h * h
            return [[x * h + y * hh for x, y in zip(ra, rb)] for ra, rb in zip(a, b)]
        for x, jacobian in self._samples:
            if abs(x - h) <= self.SAME_STEP * h:
                return [list(row) for row in jacobian]
        return None


class IterativeMaster(Master):
    """Implicit coupling: the torques ``u`` the shafts hold over a step are iterated until
    they agree with what the coupling gives on the states they produce,

        implicit:     u = tau(t + h)                    (order 1, damps like backward Euler)
        trapezoidal:  u = (tau(t) + tau(t + h)) / 2     (order 2; for a linear spring at a
                      constant ratio, the shafts receive exactly the energy the spring gives)

    Every evaluation rolls the stateful components back to the start of the step (their
    full FMU state) and steps them again.  ``fixed-point`` iterates ``u <- G(u)`` and
    converges only while the coupling is soft for the step (``c h^2 / I`` well below 1);
    ``newton`` solves ``G(u) - u = 0`` with an interface Jacobian from finite differences
    over rolled-back steps, reused across steps while it keeps converging fast.  The
    first guess extrapolates the last accepted torques linearly.

    Direct-feedthrough components are taken to be algebraic (their outputs functions of
    their inputs, as the coupling's are): they are not rolled back and step once.
    """

    scheme = "implicit"
    solver = "newton"
    options = {"tolerance": 1e-7, "max_iterations": 30}

    #: scheme -> (order, what the shafts hold)
    SCHEMES = {"implicit": (1, "end-of-step torques"), "trapezoidal": (2, "mean of both ends' torques")}

    def __init_subclass__(cls, **kwargs):
        """A subclass that picks a scheme and a solver is named and described by them."""
        super().__init_subclass__(**kwargs)
        if "scheme" in cls.__dict__ or "solver" in cls.__dict__:
            cls.order, held = cls.SCHEMES[cls.scheme]
            cls.name = f"{cls.scheme}-{cls.solver}"
            cls.description = f"{cls.scheme} coupling ({held}), {cls.solver} iteration with rollback"

    def __init__(self, system: System, step: float, **options):
        super().__init__(system, step, **options)
        self._inputs = self._coupled_inputs()
        self._history: deque = deque(maxlen=2)
        self._jacobians = InterfaceJacobian()
        self._jacobian = None       # d G / d u at the step ``_jacobian_step``, Broyden-updated
        self._jacobian_step = None
        self.n_jacobians = 0
        # Evaluations write the held torques themselves: propagation only fills the
        # buffers; the converged end-of-step torques are sent once per step.
        self._held_plan = system.held_plan({target.name for target, _, _ in self._inputs})

    def counters(self) -> dict:
        return {**super().counters(), "jacobians": self.n_jacobians}

    # u is a flat list over the coupled inputs, in the order of self._inputs (plain
    # lists: see _solve_linear)
    def _current_inputs(self) -> list[float]:
        return [v for _, _, values in self._inputs for v in values]

    def _evaluate(self, u, t, h, states, start, rolled):
        """Step the stateful components from their saved ``states`` holding ``u`` and
        return ``G(u)``; ``rolled`` says whether they must be rolled back first."""
        if rolled:
            self._restore_states(states, t)
        k = 0
        for target, vrs, values in self._inputs:
            for i in range(len(values)):
                values[i] = u[k]
                k += 1
            target.write(vrs, values)
        self._step_stateful(t, h)
        self.system.propagate_with(self._held_plan)     # the inputs' buffers now hold tau(t + h)
        end = self._current_inputs()
        return end if self.scheme == "implicit" else [0.5 * (a + b) for a, b in zip(start, end)]

    def _send_end_torques(self):
        """Leave the system consistent: the stateful components' inputs hold the torques
        at the end of the step (the evaluations left the held ones in place)."""
        for target, vrs, values in self._inputs:
            target.write(vrs, values)

    def _guess(self, t, h, start):
        if len(self._history) < 2:
            return list(start)
        (t0, u0), (t1, u1) = self._history
        if not t1 > t0:
            return list(u1)
        ratio = (t + h - t1) / (t1 - t0)
        return [b + (b - a) * ratio for a, b in zip(u0, u1)]

    def _step_impl(self, t, h):
        start = self._current_inputs()
        states = self._save_states()
        try:
            u = self._solve(t, h, states, start, self.tolerance, self._guess(t, h, start))
        finally:
            self._free_states(states)
        self._history.append((t + h, u))
        self._send_end_torques()
        self._step_feedthrough(t, h)

    def _solve(self, t, h, states, start, relative_tolerance, guess):
        """Iterate the held torques of the step from ``t`` to convergence, starting from
        ``guess``; the stateful components end at ``t + h`` stepped with them.  Returns them."""
        u = guess
        scale = max(1.0, max(abs(x) for x in start))
        tolerance = relative_tolerance * scale
        newton = self.solver == "newton"
        g = self._evaluate(u, t, h, states, start, rolled=False)
        residual = [b - a for a, b in zip(u, g)]
        norm = max(abs(r) for r in residual)
        previous = math.inf
        iteration = 0
        for iteration in range(self.max_iterations):
            if norm <= tolerance:
                break
            if newton:
                # The Jacobian at this step size from the model fitted to earlier
                # finite-difference ones; a new finite-difference one when there is none
                # or the iteration stalls.  Broyden's secant updates keep it current
                # while the transfer ratio changes it from step to step.
                if self._jacobian_step is None or abs(h - self._jacobian_step) > InterfaceJacobian.SAME_STEP * h:
                    self._jacobian, self._jacobian_step = self._jacobians.at(h), h
                if self._jacobian is None or norm > 0.5 * previous:
                    self._jacobian = self._finite_difference_jacobian(u, g, t, h, states, start, scale)
                    self._jacobians.add(h, self._jacobian)
                # (J - 1) change = -residual
                shifted = [[x - (i == j) for j, x in enumerate(row)] for i, row in enumerate(self._jacobian)]
                try:
                    change = _solve_linear(shifted, [-r for r in residual])
                except ZeroDivisionError:
                    raise MasterFailure(f"{self.name}: the interface Jacobian is singular in the step from "
                                        f"t = {t:.9g} s (h = {h:.3g} s); use a smaller step") from None
            else:
                change = residual
            previous = norm
            u_new = [a + d for a, d in zip(u, change)]
            g_new = self._evaluate(u_new, t, h, states, start, rolled=True)
            self.n_iterations += 1
            if newton:
                # Broyden: J += (secant - J change) change^T / |change|^2
                jacobian = self._jacobian
                squared = sum(d * d for d in change)
                if squared > 0.0:
                    miss = [(b - a) - sum(x * d for x, d in zip(row, change))
                            for a, b, row in zip(g, g_new, jacobian)]
                    self._jacobian = [[x + m * d / squared for x, d in zip(row, change)]
                                      for row, m in zip(jacobian, miss)]
            u, g = u_new, g_new
            residual = [b - a for a, b in zip(u, g)]
            norm = max(abs(r) for r in residual)
            if not math.isfinite(norm) or (not newton and iteration > 2 and norm > previous):
                break
        if not norm <= tolerance:
            hint = "use a newton master or a smaller step" if self.solver == "fixed-point" else "use a smaller step"
            raise MasterFailure(f"{self.name}: the coupling iteration did not converge in the step from "
                                f"t = {t:.9g} s (h = {h:.3g} s): residual {norm:.3g} N.m after "
                                f"{iteration + 1} iterations, tolerance {tolerance:.3g} N.m; {hint}")
        return u

    def _finite_difference_jacobian(self, u, g, t, h, states, start, scale):
        """``dG/du`` by forward differences over rolled-back steps, as nested lists."""
        self.n_jacobians += 1
        columns = []
        for j in range(len(u)):
            delta = 1e-6 * max(abs(u[j]), scale)
            shifted = list(u)
            shifted[j] += delta
            g_shifted = self._evaluate(shifted, t, h, states, start, rolled=True)
            columns.append([(b - a) / delta for a, b in zip(g, g_shifted)])
            self.n_iterations += 1
        return [list(row) for row in zip(*columns)]


class ImplicitFixedPointMaster(IterativeMaster):
    scheme, solver = "implicit", "fixed-point"


class ImplicitNewtonMaster(IterativeMaster):
    scheme, solver = "implicit", "newton"


class TrapezoidalFixedPointMaster(IterativeMaster):
    scheme, solver = "trapezoidal", "fixed-point"


class TrapezoidalNewtonMaster(IterativeMaster):
    scheme, solver = "trapezoidal", "newton"


class _StepControl:
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
        states = self._save_states()
        try:
            while True:
                error, result = attempt(h, states)
                if error <= 1.0 or h <= self.min_step:
                    break
                self._restore_states(states, t)
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


class AdaptiveTrapezoidalMaster(_StepControl, TrapezoidalNewtonMaster):
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
        start = self._current_inputs()
        self._scale = max(self._scale, max(abs(x) for x in start))
        points = list(self._ends) + [(t, start)]
        times = [p[0] for p in points]
        full = len(points) == 3

        def attempt(h, states):
            weights = _lagrange_weights(times, t + h)
            predicted = [sum(w * p[1][i] for w, p in zip(weights, points)) for i in range(len(start))]
            try:      # from the held torques that the extrapolated end-of-step torques give
                u = self._solve(t, h, states, start, self.iteration_tolerance,
                                [0.5 * (a + b) for a, b in zip(start, predicted)])
            except MasterFailure:
                if h <= self.min_step:
                    raise
                return 1.0 / self.SHRINK ** 3, None      # not converged: shrink hard and retry
            end = self._current_inputs()                 # tau(t + h) with the converged torques
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

class AdaptiveMaster(_StepControl, ExtrapolatingJacobiMaster):
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

    MEAN_FRACTION = (0.5, 5.0 / 12.0, 3.0 / 8.0)   # by degree: mean error / end-point error
    ESTIMATE_ORDER = 3

    def __init__(self, system: System, step: float, **options):
        super().__init__(system, step, **options)
        self._init_control()
        self._speeds = self._bond_speeds()
        self.bond_energy_residual = 0.0

    def _bond_speeds(self):
        """For each coupled input (a torque on a shaft), the speed at the same port: the
        component's exposed output in rad/s, if it has one."""
        system = self.system
        speeds = []
        for target, _, _ in self._inputs:
            candidates = [v for v in system.exposed[target.name] if _unit(target, v) == "rad/s"]
            index = system.index[(target.name, candidates[0])] if candidates else None
            speeds.append((system.buffers[target.name][1], index))
        return speeds

    def _read_speeds(self):
        return [values[i] if i is not None else 0.0 for values, i in self._speeds]

    def counters(self) -> dict:
        return {**super().counters(), "bond_energy_residual_J": self.bond_energy_residual}

    def _step_impl(self, t, h):
        start = [list(values) for _, _, values in self._inputs]
        speeds = self._read_speeds()
        points = list(self._history) + [(t, start)]
        fraction = self.MEAN_FRACTION[len(points) - 1]

        def attempt(h, states):
            predicted = self._hold(t, h, points)
            self._step_stateful(t, h)
            self.system.propagate()
            end = [list(values) for _, _, values in self._inputs]
            self._scale = max(self._scale, *(abs(x) for torques in start + end for x in torques))
            difference = max(abs(p - e) for ps, es in zip(predicted, end) for p, e in zip(ps, es))
            return fraction * difference / (self.tolerance * (self._scale or 1.0)), end

        h, error, end = self._controlled_step(t, self._clip(t, h), attempt)
        if error > 1.0:
            raise MasterFailure(f"{self.name}: the step size fell to its minimum {self.min_step:.3g} s at "
                                f"t = {t:.9g} s with the error estimate still {error:.3g} times the tolerance "
                                f"{self.tolerance:g}; the coupling torque changes too fast for this tolerance")
        # ECCO's power-bond residual: work given (held means) against work accounted for.
        end_speeds = self._read_speeds()
        for (_, _, values, n, ramped), ss, es, w0, w1 in zip(self._held, start, end, speeds, end_speeds):
            for i in range(n):
                mean = values[i] + (0.5 * values[n + i] * h if ramped else 0.0)
                self.bond_energy_residual += h * (mean - 0.5 * (ss[i] + es[i])) * 0.5 * (w0 + w1)
        self._history.append((t, start))
        self._step_feedthrough(t, h)
        return h


def _unit(component, name):
    variable = component.variable(name)
    return variable.unit or (variable.declaredType.unit if variable.declaredType is not None else None)


MASTERS = {cls.name: cls for cls in (JacobiMaster, GaussSeidelMaster, LinearExtrapolationMaster,
                                     QuadraticExtrapolationMaster, MidpointPredictionMaster,
                                     ImplicitFixedPointMaster, ImplicitNewtonMaster,
                                     TrapezoidalFixedPointMaster, TrapezoidalNewtonMaster, AdaptiveMaster,
                                     AdaptiveTrapezoidalMaster)}


def make(name: str, system: System, step: float, **options) -> Master:
    try:
        cls = MASTERS[name]
    except KeyError:
        raise ValueError(f"unknown master '{name}' (known: {', '.join(MASTERS)})") from None
    if issubclass(cls, (IterativeMaster, _StepControl)) and not system.scene.connections:
        # nothing to iterate on or to estimate an error from (e.g. the rectifier scene's one FMU)
        raise MasterFailure(f"master '{name}' iterates on the values the scene's components exchange, and scene "
                            f"'{system.scene.name}' connects none: use jacobi")
    return cls(system, step, **options)
