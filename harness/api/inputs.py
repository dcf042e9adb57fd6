"""What ``harness.api`` accepts, read the way its users hold it: times with units ("1 ms"),
numpy scalars as numbers, a result to validate as a ``Run``, an fmpy-style structured
array, a ``(times, {name: values})`` pair, a pandas DataFrame or a CSV path, and signal
names as the traces write them (``coupling.tau2``) or short where that is unambiguous.
Anything else is an ``InputError`` naming the argument, as the command line refuses it.
"""
from __future__ import annotations

import contextlib
import math
import numbers
import os
import sys
from contextvars import ContextVar
from pathlib import Path
from typing import Iterable, Mapping

import numpy as np

from harness.description import scene as scene_files
from harness.description.arguments import Argument


class InputError(ValueError):
    """Bad input: the message names the parameter and what is allowed (``lever``: exit 2)."""


class UnknownSignal(InputError, KeyError):
    """A signal name that is none of the traces', or a short name more than one ends with.
    A ``KeyError`` too, so that ``name in traces`` and ``traces.get(name)`` keep working."""

    def __str__(self):
        return self.args[0] if self.args else ""


# -- how a refusal names an argument ------------------------------------------------------------

#: keyword -> the command line's option for it, while the command line calls the API (``named_as_options``)
_OPTIONS: ContextVar[Mapping[str, str | Argument]] = ContextVar("harness_api_options", default={})


@contextlib.contextmanager
def named_as_options(options: Mapping[str, str | Argument]):
    """Inside it, a refusal names an argument by the command line's option for it
    (``options``: keyword -> option, ``{"rtol": "--rtol", "overrides": "--set"}``): the
    command line calls the API and its user is told what they typed.  Elsewhere a refusal
    names the keyword the Python caller wrote (``rtol=``)."""
    token = _OPTIONS.set(dict(options))
    try:
        yield
    finally:
        _OPTIONS.reset(token)


def named(keyword: str) -> Argument:
    """``keyword`` as the caller named it: itself, or its option inside ``named_as_options``."""
    spelled = _OPTIONS.get().get(keyword, keyword)
    return spelled if isinstance(spelled, Argument) else Argument(spelled)


def _said(keyword: str, shown: str) -> str:
    """``keyword=shown`` (``--option shown`` from the command line)."""
    return named(keyword).given(shown)


def _shown(value) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def number(value, argument: str) -> float:
    """A real number from an int, a float or a numpy scalar (never a boolean or a string)."""
    if isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_)):
        return float(value)
    raise InputError(f"{_said(argument, _shown(value))}: expected a number")


def flag(value, argument: str) -> bool:
    """True or False (a numpy boolean too; never a number or a string such as "no")."""
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    raise InputError(f"{_said(argument, _shown(value))}: expected True or False")


def count(value, argument: str, low: int, high: int | None = None) -> int:
    """A whole number in [low, high] from an int or a numpy integer."""
    if not isinstance(value, numbers.Integral) or isinstance(value, (bool, np.bool_)):
        raise InputError(f"{_said(argument, _shown(value))}: expected a whole number "
                         f"{'>= ' + str(low) if high is None else f'in [{low}, {high}]'}")
    if value < low or (high is not None and value > high):
        raise InputError(f"{_said(argument, str(value))}: must be "
                         f"{'>= ' + str(low) if high is None else f'in [{low}, {high}]'}")
    return int(value)


def seconds(value, argument: str) -> float | None:
    """A time: a number in seconds (a numpy scalar too) or a string with a time unit, as a
    scene's overrides take it ("1 ms", "0.5 s", "0.5"); None stays None.  InputError
    naming ``argument`` otherwise (not finite, another dimension, not a time at all)."""
    if value is None:
        return None
    if isinstance(value, str):
        text = value.strip()
        try:
            value = float(text)
        except ValueError:
            try:
                value = scene_files.experiment_value("stop", text, named(argument).name)
            except scene_files.SceneError as error:
                said = named(argument)
                raise InputError(str(error).replace(f"{said} = ", said.given(""), 1)) from None
    elif not isinstance(value, numbers.Real) or isinstance(value, (bool, np.bool_)):
        raise InputError(f"{_said(argument, _shown(value))}: expected a time in seconds (a number, or a string with a "
                         "time unit, e.g. '1 ms')")
    value = float(value)
    if not math.isfinite(value):
        raise InputError(f"{_said(argument, str(value))}: expected a finite time in seconds")
    return value


def scene_argument(scene, argument: str = "scene"):
    """``scene`` when it is a name, a path or a ``Scene``; InputError otherwise."""
    if isinstance(scene, (str, os.PathLike, scene_files.Scene)):
        return scene
    raise InputError(f"{_said(argument, _shown(scene))}: expected a scene's name (e.g. 'kavz685', `api.scenes()` lists "
                     "them), a .toml or .ssp path, or a Scene")


def folder(out, argument: str = "out") -> Path | None:
    """An output folder given as a string or a path (None: none)."""
    if out is None:
        return None
    if isinstance(out, (str, os.PathLike)) and str(out).strip():
        return Path(out)
    raise InputError(f"{_said(argument, _shown(out))}: expected a folder (a string or a pathlib.Path)")


def names(values, argument: str) -> list[str]:
    """A list of names from one string or an iterable of strings."""
    if values is None:
        return []
    if isinstance(values, (str, os.PathLike)):
        return [str(values)]
    try:
        listed = [str(v) if isinstance(v, os.PathLike) else v for v in values]
    except TypeError:
        raise InputError(f"{_said(argument, _shown(values))}: expected a name or a list of names") from None
    wrong = [v for v in listed if not isinstance(v, str)]
    if wrong:
        raise InputError(f"{named(argument)}: {_shown(wrong[0])} is not a name (a string)")
    return listed


def choice(value, argument: str, allowed: Iterable[str]) -> str:
    """``value`` when it is one of ``allowed``."""
    allowed = list(allowed)
    if not isinstance(value, str) or value not in allowed:
        hint = scene_files.did_you_mean(value, allowed) if isinstance(value, str) else ""
        raise InputError(f"{_said(argument, _shown(value))}{hint}: one of {', '.join(allowed)}")
    return value


# -- signal names ---------------------------------------------------------------------------------

def resolve_signal(name, known: Iterable[str], aliases: Mapping[str, str] | None = None) -> str:
    """The signal ``name`` stands for among ``known``: itself, the one whose variable it is
    (``tau2`` -> ``coupling.tau2``) when exactly one is, or an alias (a driveline's ``w1``
    -> ``engine.w``).  ``UnknownSignal`` saying what is known or which ones it could be."""
    known = list(known)
    if name in known:
        return name
    if not isinstance(name, str):
        raise UnknownSignal(f"{_shown(name)}: a signal's name is a string (known: {', '.join(known)})")
    ending = [k for k in known if k.split(".", 1)[-1] == name]
    if len(ending) == 1:
        return ending[0]
    if len(ending) > 1:
        raise UnknownSignal(f"signal '{name}' is ambiguous: {', '.join(ending)} (name one of them)")
    if aliases and aliases.get(name) in known:
        return aliases[name]
    hint = scene_files.did_you_mean(name, known + [k.split(".", 1)[-1] for k in known])
    raise UnknownSignal(f"no signal '{name}'{hint} (known: {', '.join(known)})")


class Signals(dict):
    """A dict of signals by their full names (``component.variable``, as the traces and
    summary.json write them) that also takes a short name where it is unambiguous
    (``traces["tau2"]`` is ``traces["coupling.tau2"]``) and a driveline's aliases
    (``w1``, ``w2``, ``tau1``, ``tau2``, ``a1``, ``a2``, ``U12``)."""

    def __init__(self, values=(), aliases: Mapping[str, str] | None = None):
        super().__init__(values)
        self.aliases = dict(aliases or {})

    def full_name(self, name) -> str:
        """The full name ``name`` stands for (``UnknownSignal`` when none or several)."""
        return resolve_signal(name, self.keys(), self.aliases)

    def __getitem__(self, name):
        return super().__getitem__(name if dict.__contains__(self, name) else self.full_name(name))

    def __contains__(self, name):
        try:
            self.full_name(name)
        except UnknownSignal:
            return False
        return True

    def get(self, name, default=None):
        return self[name] if name in self else default

    def __repr__(self):
        return f"Signals({dict.__repr__(self)})" if len(dict.__repr__(self)) < 300 else \
            f"Signals({len(self)} signals: {', '.join(self)})"


# -- a result to validate -------------------------------------------------------------------------

def result_traces(result, argument: str = "result") -> tuple[np.ndarray, dict[str, np.ndarray], str] | Path:
    """``(times, {name: values}, how)`` of a result to judge, from what a user holds: a
    ``Run`` (or anything with ``.times`` and ``.traces``), a numpy structured array with a
    ``time`` field (fmpy's ``simulate_fmu``, ``Run.array()``), a pandas DataFrame with a
    ``time`` column, or a ``(times, {name: values})`` pair.  A CSV path is returned as a
    ``Path`` (the caller reads it with its own checks).  InputError naming ``argument``."""
    if isinstance(result, (str, os.PathLike)):
        return Path(result)
    if hasattr(result, "times") and hasattr(result, "traces"):
        times, traces, how = result.times, result.traces, "the Run given"
    elif isinstance(result, np.ndarray) and result.dtype.names:
        fields = result.dtype.names
        if "time" not in fields:
            raise InputError(f"{named(argument)}: a structured array without a 'time' field (fields: "
                             f"{', '.join(fields)})")
        times, traces, how = result["time"], {n: result[n] for n in fields if n != "time"}, "the array given"
    elif hasattr(result, "columns") and hasattr(result, "to_numpy"):
        columns = [str(c) for c in result.columns]
        if "time" not in columns:
            raise InputError(f"{named(argument)}: a table without a 'time' column (columns: {', '.join(columns)})")
        times = result["time"].to_numpy()
        traces, how = {c: result[c].to_numpy() for c in columns if c != "time"}, "the table given"
    elif isinstance(result, (tuple, list)) and len(result) == 2 and isinstance(result[1], Mapping):
        times, traces, how = result[0], result[1], "given"
    else:
        raise InputError(f"{_said(argument, _shown(result))}: expected a Run, a numpy structured array with a 'time' "
                         "field (as fmpy's simulate_fmu returns), a (times, {name: values}) pair, a DataFrame "
                         "with a 'time' column, or a CSV file's path")
    times = _column(times, f"{named(argument)}: the times")
    out = {}
    for name, values in traces.items():
        column = _column(values, f"{named(argument)}: signal '{name}'")
        if column.shape != times.shape:
            raise InputError(f"{named(argument)}: signal '{name}' has {len(column)} values for {len(times)} times")
        out[str(name)] = column
    return times, out, how


def _column(values, what: str) -> np.ndarray:
    try:
        column = np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{what}: expected numbers") from None
    if column.ndim != 1:
        raise InputError(f"{what}: expected one value per time (a 1-D sequence), got shape {column.shape}")
    return column


# -- arguments every command reads the same way -----------------------------------------------

def assignments(overrides, argument: str = "overrides") -> list[str]:
    """``{"coupling.stiffness": 900}`` or ``["coupling.stiffness=900"]`` as ``--set`` texts
    (``argument``: the name a refusal gives, the caller's: ``overrides``, ``rtol``).  A
    list's texts are read as the command line reads ``--set``; a dict's values keep their
    type (``override_text``)."""
    if overrides is None:
        return []
    if isinstance(overrides, Mapping):
        for key in overrides:
            if not isinstance(key, str):
                raise InputError(f"{named(argument)}: {_shown(key)} is not a parameter's name (a string such as "
                                 "'coupling.stiffness')")
        return [f"{key}={override_text(value, named(argument).item(key))}" for key, value in overrides.items()]
    if isinstance(overrides, str):
        return [overrides]
    return names(overrides, argument)


def override_text(value, label: str) -> str:
    """A dict override's value as the ``--set`` text that reads back as the same type (the
    scene's parameters check that type as a scene file's: ``harness.description.plan``): a
    number (a numpy scalar too) as a number, True or False as true or false, a string as a
    string - quoted where its text would read as a number or a boolean, so ``"900"`` is the
    text '900', refused for a numeric parameter, while ``"900 N*m/rad"`` is a quantity
    with its unit as ``--set`` takes it.  ``label`` names it in a refusal."""
    value = _plain(value)
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, numbers.Integral):
        return str(int(value))
    if isinstance(value, numbers.Real):
        return repr(float(value))
    if isinstance(value, str):
        value = value.strip()           # as --set reads its text
        for text in (value, f"'{value}'", f'"{value}"'):
            read = scene_files.coerce(text)
            if isinstance(read, str) and read == value:
                return text
        raise InputError(f"{label}={_shown(value)}: a text value cannot begin or end with a quote")
    raise InputError(f"{label}={_shown(value)}: expected a number, True or False, or a string (a quantity with "
                     "its unit, e.g. '20 deg', or a name)")


def tolerances(rtol, argument: str = "rtol") -> list[str]:
    """Relative tolerances as ``--rtol`` texts: ``"amplitude=0.05"``, a list of such texts,
    or ``{"amplitude": 0.05, "torque:mean": 0.002}`` whose values are numbers (a boolean or a
    string is no tolerance).  InputError naming ``argument`` otherwise."""
    if isinstance(rtol, Mapping):
        for key, value in rtol.items():
            if not isinstance(key, str):
                raise InputError(f"{named(argument)}: {_shown(key)} is not a quantity's name (e.g. 'amplitude', "
                                 "'torque:mean')")
            number(value, f"{argument}[{key!r}]")
        return [f"{k}={_plain(v)}" for k, v in rtol.items()]
    if rtol is not None and not isinstance(rtol, (str, os.PathLike)) and not isinstance(rtol, Iterable):
        raise InputError(f"{_said(argument, _shown(rtol))}: expected 'QUANTITY=VALUE' texts (e.g. 'amplitude=0.05'), "
                         "a list of them or a dict {quantity: number}")
    return assignments(rtol, argument)


def _plain(value):
    """A numpy scalar as the Python number it is (``--set`` reads its text)."""
    return value.item() if isinstance(value, np.generic) else value


def step(step, label="step") -> float | None:
    """``step`` as seconds (units taken), checked as every communication step is."""
    step = seconds(step, label)
    if step is not None and (problem := scene_files.step_problem(step, named(label).name)):
        raise InputError(problem)
    return step


def window(window, argument: str = "window") -> tuple[float | None, float | None] | None:
    """``window`` as ``(start, stop)`` in seconds: from ``"START:STOP"`` or a pair whose
    sides are times (units taken) or None."""
    if window is None or isinstance(window, str):
        return parse_window(window, argument)
    if not (isinstance(window, (tuple, list)) and len(window) == 2):
        raise InputError(f"{_said(argument, _shown(window))}: expected (start, stop) in seconds or 'START:STOP'")
    return seconds(window[0], f"{argument} start"), seconds(window[1], f"{argument} stop")


def parse_window(text: str | None, argument: str = "window") -> tuple[float | None, float | None] | None:
    """``START:STOP`` (``--window``; either side may be left empty: the reference's own end;
    a side may carry a time unit, ``0:500 ms``)."""
    if text is None:
        return None
    said = named(argument).typed(str(text))
    parts = str(text).split(":")
    try:
        if len(parts) != 2:
            raise ValueError
        low, high = (seconds(p, argument) if p.strip() else None for p in parts)
    except (ValueError, InputError):
        raise InputError(f"{said}: expected START:STOP in seconds, e.g. 2:10 or 0:1 or 0:500 ms (an empty "
                         "side: the reference's own start or stop)") from None
    for v in (low, high):
        if v is not None and not math.isfinite(v):
            raise InputError(f"{said}: the times must be finite")
    if low is not None and high is not None and not high > low:
        raise InputError(f"{said}: STOP must be > START")
    return low, high


# -- warnings at the user's line ------------------------------------------------------------------

_HARNESS = str(Path(__file__).resolve().parents[1])


def user_stacklevel() -> int:
    """The ``stacklevel`` for ``warnings.warn`` called here that names the first frame
    outside the harness: the user's line, not one of ours."""
    frame, level = sys._getframe(1), 1
    while frame is not None and str(Path(frame.f_code.co_filename).resolve()).startswith(_HARNESS + os.sep):
        frame, level = frame.f_back, level + 1
    return level
