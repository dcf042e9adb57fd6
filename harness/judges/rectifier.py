"""The freewheel rectifier scene (MODEL.md section 8): its monolithic reference, the
analysis of a run (engagement and free-wheeling phases, gaps closing and opening, energy
balance, the kinematics set beside the source's description) and its report.

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

from lever.physics import catalogue
from lever.physics.freewheel import EVENTS, N_EDGES

from . import metrics
from . import scene as scenes

FMU = "FreewheelRectifier"
RTOL = 1e-10
ATOL = 1e-12


def component(scene: scenes.Scene) -> str | None:
    return scene.component_of(FMU)


# -- the monolithic reference --------------------------------------------------------------------

def solve_reference(scene: scenes.Scene, times: np.ndarray, use_cache: bool = True, rtol: float = RTOL,
                    atol: float = ATOL, method: str = "DOP853"):
    from .reference import Reference, ReferenceUnavailable, cache_path, load_cached, store

    name = component(scene)
    if len(scene.components) != 1 or scene.connections:
        raise ReferenceUnavailable(f"scene '{scene.name}': the rectifier's reference covers the rectifier alone "
                                   "(its port unconnected, tau = 0)")
    path = cache_path(scene, times, rtol, atol, method)
    if use_cache and (cached := load_cached(path)) is not None:
        return cached
    model = catalogue.freewheel_from(metrics.parameters(scene, name))
    started = clock.perf_counter()
    rows, n_rhs, events = integrate(model, np.asarray(times, dtype=float), rtol, atol, method)
    wall = clock.perf_counter() - started
    # ``events`` counts the events the integrator located: bookkeeping of each solver, not
    # a signal a co-simulation could match (the reference's own count is in ``info``).
    traces = {f"{name}.{k}": np.array([r[k] for r in rows]) for k in rows[0] if k != "events"}
    reference = Reference(np.asarray(times, dtype=float)[:len(rows)], traces, wall, n_rhs,
                          f"{method} rtol={rtol:g} atol={atol:g}, restarted at {len(events)} located events",
                          info={"events": len(events), "bookkeeping": [f"{name}.events"]})
    if use_cache:
        store(path, reference)
    return reference


def integrate(model, times: np.ndarray, rtol: float = RTOL, atol: float = ATOL, method: str = "DOP853"):
    """``(rows, rhs evaluations, events)``: the named outputs at ``times`` and the events
    ``(time, name)``, by scipy with terminal events and a restart at each."""
    from .reference import ReferenceUnavailable

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


def analyse(scene: scenes.Scene, times: np.ndarray, traces: dict) -> dict:
    """Phases, gaps, energy balance and kinematics of a run (co-simulation or reference)."""
    name = component(scene)
    model = catalogue.freewheel_from(metrics.parameters(scene, name))

    def tr(var):
        return np.asarray(traces[f"{name}.{var}"])

    period = 2.0 * math.pi / model.omega
    engaged = tr("msm_contact") > 0.5
    slipping = tr("disc_slip") != 0.0
    contacts = _intervals(times, engaged)
    # Per rocker cycle: the main engagement (the longest contact of the ramps) and the
    # short contacts before it, where the half-couplings bounce across the gap.
    phases = []
    n_cycles = int(math.ceil(times[-1] / period - 1e-9))
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
    # torque impulse on the torsion shaft: from the first to the last instant it carries
    # more than 5 % of its peak, per complete cycle
    torsion = tr("torsion_torque")
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
    gaps = {"msm (z1)": _transitions(tr("msm_contact")), "torsion splines (z2)": _transitions(tr("torsion_contact")),
            "gear mesh (z3)": _transitions(tr("mesh_contact"))}
    time_open = {label: float(np.mean(tr(var) == 0.0)) for label, var in
                 (("msm (z1)", "msm_contact"), ("torsion splines (z2)", "torsion_contact"),
                  ("gear mesh (z3)", "mesh_contact"))}
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
    tan_a, nf = model.self_locking()
    return {
        "period_s": period,
        "phases": phases,
        "engaged_fraction": float(np.mean(engaged)),
        "torque_impulses": impulses,
        "gap_transitions": gaps,
        "fraction_of_time_gap_open": time_open,
        "events_located": float(tr("events")[-1]) if f"{name}.events" in traces else None,
        "energy_balance": balance,
        "kinematics": kinematics,
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
    name = component(scene)
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


# -- report ----------------------------------------------------------------------------------------

def summarize(result, reference=None) -> dict:
    scene = result.scene
    summary = {
        "scene": scene.name, "description": scene.description, "master": result.master, "step_s": result.step,
        "stop_s": scene.experiment.stop, "transient_s": scene.experiment.transient, "ok": result.ok,
        "failure": result.failure, "wall_time_s": result.wall_time, "counters": result.counters,
    }
    if len(result.times) > 1:
        summary["freewheel"] = analyse(scene, result.times, result.traces)
        summary["energy_balance"] = summary["freewheel"]["energy_balance"]
    if reference is not None and len(result.times):
        summary["error_vs_reference"] = errors(scene, result.times, result.traces, reference)
        summary["reference"] = {"method": reference.method, "wall_time_s": reference.wall_time,
                                "rhs_evaluations": reference.n_rhs,
                                "energy_balance": analyse(scene, reference.times, reference.traces)["energy_balance"]}
    return summary


def _f(x, digits=4):
    if x is None:
        return "-"
    if isinstance(x, float) and x != 0.0 and (abs(x) >= 1e4 or abs(x) < 1e-3):
        return f"{x:.{digits - 1}e}"
    return f"{x:.{digits}g}"


def write_report(path, summary: dict):
    lines = [f"# {summary['scene']}: {summary['description']}", "",
             f"Master **{summary['master']}**, communication step {summary['step_s']:g} s, 0 ... {summary['stop_s']:g} s; "
             f"wall time {summary['wall_time_s']:.2f} s.  One FMU (`FreewheelRectifier`) holds the whole chain "
             "(docs/decisions.md: why one FMU)."]
    if summary["failure"]:
        lines += ["", f"**The run failed:** {summary['failure']}", "", "The traces up to the failure are in traces.csv."]
    fw = summary.get("freewheel")
    if fw:
        d = fw["derived"]
        z1, z2, z3 = d["gaps_rad"]
        lines += ["", "## Engagement and free-wheeling", "",
                  f"Rocker period {fw['period_s'] * 1e3:.2f} ms; the freewheel was engaged (discs clamped, e > 0) "
                  f"{100 * fw['engaged_fraction']:.1f} % of the time and free-wheeling the rest.", "",
                  "Per rocker cycle, the main engagement (the longest contact on the ramps; before it the "
                  "half-couplings may touch the ramps briefly and bounce back across the gap):", "",
                  "| cycle | engaged from [s] | to [s] | for [ms] | bounces before | rocker angle at engagement [rad] | "
                  "into the forward stroke | peak rocker torque [N*m] | peak torsion torque [N*m] | "
                  "peak torsion twist [rad] | discs slipping [ms] (up to rocker torque [N*m]) |",
                  "|---|---|---|---|---|---|---|---|---|---|---|"]
        for p in fw["phases"]:
            slip = (f"{1e3 * p['slip_time_s']:.1f} ({p['largest_rocker_torque_while_slipping_Nm']:.1f})"
                    if p["slip_time_s"] else "0")
            lines.append(f"| {p['cycle']}{'' if p['complete'] else ' (cut)'} | {p['start_s']:.4f} | {p['end_s']:.4f} | "
                         f"{1e3 * p['duration_s']:.1f} | {p['bounces_before']} | "
                         f"{p['rocker_angle_at_engagement_rad']:.4f} | {100 * p['rocker_stroke_fraction']:.0f} % | "
                         f"{p['peak_rocker_torque_Nm']:.1f} | {p['peak_torsion_torque_Nm']:.1f} | "
                         f"{p['peak_torsion_twist_rad']:.4f} | {slip} |")
        lines += ["", "## The gaps closing and opening", "",
                  f"z1 = {z1:.4f} rad (axial gap of the freewheel as a rocker angle), z2 = {z2:.4f} rad (torsion "
                  f"splines), z3 = {z3:.4f} rad (gear mesh).  Counted at the recorded resolution; the FMU located "
                  f"{_f(fw['events_located'])} events in all (gap edges and stick/slip changes).", "",
                  "| gap | closed on the drive flank | closed on the back flank | opened | share of time open |",
                  "|---|---|---|---|---|"]
        for label, g in fw["gap_transitions"].items():
            lines.append(f"| {label} | {g['closed_drive_flank']} | {g['closed_back_flank']} | {g['opened']} | "
                         f"{100 * fw['fraction_of_time_gap_open'][label]:.0f} % |")
        eb = fw["energy_balance"]
        lines += ["", "## Energy balance", "",
                  f"input work (rocker) {eb['input_work_J']:.6g} J = output work {eb['output_work_J']:.4g} J + change of "
                  f"stored energy (kinetic + elastic) {eb['stored_change_J']:.6g} J + dissipated {eb['dissipated_J']:.6g} J "
                  f"+ residual {eb['residual_J']:.3g} J.", "",
                  f"The rocker put in up to {eb['largest_input_work_J']:.4g} J within a stroke (most of it comes back "
                  f"when the torsion shaft unwinds); relative to that the residual is "
                  f"**{eb['residual_relative']:.2g}** at the end and at most {eb['worst_residual_relative']:.2g} "
                  "at any recorded time."]
        lines += ["", "## Kinematics beside the source's description", ""] + _comparison(fw)
    from .report import reference_error_lines
    errs = summary.get("error_vs_reference")
    lines += reference_error_lines(summary, "Against the monolithic reference",
                                   "speeds relative to the rocker's peak speed, torques to the reference's peak torque")
    lines += ["", "Plots: kinematics.png (elements 1-4, as the paper's Figs. 8-11), gaps.png, torques.png, energy.png"
              + (", vs_reference.png" if errs else "") + ".  Traces: traces.csv" + (" and reference.csv." if errs else ".")]
    path.write_text("\n".join(lines) + "\n")


def _comparison(fw: dict) -> list[str]:
    """The source's statements (in our words) beside the numbers of this run."""
    k = fw["kinematics"]
    d = fw["derived"]
    z1, z2, z3 = d["gaps_rad"]
    phases = fw["phases"]
    rows = []
    rocker = k["rocker (1)"]
    rows.append(("Rocker (Fig. 8): harmonic oscillation phi0 (1 - cos(omega t)), phi0 = 0.103 rad, omega = 42.41 rad/s "
                 "(8).",
                 f"angle {rocker['angle_range_rad'][0]:.4f} ... {rocker['angle_range_rad'][1]:.4f} rad, peak speed "
                 f"{rocker['peak_speed_rad_s']:.3f} rad/s (phi0 omega = {d['rocker_peak_speed_rad_s']:.3f}), peak "
                 f"acceleration {rocker['peak_acceleration_rad_s2']:.1f} rad/s^2 (phi0 omega^2 = "
                 f"{d['rocker_peak_acceleration_rad_s2']:.1f}): prescribed, exact."))
    if phases:
        first = phases[0]
        later = [p["rocker_angle_at_engagement_rad"] for p in phases[1:]]
        rows.append(("The torque on the rocker, and its turning relative to the torsion shaft, appear only once the "
                     "axial gap of the freewheel has been taken up.",
                     f"first stroke (from rest, every gap open): first contact of the ramps at rocker angle "
                     f"{first['rocker_angle_at_first_contact_rad']:.4f} rad (z1 = {z1:.4f} rad plus what the free "
                     f"parts moved), sustained torque from {first['rocker_angle_at_engagement_rad']:.4f} rad, after the "
                     f"driven parts crossed z2 = {z2:.4f} and z3 = {z3:.4f} rad; "
                     + (f"later strokes from {min(later):.4f} ... {max(later):.4f} rad (the rocker's stroke is "
                        f"{2 * d['rocker_peak_speed_rad_s'] / (2 * math.pi / fw['period_s']):.3f} rad)"
                        if later else "no later stroke engaged")
                     + "; before that the rocker torque is the return springs' "
                     f"{d['return_spring_torque_Nm']:.3f} N*m."))
    half = k["half-couplings (2)"]
    rows.append(("Half-couplings (Fig. 9): the balls keep them tied to the rocker through the whole cycle (1); they "
                 "follow the rocker, lagging it by the gap.",
                 f"angle {half['angle_range_rad'][0]:.4f} ... {half['angle_range_rad'][1]:.4f} rad (amplitude "
                 f"{half['angle_amplitude_rad']:.4f} against the rocker's {rocker['angle_amplitude_rad']:.4f}), peak speed "
                 f"{half['peak_speed_rad_s']:.3f} rad/s, peak acceleration {half['peak_acceleration_rad_s2']:.0f} "
                 "rad/s^2 (the impacts at the gaps' edges)."))
    driven = k["driven parts, torsion input end (3)"]
    end = k["torsion output end (4)"]
    twist = max((p["peak_torsion_twist_rad"] for p in phases), default=float("nan"))
    rows.append(("Driven parts and torsion shaft (Figs. 10, 11): in the stop mode the output is held, so the torsion's "
                 "input end turns only by the shaft's twist and the gaps, its output end only within the mesh.",
                 f"input end {driven['angle_range_rad'][0]:.4f} ... {driven['angle_range_rad'][1]:.4f} rad, peak twist "
                 f"{twist:.4f} rad; output end {end['angle_range_rad'][0]:.4f} ... {end['angle_range_rad'][1]:.4f} rad "
                 f"(the backlash z3 = {z3:.4f} rad plus the mesh deflection); peak speeds {driven['peak_speed_rad_s']:.2f} "
                 f"and {end['peak_speed_rad_s']:.2f} rad/s."))
    sl = fw["self_locking"]
    slip_torque = max((p["largest_rocker_torque_while_slipping_Nm"] for p in phases), default=0.0)
    peak_torque = max((p["peak_rocker_torque_Nm"] for p in phases), default=0.0)
    rows.append(("Self-locking: the discs hold while tan(alpha) <= n f; with n = 9 and alpha = 17.5 deg the least f is "
                 "0.035.",
                 f"tan(alpha) = {sl['tan_alpha']:.4f}, n f_s = {sl['n_f_s']:.3f}, least f = {sl['f_min']:.4f}: "
                 + (f"while engaged the discs slipped only as the ramps came into contact, at rocker torques up to "
                    f"{slip_torque:.1f} N*m (the clamp force still small, the driven parts hit through the gaps), "
                    f"and held up to the peak of {peak_torque:.0f} N*m" if slip_torque else
                    f"while engaged the discs held up to the peak of {peak_torque:.0f} N*m")
                 + "; in free-wheeling they slip, passing only the drag M_v."))
    if fw["torque_impulses"]:
        durations = [i["duration_s"] for i in fw["torque_impulses"]]
        rows.append(("The torsion shafts stretch the torque impulses in time (that is what gives the transmission "
                     "overlapping, continuous output torque).",
                     f"torque above 5 % of its peak for {1e3 * min(durations):.1f} ... {1e3 * max(durations):.1f} ms per "
                     f"cycle, against a forward stroke of {1e3 * fw['period_s'] / 2:.1f} ms; peaks "
                     + ", ".join(f"{i['peak_Nm']:.0f}" for i in fw["torque_impulses"]) + " N*m."))
    rows.append(("The gaps harm the elements' kinematics; the paper's computed and measured kinematics differ by "
                 "10-15 %.",
                 "the dead stroke above and the impacts at the gaps' edges (accelerations of the half-couplings and "
                 "driven parts far above the rocker's) are the gaps' doing.  The paper's curves themselves are not in "
                 "the text we have, so the comparison stops at these statements."))
    out = ["| the source says (in our words) | this run |", "|---|---|"]
    out += [f"| {a} | {b} |" for a, b in rows]
    return out


def plot(out, result, reference=None):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scene = result.scene
    name = component(scene)
    t = result.times
    tr = {k.split(".", 1)[1]: v for k, v in result.traces.items() if k.startswith(name + ".")}
    title = f"{scene.name} - {result.master}, h = {result.step:g} s"
    elements = (("rocker", "1 rocker"), ("half_coupling", "2 half-couplings"), ("driven", "3 driven parts"),
                ("torsion_end", "4 torsion output end"))

    fig, axes = plt.subplots(3, 1, figsize=(11, 9), sharex=True)
    for ax, (quantity, unit) in zip(axes, (("angle", "rad"), ("speed", "rad/s"), ("acceleration", "rad/s^2"))):
        for prefix, label in elements:
            ax.plot(t, tr[f"{prefix}_{quantity}"], lw=0.8, label=label)
        ax.set_ylabel(f"{quantity} [{unit}]")
        ax.grid(alpha=0.3)
    axes[2].set_yscale("symlog", linthresh=200.0)
    axes[0].legend(loc="upper right", fontsize=8, ncol=4)
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(f"{title}: kinematics of the elements (cf. the paper's Figs. 8-11)")
    fig.tight_layout()
    fig.savefig(out / "kinematics.png", dpi=110)
    plt.close(fig)

    model = catalogue.freewheel_from(metrics.parameters(scene, name))
    fig, axes = plt.subplots(4, 1, figsize=(11, 10), sharex=True)
    for ax, (var, gap, label) in zip(axes, (("msm_deflection", model.z1, "e = phi1 - phi2 (gap z1)"),
                                            ("torsion_twist", model.z2, "phi3 - phi4 (gap z2)"),
                                            ("mesh_deflection", model.z3, "phi4 - phi5 (gap z3)"))):
        ax.axhspan(-gap, 0.0, color="C1", alpha=0.15, label="gap")
        ax.plot(t, tr[var], "k-", lw=0.8, label=label)
        ax.set_ylabel("[rad]")
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=8)
    for k, (var, label) in enumerate((("msm_contact", "freewheel"), ("torsion_contact", "torsion splines"),
                                      ("mesh_contact", "gear mesh"), ("disc_slip", "disc slip"))):
        axes[3].plot(t, tr[var] + 3.0 * (3 - k), lw=0.8, label=f"{label} (+{3 * (3 - k)})")
    axes[3].set_ylabel("contact: +1 drive, 0 open, -1 back")
    axes[3].legend(loc="upper right", fontsize=7, ncol=4)
    axes[3].grid(alpha=0.3)
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(f"{title}: the gaps closing and opening")
    fig.tight_layout()
    fig.savefig(out / "gaps.png", dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(1, 1, figsize=(11, 4))
    for var, label in (("rocker_torque", "T12 rocker -> half-couplings"), ("disc_torque", "through the discs"),
                       ("disc_capacity", "discs' capacity"), ("torsion_torque", "T34 torsion shaft"),
                       ("mesh_torque", "T45 gear mesh")):
        ax.plot(t, tr[var], lw=0.8, label=label, ls="--" if var == "disc_capacity" else "-")
    ax.set_ylabel("torque [N*m]")
    ax.set_xlabel("time [s]")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    fig.suptitle(f"{title}: torques")
    fig.tight_layout()
    fig.savefig(out / "torques.png", dpi=110)
    plt.close(fig)

    stored = tr["kinetic_energy"] + tr["elastic_energy"]
    stored = stored - stored[0]
    residual = tr["input_work"] - tr["output_work"] - stored - tr["dissipated_energy"]
    fig, axes = plt.subplots(2, 1, figsize=(11, 6), sharex=True)
    axes[0].plot(t, tr["input_work"], lw=0.9, label="input work (rocker)")
    axes[0].plot(t, stored, lw=0.9, label="stored (kinetic + elastic)")
    axes[0].plot(t, tr["dissipated_energy"], lw=0.9, label="dissipated")
    axes[0].plot(t, tr["output_work"], lw=0.9, label="output work")
    axes[0].set_ylabel("energy [J]")
    axes[0].legend(loc="upper left", fontsize=8)
    axes[0].grid(alpha=0.3)
    axes[1].plot(t, residual, "k-", lw=0.8)
    axes[1].set_ylabel("residual [J]")
    axes[1].set_xlabel("time [s]")
    axes[1].grid(alpha=0.3)
    fig.suptitle(f"{title}: energy balance, input = stored + dissipated + output + residual")
    fig.tight_layout()
    fig.savefig(out / "energy.png", dpi=110)
    plt.close(fig)

    if reference is not None:
        n = min(len(t), len(reference.times))
        fig, axes = plt.subplots(3, 1, figsize=(11, 8), sharex=True)
        for ax, var in zip(axes, ("half_coupling_speed", "driven_speed", "torsion_torque")):
            ax.plot(reference.times[:n], reference.traces[f"{name}.{var}"][:n], "k-", lw=1.2, label="reference")
            ax.plot(t[:n], tr[var][:n], "C1--", lw=0.8, label=f"FMU ({result.master})")
            ax.set_ylabel(var)
            ax.grid(alpha=0.3)
            ax.legend(loc="upper right", fontsize=8)
        axes[-1].set_xlabel("time [s]")
        fig.suptitle(f"{title}: FMU against the monolithic reference")
        fig.tight_layout()
        fig.savefig(out / "vs_reference.png", dpi=110)
        plt.close(fig)


def write(out, result, reference=None) -> dict:
    from .report import write_run
    return write_run(out, result, reference, summarize, write_report, plot)


__all__ = ["solve_reference", "integrate", "analyse", "errors", "summarize", "write"]
