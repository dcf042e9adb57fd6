"""The report of a model-against-measurement check: measured.md, measured.json and a plot a
grade (``harness.studies.measured`` computes the numbers)."""
from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np

from harness.description.tables import Table
from harness.studies.measured_conditions import (DEFAULT_READING, GENERAL_ASSUMPTIONS, MASTER, MONOGRAPH_DIFFERENCE,
                                                 READINGS, STEP, STOP, TARGET, Prediction, assumptions_of)


def write_report(out: Path, grades: list[dict], findings: list[str], reading: str = DEFAULT_READING) -> Path:
    """measured.md and measured.json in ``out``: each grade's numbers, the conditions assumed, the findings."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "measured.json").write_text(json.dumps({"target": TARGET, "monograph_difference": MONOGRAPH_DIFFERENCE,
                                                   "reading": reading, "grades": grades, "findings": findings},
                                                  indent=2))
    pct = lambda x: "-" if x is None else f"{100 * x:.1f} %"   # noqa: E731
    signed = lambda x: "-" if x is None else f"{100 * x:+.0f} %"   # noqa: E731
    other = next(r for r in READINGS if r != reading)
    has_other = any(g.get("alternative") for g in grades)
    lines = ["# Model against measurement: drive-shaft torque predicted from the driven-shaft torque", "",
             f"Reading of the gauges: **{reading}**: {READINGS[reading]}.  Errors are RMS over the table's "
             "angles, relative to the mean measured drive torque.  Target: at or below the monograph's own "
             f"model-experiment difference, {100 * MONOGRAPH_DIFFERENCE[0]:g}-{100 * MONOGRAPH_DIFFERENCE[1]:g} % "
             "(Fig. 4.8; there it is the difference of fluctuation ranges, here the column *A error*)." +
             (f"  Last column: the {other} reading ({READINGS[other]}), from the mean curve." if has_other else ""),
             "",
             "| grade | c [N*m/rad] | model (mean curve) | naive drive = driven | model (per cycle) | naive (per cycle) "
             "| A measured | A predicted | A driven | A error | cycle scatter | mean-curve uncertainty | within target "
             f"| beats naive |{f' {other} reading |' if has_other else ''}",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|" + ("---|" if has_other else "")]
    for g in grades:
        alt = g.get("alternative")
        lines.append(f"| {g['grade']} | {g['conditions']['stiffness']:g} | **{pct(g['rms_model'])}** | "
                     f"{pct(g['rms_naive'])} | {pct(g.get('rms_model_cycles'))} | {pct(g.get('rms_naive_cycles'))} | "
                     f"{g['amplitude_measured']:.1f} | {g['amplitude_predicted']:.1f} | {g['amplitude_driven']:.1f} | "
                     f"{signed(g['amplitude_error'])} | {pct(g['scatter'])} | {pct(g['mean_curve_uncertainty'])} | "
                     f"{'yes' if g['within_target'] else '**no**'} | {'yes' if g['beats_naive'] else 'no'} |"
                     + (f" {pct(alt['rms_model'])} (A {alt['amplitude_predicted']:.1f}) |" if has_other and alt
                        else " - |" if has_other else ""))
    lines += ["", "Amplitudes A = (max - min)/2 in N*m of the mean curves; *A error* = A predicted / A measured - 1.  "
              "*Cycle scatter*: RMS deviation of the measured drive cycles from their mean, the floor of any per-cycle "
              "prediction made from the mean; *mean-curve uncertainty*: its standard error over the cycles, the "
              "resolution of the mean-curve comparison (differences between predictions smaller than it are not "
              "resolved by the data).  A prediction with no fluctuation at all (the mean) would score "
              + ", ".join(f"{g['grade']} {pct(g['rms_no_fluctuation'])}" for g in grades) + "."]
    lines += ["", "## Where the error comes from: the fundamental", "",
              "The shaft-frequency harmonic carries most of the fluctuation.  Its phase of the drive against the "
              "driven torque (positive: the drive torque leads):", "",
              "| grade | A1 driven | A1 drive measured | A1 predicted | phase measured (per cycle) | phase predicted | "
              f"its share of the model's RMS error |{f' phase, {other} reading |' if has_other else ''}",
              "|---|---|---|---|---|---|---|" + ("---|" if has_other else "")]
    for g in grades:
        f, alt = g["fundamental"], g.get("alternative")
        each = " ".join(f"{p:+.0f}" for p in f.get("measured_phase_each_cycle_deg", []))
        lines.append(f"| {g['grade']} | {f['driven_amplitude']:.1f} | {f['measured_amplitude']:.1f} | "
                     f"{f['predicted_amplitude']:.1f} | {_deg(f['measured_phase_deg'])} ({each}) | "
                     f"{_deg(f['predicted_phase_deg'])} | {pct(f['rms_error_share'])} |"
                     + (f" {_deg(alt['predicted_phase_deg'])} |" if has_other and alt else " - |" if has_other else ""))
    lines += ["", "Read as transmitted torque, the two gauges bracket a massless coupling: T = M2/U12 at the same "
              "instant, and since the kinematic U12 has only even harmonics the predicted fundamental is the "
              "driven one (to within the small U12 correction), phase 0.  Read as the brake's resistance, the driven inertia lies between load and "
              "coupling and the drive torque lags: linearised T/Mc = Z/(Z + i*w*I2) with Z the positive-real "
              "impedance of coupling and drive side, phase in (-180, 0] deg.  No passive inertia between a gauge "
              "and the coupling makes the drive torque lead; the measured lead varies from cycle to cycle (see the "
              "per-cycle phases) and is within what the offset between the two shafts' revolution marks, which "
              "the monograph does not state, and the reading of the oscillograms can produce."]
    if grades:
        lines += ["", "## Conditions and assumptions (the tables do not state them)", "",
                  "| grade | c [N*m/rad] | b [N*m*s/rad] | mean load [N*m] | speed [rad/s] (simulated) | M1 [N*m] |",
                  "|---|---|---|---|---|---|"]
        for g in grades:
            c = g["conditions"]
            simulated = "-" if g["speed"] is None else f"{g['speed']:.2f}"
            lines.append(f"| {g['grade']} | {c['stiffness']:g} ({c['stiffness_source']}) | {c['damping']:.3g} | "
                         f"{c['mean_load']:.1f} | {c['speed']:.2f} ({simulated}) | {c['stall_torque']:.1f} |")
        lines += ["", f"The {reading} reading:"] + [f"- {a}" for a in assumptions_of(reading)]
        simulated = [g for g in grades if g["reading"] == "brake" or g.get("alternative")]
        if simulated:
            lines += ["", "The brake reading" + (" (last column)" if reading != "brake" else "") + ":"]
            lines += [f"- {a}" for a in GENERAL_ASSUMPTIONS]
            lines += [f"- co-simulation: master {MASTER}, step {STEP:g} s, {STOP:g} s from the operating point; the "
                      "last full revolution is compared (largest change from the one before: " + ", ".join(
                          f"{g['grade']} {100 * _settled_of(g):.2g} %" for g in simulated) + ")"]
    lines += ["", "## Plots", ""] + [f"![{g['grade']}](measured_{_safe(g['grade'])}.png)" for g in grades]
    lines += ["", "## Findings", ""] + ([f"- {f}" for f in findings] if findings else ["none"])
    path = out / "measured.md"
    path.write_text("\n".join(lines) + "\n")
    return path


def _settled_of(g: dict) -> float:
    if g["reading"] == "brake":
        return max(g["settled"], g.get("settled_cycles", 0.0))
    return g["alternative"]["settled"]


def plot_grade(out: Path, drive: Table, driven: Table, prediction: Prediction, per_cycle, numbers: dict,
          alternative: Prediction | None = None):
    """measured_<grade>.png in ``out``: the measured cycles and mean curves, the predictions."""
    from harness.formats import plotting

    plt = plotting.pyplot()
    path = out / f"measured_{_safe(drive.grade)}.png"
    path.parent.mkdir(parents=True, exist_ok=True)
    angles = np.append(drive.angles_deg, 360.0)
    close = lambda y: np.append(y, y[0])  # noqa: E731
    fig, ax = plt.subplots(figsize=(11, 4.8), layout="constrained")
    for k, cycle in enumerate(drive.cycles):
        ax.plot(angles, close(cycle), color="0.7", lw=0.8, marker=".", label="measured drive, cycles" if k == 0 else None)
    ax.plot(angles, close(drive.mean_curve), color="k", lw=2, marker="o", label="measured drive, mean")
    ax.plot(angles, close(driven.mean_curve), color="tab:blue", lw=1.2, ls="--", label="measured driven, mean (naive)")
    if per_cycle:
        for k, p in enumerate(per_cycle):
            ax.plot(angles, close(p.at_marks), color="tab:red", lw=0.6, alpha=0.5,
                    label="predicted drive, per cycle" if k == 0 else None)
    ax.plot(prediction.dense_angles_deg, prediction.dense, color="tab:red", lw=2,
            label=f"predicted drive, from mean ({numbers['reading']})")
    if alternative is not None:
        ax.plot(alternative.dense_angles_deg, alternative.dense, color="tab:orange", lw=1.2, ls=":",
                label=f"predicted drive, from mean ({numbers['alternative_reading']} reading)")
    ax.set_xlabel("shaft angle [deg] (drive table: phi1, driven table: phi2, read as the same instants)")
    ax.set_ylabel("torque [N*m]")
    ax.set_xticks(np.arange(0, 361, 30))
    ax.set_title(f"{drive.grade}, c = {numbers['conditions']['stiffness']:g} N*m/rad: RMS error model "
                 f"{100 * numbers['rms_model']:.1f} %, naive {100 * numbers['rms_naive']:.1f} %")
    ax.grid(alpha=0.3)
    plotting.legend_outside(ax)
    plotting.save_png(fig, path, dpi=110)
    plt.close(fig)


def _deg(x: float) -> str:
    """A phase in whole degrees, with no "-0"."""
    return f"{(x if abs(x) >= 0.5 else 0.0):+.0f} deg"


def _safe(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", text)
