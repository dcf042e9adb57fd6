"""Quantities with dimensions: every value a user writes with a unit ("15 deg", "2 kN.m/rad",
an SSP parameter's unit) is checked against the dimension of the variable it is for and
converted to that variable's unit, with pint.

**Angle is a dimension of its own here.**  In SI the radian is 1 (m/m), so pint's own
registry would take "1000 deg" for a stiffness in N.m/rad (17.45 N.m/rad) and "0.5 rpm"
(1/s) for an angle per ... nothing.  The registry below is pint's default one with a
single change: ``radian = [angle]`` instead of ``radian = []``, so that deg, rev, rpm,
N.m/rad and N.m.s/rad carry the angle and a value of the wrong kind is refused.  The
price: an angle is never dimensionless (a ratio given as "0.1 rad" is refused), and rad/s
is not Hz (a cycle is 2*pi rad, Hz is 1/s) - both what a shaft's units mean.

Units are written as pint reads them ("N*m/rad", "kg*m**2") or as FMI/Modelica model
descriptions write them ("N.m/rad", "kg.m2", "rad/s2"); "1" and "" are dimensionless.
"""
from __future__ import annotations

import functools
import math
import re
from pathlib import Path

#: a number followed by a unit: "15 deg", "-2.5e3 N.m/rad", "374.8rpm"
_QUANTITY = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?|[-+]?inf|nan)\s*([^\s\d.+-].*?)\s*$",
                       re.IGNORECASE)


class UnitProblem(ValueError):
    """A value's unit is unknown or of another dimension than its variable's."""


@functools.lru_cache(maxsize=1)
def registry():
    """pint's default registry with the angle as a base dimension (see the module's text);
    built once per process (about a second)."""
    import pint

    folder = Path(pint.__file__).parent
    text = (folder / "default_en.txt").read_text(encoding="utf-8")
    constants = (folder / "constants_en.txt").read_text(encoding="utf-8")
    radian = "radian = [] = rad\n"
    if text.count(radian) != 1 or text.count("@import constants_en.txt\n") != 1:
        raise RuntimeError(f"pint {pint.__version__}: its default units file changed; harness/description/units.py "
                           "makes the radian a base dimension by editing one line of it")
    text = text.replace(radian, "radian = [angle] = rad\n").replace("@import constants_en.txt\n", constants)
    return pint.UnitRegistry(text.splitlines(), autoconvert_offset_to_baseunit=False)


def pint_syntax(unit: str) -> str:
    """A unit as pint reads it: FMI/Modelica's "N.m.s/rad", "kg.m2" become "N*m*s/rad",
    "kg*m**2"; "1" and "" become "dimensionless"."""
    unit = (unit or "").strip()
    if unit in ("", "1"):
        return "dimensionless"
    unit = re.sub(r"(?<=[A-Za-z)])\.(?=[A-Za-z(])", "*", unit)     # N.m -> N*m
    return re.sub(r"(?<=[A-Za-z)])(-?\d+)", r"**\1", unit)          # m2 -> m**2, s-1 -> s**-1


@functools.lru_cache(maxsize=256)
def parse_unit(unit: str):
    """The pint unit of ``unit``; ``UnitProblem`` when pint does not know it."""
    try:
        return registry().parse_units(pint_syntax(unit))
    except Exception as error:    # noqa: BLE001 - pint parses with Python's tokenizer: user text raises
        # PintError, SyntaxError, tokenize.TokenError ("0{"), ... - all mean the same: not a unit
        raise UnitProblem(f"unknown unit {unit!r} ({type(error).__name__}: {error})") from None


def dimension(unit: str) -> str:
    """The dimension of ``unit`` in words, e.g. "[mass] * [length] ** 2 / [time] ** 2 / [angle]"."""
    dims = parse_unit(unit).dimensionality
    return str(dims) if dims else "dimensionless"


def declared_unit(variable) -> str | None:
    """The unit a model variable declares: its own ``unit``, else its declared type's (fmpy
    leaves a type's unit on the type); None when neither declares one - in FMI an unknown
    unit, not unit 1 ("1" declared is dimensionless)."""
    unit = getattr(variable, "unit", None)
    if not unit:
        unit = getattr(getattr(variable, "declaredType", None), "unit", None)
    return unit or None


def same_dimension(a: str | None, b: str | None) -> bool:
    """Whether units ``a`` and ``b`` measure the same kind of quantity (None: dimensionless);
    kept in the cache as a factor is (``factor``)."""
    return _kept(f"same dimension {a or ''}\0{b or ''}",
                 lambda: parse_unit(a or "").dimensionality == parse_unit(b or "").dimensionality)


#: the SI unit of each base dimension (pint's own root of [mass] is the gram)
_SI = {"[mass]": "kg", "[length]": "m", "[time]": "s", "[angle]": "rad", "[current]": "A",
       "[temperature]": "K", "[substance]": "mol", "[luminosity]": "cd"}


def si_unit(unit):
    """The SI unit (kg, m, s, rad, ...) of the pint unit ``unit``'s dimension."""
    dims = unit.dimensionality
    unknown = [d for d in dims if d not in _SI]
    if unknown:
        raise UnitProblem(f"{unit}: no SI unit for the dimension {', '.join(unknown)}")
    target = registry().parse_units("dimensionless")
    for d, exponent in dims.items():
        target = target * registry().parse_units(_SI[d]) ** exponent
    return target


def split(text: str) -> tuple[float, str] | None:
    """``(number, unit)`` of a string "<number> <unit>", None when it is not of that form -
    also for a number written as text, "9e2" (not 9 in the unit e2, elementary charges squared)."""
    m = _QUANTITY.match(text) if isinstance(text, str) else None
    if m is None:
        return None
    try:
        float(text)
    except ValueError:
        return float(m.group(1)), m.group(2)
    return None


def factor(unit: str, target: str | None) -> float:
    """What a value in ``unit`` is multiplied by to be in ``target`` (None: the SI base
    units, kg m s rad); ``UnitProblem`` when the dimensions differ or a unit is unknown.
    A factor once worked out is kept in the cache (``FACTORS``): pint's import and its
    registry are a second of every process that converts a value ("15 deg" in a scene)."""
    return _kept(f"factor {unit}\0{target}", lambda: _factor_by_pint(unit, target))


#: the part of the cache (``harness.cache.PARTS``) the factors (and which units share a
#: dimension) are kept in: one file for the pint release that worked them out (its registry,
#: with the change this module makes, is code the cache's digest covers)
FACTORS = "unit-factors"


def _kept(key: str, work):
    """What ``work()`` answers for ``key``: from the cache, else worked out and kept (an
    exception it raises - a refusal - is not kept)."""
    known = _known_factors()
    if key not in known:
        known[key] = work()
        _keep_factors(known)
    return known[key]


def _factors_file() -> Path:
    from harness import cache

    return cache.entries(FACTORS) / f"pint-{_pint_version()}.json"


@functools.lru_cache(maxsize=1)
def _pint_version() -> str:
    from importlib.metadata import version

    return version("pint")


#: the factors read from each cache file this process used (a process that changes
#: ``LEVER_CACHE_DIR`` reads and writes the new folder's)
_read: dict[Path, dict[str, float | bool]] = {}


def _known_factors() -> dict[str, float | bool]:
    """What the cache keeps, read once a process (nothing when it holds no readable file)."""
    import json

    path = _factors_file()
    if path not in _read:
        try:
            kept = json.loads(path.read_text())
        except (OSError, ValueError):
            kept = {}
        _read[path] = {k: v for k, v in kept.items() if isinstance(v, (float, bool))} if isinstance(kept, dict) else {}
    return _read[path]


def _keep_factors(known: dict[str, float | bool]) -> None:
    """``known`` written to the cache whole (a temporary file renamed over the old one: a
    process reading it at the same time sees the old or the new file); a cache that cannot
    be written only means pint works it out again."""
    import json
    import os
    import tempfile

    path = _factors_file()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile("w", dir=path.parent, prefix=".factors-", delete=False) as scratch:
            json.dump(known, scratch)
        os.replace(scratch.name, path)
    except OSError:
        pass


def _factor_by_pint(unit: str, target: str | None) -> float:
    import pint

    source = parse_unit(unit)
    goal = parse_unit(target) if target is not None else None
    if goal is not None and source.dimensionality != goal.dimensionality:
        raise UnitProblem(f"a value in {unit} ({dimension(unit)}) cannot be a value in {target} "
                          f"({dimension(target)})")
    try:
        one = registry().Quantity(1.0, source)
        if not (one._is_multiplicative and (goal is None or registry().Quantity(1.0, goal)._is_multiplicative)):
            raise UnitProblem(f"{unit}: a unit with an offset (a temperature scale) is not taken here")
        converted = one.to(goal if goal is not None else si_unit(source))
    except pint.errors.PintError as error:   # offset units (degC) and the like
        raise UnitProblem(f"{unit}: cannot be converted ({error})") from None
    return float(converted.magnitude)


def convert(text: str, target: str | None = None) -> float:
    """The string "<number> <unit>" as a number in ``target`` (None: the SI base units).
    ``UnitProblem`` when it is not a number with a known unit of ``target``'s dimension."""
    parsed = split(text)
    if parsed is None:
        raise UnitProblem(f"{text!r} is not a number with a unit (e.g. '15 deg')")
    number, unit = parsed
    try:
        scale = factor(unit, target)
    except UnitProblem as problem:
        if target is None or not _known(target) or "cannot be a value in" not in str(problem):
            raise
        # what to write instead, in the variable's own unit as pint reads it
        raise UnitProblem(f"{problem}; write it in {target}, e.g. '{number:g} {pint_syntax(target)}'") from None
    # the same arithmetic as a table of factors: number * factor (bit for bit what
    # "15 deg" gave before the units were checked)
    return number * scale if scale != 1.0 else number


def _known(unit: str) -> bool:
    try:
        parse_unit(unit)
    except UnitProblem:
        return False
    return True


def is_number(value) -> bool:
    """A real number as a scene may write one: int or float, never a boolean."""
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def kind_of_value(value) -> str:
    """What a TOML value is, in words, for messages."""
    import datetime

    if isinstance(value, bool):
        return f"the boolean {str(value).lower()}"
    if isinstance(value, (datetime.date, datetime.time, datetime.datetime)):
        return f"the date/time {value.isoformat()}"
    if isinstance(value, list):
        return "a list"
    if isinstance(value, dict):
        return "a table"
    if isinstance(value, float) and not math.isfinite(value):
        return f"{value}"
    return repr(value)


def same_value(given: str, reference: str) -> bool:
    """Whether two values as a run's record writes them are the same quantity: "15.0 deg" is
    "15 deg", "6.35 N*m*s/rad" is "6.35 N.m.s/rad", "0.2617993877991494 rad" is "15 deg" to
    twelve digits - each converted to ``reference``'s unit (a parameter's declared unit as the
    record writes it).  Numbers without a unit compare as numbers; a value that is neither
    (a Fourier series' text, a file's name) as text; a number without a unit is never the
    same as one with a unit (which unit it is in is not said)."""
    given, reference = str(given).strip(), str(reference).strip()
    if given == reference:
        return True
    numbers = [_plain_number(given), _plain_number(reference)]
    if None not in numbers:
        return math.isclose(numbers[0], numbers[1], rel_tol=1e-12, abs_tol=0.0)
    parsed = split(reference)
    if parsed is None or split(given) is None:
        return False
    try:
        value = convert(given, parsed[1])
    except UnitProblem:
        return False
    return math.isclose(value, parsed[0], rel_tol=1e-12, abs_tol=0.0)


def _plain_number(text: str) -> float | None:
    try:
        return float(text)
    except ValueError:
        return None
