"""What a run is judged by: statistics of the motion (means, amplitudes
``A = (max - min)/2``, unevenness ``(w_max - w_min)/w_mean``), errors against the
reference, and the energy balance.  Pure functions of traces."""
from __future__ import annotations

import math

import numpy as np

from harness.description import plan as plans, scene as scenes
from harness.description.scene_kinds import roles


def rms(values) -> float:
    """Root mean square of ``values`` (equal weights: the rows of one grid)."""
    return float(np.sqrt(np.mean(np.asarray(values) ** 2)))


def _trapezoid(y, x):
    return float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(x))) if len(x) > 1 else 0.0


def signals(scene: scenes.Scene) -> dict[str, str]:
    """Short names of the driveline's main signals -> the scene's variable names."""
    engine, coupling, load = roles(scene)
    names = {"w1": f"{engine}.w", "w2": f"{load}.w", "a1": f"{engine}.a", "a2": f"{load}.a",
             "tau1": f"{coupling}.tau1", "tau2": f"{coupling}.tau2", "U12": f"{coupling}.U12"}
    if coupling is not None and (engine is None or load is None):
        # a shaft of the user's own in a role: its speed is what drives the coupling's speed input
        driving = {(c.target, c.input): f"{c.source}.{c.output}" for c in scene.connections}
        for short, taken in (("w1", engine), ("w2", load)):
            if taken is None and (coupling, short) in driving:
                names[short] = driving[(coupling, short)]
    return names


def inertias(scene: scenes.Scene) -> tuple[float, float]:
    driveline = plans.driveline_of(scene)
    return driveline.engine.get()["inertia"], driveline.load.get()["inertia"]


#: the largest energy residual (share of the work in) of a run whose results are to be
#: trusted: five times a master's worst on the committed scenes (2.0 %, jacobi on
#: kavz685_stall_resistive); beyond it the run's energy bookkeeping says its traces are not
#: the system's motion (an unstable coupling, a tolerance of 0.999)
TRUSTED_RESIDUAL = 0.05


def untrusted(balance: dict | None) -> str | None:
    """The sentence saying a run cannot be trusted from its energy balance (``energy_balance``),
    or None where the residual is within ``TRUSTED_RESIDUAL`` (or there is no balance)."""
    if not balance:
        return None
    share = balance["residual_relative"]
    if math.isfinite(share) and share <= TRUSTED_RESIDUAL:
        return None
    said = f"{100 * share:.2g} %" if math.isfinite(share) else "not finite"
    return (f"the energy residual is {said} of the work in (trusted up to {100 * TRUSTED_RESIDUAL:g} %): the traces "
            "are not the system's motion to be relied on - take a smaller step or tolerance, or another master")


def energy_balance(scene: scenes.Scene, times: np.ndarray, traces: dict, dissipated: np.ndarray | None = None) -> dict:
    """Work in - work out - stored - dissipated, over the whole run, in J and relative to
    the work in.  ``dissipated`` (cumulative, J) is used when given (the reference
    integrates it exactly); otherwise the dissipated power is integrated by trapezoids."""
    engine, coupling, load = roles(scene)
    i1, i2 = inertias(scene)
    w1, w2 = traces[f"{engine}.w"], traces[f"{load}.w"]
    work_in = float(traces[f"{engine}.engine_work"][-1] - traces[f"{engine}.engine_work"][0])
    work_out = float(traces[f"{load}.load_work"][-1] - traces[f"{load}.load_work"][0])
    kinetic = 0.5 * i1 * (w1[-1] ** 2 - w1[0] ** 2) + 0.5 * i2 * (w2[-1] ** 2 - w2[0] ** 2)
    elastic = float(traces[f"{coupling}.elastic_energy"][-1] - traces[f"{coupling}.elastic_energy"][0])
    if dissipated is None and f"{coupling}.dissipated_energy" in traces:
        dissipated = traces[f"{coupling}.dissipated_energy"]   # integrated over every row (a streamed run)
    if dissipated is None:
        lost = _trapezoid(traces[f"{coupling}.dissipated_power"], times)
    else:
        lost = float(dissipated[-1] - dissipated[0])
    residual = work_in - work_out - kinetic - elastic - lost
    return {"work_in_J": work_in, "work_out_J": work_out, "kinetic_change_J": float(kinetic),
            "elastic_change_J": elastic, "dissipated_J": lost, "residual_J": float(residual),
            "residual_relative": float(abs(residual) / abs(work_in)) if work_in else float("nan")}


def statistics(times: np.ndarray, traces: dict, names: list[str], transient: float) -> dict:
    """Mean and amplitude of each signal after the start-up transient; unevenness for
    speeds (names ending in ``.w``)."""
    keep = times >= times[0] + transient
    out = {}
    for name in names:
        if name not in traces:
            continue
        y = traces[name][keep]
        if y.size == 0:
            continue
        mean = float(np.mean(y))
        stats = {"mean": mean, "min": float(np.min(y)), "max": float(np.max(y)),
                 "amplitude": float((np.max(y) - np.min(y)) / 2.0)}
        if name.endswith(".w") and mean != 0.0:
            stats["unevenness"] = float((np.max(y) - np.min(y)) / mean)
        out[name] = stats
    return out


def errors(times: np.ndarray, traces: dict, reference_times: np.ndarray, reference: dict, names: list[str],
           scales: dict[str, float], after: float | None = None) -> dict:
    """RMS and max error of each signal against the reference, absolute and relative to
    ``scales[name]`` (the scene's mean torque for torques, mean speed for speeds).  The
    RMS is a time average (trapezoidal weights), so variable-step runs are judged by the
    same measure as fixed-step ones; ``after`` leaves out the times before it."""
    out = {}
    n = min(len(times), len(reference_times))
    if n == 0:
        return out
    if not np.allclose(times[:n], reference_times[:n], rtol=0, atol=1e-9):
        raise ValueError("co-simulation and reference are not on the same time grid")
    keep = slice(0, n) if after is None else np.flatnonzero(times[:n] >= after)
    t = times[:n][keep]
    if len(t) == 0:
        return out
    if len(t) > 1:
        dt = np.diff(t)
        weights = np.concatenate([[dt[0] / 2], (dt[1:] + dt[:-1]) / 2, [dt[-1] / 2]])
        weights /= weights.sum()
    else:
        weights = np.ones(1)
    for name in names:
        if name not in traces or name not in reference:
            continue
        diff = traces[name][:n][keep] - reference[name][:n][keep]
        rms = float(np.sqrt(np.dot(weights, diff ** 2)))
        peak = float(np.max(np.abs(diff)))
        scale = scales.get(name, 1.0)
        out[name] = {"rms": rms, "max": peak, "rms_relative": rms / scale, "max_relative": peak / scale,
                     "scale": scale}
    return out


#: the band of the oscillograms' high-frequency component (docs/physics.md#loads) [rad/s]
OSCILLOGRAM_BAND = (415.0, 425.0)


def spectrum(times: np.ndarray, y: np.ndarray, transient: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """One-sided complex spectrum of ``y`` after ``transient``: angular frequencies [rad/s]
    and the complex amplitude of a sinusoid at each (``abs``: its amplitude, ``angle``: its
    phase against the window's first sample; Hann window, its coherent gain divided out;
    the mean removed).  A variable-step trace is first put on a uniform grid of its median
    step."""
    keep = times >= times[0] + transient
    t, v = times[keep], np.asarray(y, dtype=float)[keep]
    if len(t) < 8:
        return np.zeros(0), np.zeros(0, dtype=complex)
    dt = float(np.median(np.diff(t)))
    if not np.allclose(np.diff(t), dt, rtol=1e-6, atol=0):
        grid = np.arange(t[0], t[-1], dt)
        v, t = np.interp(grid, t, v), grid
    window = np.hanning(len(v))
    return 2.0 * np.pi * np.fft.rfftfreq(len(v), dt), 2.0 * np.fft.rfft((v - v.mean()) * window) / window.sum()


def amplitude_spectrum(times: np.ndarray, y: np.ndarray, transient: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """The amplitudes of ``spectrum``: of a sinusoid at each angular frequency [rad/s]."""
    omega, components = spectrum(times, y, transient)
    return omega, np.abs(components)


def peak_index(omega: np.ndarray, amplitude: np.ndarray, low: float, high: float) -> int | None:
    """The index of the largest amplitude with ``low <= omega <= high``; None when none lies there."""
    inside = np.flatnonzero((omega >= low) & (omega <= high))
    return int(inside[np.argmax(amplitude[inside])]) if inside.size else None


#: a shaft order's peak is looked for within this share of its nominal frequency
ORDER_SEARCH = 0.1


def spectral_components(times: np.ndarray, traces: dict, names: list[str], shaft_speed: str,
                        transient: float = 0.0, band: tuple[float, float] = OSCILLOGRAM_BAND) -> dict:
    """The two components the monograph's oscillograms show, in each signal of ``names``:
    the peak amplitude within ``ORDER_SEARCH`` (10 %) of the mean speed of ``shaft_speed`` (the shaft's rotation
    frequency) and the peak in ``band``, with their frequencies."""
    keep = times >= times[0] + transient
    rotation = float(np.mean(traces[shaft_speed][keep]))
    out = {"rotation_frequency_rad_s": rotation}
    for name in names:
        if name not in traces:
            continue
        omega, amplitude = amplitude_spectrum(times, traces[name], transient)
        entry = {}
        for label, (low, high) in (("rotation", ((1 - ORDER_SEARCH) * abs(rotation), (1 + ORDER_SEARCH) * abs(rotation))),
                                   ("band", band)):
            k = peak_index(omega, amplitude, low, high)
            if k is not None:
                entry[label] = {"frequency_rad_s": float(omega[k]), "amplitude": float(amplitude[k])}
        out[name] = entry
    return out


#: the driveline signals runs are judged by
JUDGED = ("w1", "w2", "tau1", "tau2")


def driveline_errors(scene: scenes.Scene, times, traces: dict, reference_times, reference: dict,
                     after: float | None = None, scale_reference: dict | None = None) -> dict:
    """``errors`` of the driveline's speeds and torques (``JUDGED``), by the traces' names
    (``coupling.tau2``, ``engine.w``), scaled by ``error_scales`` of the reference (or of
    ``scale_reference``, a longer run of it)."""
    names = signals(scene)
    scales = error_scales(scene, reference if scale_reference is None else scale_reference)
    full = errors(times, traces, reference_times, reference, [names[s] for s in JUDGED], scales, after)
    return {names[s]: full[names[s]] for s in JUDGED if names[s] in full}


def error_scales(scene: scenes.Scene, reference: dict) -> dict[str, float]:
    """Torques are judged relative to the mean transmitted torque, speeds relative to
    the mean speed (both from the reference)."""
    names = signals(scene)
    torque = float(abs(np.mean(reference[names["tau2"]])))
    speed = float(abs(np.mean(reference[names["w1"]])))
    return {names["tau1"]: torque, names["tau2"]: torque, names["w1"]: speed, names["w2"]: speed}
