"""The iterative masters: implicit (backward Euler) or trapezoidal coupling of the
exchanged values, solved by fixed-point or Newton iteration with rollback of the FMUs'
states."""
from __future__ import annotations

import math
from collections import deque

from harness.engine.masters.base import Master, MasterFailure
from harness.engine.straight_line import straight_line
from harness.engine.system import System


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
        self.coupled_inputs = self._coupled_inputs()
        self.history: deque = deque(maxlen=2)
        self._jacobians = InterfaceJacobian()
        self._jacobian = None       # d G / d u at the step ``_jacobian_step``, Broyden-updated
        self._jacobian_step = None
        self.n_jacobians = 0
        # Evaluations write the held torques themselves: propagation only fills the
        # buffers; the converged end-of-step torques are sent once per step.
        self._held_plan = system.held_plan({inputs.component.name for inputs in self.coupled_inputs})
        # the held torques' buffers, and their writes compiled once
        self._live = tuple(inputs.values for inputs in self.coupled_inputs)
        self._sends = system.send_plan(self.coupled_inputs)
        # an evaluation's calls, one function (``harness.engine.straight_line``): the held
        # torques sent, the stateful components stepped, the torques at the end read
        self._send_step_fill = straight_line("evaluate", self._held_plan, self._stateful_steps, before=self._sends)
        self._send_held = system.runner(self._sends)

    def counters(self) -> dict:
        return {**super().counters(), "jacobians": self.n_jacobians}

    # u is a flat list over the coupled inputs, in the order of self.coupled_inputs (plain
    # lists: see _solve_linear)
    def current_inputs(self) -> list[float]:
        return [v for values in self._live for v in values]

    def evaluate(self, u, t, h, states, start, rolled):
        """Step the stateful components from their saved ``states`` holding ``u`` and
        return ``G(u)``; ``rolled`` says whether they must be rolled back first."""
        if rolled:
            self.restore_states(states, t)
        k = 0
        for values in self._live:
            for i in range(len(values)):
                values[i] = u[k]
                k += 1
        self._send_step_fill(t, h)          # the inputs' buffers now hold tau(t + h)
        end = self.current_inputs()
        return end if self.scheme == "implicit" else [0.5 * (a + b) for a, b in zip(start, end)]

    def _send_end_torques(self):
        """Leave the system consistent: the stateful components' inputs hold the torques
        at the end of the step (the evaluations left the held ones in place)."""
        self._send_held()

    def _guess(self, t, h, start):
        if len(self.history) < 2:
            return list(start)
        (t0, u0), (t1, u1) = self.history
        if not t1 > t0:
            return list(u1)
        ratio = (t + h - t1) / (t1 - t0)
        return [b + (b - a) * ratio for a, b in zip(u0, u1)]

    def _step_impl(self, t, h):
        start = self.current_inputs()
        states = self.save_states()
        try:
            u = self._solve(t, h, states, start, self.tolerance, self._guess(t, h, start))
        finally:
            self._free_states(states)
        self.history.append((t + h, u))
        self._send_end_torques()
        self._step_feedthrough(t, h)

    def _solve(self, t, h, states, start, relative_tolerance, guess):
        """Iterate the held torques of the step from ``t`` to convergence, starting from
        ``guess``; the stateful components end at ``t + h`` stepped with them.  Returns them."""
        u = guess
        scale = max(1.0, max(abs(x) for x in start))
        tolerance = relative_tolerance * scale
        newton = self.solver == "newton"
        g = self.evaluate(u, t, h, states, start, rolled=False)
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
            g_new = self.evaluate(u_new, t, h, states, start, rolled=True)
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
            g_shifted = self.evaluate(shifted, t, h, states, start, rolled=True)
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
