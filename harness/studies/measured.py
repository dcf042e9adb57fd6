"""Model against measurement: the monograph's strain-gauge tables (Tables 4.2-4.11).

For each rubber grade the monograph gives the torque measured on the drive and the driven
shaft of the coupling, read every 30 deg of shaft angle over six load cycles (one cycle =
one revolution).  The model takes the measured *driven*-shaft torque and predicts the
*drive*-shaft torque over a revolution, which is set against the measured one.

What a gauge measures decides how the driven torque enters the model (``READINGS``):

* ``transmitted`` (default): strain gauges glued on a shaft measure the torque the shaft
  transmits at the gauge.  The gauges sit on the drive and driven shafts on either side of
  the coupling (monograph section 4.1, Fig. 4.2), so they read the coupling's own torques,
  ``T`` on the drive side and ``U12*T`` on the driven side (docs/physics.md#linear-law-and-damping; the coupling
  is massless).  The driven table then fixes ``T = M2 / U12(phi2)`` at every instant,
  whatever the dynamics: stiffness, damping, inertias, engine and speed do not enter.
  Assumed: no inertia between a gauge and the coupling (the monograph gives no gauge
  positions).
* ``brake``: the driven torque is the brake's resistance ``Mc(phi2)`` acting beyond the
  whole driven inertia (the monograph's own use of the measured torque in its theory,
  (3.30)); the driveline is simulated (scenes ``measured_<grade>``) and the coupling's
  drive-side torque is the prediction.  A gauge with inertia ``I`` between it and the
  coupling lies between the two readings (``inertia_driven = I`` in that scene; I -> 0 is
  the transmitted reading).

Files (``torque_drive_<grade>.csv``, ``torque_driven_<grade>.csv``; see
``resources/data/monograph``): ``#`` comment lines, then a CSV table with a column
``angle_deg`` (equally spaced over one revolution, starting at 0) and one column
``cycle_<k>`` per load cycle in N*m (other columns, such as ``mean_reported``, are
ignored).  The comment lines say which shaft (``drive shaft`` / ``driven shaft``) unless the
file name does, and state the grade's stiffness as a line containing
``stiffness ... : <value> N*m/rad``; ``validate_measured(..., stiffness=...)`` overrides it.

The conditions the tables do not state are assumptions, made once here (``Conditions``)
and listed in every report.  What is compared, per grade:

* the prediction from the mean of the cycles against the mean measured drive curve, and
  the prediction from each cycle's driven torque against that cycle's drive torque;
* RMS error relative to the mean measured drive torque, for the model and for the naive
  prediction "drive torque = driven torque";
* amplitudes A = (max - min)/2, measured and predicted;
* the cycle-to-cycle scatter of the measured drive torque (RMS deviation of the cycles
  from their mean): no prediction of a single cycle from the mean can do better, and its
  standard error over the cycles bounds how well the mean curve itself is known.
"""
from __future__ import annotations

import math
from dataclasses import asdict
from pathlib import Path

import numpy as np

from lever.physics.kinematics import TransferFunction
from lever.physics.parameters import ParameterError

from harness.description import scene as scenes
from harness.description.tables import MeasuredDataError, Table, cycle_of, load_series, read_table
from harness.engine.system import SceneInvalid
from harness.paths import DATA, RESULTS
from harness.studies.measured_conditions import (DEFAULT_READING, MONOGRAPH_DIFFERENCE, READINGS, SETTLED, TARGET,
                                                 Conditions, Prediction, scene_for)
from harness.studies.measured_report import plot_grade, write_report


def pair_tables(files) -> tuple[list[tuple[Table, Table]], list[str]]:
    """Drive/driven pairs by grade from files (or folders holding ``torque_*.csv``), and
    findings about what could not be read or paired."""
    paths, findings = [], []
    for item in files:
        item = Path(item)
        if item.is_dir():
            found = sorted(item.glob("torque_drive*_*.csv"))
            if not found:
                findings.append(f"{item}: no torque_drive_<grade>.csv / torque_driven_<grade>.csv files")
            paths += found
        else:
            paths.append(item)
    tables: dict[tuple[str, str], Table] = {}
    for path in paths:
        try:
            table = read_table(path)
        except MeasuredDataError as error:
            findings.append(str(error))
            continue
        key = (table.grade, table.shaft)
        if key in tables:
            findings.append(f"{path}: a second {table.shaft}-shaft table for grade {table.grade} "
                            f"(first: {tables[key].path})")
            continue
        tables[key] = table
    pairs = []
    for grade in sorted({g for g, _ in tables}):
        drive, driven = tables.get((grade, "drive")), tables.get((grade, "driven"))
        if drive is None or driven is None:
            have = drive or driven
            findings.append(f"{have.path}: grade {grade} has no {'drive' if drive is None else 'driven'}-shaft "
                            "table to pair with")
            continue
        problem = check_pair(drive, driven)
        if problem:
            findings += problem
            continue
        pairs.append((drive, driven))
    return pairs, findings


def check_pair(drive: Table, driven: Table) -> list[str]:
    findings = []
    if len(drive.angles_deg) != len(driven.angles_deg):
        findings.append(f"grade {drive.grade}: the drive table has {len(drive.angles_deg)} ordinates a revolution, "
                        f"the driven one {len(driven.angles_deg)}")
    if len(drive.cycles) != len(driven.cycles):
        findings.append(f"grade {drive.grade}: {len(drive.cycles)} drive cycles but {len(driven.cycles)} driven "
                        "cycles; cycles are compared one to one")
    if not drive.mean_curve.mean() > 0:
        findings.append(f"{drive.path}: the mean drive torque is {drive.mean_curve.mean():.6g} N*m; the errors are "
                        "relative to it, so it must be > 0 (the torque the coupling transmits)")
    return findings


# ----------------------------------------------------------------------------------------
# Prediction and comparison


def transfer_of(conditions: Conditions) -> TransferFunction:
    """The coupling's transfer function U12(phi2) at the conditions (as in the grade's scene)."""
    c = conditions
    return TransferFunction(c.transfer_mode, math.radians(c.misalignment_deg), c.support_deformation,
                            c.hinge_deformation)


def predict_transmitted(driven: Table, conditions: Conditions, cycle: int | str = "mean",
                        angles_deg: np.ndarray | None = None) -> Prediction:
    """The transmitted reading: the driven gauge reads the coupling's driven-side torque
    U12*T, so the drive-side torque is T = M2/U12(phi2) at the same instant (a massless
    coupling ties its two torques algebraically; nothing else enters)."""
    transfer = transfer_of(conditions)
    marks = np.radians(driven.angles_deg if angles_deg is None else angles_deg)
    ratio = np.vectorize(transfer.ratio, otypes=[float])     # the physics takes scalars
    at_marks = cycle_of(driven, cycle) / ratio(marks)
    dense_deg = np.arange(0.0, 360.0 + 1e-9, 2.0)
    phi = np.radians(dense_deg)
    series = load_series(driven, cycle)
    dense = np.array([series.resistance(0.0, p, 0.0) for p in phi]) / ratio(phi)
    return Prediction(np.asarray(at_marks, dtype=float), dense_deg, np.asarray(dense, dtype=float), None, 0.0)


def predict(scene: scenes.Scene, angles_deg: np.ndarray) -> Prediction:
    """The brake reading: run the scene and read the drive-shaft torque (the torque the
    drive shaft transmits to the coupling, -tau1) over its last full revolution of the
    driven shaft."""
    from harness.engine.run import simulate

    result = simulate(scene)
    if not result.ok:
        raise RuntimeError(result.failure)
    phi2 = result.traces["load.phi"]
    torque = -result.traces["coupling.tau1"]
    if np.any(np.diff(phi2) <= 0):
        raise RuntimeError("the driven shaft stopped or turned back: no angle-periodic steady state")
    last = math.floor(phi2[-1] / (2 * math.pi)) - 1       # start of the last full revolution
    if last < 1:
        raise RuntimeError(f"fewer than two revolutions in {scene.experiment.stop:g} s")
    base = 2 * math.pi * last
    marks = np.radians(angles_deg)
    now = np.interp(base + marks, phi2, torque)
    before = np.interp(base - 2 * math.pi + marks, phi2, torque)
    dense_deg = np.arange(0.0, 360.0 + 1e-9, 2.0)
    dense = np.interp(base + np.radians(dense_deg), phi2, torque)
    times = np.interp([base, base + 2 * math.pi], phi2, result.times)
    speed = 2 * math.pi / (times[1] - times[0])
    return Prediction(now, dense_deg, dense, float(speed), float(np.max(np.abs(now - before)) / np.mean(now)))


def amplitude(y) -> float:
    return float((np.max(y) - np.min(y)) / 2.0)


def rms(y) -> float:
    return float(np.sqrt(np.mean(np.square(y))))


def _harmonic(y: np.ndarray, n: int) -> complex:
    return complex(2.0 * np.fft.rfft(y)[n] / len(y))


def compare(drive: Table, driven: Table, mean_prediction: Prediction,
            cycle_predictions: list[Prediction] | None, alternative: Prediction | None = None) -> dict:
    """The numbers of one grade (pure function of the tables and the predictions);
    ``alternative``: the other reading's prediction from the mean curve, for comparison."""
    measured = drive.mean_curve
    scale = float(measured.mean())
    spread = drive.cycles - measured
    n = len(drive.cycles)
    out = {
        "grade": drive.grade,
        "mean_drive_torque": scale,
        "mean_driven_torque": float(driven.cycles.mean()),
        "rms_model": rms(mean_prediction.at_marks - measured) / scale,
        "rms_naive": rms(driven.mean_curve - measured) / scale,
        "rms_no_fluctuation": rms(measured - scale) / scale,
        "amplitude_measured": amplitude(measured),
        "amplitude_predicted": amplitude(mean_prediction.at_marks),
        "amplitude_driven": amplitude(driven.mean_curve),
        # what the monograph's 6.5-8.5 % compares: fluctuation ranges (Fig. 4.8), not curves
        "amplitude_error": amplitude(mean_prediction.at_marks) / amplitude(measured) - 1.0,
        "amplitude_measured_cycles": [amplitude(c) for c in drive.cycles],
        "scatter": rms(spread) / scale,
        # the standard error of the mean curve: how well the averaged measurement is known
        "mean_curve_uncertainty": (float(np.sqrt(np.sum(spread ** 2) / (spread.shape[1] * (n - 1) * n))) / scale
                                   if n > 1 else float("nan")),
        "speed": mean_prediction.speed,
        "settled": mean_prediction.settled,
    }
    # The fundamental (shaft frequency) carries most of the fluctuation: its phase of the
    # drive against the driven torque, measured and predicted (positive: drive leads).
    d1, v1, p1 = (_harmonic(y, 1) for y in (measured, driven.mean_curve, mean_prediction.at_marks))
    out["fundamental"] = {
        "driven_amplitude": abs(v1), "measured_amplitude": abs(d1), "predicted_amplitude": abs(p1),
        "measured_phase_deg": math.degrees(np.angle(d1 / v1)), "predicted_phase_deg": math.degrees(np.angle(p1 / v1)),
        "measured_phase_each_cycle_deg": [math.degrees(np.angle(_harmonic(d, 1) / _harmonic(v, 1)))
                                          for d, v in zip(drive.cycles, driven.cycles)],
        "rms_error_share": abs(d1 - p1) / math.sqrt(2) / scale,
    }
    if alternative is not None:
        a1 = _harmonic(alternative.at_marks, 1)
        out["alternative"] = {"rms_model": rms(alternative.at_marks - measured) / scale,
                              "amplitude_predicted": amplitude(alternative.at_marks),
                              "amplitude_error": amplitude(alternative.at_marks) / amplitude(measured) - 1.0,
                              "predicted_phase_deg": math.degrees(np.angle(a1 / v1)),
                              "speed": alternative.speed, "settled": alternative.settled}
        if out["speed"] is None:
            out["speed"] = alternative.speed
    if cycle_predictions:
        predicted = np.array([p.at_marks for p in cycle_predictions])
        out["rms_model_cycles"] = rms(predicted - drive.cycles) / scale
        out["rms_naive_cycles"] = rms(driven.cycles - drive.cycles) / scale
        out["rms_model_each_cycle"] = [rms(p - d) / scale for p, d in zip(predicted, drive.cycles)]
        out["settled_cycles"] = max(p.settled for p in cycle_predictions)
    out["beats_naive"] = out["rms_model"] < out["rms_naive"]
    out["within_target"] = out["rms_model"] <= TARGET
    return out


def validate_measured(files, out: Path | str, stiffness: float | None = None, cycles: bool = True,
                      reading: str = DEFAULT_READING, alternative: bool = True) -> list[str]:
    """Check the model against measured drive/driven torque tables (``files``: paths of
    tables or folders holding them).  Writes ``measured.md``, ``measured.json`` and a plot
    per grade into ``out``; returns findings: files that could not be used, and grades
    whose prediction misses the monograph's stated model-experiment difference (empty when
    every grade is within it).  ``stiffness`` [N*m/rad] overrides the files' statement;
    ``cycles=False`` compares only the mean curves; ``reading`` is how the driven table
    enters the model (``READINGS``); ``alternative`` adds the other reading's prediction
    from the mean curve (one simulated run a grade) for comparison."""
    if reading not in READINGS:
        raise ValueError(f"reading {reading!r} is not one of {', '.join(READINGS)}")
    other = next(r for r in READINGS if r != reading)
    out = Path(out)
    pairs, findings = pair_tables(files)
    grades = []
    for drive, driven in pairs:
        try:
            conditions = Conditions.of(drive, driven, stiffness)
            run = lambda how, cycle: _predict(how, drive, driven, conditions, cycle)  # noqa: E731
            mean_prediction = run(reading, "mean")
            per_cycle = [run(reading, k + 1) for k in range(len(drive.cycles))] if cycles else None
        except (MeasuredDataError, scenes.SceneError, SceneInvalid, ParameterError) as error:
            findings.append(str(error))
            continue
        except RuntimeError as error:
            findings.append(f"grade {drive.grade}: the model run failed: {error}")
            continue
        second = None
        if alternative:
            try:
                second = run(other, "mean")
            except (scenes.SceneError, SceneInvalid, ParameterError, RuntimeError) as error:
                findings.append(f"grade {drive.grade}: the {other} reading (for comparison) failed: {error}")
        numbers = compare(drive, driven, mean_prediction, per_cycle, second)
        numbers["reading"] = reading
        numbers["alternative_reading"] = other if second is not None else None
        numbers["conditions"] = asdict(conditions)
        numbers["assumptions"] = conditions.assumptions(reading)
        numbers["files"] = [str(drive.path), str(driven.path)]
        grades.append(numbers)
        if numbers["settled"] > SETTLED:
            findings.append(f"grade {drive.grade}: the model had not settled to a periodic state "
                            f"({100 * numbers['settled']:.2g} % change over the last revolution)")
        if not numbers["within_target"]:
            findings.append(f"grade {drive.grade}: predicted drive torque RMS error {100 * numbers['rms_model']:.1f} % "
                            f"of the mean is above the monograph's stated {100 * MONOGRAPH_DIFFERENCE[0]:g}-"
                            f"{100 * MONOGRAPH_DIFFERENCE[1]:g} % (naive 'drive = driven': "
                            f"{100 * numbers['rms_naive']:.1f} %)")
        plot_grade(out, drive, driven, mean_prediction, per_cycle, numbers, second)
    write_report(out, grades, findings, reading)
    return findings


def _predict(reading: str, drive: Table, driven: Table, conditions: Conditions, cycle) -> Prediction:
    if reading == "transmitted":
        return predict_transmitted(driven, conditions, cycle, drive.angles_deg)
    return predict(scene_for(drive, driven, conditions, cycle), drive.angles_deg)


def default_files() -> list[Path]:
    return [DATA / "monograph"]


def default_out() -> Path:
    return RESULTS / "measured"
