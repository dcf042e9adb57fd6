"""A shaft: an inertia driven by an external torque model and the coupling torque,
``I * a = M_ext(t, phi, w) + tau`` (docs/physics.md#how-a-shaft-steps).

The coupling torque over a communication step is ``tau + tau_rate * s`` (``s`` the time
into the step): held constant (zero-order hold, ``tau_rate = 0``) or ramped (first-order
hold), as a co-simulation master gives it.  A master that extrapolates the torque by a
quadratic gives its second derivative too (``tau_accel``): the shaft then takes the ramp
with the quadratic's mean and first moment over the step (``equivalent_ramp``), which gives
a free inertia's speed and angle at the step's end exactly.  Where the external torque model has a closed-form
solution (linear engine zone, loads that depend on time only) the step is exact, so the
only error a co-simulation makes is the coupling's; a load with a closed-form time part and
an angle-locked part (the spectrum load's shaft order) steps itself, exact in time and by
RK4 on the angle part; otherwise classical RK4 substeps.
"""
from __future__ import annotations

import math

from .engine import LinearCharacteristic
from .friction import ResistingLoad, integrate
from .parameters import ParameterError


def speed_moment_factor(h, w0, w1, a0, a1):
    """``integral of s * w(s) ds / h^2`` over a step of ``h``, from the cubic Hermite
    interpolant of the speed (ends ``w0``, ``w1``, slopes ``a0``, ``a1``; error O(h^6), far
    below the coupling's): the ramped coupling torque's work needs it.  Callers multiply by
    ``h * h`` themselves, each in the order it always had (the traces stay bit for bit)."""
    return 0.15 * w0 + 0.35 * w1 + h * (a0 / 30.0 - a1 / 20.0)


def equivalent_ramp(tau, tau_rate, tau_accel, h):
    """``(tau0, rate)``: the ramp ``tau0 + rate * s`` over a step of ``h`` with the mean
    and the first moment of the torque ``tau + tau_rate * s + tau_accel * s^2 / 2``.

    A shaft's speed at the step's end sees the torque's mean, its angle the first moment;
    what the ramp leaves out, ``tau_accel / 2 * (s^2 - h s + h^2 / 6)``, has neither, so it
    changes the end state only through the state's own feedback on the external torque:
    with the engine's slope ``K`` the angle by ``-tau_accel K h^5 / (720 I^2)`` to first
    order in ``K h / I``, the speed at second order (a master extrapolating the torque
    errs by O(h^4) a step).  The coupling torque's work differs by
    ``tau_accel * h^5 * w''(t) / 720``."""
    return tau - tau_accel * h * h / 12.0, tau_rate + 0.5 * tau_accel * h


class Shaft:
    def __init__(self, inertia: float, external, max_substep: float = 2.5e-4):
        self.inertia = float(inertia)
        self.external = external
        self.max_substep = float(max_substep)
        #: a load that resists the motion (friction, a brake): its torque at rest depends
        #: on the coupling torque, and its stops and breakaways are located in the step
        self.resisting = isinstance(external, ResistingLoad) and external.sticks
        #: a load with a time part in closed form and an angle part (SpectrumLoad's order
        #: term): it steps itself, exact in time, RK4 on the angle part only
        self.split = hasattr(external, "advance_split")

    def rates(self, t, phi, w, tau):
        """``(a, M_ext)``: the acceleration with coupling torque ``tau`` and the
        external torque on the shaft (scalars: the harness maps it over arrays)."""
        if self.resisting:
            external = self.external.torque_with(t, phi, w, tau)
        else:
            external = self.external.torque(t, phi, w)
        return (external + tau) / self.inertia, external

    def acceleration(self, t, phi, w, tau):
        return self.rates(t, phi, w, tau)[0]

    def external_partials(self, t, phi, w, tau):
        """``(dM/dphi, dM/dw, dM/dtau)`` of the external torque ``rates`` applies: an
        engine's characteristic slope, a load's angle slope and viscous friction; a shaft
        held by static friction feels ``-tau``.  At a stop or a kink the side ``rates``
        takes there."""
        external = self.external
        if isinstance(external, ResistingLoad):
            direction = 0.0 if w == 0.0 else math.copysign(1.0, w)
            if self.resisting and w == 0.0:
                margin, net = external.breakaway_margin(t, phi, tau)
                if margin <= 0.0:
                    return 0.0, 0.0, -1.0
                direction = math.copysign(1.0, net)
            return external.slip_partials(t, phi, w, direction) + (0.0,)
        if hasattr(external, "torque_slope"):          # an engine characteristic: Mg(w)
            return 0.0, external.torque_slope(t, phi, w), 0.0
        return -external.resistance_slope(t, phi, w), 0.0, 0.0

    def partials(self, t, phi, w, tau):
        """``(da/dphi, da/dw, da/dtau)`` of the acceleration ``rates`` gives."""
        d_phi, d_w, d_tau = self.external_partials(t, phi, w, tau)
        return d_phi / self.inertia, d_w / self.inertia, (d_tau + 1.0) / self.inertia

    def advance(self, t, phi, w, tau, h, tau_rate=0.0, tau_accel=0.0):
        """State after ``h`` seconds with coupling torque ``tau + tau_rate * s`` (with
        ``tau_accel``: its ``equivalent_ramp``): ``(phi, w, external_work)``, where
        ``external_work`` is the work the external torque did on the shaft in the step,
        from the shaft's own energy balance ``dKE = W_ext + W_coupling``."""
        if tau_accel:
            tau, tau_rate = equivalent_ramp(tau, tau_rate, tau_accel, h)
        if self.resisting:
            phi1, w1, moment, _ = integrate(self.external, self.inertia, t, phi, w, tau, h, tau_rate,
                                            self._substeps(h))
            work = 0.5 * self.inertia * (w1 * w1 - w * w) - tau * (phi1 - phi) - tau_rate * moment
            return phi1, w1, work
        exact = self.external.advance(self.inertia, t, phi, w, tau, h, tau_rate)
        start = None            # the external torque at the step's start, where it was needed
        if exact is not None:
            phi1, w1 = exact
        elif self.split:
            # the order term turns at k*|w| over the whole step: the speed at its end too,
            # predicted by one Euler step (a shaft spinning up within a step)
            start = self.external.torque(t, phi, w)
            ahead = w + h * ((start + (tau + 0.5 * tau_rate * h)) / self.inertia)
            phi1, w1 = self.external.advance_split(self.inertia, t, phi, w, tau, h, tau_rate,
                                                   self._substeps(h, max(abs(w), abs(ahead))))
        else:
            phi1, w1 = self._rk4(t, phi, w, tau, h, tau_rate)
        coupling_work = tau * (phi1 - phi)
        if tau_rate:
            a0 = self.acceleration(t, phi, w, tau) if start is None else (start + tau) / self.inertia
            coupling_work += tau_rate * self._first_moment_of_speed(t, h, tau + tau_rate * h, phi1, w, w1, a0)
        work = 0.5 * self.inertia * (w1 * w1 - w * w) - coupling_work
        return phi1, w1, work

    def _first_moment_of_speed(self, t, h, tau_end, phi1, w, w1, a0):
        """``integral of s * w(s) ds`` over the step, from the cubic Hermite interpolant
        of the speed (error O(h^6), far below the coupling's): ``a0`` the acceleration at
        its start, the one at its end from ``(phi1, w1)`` and the torque ``tau_end``."""
        a1 = self.acceleration(t + h, phi1, w1, tau_end)
        return h * h * speed_moment_factor(h, w, w1, a0, a1)

    #: RK4 substeps one step may take: beyond it the step is refused, not ground through
    #: for minutes (an importer waiting on doStep would hang).
    MAX_SUBSTEPS = 200_000

    #: RK4's stability limit on the real axis is 2.78 (2.83 on the imaginary): substeps
    #: stay below it for the external torque model's fastest rate
    STABLE = 2.5

    def _substeps(self, h, w=0.0):
        """RK4 substeps a step of ``h`` takes (refused beyond ``MAX_SUBSTEPS``); a split
        step at speed ``w`` also resolves its angle part's phase."""
        ratio = h / self.max_substep
        rate = self.external.rate(self.inertia) if hasattr(self.external, "rate") else 0.0
        turning = h * self.external.phase_rate(w) / self.external.PHASE_STEP if self.split else 0.0
        needed = max(ratio, h * rate / self.STABLE, turning)
        if not needed <= self.MAX_SUBSTEPS:
            why = (f"of max_substep = {self.max_substep:.6g} s" if needed == ratio else
                   f"to follow the load's order term at w = {w:.6g} rad/s" if needed == turning else
                   f"to stay stable with the external torque's rate {rate:.3g} 1/s")
            raise ParameterError("max_substep", f"a step of h = {h:.6g} s needs {needed:.3g} RK4 substeps {why}, "
                                 f"more than the {self.MAX_SUBSTEPS} allowed per step: take smaller communication "
                                 "steps, a larger 'max_substep' or a smoother characteristic")
        return max(1, math.ceil(needed - 1e-9))

    def _rk4(self, t, phi, w, tau, h, tau_rate=0.0):
        n = self._substeps(h)
        dt = h / n

        # rates()' own expression for a load that does not resist (a resisting one steps by
        # friction.integrate), without its two calls in between: four per substep
        torque, inertia = self.external.torque, self.inertia

        def acc(ti, p, v):
            return (torque(ti, p, v) + (tau + tau_rate * (ti - t))) / inertia

        for i in range(n):
            ti = t + i * dt
            k1p, k1w = w, acc(ti, phi, w)
            k2p, k2w = w + 0.5 * dt * k1w, acc(ti + 0.5 * dt, phi + 0.5 * dt * k1p, w + 0.5 * dt * k1w)
            k3p, k3w = w + 0.5 * dt * k2w, acc(ti + 0.5 * dt, phi + 0.5 * dt * k2p, w + 0.5 * dt * k2w)
            k4p, k4w = w + dt * k3w, acc(ti + dt, phi + dt * k3p, w + dt * k3w)
            phi += dt * (k1p + 2.0 * k2p + 2.0 * k3p + k4p) / 6.0
            w += dt * (k1w + 2.0 * k2w + 2.0 * k3w + k4w) / 6.0
        return phi, w


class LaggedShaft:
    """The drive shaft with an engine whose torque lags its static characteristic
    ``Ms(w)`` (``external``) by a first-order lag of time constant ``lag`` [s]:

        Te dM/dt = Ms(w) - M,      I dw/dt = M + tau

    (Simscape's Generic Engine has the same torque time constant: fuel, air and
    combustion do not answer a speed change at once).  State ``(phi, w, M)``; ``M`` starts
    at ``torque_start``.  Over a step with coupling torque ``tau + tau_rate * s``: exact
    for the linear zone (the step's matrix exponential, stable at any ``Te``), RK4
    substeps for a tabulated characteristic.  ``lag = 0`` is not this class: the engine
    then answers instantly (``Shaft``)."""

    MAX_SUBSTEPS = Shaft.MAX_SUBSTEPS
    STABLE = Shaft.STABLE

    def __init__(self, inertia: float, external, lag: float, torque_start: float, max_substep: float = 2.5e-4):
        if not (math.isfinite(lag) and lag > 0.0):
            raise ParameterError("torque_lag", f"parameter 'torque_lag' = {lag} must be > 0 for a lagged engine")
        self.inertia = float(inertia)
        self.external = external
        self.lag = float(lag)
        self.torque_start = float(torque_start)
        self.max_substep = float(max_substep)
        self._exponentials: dict[float, list[list[float]]] = {}

    def rates(self, t, phi, w, tau, torque):
        """``(a, M)``: the acceleration with coupling torque ``tau`` and the engine's
        (lagged) torque ``M``, which is state."""
        return (torque + tau) / self.inertia, torque

    def acceleration(self, t, phi, w, tau, torque):
        return (torque + tau) / self.inertia

    def torque_rate(self, t, phi, w, torque):
        """``dM/dt = (Ms(w) - M) / Te``."""
        return (self.external.torque(t, phi, w) - torque) / self.lag

    def partials(self, t, phi, w, tau, torque):
        """``((da/dw, da/dM, da/dtau), (dM'/dw, dM'/dM))``, with ``M' = dM/dt``: the
        acceleration ``(M + tau)/I`` and the lag ``(Ms(w) - M)/Te`` (nothing depends on
        the angle)."""
        return ((0.0, 1.0 / self.inertia, 1.0 / self.inertia),
                (self.external.torque_slope(t, phi, w) / self.lag, -1.0 / self.lag))

    def advance(self, t, phi, w, torque, tau, h, tau_rate=0.0, tau_accel=0.0):
        """State after ``h`` seconds: ``(phi, w, M, engine_work)`` (the work from the
        shaft's energy balance, as ``Shaft.advance``)."""
        if tau_accel:
            tau, tau_rate = equivalent_ramp(tau, tau_rate, tau_accel, h)
        if isinstance(self.external, LinearCharacteristic):
            phi1, w1, m1 = self._exact(phi, w, torque, tau, h, tau_rate)
        else:
            phi1, w1, m1 = self._rk4(t, phi, w, torque, tau, h, tau_rate)
        coupling_work = tau * (phi1 - phi)
        if tau_rate:
            a0 = self.acceleration(t, phi, w, tau, torque)
            a1 = self.acceleration(t + h, phi1, w1, tau + tau_rate * h, m1)
            coupling_work += tau_rate * h * h * speed_moment_factor(h, w, w1, a0, a1)
        return phi1, w1, m1, 0.5 * self.inertia * (w1 * w1 - w * w) - coupling_work

    # -- the linear zone, exactly: x' = A x on x = (phi, w, M, 1, tau, q, tau_rate), q = tau_rate*s --
    def _exact(self, phi, w, torque, tau, h, tau_rate):
        e = self._exponentials.get(h)
        if e is None:
            if len(self._exponentials) > 64:        # an adaptive master's many step sizes
                self._exponentials.clear()
            e = self._exponentials[h] = self._step_exponential(h)
        x = (phi, w, torque, 1.0, tau, 0.0, tau_rate)
        return tuple(sum(row[j] * x[j] for j in range(7)) for row in e)

    def _step_exponential(self, h):
        """The first three rows of ``expm(A h)``, by scaling and squaring a Taylor series:
        exact to rounding however fast the lag is against the step."""
        i, te = self.inertia, self.lag
        m1, k1 = self.external.stall_torque, self.external.slope
        a = [[0.0] * 7 for _ in range(7)]
        a[0][1] = 1.0                                              # phi' = w
        a[1][2] = a[1][4] = a[1][5] = 1.0 / i                      # I w' = M + tau + q
        a[2][1], a[2][2], a[2][3] = -k1 / te, -1.0 / te, m1 / te   # Te M' = M1 - K1 w - M
        a[5][6] = 1.0                                              # q' = tau_rate
        return expm(a, h)[:3]

    # -- a tabulated characteristic: RK4 substeps ------------------------------------------------
    def _rk4(self, t, phi, w, torque, tau, h, tau_rate):
        stiffness = getattr(self.external, "speed_stiffness", 0.0)
        rate = max(1.0 / self.lag, math.sqrt(stiffness / (self.inertia * self.lag)))
        ratio = h / self.max_substep
        needed = max(ratio, h * rate / self.STABLE)
        if not needed <= self.MAX_SUBSTEPS:
            raise ParameterError("max_substep", f"a step of h = {h:.6g} s needs {needed:.3g} RK4 substeps (torque "
                                 f"lag {self.lag:.3g} s, characteristic slope up to {stiffness:.3g} N.m.s/rad), more "
                                 f"than the {self.MAX_SUBSTEPS} allowed per step: take smaller communication steps, "
                                 "a larger 'max_substep' or 'torque_lag', or a smoother characteristic")
        n = max(1, math.ceil(needed - 1e-9))
        dt = h / n
        inertia, lag, static = self.inertia, self.lag, self.external.torque

        def f(ti, p, v, m):
            return v, (m + tau + tau_rate * (ti - t)) / inertia, (static(ti, p, v) - m) / lag

        for k in range(n):
            ti = t + k * dt
            k1 = f(ti, phi, w, torque)
            k2 = f(ti + 0.5 * dt, phi + 0.5 * dt * k1[0], w + 0.5 * dt * k1[1], torque + 0.5 * dt * k1[2])
            k3 = f(ti + 0.5 * dt, phi + 0.5 * dt * k2[0], w + 0.5 * dt * k2[1], torque + 0.5 * dt * k2[2])
            k4 = f(ti + dt, phi + dt * k3[0], w + dt * k3[1], torque + dt * k3[2])
            phi += dt * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0]) / 6.0
            w += dt * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1]) / 6.0
            torque += dt * (k1[2] + 2.0 * k2[2] + 2.0 * k3[2] + k4[2]) / 6.0
        return phi, w, torque


def expm(a: list[list[float]], h: float) -> list[list[float]]:
    """``exp(A h)`` of a small dense matrix: the Taylor series of ``A h / 2^k`` (norm below
    1/2, 18 terms: far below rounding) squared ``k`` times."""
    n = len(a)
    norm = max(sum(abs(x) for x in row) for row in a) * h
    k = max(0, math.ceil(math.log2(norm / 0.5))) if norm > 0.5 else 0
    scale = h / 2.0 ** k
    b = [[x * scale for x in row] for row in a]
    result = [[float(r == c) for c in range(n)] for r in range(n)]
    term = [row[:] for row in result]
    for j in range(1, 19):
        term = [[sum(term[r][m] * b[m][c] for m in range(n)) / j for c in range(n)] for r in range(n)]
        result = [[result[r][c] + term[r][c] for c in range(n)] for r in range(n)]
    for _ in range(k):
        result = [[sum(result[r][m] * result[m][c] for m in range(n)) for c in range(n)] for r in range(n)]
    return result
