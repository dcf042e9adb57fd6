"""Linear stability of the co-simulation masters on the two-inertia driveline, and the
stability advisor that warns before a run.

The model (linearised about the steady operating point):

    I1 * dw1/dt = M + tau1                 drive shaft; M = -K1 * w1 (K1 = -dMg/dw, the engine's
    Te * dM/dt = -K1 * w1 - M              slope) at once when its torque lag Te = 0, else a state
    I2 * dw2/dt = -b_v * w2 + tau2         driven shaft; b_v the load's viscous friction
    T = c * (phi1 - phi2) + b * (w1 - w2), tau1 = -T, tau2 = T

in deviations from the steady motion.  Where a side of the coupling is not our EngineShaft
or LoadShaft but an FMU of one's own, its inertia and its slope (K1, or b_v) are measured
(``harness.judges.coupling_scene``, ``port_probe``) and the model says how well
(``TwoInertia.uncertainty``); the stand-in then carries that FMU's model description.
Linearisation: the transfer function is taken
at its mean, ``U12 = 1`` and ``Phi(phi2) = phi2`` (the kinematic mode's ratio varies by
under 1 % about it: a parametric modulation left out; the ``scaled`` mode's 14 % is not
small and is only roughly covered), a tabulated elastic law by its nominal stiffness,
a tabulated engine characteristic by its slope at the starting speed; the mean load and
the engine's stall torque set the operating point and drop out of the deviations, the
random and periodic parts of the load are forcing, not feedback; a Coulomb friction or a
brake is constant while the shaft slips (it drops out too; a shaft held at rest has no
coupling mode to lose).

Coupling mode: ``omega_n = sqrt(c / I_red)`` with ``I_red = I1*I2/(I1 + I2)``, the
undamped eigenfrequency, and the modal damping ratio of its mode shape (the drive
shaft moves ``I2/(I1 + I2)`` of the deflection, so the engine's slope damps it too):

    zeta = (b + K1e * (I2/(I1 + I2))^2) / (2 * sqrt(c * I_red)),   K1e = K1 / (1 + (omega_n Te)^2)

(``K1e``: the in-phase part of the lagged engine's answer ``K1 / (1 + i omega Te)`` at the
mode's frequency; a lag slower than the mode takes the engine's damping away.  The
one-step maps below carry the lagged torque as a state of their own and need no such
approximation.)

The one-step map of each master is not written out by hand: ``LinearDriveline`` is a
stand-in for ``harness.engine.system.System`` whose three components carry the FMUs' own model
descriptions (ports, time-derivative relations, output dependencies) but compute the linear
model above in Python, with the same exact shaft integrators the FMUs use.  The real
master classes step it, so the map is the one of the masters as implemented: zero-order
hold, the ramp (``tau_rate``) of the extrapolating masters with their torque history in
the augmented state, Gauss-Seidel's order (its ``c*w*h`` torque bias is affine in the
steady speed: it moves the operating point, not the map), the mid-step prediction from
the accelerations of the last propagation (kept in the map's state, as the master reads
them from its buffers), the implicit and trapezoidal couplings iterated to
convergence (Newton to 1e-9).  A fixed-point master ends at the same torques where its
iteration converges; it fails - spectral radius reported as infinite - where the
contraction of ``u <- G(u)`` is too slow for its own tolerance and iteration limit
(``fixed_point_limit``).  The map's columns are the images of unit perturbations of the
augmented state (exact: the stand-in is linear); the common angle of both shafts, which
nothing depends on (eigenvalue 1 for every master), is removed.  ``tests/judges/test_stability.py``
checks the stand-in against the masters on the real FMUs, step for step.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, replace
from functools import lru_cache
from pathlib import Path

import numpy as np

from lever.physics.coupling import coupling_mode

from harness.description import plan as plans, scene_kinds
from harness.engine import masters as master_family
from harness.description import scene as scenes
from harness.paths import FMUS
from harness.engine.system import CO_SIMULATION
from harness.judges import coupling_scene
from harness.judges.linear_driveline import DRIVELINE_CONNECTIONS, LinearDriveline, Wiring  # noqa: F401 - re-exported

#: A spectral radius above 1 + this is unstable (rounding of the map stays far below).
RHO_TOLERANCE = 1e-7

#: Masters that choose their own steps, by the fixed-step master they step with.
FIXED_STEP_EQUIVALENT = {"adaptive": "jacobi-quadratic", "adaptive-trapezoidal": "trapezoidal-newton"}

#: Options that make the analysed iterative masters iterate to convergence.
CONVERGED = {"tolerance": 1e-9, "max_iterations": 100}


# -- the two-inertia model ---------------------------------------------------------------------

@dataclass(frozen=True)
class TwoInertia:
    """The linearised driveline: inertias [kg*m^2], engine slope K1 [N*m*s/rad],
    coupling stiffness c [N*m/rad] and damping b [N*m*s/rad], engine torque lag Te [s]
    (0: the engine answers at once)."""

    drive_inertia: float
    driven_inertia: float
    engine_slope: float
    stiffness: float
    damping: float
    engine_lag: float = 0.0
    #: b_v, the load's viscous friction [N*m*s/rad] (the one slope of a load in w)
    driven_slope: float = 0.0
    #: the ports' FMUs where they are not our EngineShaft and LoadShaft (None: ours)
    wiring: Wiring | None = None
    #: the ports measured by probe runs, ``(("drive" | "driven", port_probe.PortModel), ...)``,
    #: whose spreads the model's uncertainty comes from
    measured: tuple = ()

    @property
    def omega_n(self) -> float:
        """Undamped eigenfrequency of the coupling mode [rad/s]."""
        return self._mode[0]

    @property
    def zeta(self) -> float:
        """Modal damping ratio of the coupling mode (coupling damping and engine slope)."""
        return self._mode[1]

    @property
    def _mode(self) -> tuple[float, float]:
        omega, _ = coupling_mode(self.stiffness, self.damping, self.drive_inertia, self.driven_inertia)
        effective_slope = self.engine_slope / (1.0 + (omega * self.engine_lag) ** 2)
        return coupling_mode(self.stiffness, self.damping, self.drive_inertia, self.driven_inertia,
                             effective_slope, self.driven_slope)

    def with_coupling(self, stiffness: float | None = None, damping: float | None = None) -> "TwoInertia":
        return replace(self, stiffness=self.stiffness if stiffness is None else float(stiffness),
                       damping=self.damping if damping is None else float(damping))

    @property
    def omega_spread(self) -> float:
        """The relative uncertainty of ``omega_n`` from the measured ports' inertias (0:
        every inertia known from the scene's values): ``omega_n ~ I_red^(-1/2)``, and a
        side's share of ``I_red``'s relative change is the other side's share of the inertia."""
        i1, i2 = self.drive_inertia, self.driven_inertia
        share = {"drive": i2 / (i1 + i2), "driven": i1 / (i1 + i2)}
        return 0.5 * sum(share[side] * port.inertia_spread for side, port in self.measured)

    def uncertainty(self) -> str:
        """What the model's figures rest on, for a finding: "" when every value is the
        scene's own."""
        if not self.measured:
            return ""
        return (f"omega_n +- {100 * self.omega_spread:.2g} % from the measured port(s): "
                + "; ".join(port.text() for _, port in self.measured))

    def step_for(self, h_omega: float) -> float:
        """The communication step [s] at which ``h * omega_n`` is ``h_omega``."""
        return h_omega / self.omega_n

    def continuous_eigenvalues(self) -> np.ndarray:
        """Eigenvalues of the continuous model in (theta, w1, w2), and the engine torque M
        when it lags."""
        c, b, k1, te = self.stiffness, self.damping, self.engine_slope, self.engine_lag
        i1, i2 = self.drive_inertia, self.driven_inertia
        bv = self.driven_slope
        if te > 0.0:
            a = np.array([[0.0, 1.0, -1.0, 0.0],
                          [-c / i1, -b / i1, b / i1, 1.0 / i1],
                          [c / i2, b / i2, -(b + bv) / i2, 0.0],
                          [0.0, -k1 / te, 0.0, -1.0 / te]])
        else:
            a = np.array([[0.0, 1.0, -1.0],
                          [-c / i1, -(b + k1) / i1, b / i1],
                          [c / i2, b / i2, -(b + bv) / i2]])
        return np.linalg.eigvals(a)


def model_of(scene: scenes.Scene, fmu_dir: Path = FMUS, say=None) -> TwoInertia:
    """The two-inertia model of ``scene`` from its parameter values (defaults where the
    scene sets none).  A scene with our LeverCoupling between shafts of other FMUs gets
    the model with those ports measured (``coupling_scene.chain``: probe runs, ``say``
    hears a long probe's estimate first); ``scene_kinds.NotADriveline`` (its subclass
    ``coupling_scene.NoCouplingModel``) says what the analysis needs where the scene has no such chain,
    ``port_probe.ProbeRefused`` names an FMU that refused its probes."""
    if not scene_kinds.is_driveline(scene):
        found = coupling_scene.chain(scene, fmu_dir, say)
        drive, driven = found.drive, found.driven
        wiring = None if found.wiring == Wiring() else found.wiring
        measured = tuple((side, s.measured) for side, s in (("drive", drive), ("driven", driven)) if s.measured)
        return TwoInertia(drive.inertia, driven.inertia, drive.slope, found.stiffness, found.damping,
                          engine_lag=drive.lag, driven_slope=driven.slope, wiring=wiring, measured=measured)
    driveline = plans.driveline_of(scene)
    built = driveline.physics.get()
    driven = driveline.load.get()
    law = built.coupling
    inertia, slope, lag = coupling_scene.engine_side(driveline.engine.get())
    return TwoInertia(inertia, driven["inertia"], slope, law.law.nominal_stiffness, law.damping, engine_lag=lag,
                      driven_slope=driven["viscous_damping"])


# -- one-step maps -------------------------------------------------------------------------------

def fixed_step_master(master: str) -> str:
    master_family.check(master)
    return FIXED_STEP_EQUIVALENT.get(master, master)


def _analysed_master(master: str, system: LinearDriveline, step: float):
    name = fixed_step_master(master)
    cls = master_family.MASTERS[name]
    if getattr(cls, "solver", None) == "fixed-point":
        # Where it converges, the fixed-point iteration ends where Newton's does.
        name = f"{cls.scheme}-newton"
        cls = master_family.MASTERS[name]
    options = {k: v for k, v in CONVERGED.items() if k in cls.options}
    return master_family.make(name, system, step, **options)


def _history_slots(driver) -> int:
    """How many past communication points the master's state carries (extrapolation)."""
    if isinstance(driver, master_family.ExtrapolatingJacobiMaster):
        return driver.degree
    return 0


class MapUndefined(RuntimeError):
    """The master cannot make the step (an iteration that does not converge)."""


def iteration_contraction(model: TwoInertia, master: str, step: float, fmu_dir: Path = FMUS) -> float:
    """Spectral radius of ``d G / d u`` for an iterative master: the torques ``u`` held
    over the step against what the coupling gives back, ``G(u)`` (end-of-step torques,
    or their mean with the start's).  A fixed-point iteration ``u <- G(u)`` converges
    if and only if it is below 1 (Newton's converges regardless, the map being linear)."""
    cls = master_family.MASTERS[fixed_step_master(master)]
    if not issubclass(cls, master_family.IterativeMaster):
        raise ValueError(f"master '{master}' does not iterate")
    system = LinearDriveline(model, step, fmu_dir)
    driver = master_family.make(cls.name, system, step)
    system.set_state(0.0, 0.0, 0.0, 0.0)
    start = driver.current_inputs()
    states = driver.save_states()
    base = np.array(driver.evaluate([0.0] * len(start), 0.0, step, states, start, rolled=True))
    jacobian = np.array([np.array(driver.evaluate(list(np.eye(len(start))[j]), 0.0, step, states, start, rolled=True))
                         - base for j in range(len(start))]).T
    return float(np.max(np.abs(np.linalg.eigvals(jacobian))))


def fixed_point_limit(cls) -> float:
    """The contraction above which a fixed-point master, as configured by default,
    cannot reduce a first residual as large as the torques themselves to its relative
    tolerance within its iterations: ``tolerance ** (1 / max_iterations)`` (0.58 for
    1e-7 and 30).  Below 1, where the iteration would converge given time."""
    return cls.options["tolerance"] ** (1.0 / cls.options["max_iterations"])


def one_step_map(model: TwoInertia, master: str, step: float, fmu_dir: Path = FMUS) -> tuple[np.ndarray, list[str]]:
    """The matrix of ``master``'s one-step map at communication step ``step`` [s] on the
    augmented state ``(theta, w1, w2, M1 when the engine lags, buffered outputs..., past torques...)``, with the names of its
    coordinates.  Raises ``MapUndefined`` where the master fails to make the step (a
    fixed-point iteration whose contraction is not below 1)."""
    cls = master_family.MASTERS[fixed_step_master(master)]
    if getattr(cls, "solver", None) == "fixed-point":
        kappa = iteration_contraction(model, master, step, fmu_dir)
        limit = fixed_point_limit(cls)
        if not kappa < limit:
            raise MapUndefined(f"{master}: the fixed-point iteration cannot converge at h = {step:.3g} s "
                               f"(contraction {kappa:.3g} >= {limit:.3g})")
    system = LinearDriveline(model, step, fmu_dir)
    driver = _analysed_master(master, system, step)
    slots = _history_slots(driver)
    inputs = driver.coupled_inputs if slots else []
    width = sum(len(each.values) for each in inputs)       # torques per communication point
    # Outputs of the shafts a master reads from the last propagation besides their states
    # (jacobi-midpoint's accelerations): propagation reads them before it writes the new
    # torques, so they carry the torque of the step before - state of the map, too.
    buffered = [(system.buffers[name][1], system.index[(name, var)], f"{name}.{var}")
                for name in system.stateful for var in system.exposed[name] if var not in system.motion(name)]
    core = ["phi1", "w1", "phi2", "w2"] + (["M1"] if system.lagged else [])   # M1: the lagged engine torque
    names = (core + [label for _, _, label in buffered]
             + [f"{each.component.name}.{vr}@t-{k + 1}h" for k in range(slots) for each in inputs
                for vr in range(len(each.vrs))])
    first = len(core) + len(buffered)         # where the torque history starts in z
    n = first + slots * width

    def apply(z):
        system.set_state(*z[:len(core)])
        for (values, index, _), value in zip(buffered, z[len(core):first]):
            values[index] = value
        if slots:
            points = []
            for k in reversed(range(slots)):       # oldest first, as the master keeps them
                flat, values = list(z[first + k * width:first + (k + 1) * width]), []
                for each in inputs:
                    values.append(flat[:len(each.values)])
                    flat = flat[len(each.values):]
                points.append((-(k + 1) * step, values))
            driver.history = deque(points, maxlen=slots)
        driver.t = 0.0
        try:
            driver.step(step, t_next=step)
        except master_family.MasterFailure as error:
            raise MapUndefined(str(error)) from None
        out = system.state() + [values[index] for values, index, _ in buffered]
        if slots:
            history = list(driver.history)  # oldest first; the newest is the step's start
            for k in range(slots):
                out += [v for values in history[-1 - k][1] for v in values]
        return np.array(out)

    # Unit perturbations; the map is linear, so its columns are the images.
    full = np.array([apply(np.eye(n)[j]) for j in range(n)]).T
    # New coordinates: theta = phi1 - phi2, w1, the common angle (phi1 = phi2 = 1), w2, ...
    # Nothing depends on the common angle (its column is its own unit vector): drop it.
    change = np.eye(n)
    change[0, 2] = 1.0
    mapped = np.linalg.solve(change, full @ change)
    keep = [i for i in range(n) if i != 2]
    return mapped[np.ix_(keep, keep)], ["theta", "w1", "w2"] + names[4:]


def spectral_radius(model: TwoInertia, master: str, step: float, fmu_dir: Path = FMUS) -> float:
    """Largest eigenvalue modulus of the master's one-step map (``inf`` where the master
    cannot make the step)."""
    return _radius(model, fixed_step_master(master), float(step), str(fmu_dir))


@lru_cache(maxsize=65536)
def _radius(model, master, step, fmu_dir):
    fmu_dir = Path(fmu_dir)
    try:
        matrix, _ = one_step_map(model, master, step, fmu_dir)
    except MapUndefined:
        return math.inf
    if not np.all(np.isfinite(matrix)):
        return math.inf
    return float(np.max(np.abs(np.linalg.eigvals(matrix))))


def is_stable(rho: float) -> bool:
    return rho <= 1.0 + RHO_TOLERANCE


#: The h * omega_n range the edge search covers.
EDGE_RANGE = (1e-3, 1e2)


def stability_edge(model: TwoInertia, master: str, fmu_dir: Path = FMUS, scan: int = 36,
                   bisections: int = 24, h_omega_range: tuple = EDGE_RANGE) -> float | None:
    """The smallest ``h * omega_n`` in ``h_omega_range`` where the spectral radius of
    ``master``'s map exceeds 1 (found on a log scan and refined by bisection); ``None``
    when it stays within 1 over the whole range, the lower end when it is unstable there."""
    return _edge(model, fixed_step_master(master), str(fmu_dir), scan, bisections, tuple(h_omega_range))


@lru_cache(maxsize=4096)
def _edge(model, master, fmu_dir, scan, bisections, h_omega_range):
    low, high = h_omega_range
    grid = np.geomspace(low, high, scan)
    previous = None
    for x in grid:
        if not is_stable(spectral_radius(model, master, model.step_for(x), Path(fmu_dir))):
            if previous is None:
                return float(low)
            a, b = math.log(previous), math.log(x)
            for _ in range(bisections):
                mid = 0.5 * (a + b)
                if is_stable(spectral_radius(model, master, model.step_for(math.exp(mid)), Path(fmu_dir))):
                    a = mid
                else:
                    b = mid
            return float(math.exp(0.5 * (a + b)))
        previous = x
    return None


# -- the advisor ---------------------------------------------------------------------------------

#: Masters the advisor proposes, in order of preference (cheapest per step first).
PREFERRED = ("jacobi-quadratic", "jacobi-linear", "jacobi-midpoint", "jacobi", "trapezoidal-newton",
             "implicit-newton")
#: Fraction of the predicted edge the advisor proposes as a step (margin for the neglected
#: nonlinearity and the transfer function's modulation).
MARGIN = 0.8


@dataclass
class Assessment:
    """The advisor's view of one master and step on a scene's driveline."""

    master: str
    step: float
    model: TwoInertia
    rho: float
    edge: float | None               # the master's predicted edge, h*omega_n
    proposals: list                  # [(master, step)] predicted stable

    @property
    def h_omega(self) -> float:
        return self.step * self.model.omega_n

    @property
    def stable(self) -> bool:
        return is_stable(self.rho)

    def finding(self) -> str:
        mode = f"omega_n = {self.model.omega_n:.4g} rad/s, zeta = {self.model.zeta:.3g}"
        why = ("its coupling iteration cannot converge at this step" if math.isinf(self.rho)
               else f"spectral radius of its one-step map {self.rho:.6g} > 1")
        own = (f"{self.master} is predicted stable up to h*omega_n = {self.edge:.3g} "
               f"(h = {self.model.step_for(self.edge):.3g} s)" if self.edge is not None and self.edge > EDGE_RANGE[0]
               else f"{self.master} is predicted unstable at any step here")
        proposal = " or ".join(f"{m} at h = {h:.3g} s" for m, h in self.proposals) or "a smaller step"
        measured = f"  The model: {self.model.uncertainty()}." if self.model.measured else ""
        return (f"stability: {self.master} at h = {self.step:.3g} s (h*omega_n = {self.h_omega:.3g}; coupling mode "
                f"{mode}) is outside the predicted stable region: {why}; {own}.  Predicted stable: {proposal}."
                + measured)


def assess(scene: scenes.Scene, master: str | None = None, step: float | None = None,
           fmu_dir: Path = FMUS, say=None) -> Assessment | None:
    """The linear analysis of ``master`` at ``step`` (defaults: the scene's) on the
    scene's driveline, with stable alternatives when it is unstable; None when the scene
    has no driveline to linearise, the master chooses its own steps (adaptive) or
    splits no coupling into communication steps (Model Exchange: its integrator is chosen
    by ``cvode_method``)."""
    master = master or scene.experiment.master
    step = float(step or scene.experiment.step)
    if (master not in master_family.MASTERS or master_family.MASTERS[master].adaptive
            or master_family.MASTERS[master].interface != CO_SIMULATION):
        return None
    try:
        model = model_of(scene, fmu_dir, say)
    except scene_kinds.NotADriveline:
        return None
    rho = spectral_radius(model, master, step, fmu_dir)
    if is_stable(rho):
        return Assessment(master, step, model, rho, None, [])
    edge = stability_edge(model, master, fmu_dir)
    proposals = []
    # The same step with another master (cheapest first), and the same master shorter.
    for candidate in PREFERRED:
        if candidate != master and is_stable(spectral_radius(model, candidate, step, fmu_dir)):
            proposals.append((candidate, step))
            break
    if edge is not None and edge > EDGE_RANGE[0]:
        shorter = float(f"{MARGIN * model.step_for(edge):.3g}")
        if is_stable(spectral_radius(model, master, shorter, fmu_dir)):
            proposals.append((master, shorter))
    return Assessment(master, step, model, rho, edge, proposals)


def advise(scene: scenes.Scene, master: str | None = None, step: float | None = None,
           fmu_dir: Path = FMUS, say=None) -> list[str]:
    """Findings (empty when none) about running ``scene`` with ``master`` at ``step``
    (defaults: the scene's): a warning when the linearised driveline's coupling mode
    makes the master's one-step map unstable at that step, naming a master and a step
    the same analysis finds stable.  Adaptive masters choose their own steps and get no
    finding; a scene without an engine - coupling - load chain gets none either."""
    assessment = assess(scene, master, step, fmu_dir, say)
    if assessment is None or assessment.stable:
        return []
    return [assessment.finding()]


def run_advice(scene: scenes.Scene, master: str, step: float, fmu_dir: Path = FMUS, say=None) -> list[str]:
    """``advise`` for a run about to start (``say`` hears a long probe's estimate first):
    advice must never stop a run, so a scene the analysis cannot read gets a finding saying
    so instead of an exception."""
    try:
        return advise(scene, master, step, fmu_dir, say)
    except Exception as error:  # noqa: BLE001 - a scene the analysis cannot read still runs
        return [f"stability advisor: no advice for this scene ({type(error).__name__}: {error})"]


# -- the integrator of the Model Exchange master ----------------------------------------------------

def cvode_method(scene: scenes.Scene) -> tuple[str, str] | None:
    """``(method, why)``: CVODE's Adams or BDF for the Model Exchange master on ``scene``,
    from the continuous eigenvalues of its linearised driveline (``TwoInertia``) by the
    master's own rule (``harness.engine.masters.model_exchange.choose_method``); None for a
    scene without an engine - coupling - load chain (the master then applies the rule to
    its system Jacobian at the start)."""
    if not scene_kinds.is_driveline(scene):
        return None
    try:
        model = model_of(scene)
    except scene_kinds.NotADriveline:
        return None
    method, why = master_family.choose_method(model.continuous_eigenvalues(),
                                              f"the linearised driveline of scene '{scene.name}'")
    return method, why


def run_method(scene: scenes.Scene, master: str, options: dict) -> str | None:
    """For a run of the Model Exchange master that leaves ``method`` to the master: set
    ``options["method"]`` from ``cvode_method`` and return the note that says which and
    why (None: another master, a method given, or no driveline to analyse).  Like the
    advice, it never stops a run: a scene the analysis cannot read is left to the master."""
    cls = master_family.MASTERS.get(master)
    if cls is None or "method" not in cls.options or options.get("method", "auto") != "auto":
        return None
    try:
        chosen = cvode_method(scene)
    except Exception:  # noqa: BLE001 - the master chooses from its own Jacobian then
        return None
    if chosen is None:
        return None
    options["method"] = chosen[0]
    return f"{master}: CVODE {chosen[0]} - {chosen[1]} (harness.judges.stability.cvode_method)"
