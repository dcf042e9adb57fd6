"""Measured torque tables (``resources/data/monograph/torque_*.csv``): one shaft's torque
over a revolution, one column per measured cycle.  A scene's load may be the Fourier
series through a table's ordinates (``{samples = "<table>.csv", cycle = "mean"}``); the
model-vs-measurement study (harness.studies.measured) reads them too.  The file format
is described in that study's docstring."""
from __future__ import annotations

import csv
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lever.physics.load import fourier_from_samples

_STIFFNESS = re.compile(r"stiffness[^:\n]*:\s*([0-9]+(?:\.[0-9]*)?(?:[eE][-+]?[0-9]+)?)\s*N\s*[*.]?\s*m\s*/\s*rad",
                        re.IGNORECASE)
_NAME = re.compile(r"torque_(drive|driven)_(.+)\.csv$", re.IGNORECASE)


#: the largest torque a table may hold [N*m]: the shafts' torque range (lever.physics.component_parameters:
#: stall_torque, mean_torque in [-1e6, 1e6] N*m)
TORQUE_LIMIT = 1e6


class MeasuredDataError(ValueError):
    """A measurement file that cannot be read as the format above."""


@dataclass
class Table:
    """One shaft's measured torque: ``cycles[k, i]`` at ``angles_deg[i]`` [N*m]."""
    path: Path
    shaft: str                     # "drive" or "driven"
    grade: str
    angles_deg: np.ndarray
    cycles: np.ndarray
    stiffness: float | None        # N*m/rad, when the file states it

    @property
    def mean_curve(self) -> np.ndarray:
        return self.cycles.mean(axis=0)


def read_table(path: Path | str) -> Table:
    path = Path(path)
    try:
        # utf-8-sig: a byte-order mark (as spreadsheets write one) is not part of the first line
        lines = path.read_text(encoding="utf-8-sig").splitlines()
    except OSError as error:
        raise MeasuredDataError(f"{path}: cannot read ({error.strerror})") from None
    except UnicodeDecodeError as error:
        raise MeasuredDataError(f"{path}: not a text file in UTF-8 (byte {error.start}: {error.reason}); expected "
                                "# comment lines and a CSV table") from None
    comments = "\n".join(line.lstrip("# ") for line in lines if line.lstrip().startswith("#"))
    try:
        rows = list(csv.DictReader(line for line in lines if line.strip() and not line.lstrip().startswith("#")))
    except csv.Error as error:
        raise MeasuredDataError(f"{path}: not a CSV table ({error})") from None
    if not rows:
        raise MeasuredDataError(f"{path}: no table rows")
    columns = [c for c in rows[0] if c and c.strip().startswith("cycle_")]
    if "angle_deg" not in rows[0] or not columns:
        raise MeasuredDataError(f"{path}: expected columns angle_deg and cycle_1, cycle_2, ... "
                                f"(found {', '.join(c for c in rows[0] if c)})")
    try:
        angles = np.array([float(r["angle_deg"]) for r in rows])
        cycles = np.array([[float(r[c]) for r in rows] for c in sorted(columns, key=_cycle_number)])
    except (TypeError, ValueError) as error:
        raise MeasuredDataError(f"{path}: a value is not a number ({error})") from None
    spacing = 360.0 / len(angles)
    if len(angles) < 4 or not np.allclose(angles, np.arange(len(angles)) * spacing, atol=1e-6):
        raise MeasuredDataError(f"{path}: angle_deg must run 0, {spacing:g}, ... in equal steps over one "
                                f"revolution (at least 4 ordinates), got {angles.tolist()}")
    if not np.all(np.isfinite(cycles)):
        raise MeasuredDataError(f"{path}: non-finite torque values")
    if np.max(np.abs(cycles)) > TORQUE_LIMIT:
        raise MeasuredDataError(f"{path}: a torque of {np.max(np.abs(cycles)):.6g} N*m: the tables hold N*m within "
                                f"+-{TORQUE_LIMIT:g} (the shafts' torque range)")
    if not np.any(cycles):
        raise MeasuredDataError(f"{path}: every torque is zero: a table of zeros measures nothing")
    name = _NAME.search(path.name)
    text = comments.lower()
    if name:
        shaft, grade = name.group(1).lower(), name.group(2)
    elif "driven shaft" in text or "drive shaft" in text:
        shaft = "driven" if "driven shaft" in text else "drive"
        grade = path.stem
    else:
        raise MeasuredDataError(f"{path}: cannot tell the shaft: name the file torque_drive_<grade>.csv or "
                                "torque_driven_<grade>.csv, or say 'drive shaft'/'driven shaft' in a # line")
    match = _STIFFNESS.search(comments)
    return Table(path, shaft, grade, angles, cycles, float(match.group(1)) if match else None)


def _cycle_number(column: str) -> int:
    try:
        return int(column.strip().split("_", 1)[1])
    except ValueError:
        return 10 ** 6


def load_series(table: Table, cycle: int | str = "mean"):
    """The series (4.4) through a table's cycle (1-based) or through the mean of its cycles."""
    return fourier_from_samples(cycle_of(table, cycle))


def cycle_of(table: Table, cycle: int | str = "mean") -> np.ndarray:
    """A table's ordinates of one cycle (1-based) or the mean of its cycles."""
    if cycle == "mean":
        return table.mean_curve
    k = int(cycle)
    if not 1 <= k <= len(table.cycles):
        raise MeasuredDataError(f"{table.path}: no cycle {k} (it has {len(table.cycles)})")
    return table.cycles[k - 1]
