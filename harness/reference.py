"""The monolithic reference: the scene's equations solved unsplit with scipy at tight
tolerance, from the same physics objects the FMUs use (``lever.physics.catalogue``).

For the driveline (engine shaft - lever coupling - load shaft) the state is
``[phi1, w1, phi2, w2]``, augmented with the engine's work, the load's work and the
energy dissipated in the coupling, so the reference's own energy balance is exact up to
the integrator's tolerance.  Results are cached by a hash of everything they depend on.
"""
from __future__ import annotations

import hashlib
import json
import time as clock
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

from lever.physics import catalogue

from . import metrics
from . import scene as scenes
from .paths import RESULTS

RTOL = 1e-10
ATOL = 1e-10
CACHE = RESULTS / ".cache"


class ReferenceUnavailable(ValueError):
    pass


@dataclass
class Reference:
    times: np.ndarray
    traces: dict[str, np.ndarray]
    wall_time: float
    n_rhs: int
    method: str
    status: str = "ok"
    info: dict = field(default_factory=dict)


def _roles(scene: scenes.Scene):
    engine, coupling, load = metrics.roles(scene)
    if not (engine and coupling and load):
        raise ReferenceUnavailable(f"scene '{scene.name}': the monolithic reference covers the engine - coupling - "
                                   "load driveline (EngineShaft, LeverCoupling, LoadShaft)")
    return engine, coupling, load


def _misalignment_source(scene: scenes.Scene, coupling_name: str):
    """alpha(t) when a source drives the coupling's misalignment input, else None."""
    driver = next((c for c in scene.connections if c.target == coupling_name and c.input == "misalignment"), None)
    if driver is None:
        return None
    if scene.components[driver.source].fmu != "MisalignmentSource" or driver.output != "misalignment":
        raise ReferenceUnavailable(f"scene '{scene.name}': the reference knows the misalignment only from a "
                                   f"MisalignmentSource, not from {driver}")
    return catalogue.misalignment_source_from(metrics.parameters(scene, driver.source))


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


def cache_key(scene: scenes.Scene, times: np.ndarray, rtol: float = RTOL, atol: float = ATOL,
              method: str = "DOP853") -> str:
    payload = {
        "components": {n: {"fmu": c.fmu, "parameters": c.parameters} for n, c in sorted(scene.components.items())},
        "grid": hashlib.sha256(np.ascontiguousarray(times, dtype=float).tobytes()).hexdigest(),
        "rtol": rtol, "atol": atol, "method": method,
        "physics": _physics_hash(),
    }
    return hashlib.sha256(json.dumps(payload, sort_keys=True, default=str).encode()).hexdigest()[:16]


def _physics_hash() -> str:
    root = Path(catalogue.__file__).parent
    digest = hashlib.sha256()
    for path in sorted(root.glob("*.py")):
        digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def solve(scene: scenes.Scene, times: np.ndarray, use_cache: bool = True, rtol: float = RTOL,
          atol: float = ATOL, method: str = "DOP853") -> Reference:
    """Reference traces at ``times`` (named like the scene's records: ``engine.w`` ...).
    Looser ``rtol``/``atol`` (or another scipy ``method``) give the monolithic solution a
    benchmark compares the masters with."""
    from . import freewheel
    if freewheel.component(scene):      # the rectifier scene: its own event-aware reference
        return freewheel.solve_reference(scene, times, use_cache, rtol, atol, method)
    engine_name, coupling_name, load_name = _roles(scene)
    path = cache_path(scene, times, rtol, atol, method)
    if use_cache and (cached := load_cached(path)) is not None:
        return cached

    engine = catalogue.engine_from(metrics.parameters(scene, engine_name))
    load = catalogue.load_from(metrics.parameters(scene, load_name))
    coupling_params = metrics.parameters(scene, coupling_name)
    coupling = catalogue.coupling_from(coupling_params)
    misalignment = _misalignment_source(scene, coupling_name)
    phi1, w1 = catalogue.start_state(metrics.parameters(scene, engine_name), catalogue.ENGINE)
    phi2, w2 = catalogue.start_state(metrics.parameters(scene, load_name), catalogue.LOAD)
    drive_rates, driven_rates = engine.rates, load.rates

    if misalignment is not None:
        # the coupling at alpha(t), exactly as the coupling FMU evaluates it (CouplingFamily)
        family = catalogue.coupling_family_from(coupling_params)
        alpha_at = misalignment.value

        def evaluate(p1, v1, p2, v2, t):
            return family.at(alpha_at(t)).evaluate(p1, v1, p2, v2)
    fixed = coupling.evaluate if misalignment is None else None

    def rhs(t, y):
        p1, v1, p2, v2 = y[0], y[1], y[2], y[3]
        r = fixed(p1, v1, p2, v2) if fixed else evaluate(p1, v1, p2, v2, t)
        a1, m1 = drive_rates(t, p1, v1, r.tau1)
        a2, m2 = driven_rates(t, p2, v2, r.tau2)
        return [v1, a1, v2, a2, m1 * v1, -m2 * v2, r.dissipation]

    started = clock.perf_counter()
    omega, _ = coupling.eigen_estimate(engine.inertia, load.inertia)
    solution = solve_ivp(rhs, (float(times[0]), float(times[-1])), [phi1, w1, phi2, w2, 0.0, 0.0, 0.0],
                         method=method, t_eval=times, rtol=rtol, atol=atol,
                         first_step=min(1e-4, 0.1 / omega))
    wall = clock.perf_counter() - started
    if not solution.success:
        raise ReferenceUnavailable(f"the reference solver failed at t = {solution.t[-1]:.6g} s: {solution.message}")
    p1, v1, p2, v2, work_in, work_out, dissipated = solution.y
    t = solution.t
    # the physics takes scalars (it runs in the FMUs on the standard library alone)
    if misalignment is None:
        rows = [coupling.evaluate(*row) for row in zip(p1, v1, p2, v2)]
    else:
        rows = [evaluate(*row) for row in zip(p1, v1, p2, v2, t)]
    r = type(rows[0])(*(np.array(column) for column in zip(*rows)))
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
        source = next(c.source for c in scene.connections if c.target == coupling_name and c.input == "misalignment")
        traces[f"{source}.misalignment"] = np.array([misalignment.value(x) for x in t])
        traces[f"{source}.misalignment_rate"] = np.array([misalignment.rate(x) for x in t])
    reference = Reference(t, traces, wall, int(solution.nfev), f"{method} rtol={rtol:g} atol={atol:g}")
    if use_cache:
        store(path, reference)
    return reference


def cache_path(scene: scenes.Scene, times, rtol, atol, method) -> Path:
    return CACHE / f"reference-{scene.name}-{cache_key(scene, times, rtol, atol, method)}.npz"


def load_cached(path: Path) -> Reference | None:
    """A stored reference (its ``info`` as stored, marked cached), or None."""
    if not path.exists():
        return None
    data = np.load(path, allow_pickle=False)
    meta = json.loads(str(data["meta"]))
    traces = {k: data[k] for k in data.files if k not in ("meta", "times")}
    return Reference(data["times"], traces, meta["wall_time"], meta["n_rhs"], meta["method"],
                     info={**meta.get("info", {}), "cached": True})


def store(path: Path, reference: Reference):
    CACHE.mkdir(parents=True, exist_ok=True)
    meta = json.dumps({"wall_time": reference.wall_time, "n_rhs": reference.n_rhs, "method": reference.method,
                       "info": reference.info})
    np.savez_compressed(path, times=reference.times, meta=np.array(meta), **reference.traces)
