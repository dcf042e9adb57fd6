"""The monolithic reference: the scene's equations solved unsplit with scipy at tight
tolerance, from the same physics objects the FMUs use (``lever.physics.component_parameters``), built
where the scene is checked (``harness.description.plan``).

For the driveline (engine shaft - lever coupling - load shaft) the state is
``[phi1, w1, phi2, w2]``, augmented with the engine's work, the load's work and the
energy dissipated in the coupling (and, for an engine with a torque lag, its torque), so the reference's own energy balance is exact up to
the integrator's tolerance.  Results are cached (harness.judges.solution).  ``solve``
picks the solver of the scene's kind (``SOLVERS``); ``method`` a scipy method or CVODE's
(``harness.judges.cvode``, on the same right-hand side with its analytic Jacobian).
"""
from __future__ import annotations

import time as clock

import numpy as np
from scipy.integrate import solve_ivp

from lever.physics.driveline import HELD, Driveline
from lever.physics.shaft import LaggedShaft

from harness.description import plan as plans
from harness.description import scene as scenes
from harness.paths import FMUS
from harness.engine import interrupt
from harness.judges import cvode, rectifier
from harness.judges.solution import MonolithicSolution, ReferenceUnavailable, cache_path, load_cached, store

RTOL = 1e-10
ATOL = 1e-10

#: DOP853 is stable for steps up to about 6 / (the fastest decay rate) (its stability region
#: on the negative real axis, Hairer & Wanner); a scene that would need more than
#: ``EXPLICIT_STEP_BUDGET`` such steps over its span is stiff for it: its reference is
#: solved by a stiff method instead (``stiff_method``)
DOP853_STABILITY = 6.0
EXPLICIT_STEP_BUDGET = 100_000


def planned(scene: scenes.Scene | plans.Plan) -> plans.Plan:
    """The checked scene a solver takes: ``scene`` itself, or a scene checked once here."""
    if isinstance(scene, plans.Plan):
        return scene
    return plans.check(scene, fmu_dir=scene.fmu_dir or FMUS)


def _driveline(plan: plans.Plan) -> plans.DrivelinePlan:
    if plan.driveline_problem:
        raise ReferenceUnavailable(f"{plan.driveline_problem}: the monolithic reference has no solver for it")
    return plan.driveline


def _misalignment_source(plan: plans.Plan):
    """``(alpha(t), the coupling at alpha)`` when a source drives the coupling's
    misalignment input, else None."""
    driver = plan.driveline.misalignment_driver
    if driver is None:
        return None
    built = plan.driveline.misalignment.get()
    if built is None:
        raise ReferenceUnavailable(f"scene '{plan.name}': the reference knows the misalignment only from a "
                                   f"MisalignmentSource, not from {driver}")
    return built


def _shaft_rates(shaft, t, phi, w, tau):
    """``Shaft.rates`` over arrays; element by element where a torque model only takes
    scalars (tabulated characteristics)."""
    try:
        a, external = shaft.rates(t, phi, w, tau)
        if np.shape(a) == np.shape(t) and np.shape(external) == np.shape(t):
            return np.asarray(a, dtype=float), np.asarray(external, dtype=float)
    except (TypeError, ValueError):  # a scalar-only model fed arrays (e.g. bisect on an array)
        pass
    a, external = zip(*(shaft.rates(*row) for row in zip(t, phi, w, tau)))
    return np.array(a), np.array(external)


def solve(scene: scenes.Scene | plans.Plan, times: np.ndarray, use_cache: bool = True, rtol: float = RTOL,
          atol: float = ATOL, method: str = "DOP853") -> MonolithicSolution:
    """Reference traces at ``times`` (named like the scene's records: ``engine.w`` ...) of a
    checked scene (harness.description.plan) or a scene, checked here.
    Looser ``rtol``/``atol`` (or another scipy ``method``) give the monolithic solution a
    benchmark compares the masters with."""
    interrupt.phase("reference")
    plan = planned(scene)
    solver = SOLVERS.get(plan.kind, solve_driveline)
    return solver(plan, times, use_cache, rtol, atol, method)


def stiff_method(driveline: Driveline, t0: float, y0, span: float, resisting: bool) -> tuple[str, str] | None:
    """``(method, why)`` of a stiff solver for the driveline when DOP853's stability alone
    would hold it to more than ``EXPLICIT_STEP_BUDGET`` steps over ``span`` (the fastest
    decay of its Jacobian at the start, as ``me-cvode`` judges stiffness): CVODE's BDF on
    the analytic Jacobian, or scipy's Radau where the load can stick (CVODE has no mode
    switching here); None where DOP853 is the reference's solver, as it is for every
    committed scene."""
    rates = np.linalg.eigvals(np.array(driveline.jacobian(t0, y0), dtype=float))
    decay = float(max([-z.real for z in rates] + [0.0]))
    steps = decay * span / DOP853_STABILITY
    if not steps > EXPLICIT_STEP_BUDGET:
        return None
    method = "Radau" if resisting else "CVODE-BDF"
    return method, (f"stiff: a mode decays at {decay:.4g} 1/s, so DOP853 would need about {steps:.3g} steps over "
                    f"{span:g} s (more than {EXPLICIT_STEP_BUDGET:,}); solved by {method}")


def reference_method(plan: plans.Plan, times: np.ndarray, method: str = "DOP853") -> tuple[str, str]:
    """``(method, note)``: the method a driveline scene's reference takes over ``times`` when
    asked for ``method`` - a stiff one (``stiff_method``) in place of DOP853 where DOP853 would
    not finish, with the note that says why; else ``method`` itself and no note."""
    if method != "DOP853" or len(times) < 2:
        return method, ""
    built = plan.driveline.physics.get()
    engine, load, coupling = built.engine, built.load, built.coupling
    misalignment = _misalignment_source(plan)
    t0 = float(times[0])
    at_start = coupling if misalignment is None else misalignment[1].at(misalignment[0].value(t0))
    (phi1, w1), (phi2, w2) = plan.driveline.start.get()
    y0 = [phi1, w1, phi2, w2, 0.0, 0.0, 0.0] + ([engine.torque_start] if isinstance(engine, LaggedShaft) else [])
    chosen = stiff_method(Driveline(engine, lambda t: at_start, load), t0, y0, float(times[-1]) - t0, load.resisting)
    return (method, "") if chosen is None else (chosen[0], f"; {chosen[1]}")


def solve_driveline(scene: scenes.Scene | plans.Plan, times: np.ndarray, use_cache: bool = True,
                    rtol: float = RTOL, atol: float = ATOL, method: str = "DOP853") -> MonolithicSolution:
    """``solve`` for a driveline scene (engine - coupling - load, a misalignment source perhaps)."""
    plan = planned(scene)
    scene = plan.scene
    roles = _driveline(plan).roles
    engine_name, coupling_name, load_name = roles.engine, roles.coupling, roles.load
    built = plan.driveline.physics.get()
    engine, load, coupling = built.engine, built.load, built.coupling
    misalignment = _misalignment_source(plan)
    (phi1, w1), (phi2, w2) = plan.driveline.start.get()
    lagged = isinstance(engine, LaggedShaft)
    y0 = [phi1, w1, phi2, w2, 0.0, 0.0, 0.0] + ([engine.torque_start] if lagged else [])
    method, stiff_note = reference_method(plan, times, method)
    path = cache_path(scene, times, rtol, atol, method)
    if use_cache and (cached := load_cached(path)) is not None:
        return cached

    if misalignment is not None:
        # the coupling at alpha(t), exactly as the coupling FMU evaluates it (CouplingFamily)
        source, family = misalignment
        alpha_at = source.value

        def coupling_at(t):
            return family.at(alpha_at(t))

        def evaluate(p1, v1, p2, v2, t):
            return family.at(alpha_at(t)).evaluate(p1, v1, p2, v2)
    else:
        def coupling_at(t):
            return coupling
    fixed = coupling.evaluate if misalignment is None else None
    # the right-hand side: the physics' own (lever.physics.driveline), as the ME editions
    driveline = Driveline(engine, coupling_at, load)
    rhs = driveline.derivatives

    started = clock.perf_counter()
    omega, _ = coupling.eigen_estimate(engine.inertia, load.inertia)
    if method in cvode.METHODS:
        if load.resisting:
            raise ReferenceUnavailable(f"scene '{scene.name}': CVODE has no stick/slip switching here (the load "
                                       "can stick); DOP853's reference switches its modes")
        t, y, counts = cvode.integrate(driveline, times, y0, cvode.METHODS[method], rtol, atol,
                                       min(1e-4, 0.1 / omega))
        nfev = counts["rhs"]
    elif load.resisting:
        couple = fixed if fixed else (lambda p1, v1, p2, v2, t: evaluate(p1, v1, p2, v2, t))
        t, y, nfev = _solve_stick_slip(couple, driveline, load, times, y0, method, rtol, atol,
                                       min(1e-4, 0.1 / omega), fixed is not None)
    else:
        solution = solve_ivp(rhs, (float(times[0]), float(times[-1])), y0,
                             method=method, t_eval=times, rtol=rtol, atol=atol,
                             first_step=min(1e-4, 0.1 / omega))
        if not solution.success:
            where = f" at t = {solution.t[-1]:.6g} s" if len(solution.t) else ""
            raise ReferenceUnavailable(f"the reference solver failed{where}: {solution.message}")
        t, y, nfev = solution.t, solution.y, int(solution.nfev)
    p1, v1, p2, v2, work_in, work_out, dissipated = y[:7]
    # the physics takes scalars (it runs in the FMUs on the standard library alone)
    if misalignment is None:
        rows = [coupling.evaluate(*row) for row in zip(p1, v1, p2, v2)]
    else:
        rows = [evaluate(*row) for row in zip(p1, v1, p2, v2, t)]
    r = type(rows[0])(*(np.array(column) for column in zip(*rows)))
    if lagged:
        m1 = y[7]
        a1 = (m1 + np.asarray(r.tau1)) / engine.inertia
    else:
        a1, m1 = _shaft_rates(engine, t, p1, v1, np.asarray(r.tau1))
    a2, m2 = _shaft_rates(load, t, p2, v2, np.asarray(r.tau2))
    e, c, l = engine_name, coupling_name, load_name
    traces = {
        f"{e}.phi": p1, f"{e}.w": v1, f"{e}.a": a1, f"{e}.engine_torque": m1,
        f"{e}.engine_work": work_in,
        f"{l}.phi": p2, f"{l}.w": v2, f"{l}.a": a2, f"{l}.load_torque": -m2,
        f"{l}.load_work": work_out,
        f"{c}.tau1": np.asarray(r.tau1), f"{c}.tau2": np.asarray(r.tau2), f"{c}.U12": np.asarray(r.ratio),
        f"{c}.theta": np.asarray(r.deflection), f"{c}.elastic_energy": np.asarray(r.energy),
        f"{c}.dissipated_power": np.asarray(r.dissipation), f"{c}.dissipated_energy": dissipated,
    }
    if misalignment is not None:        # the source's outputs: known functions of time
        name = plan.driveline.misalignment_driver.source
        traces[f"{name}.misalignment"] = np.array([source.value(x) for x in t])
        traces[f"{name}.misalignment_rate"] = np.array([source.rate(x) for x in t])
    # the time to the traces, the recorded outputs computed as a master reads them at its points
    wall = clock.perf_counter() - started
    reference = MonolithicSolution(t, traces, wall, nfev, f"{method} rtol={rtol:g} atol={atol:g}{stiff_note}")
    if use_cache:
        store(path, reference)
    return reference


#: mode switches (stops, breakaways) one reference run may hold before it is refused as chatter
MAX_SWITCHES = 100_000


def _solve_stick_slip(couple, driveline, load, times, y0, method, rtol, atol, first_step, time_free):
    """The driveline with a resisting load (``lever.physics.friction``): integrated in
    segments of one mode each - the driven shaft slipping in a fixed direction, or held
    at rest - switched at scipy's located events: the speed through zero (stop; the
    stick condition decides) and the breakaway margin through zero (slip off in the
    direction of the net torque).  The same functions of the physics as the FMU's
    integrator; ``driveline`` (``lever.physics.driveline.Driveline``) gives the
    right-hand side of each mode.  Returns ``(t, y, nfev)`` at ``times``."""
    shaft = load
    friction = shaft.external

    def coupling_at(t, y):
        return couple(y[0], y[1], y[2], y[3]) if time_free else couple(y[0], y[1], y[2], y[3], t)

    def slipping(direction):
        def rhs(t, y):
            return driveline.derivatives(t, y, direction)

        def stop(t, y):
            return y[3]
        stop.terminal = True
        stop.direction = -direction
        return rhs, stop

    def held(t, y):
        return driveline.derivatives(t, y, HELD)

    def breakaway(t, y):
        return friction.breakaway_margin(t, y[2], coupling_at(t, y).tau2)[0]
    breakaway.terminal = True
    breakaway.direction = 1.0

    def mode_at(t, y):
        """(held?, direction) by the memoryless law of the physics."""
        tau2 = coupling_at(t, y).tau2
        if friction.stuck(t, y[2], y[3], tau2):
            return True, 0.0
        if y[3] != 0.0:
            return False, np.copysign(1.0, y[3])
        return False, float(np.copysign(1.0, friction.breakaway_margin(t, y[2], tau2)[1]))

    t_out, y_out, nfev = [], [], 0
    start, stop_time = float(times[0]), float(times[-1])
    y = list(map(float, y0))
    done = 0
    step = first_step
    mode = mode_at(start, y)
    for _ in range(MAX_SWITCHES):
        is_held, direction = mode
        if is_held:
            y[3] = 0.0
            rhs, events = held, [breakaway]
        else:
            rhs, stop = slipping(direction)
            events = [stop]
        remaining = times[done:]
        solution = solve_ivp(rhs, (start, stop_time), y, method=method, t_eval=remaining, rtol=rtol, atol=atol,
                             first_step=step, events=events)
        nfev += int(solution.nfev)
        if solution.status == -1:
            raise ReferenceUnavailable(f"the reference solver failed at t = {solution.t[-1]:.6g} s: "
                                       f"{solution.message}")
        t_out.append(solution.t)
        y_out.append(solution.y)
        done += len(solution.t)
        if solution.status == 0:
            break
        start = float(solution.t_events[0][0])
        y = [float(v) for v in solution.y_events[0][0]]
        if is_held:         # broke away: slips off in the direction of the net torque
            net = friction.breakaway_margin(start, y[2], coupling_at(start, y).tau2)[1]
            mode = (False, float(np.copysign(1.0, net)))
        else:               # stopped, exactly: the stick condition decides
            y[3] = 0.0
            mode = mode_at(start, y)
        step = min(first_step, max(1e-12, 1e-3 * (stop_time - start)))
    else:
        raise ReferenceUnavailable(f"the driven shaft stopped and broke away more than {MAX_SWITCHES} times "
                               "(chattering friction): the reference gives up")
    return np.concatenate(t_out), np.concatenate(y_out, axis=1), nfev


#: the reference solver of each kind of scene (harness.description.scene_kinds); the rectifier
#: scene has its own event-aware one
SOLVERS = {"driveline": solve_driveline, "rectifier": rectifier.solve_reference}
