"""Parameter declarations: the single place where a value's unit, meaning and allowed
range are written down.  The FMU adapters turn them into FMI variables (units, min/max,
descriptions), the harness checks scene files against them, and the physics checks
them when it builds a model, so an out-of-range value is refused with the same message
wherever it enters.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, Optional, Sequence


class ParameterError(ValueError):
    """A value a model cannot accept.  ``name`` is the parameter, the message says
    the value, the allowed range and why."""

    def __init__(self, name: str, message: str):
        super().__init__(message)
        self.name = name


# SI unit definitions used by the FMUs' model descriptions:
# name -> (exponents of kg, m, s, rad; factor to SI).
UNITS: dict[str, tuple[dict[str, int], float]] = {
    "1": ({}, 1.0),
    "s": ({"s": 1}, 1.0),
    "m": ({"m": 1}, 1.0),
    "kg": ({"kg": 1}, 1.0),
    "N": ({"kg": 1, "m": 1, "s": -2}, 1.0),
    "rad": ({"rad": 1}, 1.0),
    "deg": ({"rad": 1}, math.pi / 180.0),
    "rad/s": ({"rad": 1, "s": -1}, 1.0),
    "rpm": ({"rad": 1, "s": -1}, 2.0 * math.pi / 60.0),
    "rad/s2": ({"rad": 1, "s": -2}, 1.0),
    "N.m": ({"kg": 1, "m": 2, "s": -2}, 1.0),
    "N.m/s": ({"kg": 1, "m": 2, "s": -3}, 1.0),
    "N.m/s2": ({"kg": 1, "m": 2, "s": -4}, 1.0),
    "N.m/rad": ({"kg": 1, "m": 2, "s": -2, "rad": -1}, 1.0),
    "N.m.s/rad": ({"kg": 1, "m": 2, "s": -1, "rad": -1}, 1.0),
    "kg.m2": ({"kg": 1, "m": 2}, 1.0),
    "J": ({"kg": 1, "m": 2, "s": -2}, 1.0),
    "W": ({"kg": 1, "m": 2, "s": -3}, 1.0),
}

# The physical quantity of each unit: the FMUs declare one FMI type definition per
# quantity (``<SimpleType name="Torque"><Real quantity="Torque" unit="N.m"/>``), and every
# real variable refers to its type.
QUANTITIES = {
    "1": "Ratio",
    "s": "Time",
    "m": "Length",
    "kg": "Mass",
    "N": "Force",
    "rad": "Angle",
    "rad/s": "AngularVelocity",
    "rad/s2": "AngularAcceleration",
    "N.m": "Torque",
    "N.m/s": "TorqueRate",
    "N.m/s2": "TorqueSecondDerivative",
    "N.m/rad": "RotationalSpringConstant",
    "N.m.s/rad": "RotationalDampingConstant",
    "kg.m2": "MomentOfInertia",
    "J": "Energy",
    "W": "Power",
}
assert set(QUANTITIES) == set(UNITS) - {"deg", "rpm"}, "every unit a variable may have needs its quantity"

# Which display unit goes with which unit (FMI DisplayUnit).
DISPLAY_UNITS = {"rad": "deg", "rad/s": "rpm"}


def _fmt(x: float) -> str:
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return f"{x:.6g}"


@dataclass(frozen=True)
class Parameter:
    """One model parameter (or input) with its unit, meaning and allowed range.

    Real values must be finite and lie in the interval [low, high] (open at an end
    where ``low_open``/``high_open``).  String values must be one of ``choices`` when
    choices are given; ``kind`` is "real", "integer" or "string".
    """

    name: str
    default: Any
    unit: str
    description: str
    low: float = -math.inf
    high: float = math.inf
    low_open: bool = False
    high_open: bool = False
    kind: str = "real"
    choices: Optional[tuple[str, ...]] = None
    fixed: bool = True  # structural: may not change after initialisation
    #: for an input: the input this one is the time derivative of (the FMUs' vendor
    #: annotation, docs/fmus.md)
    derivative_of: str = ""
    #: for a string holding a table: parses a non-empty value, raising ParameterError when
    #: it is malformed, so a bad table is refused when it is set, like a bad number
    parser: Optional[Callable[[str], Any]] = field(default=None, compare=False)

    def range_text(self) -> str:
        if self.kind == "string":
            return "one of " + ", ".join(repr(c) for c in self.choices) if self.choices else "a string"
        left = "(" if self.low_open else "["
        right = ")" if self.high_open else "]"
        unit = "" if self.unit in ("", "1") else " " + self.unit
        return f"{left}{_fmt(self.low)}, {_fmt(self.high)}{right}{unit}"

    def problem(self, value: Any) -> Optional[str]:
        """Return why ``value`` is not acceptable, or None when it is."""
        if self.kind == "string":
            if not isinstance(value, str):
                return f"parameter '{self.name}' must be a string, got {value!r}"
            if self.choices and value not in self.choices:
                return (f"parameter '{self.name}' = {value!r} is not allowed: "
                        f"it must be {self.range_text()} ({self.description})")
            if self.parser is not None and value.strip():
                try:
                    self.parser(value)
                except ParameterError as error:
                    return f"{error} (allowed: {self.description})"
            return None
        try:
            x = float(value)
        except (TypeError, ValueError):
            return f"parameter '{self.name}' must be a number, got {value!r}"
        if self.kind == "integer" and x != int(x):
            return f"parameter '{self.name}' must be a whole number, got {value!r}"
        if not math.isfinite(x):
            return (f"parameter '{self.name}' = {x} is not finite: allowed range is "
                    f"{self.range_text()} ({self.description})")
        below = x < self.low or (self.low_open and x == self.low)
        above = x > self.high or (self.high_open and x == self.high)
        if below or above:
            unit = "" if self.unit in ("", "1") else " " + self.unit
            return (f"parameter '{self.name}' = {_fmt(x)}{unit} is outside its allowed range "
                    f"{self.range_text()} ({self.description})")
        return None

    def check(self, value: Any) -> Any:
        """Return ``value`` (as float/int/str) or raise ParameterError."""
        message = self.problem(value)
        if message:
            raise ParameterError(self.name, message)
        if self.kind == "real":
            return float(value)
        if self.kind == "integer":
            return int(value)
        return value


def check_all(declared: Sequence[Parameter], values: dict) -> dict:
    """Check ``values`` against ``declared``; unknown names are refused, missing
    ones take their defaults.  Returns the complete, converted value dict."""
    by_name = {p.name: p for p in declared}
    for name in values:
        if name not in by_name:
            raise ParameterError(name, f"unknown parameter '{name}'; known: {', '.join(by_name)}")
    return {p.name: p.check(values.get(p.name, p.default)) for p in declared}


#: Largest magnitude of a table value: keeps slopes, integrals and energies of any
#: table representable (a table of physical values never comes near it).
TABLE_LIMIT = 1e15


def parse_table(text: str, name: str, columns: int = 2) -> list[tuple[float, ...]]:
    """Parse a table given as text: rows separated by ';' or newlines, values within a
    row by ',' or ':' or whitespace, each finite and within +-TABLE_LIMIT.  Example:
    ``"0:0; 0.05:10; 0.1:16"``."""
    rows = []
    for raw in text.replace("\n", ";").split(";"):
        raw = raw.strip()
        if not raw:
            continue
        cells = raw.replace(":", " ").replace(",", " ").split()
        if len(cells) != columns:
            raise ParameterError(name, f"parameter '{name}': row {raw!r} must have {columns} values")
        try:
            row = tuple(float(c) for c in cells)
        except ValueError:
            raise ParameterError(name, f"parameter '{name}': row {raw!r} is not numeric") from None
        if not all(math.isfinite(v) for v in row):
            raise ParameterError(name, f"parameter '{name}': row {raw!r} has a non-finite value")
        if any(abs(v) > TABLE_LIMIT for v in row):
            raise ParameterError(name, f"parameter '{name}': row {raw!r} has a value beyond the allowed "
                                 f"magnitude: values must lie within +-{TABLE_LIMIT:g}")
        rows.append(row)
    return rows


def format_table(rows: Sequence[Sequence[float]]) -> str:
    """Inverse of parse_table (full double precision)."""
    return "; ".join(":".join(repr(float(v)) for v in row) for row in rows)
