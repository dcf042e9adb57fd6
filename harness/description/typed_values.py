"""A value of an FMI 2.0 variable, by the variable's type (Real, Integer, Enumeration,
Boolean, String), or of an FMI 3.0 one (Float64, Float32, Int8 ... UInt64, Enumeration,
Boolean, String; seen as the FMI 2.0 kind they carry: Float64 a Real, Int32 an Integer): a
scene's value checked for it, converted to what the FMU takes, set on an fmpy ``FMU2Slave``
or ``FMU3Slave``, written as the text of an SSV/OSP/model-description value and read back
from one.  Every place that sets or writes a start value goes through here (as
fmpy's ``apply_start_values`` is its one setter), so a type is handled the same way in
the harness, the peers and the exported files.
"""
from __future__ import annotations

import math

#: the kind of each type: the fmi2Set/fmi2Get call an FMI 2.0 type goes through - an
#: Enumeration is an Integer to them - and the element a value takes in SSV and OSP files
#: (FMI 3.0's types by the kind they carry)
CALL_TYPE = {"Real": "Real", "Integer": "Integer", "Enumeration": "Integer", "Boolean": "Boolean",
             "String": "String", "Float64": "Real", "Float32": "Real",
             **{f"{u}Int{bits}": "Integer" for u in ("", "U") for bits in (8, 16, 32, 64)}}

#: the fmi3Set call of each FMI 3.0 type (an FMI 3.0 Enumeration is an Int64)
FMI3_CALL = {**{t: t for t in CALL_TYPE if t not in ("Real", "Integer", "Enumeration")}, "Enumeration": "Int64"}

#: the range of FMI 2.0's fmi2Integer (a C int), FMI 3.0's Int32 and an FMI 2.0 Enumeration
INTEGER_RANGE = (-2 ** 31, 2 ** 31 - 1)
#: the ranges of FMI 3.0's integer types
INTEGER_RANGES = {f"{u}Int{bits}": ((0, 2 ** bits - 1) if u else (-2 ** (bits - 1), 2 ** (bits - 1) - 1))
                  for u in ("", "U") for bits in (8, 16, 32, 64)}


def kind(var) -> str:
    """``var``'s kind: Real, Integer, Boolean or String (FMI 3.0's Float64 a Real)."""
    return CALL_TYPE[var.type]


def is_fmi3(fmu) -> bool:
    """Whether ``fmu`` (an fmpy instance) is an FMI 3.0 one."""
    return type(fmu).__name__.startswith("FMU3")

#: what the text of a value of each type must be, as the messages about a malformed one say it
LITERAL_FORMS = {"Real": "a number", "Integer": "a whole number", "Enumeration": "a whole number",
                 "Boolean": "true, false, 1 or 0", "String": "a string"}


def findings(label: str, var, value, given: str) -> list[str]:
    """Findings about a scene's ``value`` for ``var``, a variable that is no Real (a Real's
    value is a quantity, checked with its unit by ``harness.description.scene``): strict
    types - a TOML boolean is no number, a fraction no integer - and an integer's
    [min, max] within its type's range (fmi2Integer's, FMI 3.0's Int8 ... UInt64).  ``given`` is how the messages show the value."""
    kind = CALL_TYPE[var.type]
    if kind == "String":
        return [] if isinstance(value, str) else [f"{label} = {given}: expected a string"]
    if kind == "Boolean":
        return [] if isinstance(value, bool) else [f"{label} = {given}: expected true or false"]
    if kind == "Integer":
        if isinstance(value, float) and math.isfinite(value) and value.is_integer():
            value = int(value)
        if not isinstance(value, int) or isinstance(value, bool):
            return [f"{label} = {given}: expected a whole number ({var.description})"]
        bounds = INTEGER_RANGES.get(var.type, INTEGER_RANGE)
        low = max(int(var.min) if var.min is not None else bounds[0], bounds[0])
        high = min(int(var.max) if var.max is not None else bounds[1], bounds[1])
        if not low <= value <= high:
            return [f"{label} = {value} is outside its allowed range [{low}, {high}] ({var.description})"]
        return []
    raise ValueError(f"{label}: a Real's value is a quantity, checked with its unit")


def typed(var, value, label: str):
    """``value`` as ``var``'s FMI call takes it: a float, an int, a bool or a str.  A
    fraction given for an integer, or a value that is no number, raises ``ValueError``
    naming ``label`` (a fraction is never rounded)."""
    kind = CALL_TYPE[var.type]
    if kind == "Integer" and isinstance(value, float) and value != int(value):
        raise ValueError(f"{label} is an integer, got {value!r}")
    try:
        if kind == "Real":
            return float(value)
        if kind == "Integer":
            return int(value)
    except (TypeError, ValueError):     # float("stiff"): a message that names no parameter
        raise ValueError(f"{label} = {value!r}: expected {'a number' if kind == 'Real' else 'an integer'}") from None
    if kind == "Boolean":
        return bool(value)
    return str(value)


def set_on(fmu, var, value, label: str) -> None:
    """Set ``var`` to ``value`` on ``fmu``, an fmpy ``FMU2Slave`` (its ``setReal``,
    ``setInteger``, ``setBoolean`` or ``setString``) or ``FMU3Slave`` (``setFloat64``,
    ``setInt32``, ...: the variable's type)."""
    call = FMI3_CALL[var.type] if is_fmi3(fmu) else CALL_TYPE[var.type]
    getattr(fmu, f"set{call}")([var.valueReference], [typed(var, value, label)])


def call_text(var, name: str, value, fmi3: bool = False) -> str:
    """How a failed set names its call: ``fmi2SetReal(stiffness = 715.4)``,
    ``fmi3SetFloat64(...)`` (``fmi3``); a string's value is left out (it may be a whole
    table)."""
    call = f"fmi3Set{FMI3_CALL[var.type]}" if fmi3 else f"fmi2Set{CALL_TYPE[var.type]}"
    return f"{call}({name})" if CALL_TYPE[var.type] == "String" else f"{call}({name} = {value!r})"


def literal(var, value, label: str) -> tuple[str, str]:
    """``(element, text)`` of ``value`` in an SSV, OSP or model-description file:
    ``("Real", "715.4")`` (Python's shortest round-trip repr), ``("Integer", "3")``,
    ``("Boolean", "true")`` (xs:boolean), ``("String", text)``."""
    kind = CALL_TYPE[var.type]
    value = typed(var, value, label)
    if kind == "Real":
        return kind, repr(value)
    if kind == "Boolean":
        return kind, "true" if value else "false"
    return kind, str(value)


def parse_literal(kind: str, text: str):
    """The value the text of an SSV/OSP element of type ``kind`` (a key of
    ``LITERAL_FORMS``) writes; ``ValueError`` when it is not ``LITERAL_FORMS[kind]`` (a
    Real must be finite)."""
    if kind == "Real":
        value = float(text)
        if not math.isfinite(value):
            raise ValueError(text)
        return value
    if CALL_TYPE[kind] == "Integer":
        return int(text)
    if kind == "Boolean":
        if text not in ("true", "false", "1", "0"):
            raise ValueError(text)
        return text in ("true", "1")
    return text
