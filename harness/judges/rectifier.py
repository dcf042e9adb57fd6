"""The freewheel rectifier scene (docs/physics.md#freewheel-rectifier): its monolithic reference, the
analysis of a run (engagement and free-wheeling phases, gaps closing and opening, energy
balance, the kinematics set beside the source's description).  Its report is written
by harness.formats.rectifier_report.

The reference integrates the same right-hand side and switching logic as the FMU
(``lever.physics.freewheel``) with scipy's DOP853 at tight tolerance, restarting at every
event that scipy locates (gap edges, stick/slip changes); the FMU uses fixed RK4 substeps
with its own event location, restarted at every communication point.
"""
from __future__ import annotations

import math
import time as clock

import numpy as np
from scipy.integrate import solve_ivp

from lever.physics.freewheel import EVENTS, N_EDGES

from harness.description import scene_kinds
from harness.description import plan as plans
from harness.description import scene as scenes
from harness.judges.solution import MonolithicSolution, ReferenceUnavailable, cache_path, load_cached, store

RTOL = 1e-10
ATOL = 1e-12


# -- the monolithic reference --------------------------------------------------------------------

def solve_reference(plan: plans.Plan, times: np.ndarray, use_cache: bool = True, rtol: float = RTOL,
                    atol: float = ATOL, method: str = "DOP853"):
    """The rectifier's reference at ``times`` from a checked scene (harness.description.plan)."""
    scene = plan.scene
    name = plan.rectifier.name
    if len(scene.components) != 1 or scene.connections or any(v != 0 for v in plan.rectifier.inputs.get().values()):
        raise ReferenceUnavailable(f"scene '{scene.name}': the rectifier's reference covers the rectifier alone "
                                   "(its port unconnected, tau = 0)")
    path = cache_path(scene, times, rtol, atol, method)
    if use_cache and (cached := load_cached(path)) is not None:
        return cached
    model = plan.rectifier.model.get()
    started = clock.perf_counter()
    rows, n_rhs, events = integrate(model, np.asarray(times, dtype=float), rtol, atol, method)
    # ``events`` counts the events the integrator located: bookkeeping of each solver, not
    # a signal a co-simulation could match (the reference's own count is in ``info``).
    traces = {f"{name}.{k}": np.array([r[k] for r in rows]) for k in rows[0] if k != "events"}
    wall = clock.perf_counter() - started     # the time to the traces, as a master's
    reference = MonolithicSolution(np.asarray(times, dtype=float)[:len(rows)], traces, wall, n_rhs,
                          f"{method} rtol={rtol:g} atol={atol:g}, restarted at {len(events)} located events",
                          info={"events": len(events), "bookkeeping": [f"{name}.events"]})
    if use_cache:
        store(path, reference)
    return reference


def integrate(model, times: np.ndarray, rtol: float = RTOL, atol: float = ATOL, method: str = "DOP853"):
    """``(rows, rhs evaluations, events)``: the named outputs at ``times`` and the events
    ``(time, name)``, by scipy with terminal events and a restart at each."""

    y, disc, fly = model.start()
    t = float(times[0])
    t_end = float(times[-1])
    rows = [model.named_outputs(t, y, disc, fly, 0.0)]
    # The side of each gap edge the motion is on; kept across restarts, so an event
    # located a round-off away from its edge does not fire again at once.
    sides = [_side(model, t, y, disc, fly, k) for k in range(N_EDGES)]
    events = []
    n_rhs = 0
    stalled = 0
    while t < t_end:
        functions = []
        for k in range(len(EVENTS)):
            def g(tt, yy, k=k, disc=disc, fly=fly):
                return model.event_values(tt, yy, disc, fly, 0.0)[k]
            g.terminal = True
            g.direction = -sides[k] if k < N_EDGES else -1
            functions.append(g)
        wanted = times[times > t]
        sol = solve_ivp(lambda tt, yy, disc=disc, fly=fly: model.derivatives(tt, yy, disc, fly, 0.0), (t, t_end), y,
                        method=method, rtol=rtol, atol=atol, t_eval=wanted, events=functions,
                        first_step=min(1e-6, t_end - t))
        n_rhs += int(sol.nfev)
        for i, ti in enumerate(sol.t):
            rows.append(model.named_outputs(ti, sol.y[:, i], disc, fly, 0.0, len(events)))
        if sol.status == -1:
            raise ReferenceUnavailable(f"the rectifier's reference failed at t = {t:.9g} s: {sol.message}")
        if sol.status == 0:
            break
        fired = [(te[0], k) for k, te in enumerate(sol.t_events) if len(te)]
        t_event, k = min(fired)
        y_event = list(sol.y_events[k][0])
        stalled = stalled + 1 if t_event <= t else 0
        if stalled > 50:
            raise ReferenceUnavailable(f"the rectifier's reference is stuck at t = {t:.9g} s on event {EVENTS[k]}")
        t, y = float(t_event), y_event
        if k < N_EDGES:
            sides[k] = -sides[k]
        else:
            y, disc, fly = model.switch(t, y, disc, fly, k, 0.0)
        events.append((t, EVENTS[k]))
    return rows, n_rhs, events


def _side(model, t, y, disc, fly, k) -> int:
    """Which side of gap edge ``k`` the motion is on, or is about to go to when it
    starts exactly on the edge (from the relative speed, else the acceleration)."""
    g = model.event_values(t, y, disc, fly, 0.0)[k]
    if g != 0.0:
        return 1 if g > 0.0 else -1
    speeds, accelerations = model.deflection_rates(t, y, disc, fly, 0.0)
    pair = k // 2
    if speeds[pair] != 0.0:
        return 1 if speeds[pair] > 0.0 else -1
    return 1 if accelerations[pair] >= 0.0 else -1


# -- analysis of a run ----------------------------------------------------------------------------

def _intervals(times: np.ndarray, flag: np.ndarray) -> list[tuple[float, float]]:
    """Time intervals where ``flag`` holds (at the recorded resolution)."""
    out = []
    start = None
    for t, f in zip(times, flag):
        if f and start is None:
            start = t
        elif not f and start is not None:
            out.append((float(start), float(t)))
            start = None
    if start is not None:
        out.append((float(start), float(times[-1])))
    return out


def _transitions(contact: np.ndarray) -> dict:
    """How often a gap closed (0 -> +-1) and opened (+-1 -> 0), per flank."""
    before, after = contact[:-1], contact[1:]
    return {"closed_drive_flank": int(np.sum((before != 1) & (after == 1))),
            "closed_back_flank": int(np.sum((before != -1) & (after == -1))),
            "opened": int(np.sum((before != 0) & (after == 0)))}


def _phases(times, tr, period: float, n_cycles: int) -> list[dict]:
    """Per rocker cycle: the main engagement (the longest contact of the ramps) and the
    short contacts before it, where the half-couplings bounce across the gap."""
    engaged = tr("msm_contact") > 0.5
    slipping = tr("disc_slip") != 0.0
    contacts = _intervals(times, engaged)
    phases = []
    for c in range(n_cycles):
        mine = [iv for iv in contacts if c * period <= iv[0] < (c + 1) * period]
        if not mine:
            continue
        start, end = max(mine, key=lambda iv: iv[1] - iv[0])
        keep = (times >= start) & (times <= end)
        slip = keep & slipping
        phases.append({
            "cycle": c + 1, "start_s": start, "end_s": end, "duration_s": end - start,
            "bounces_before": sum(1 for iv in mine if iv[0] < start),
            "rocker_angle_at_first_contact_rad": float(np.interp(mine[0][0], times, tr("rocker_angle"))),
            "rocker_angle_at_engagement_rad": float(np.interp(start, times, tr("rocker_angle"))),
            "rocker_stroke_fraction": (start - c * period) / (0.5 * period),
            "peak_rocker_torque_Nm": float(np.max(tr("rocker_torque")[keep])),
            "peak_torsion_torque_Nm": float(np.max(tr("torsion_torque")[keep])),
            "peak_torsion_twist_rad": float(np.max(tr("torsion_twist")[keep])),
            "slip_time_s": float(np.sum(slip) * (times[1] - times[0])) if len(times) > 1 else 0.0,
            "largest_rocker_torque_while_slipping_Nm": float(np.max(tr("rocker_torque")[slip])) if slip.any() else 0.0,
            "complete": (c + 1) * period <= times[-1] + 1e-9,
        })
    return phases


def _impulses(times, torsion, period: float, n_cycles: int) -> list[dict]:
    """The torque impulse on the torsion shaft: from the first to the last instant it
    carries more than 5 % of its peak, per complete cycle."""
    impulses = []
    for c in range(n_cycles):
        if (c + 1) * period > times[-1] + 1e-9:
            break
        keep = (times >= c * period) & (times < (c + 1) * period)
        peak = float(np.max(torsion[keep]))
        if peak <= 0.0:
            continue
        above = times[keep][torsion[keep] > 0.05 * peak]
        impulses.append({"cycle": c + 1, "peak_Nm": peak, "duration_s": float(above[-1] - above[0]),
                         "impulse_Nms": float(np.trapezoid(np.clip(torsion[keep], 0.0, None), times[keep]))})
    return impulses


def _energy_balance(tr) -> dict:
    """Input work = output work + change of stored energy + dissipated + residual, at the
    end and (the worst residual) at any recorded time."""
    work_in = tr("input_work")
    stored = tr("kinetic_energy") + tr("elastic_energy")
    balance = {
        "input_work_J": float(work_in[-1] - work_in[0]),
        "output_work_J": float(tr("output_work")[-1] - tr("output_work")[0]),
        "stored_change_J": float(stored[-1] - stored[0]),
        "dissipated_J": float(tr("dissipated_energy")[-1] - tr("dissipated_energy")[0]),
        "largest_input_work_J": float(np.max(work_in - work_in[0])),
    }
    residual = balance["input_work_J"] - balance["output_work_J"] - balance["stored_change_J"] - balance["dissipated_J"]
    # the whole history: the worst residual at any recorded time
    history = (work_in - work_in[0]) - (tr("output_work") - tr("output_work")[0]) - (stored - stored[0]) \
        - (tr("dissipated_energy") - tr("dissipated_energy")[0])
    scale = max(balance["largest_input_work_J"], 1e-12)
    balance.update({"residual_J": float(residual), "worst_residual_J": float(np.max(np.abs(history))),
                    "residual_relative": float(abs(residual) / scale),
                    "worst_residual_relative": float(np.max(np.abs(history)) / scale),
                    "relative_to": "the largest work the rocker had put in at any time"})
    return balance


def _kinematics(tr) -> dict:
    """Angle amplitude and range, peak speed and acceleration of elements 1-4."""
    def amplitude(var):
        y = tr(var)
        return float((np.max(y) - np.min(y)) / 2.0)

    kinematics = {}
    for label, prefix in (("rocker (1)", "rocker"), ("half-couplings (2)", "half_coupling"),
                          ("driven parts, torsion input end (3)", "driven"),
                          ("torsion output end (4)", "torsion_end")):
        kinematics[label] = {
            "angle_amplitude_rad": amplitude(f"{prefix}_angle"),
            "angle_range_rad": [float(np.min(tr(f"{prefix}_angle"))), float(np.max(tr(f"{prefix}_angle")))],
            "peak_speed_rad_s": float(np.max(np.abs(tr(f"{prefix}_speed")))),
            "peak_acceleration_rad_s2": float(np.max(np.abs(tr(f"{prefix}_acceleration")))),
        }
    return kinematics


def analyse(scene: scenes.Scene, times: np.ndarray, traces: dict) -> dict:
    """Phases, gaps, energy balance and kinematics of a run (co-simulation or reference)."""
    name = scene_kinds.rectifier(scene)
    model = scene_kinds.rectifier_model(scene)

    def tr(var):
        return np.asarray(traces[f"{name}.{var}"])

    period = 2.0 * math.pi / model.omega
    n_cycles = int(math.ceil(times[-1] / period - 1e-9))
    gaps = {"msm (z1)": _transitions(tr("msm_contact")), "torsion splines (z2)": _transitions(tr("torsion_contact")),
            "gear mesh (z3)": _transitions(tr("mesh_contact"))}
    time_open = {label: float(np.mean(tr(var) == 0.0)) for label, var in
                 (("msm (z1)", "msm_contact"), ("torsion splines (z2)", "torsion_contact"),
                  ("gear mesh (z3)", "mesh_contact"))}
    tan_a, nf = model.self_locking()
    return {
        "period_s": period,
        "phases": _phases(times, tr, period, n_cycles),
        "engaged_fraction": float(np.mean(tr("msm_contact") > 0.5)),
        "torque_impulses": _impulses(times, tr("torsion_torque"), period, n_cycles),
        "gap_transitions": gaps,
        "fraction_of_time_gap_open": time_open,
        "events_located": float(tr("events")[-1]) if f"{name}.events" in traces else None,
        "energy_balance": _energy_balance(tr),
        "kinematics": _kinematics(tr),
        "self_locking": {"tan_alpha": tan_a, "n_f_s": nf, "f_min": tan_a / model.p["friction_pairs"],
                         "holds": tan_a <= nf},
        "derived": {"axial_stiffness_N_per_m": model.axial_stiffness(),
                    "return_spring_torque_Nm": model.t_p,
                    "gaps_rad": [model.z1, model.z2, model.z3],
                    "rocker_peak_speed_rad_s": model.phi0 * model.omega,
                    "rocker_peak_acceleration_rad_s2": model.phi0 * model.omega ** 2},
        "output": {"final_speed_rad_s": float(tr("w")[-1]), "angle_range_rad": [float(np.min(tr("phi"))),
                                                                                 float(np.max(tr("phi")))]},
    }


# -- comparison with the reference ----------------------------------------------------------------

#: what the co-simulation is judged by against the reference, and the scale of each
COMPARED = ("half_coupling_speed", "driven_speed", "torsion_end_speed", "torsion_torque", "mesh_torque",
            "rocker_torque")


def errors(scene: scenes.Scene, times, traces, reference) -> dict:
    """RMS and max error of the main signals against the reference, relative to the
    reference's peak magnitude of each (speeds to the rocker's peak speed)."""
    name = scene_kinds.rectifier(scene)
    n = min(len(times), len(reference.times))
    if n == 0 or not np.allclose(times[:n], reference.times[:n], rtol=0, atol=1e-9):
        return {}
    out = {}
    rocker_peak = float(np.max(np.abs(reference.traces[f"{name}.rocker_speed"][:n])))
    for var in COMPARED:
        full = f"{name}.{var}"
        if full not in traces or full not in reference.traces:
            continue
        diff = traces[full][:n] - reference.traces[full][:n]
        scale = rocker_peak if var.endswith("speed") else float(np.max(np.abs(reference.traces[full][:n])))
        rms, peak = float(np.sqrt(np.mean(diff ** 2))), float(np.max(np.abs(diff)))
        out[var] = {"rms": rms, "max": peak, "rms_relative": rms / scale, "max_relative": peak / scale,
                    "scale": scale}
    return out


__all__ = ["solve_reference", "integrate", "analyse", "errors"]
