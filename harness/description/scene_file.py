"""A scene file as written: its TOML read (``read_data``, with what a variant takes from its
base, ``extend``), its shape and the types of every table a user writes in it checked
strictly (``check_shape``: a boolean or a string where a number belongs is refused, in
``[experiment]``, ``[limits]``, ``[validation]`` and ``[bench]`` alike), a scene's name
resolved to its file.  ``harness.description.scene`` builds the ``Scene`` from it."""
from __future__ import annotations

import copy
import difflib
import functools
import tomllib
from pathlib import Path

from harness.description import units
from harness.paths import SCENES


class SceneError(ValueError):
    """A scene that cannot be read or run as written: the message names the key or value and
    what is allowed."""


def is_fmu_path(fmu: str) -> bool:
    """True when ``fmu`` names a file (``X.fmu``, the extension in any case), not one of our
    FMUs: a scene component's ``fmu``, a name given to ``lever validate``."""
    return str(fmu).lower().endswith(".fmu")


def fmu_name(fmu: str) -> str:
    """The FMU's name: ``EngineShaft`` for ``EngineShaft`` and for ``/x/EngineShaft.fmu``."""
    return Path(fmu).stem if is_fmu_path(fmu) else fmu


def resolve(name_or_path: str | Path) -> Path:
    path = Path(name_or_path)
    if path.suffix == ".toml" and path.exists():
        return path
    candidate = SCENES / f"{name_or_path}.toml"
    if candidate.exists():
        return candidate
    known = sorted(p.stem for p in SCENES.glob("*.toml"))
    raise SceneError(f"no scene '{name_or_path}'{did_you_mean(str(name_or_path), known)} (a .toml path or one of: "
                     f"{', '.join(known)})")


def did_you_mean(word: str, known) -> str:
    """`` (did you mean 'X'?)`` for the name in ``known`` closest to a mistyped ``word``
    (difflib's ratio of at least 0.6), else ``""``."""
    close = difflib.get_close_matches(word, list(known), n=1)
    return f" (did you mean '{close[0]}'?)" if close else ""


#: what a variant (``extends = "base"``) does not take from its base: its identity
OWN = ("name", "description", "extends")
#: tables a variant merges key by key into its base's (components: each one's ``fmu`` and
#: ``parameters``); any other table or value a variant states replaces its base's whole
#: (an empty ``[bench]`` says: no benchmark plan)
MERGED = ("experiment", "limits", "validation")


@functools.lru_cache(maxsize=256)
def _parsed(text: str) -> dict:
    return tomllib.loads(text)


def parse_toml(text: str) -> dict:
    """``text`` read as TOML, a table of the caller's own: a scene file is read many times
    over (every scene's features when a command lists the references, a base once for each
    variant), and parsing took most of a ``lever validate`` that refuses its input."""
    return copy.deepcopy(_parsed(text))


def read_data(path: Path, extending: tuple[Path, ...] = ()) -> dict:
    """The TOML table of the scene file ``path``, with what it inherits when it names a
    base scene (``extends = "kavz685"``: a scene beside it or in resources/scenes, or a
    .toml path relative to it) and states only what differs."""
    try:
        data = parse_toml(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as error:
        raise SceneError(f"{path}: not a valid TOML file: {error}") from None
    except UnicodeDecodeError as error:
        raise SceneError(f"{path}: not a UTF-8 text file (byte {error.start}: {error.reason}); a scene is "
                         "TOML in UTF-8") from None
    except OSError as error:
        raise SceneError(f"{path}: cannot read it ({error.strerror or error})") from None
    check_shape(data, path)
    # An FMU by path is relative to the file that names it (a base scene's to the base).
    for spec in (data.get("components") or {}).values():
        if isinstance(spec, dict) and isinstance(spec.get("fmu"), str) and is_fmu_path(spec["fmu"]):
            spec["fmu"] = str((path.parent / Path(spec["fmu"]).expanduser()).resolve())
    base_name = data.get("extends")
    if base_name is None:
        return data
    if not isinstance(base_name, str) or not base_name:
        raise SceneError(f"{path}: extends = {base_name!r}: expected the name or .toml path of a scene")
    beside = path.parent / (base_name if base_name.endswith(".toml") else f"{base_name}.toml")
    base_path = (beside if beside.exists() else resolve(base_name)).resolve()
    chain = extending + (path.resolve(),)
    if base_path in chain:
        raise SceneError(f"{path}: extends {base_name}, which extends it back "
                         f"({' -> '.join(p.stem for p in chain + (base_path,))})")
    return extend(read_data(base_path, chain), data)


def extend(base: dict, variant: dict) -> dict:
    """The scene table of ``variant`` on top of ``base`` (see ``OWN`` and ``MERGED``)."""
    merged = {key: value for key, value in base.items() if key not in OWN}
    for key, value in variant.items():
        if key == "extends":
            continue
        if key in MERGED:
            merged[key] = {**base.get(key, {}), **value}
        elif key == "components":
            components = {name: {**spec, "parameters": dict(spec.get("parameters", {}))}
                          for name, spec in base.get("components", {}).items()}
            for name, spec in value.items():
                old = components.get(name, {})
                components[name] = {**old, **spec,
                                    "parameters": {**old.get("parameters", {}), **spec.get("parameters", {})}}
            merged[key] = components
        else:
            merged[key] = value
    return merged


#: the shape of a scene file: key -> (what it must be, in words; test)
SHAPE = {
    "name": ("a string", lambda v: isinstance(v, str)),
    "description": ("a string", lambda v: isinstance(v, str)),
    "notes": ("a string", lambda v: isinstance(v, str)),
    "extends": ("the name or .toml path of a scene", lambda v: isinstance(v, str)),
    "features": ("a list of strings", lambda v: isinstance(v, list) and all(isinstance(x, str) for x in v)),
    "record": ("a list of strings", lambda v: isinstance(v, list) and all(isinstance(x, str) for x in v)),
    "connections": ("a list of strings 'component.output -> component.input'",
                    lambda v: isinstance(v, list) and all(isinstance(x, str) for x in v)),
    "experiment": ("a table", lambda v: isinstance(v, dict)),
    "limits": ("a table", lambda v: isinstance(v, dict)),
    "bench": ("a table", lambda v: isinstance(v, dict)),
    "validation": ("a table of relative tolerances (mean, amplitude, order, tube), sub-tables by kind or signal",
                   lambda v: isinstance(v, dict)),
    "components": ("a table of components, each a table with fmu = \"<FMU name>\" and a [parameters] table",
                   lambda v: isinstance(v, dict) and all(
                       isinstance(c, dict) and isinstance(c.get("fmu", ""), str)
                       and isinstance(c.get("parameters", {}), dict) for c in v.values())),
}


def check_shape(data: dict, path: Path):
    """``SceneError`` naming the key when a scene file's table is not of the scene's shape
    (``SHAPE``; unknown keys too)."""
    for key, value in data.items():
        if key not in SHAPE:
            raise SceneError(f"{path}: unknown key '{key}' (a scene has: {', '.join(SHAPE)})")
        what, test = SHAPE[key]
        if not test(value):
            raise SceneError(f"{path}: {key} = {units.kind_of_value(value)}: expected {what}")
    problems = validation_problems(data.get("validation", {})) + bench_problems(data.get("bench", {}))
    if problems:
        raise SceneError(f"{path}: " + "; ".join(problems))


#: a tolerance is a number: a boolean (true would be 100 %) or a string ("0.05") is not
_TOLERANCE = "a relative tolerance, a number (e.g. 0.05 for 5 %)"


def validation_problems(table: dict) -> list[str]:
    """The ``[validation]`` table's values that are not numbers (its quantities' names and
    ranges are checked where the verdict reads them, ``harness.judges.verdict``)."""
    problems = []
    for key, value in table.items():
        inner = value.items() if isinstance(value, dict) else [(None, value)]
        for quantity, number in inner:
            label = f"validation.{key}" + (f".{quantity}" if quantity is not None else "")
            if not units.is_number(number):
                problems.append(f"{label} = {units.kind_of_value(number)}: expected {_TOLERANCE}"
                                + (", or a sub-table of them by kind or signal" if quantity is None else ""))
    return problems


#: the ``[bench]`` table's keys, the one registry of them (the scene file's check reads the
#: shape, ``harness.studies.bench.schedule`` and the generated scene-format page the rest):
#: key -> (shape, what a value must be, what it sets, its default)
BENCH_KEYS = {
    "steps": ("table of numbers", "a list of steps [s] per master",
              "{master = [h, ...]}: the communication steps [s] each fixed-step master runs at", "the ladder"),
    "tolerances": ("table of numbers", "a list of tolerances per master",
                   "{master = [tol, ...]}: the tolerances each adaptive or Model Exchange master runs at",
                   "the ladder"),
    "output_steps": ("table of number", "a step [s] per master",
                     "{master = h}: the grid [s] a tolerance run records on", "the scene's step"),
    "peers": ("table of numbers", "a list of steps [s] per peer",
              "{peer = [h, ...]}: the steps each peer engine runs at (`lever engines` names them)", "none"),
    "peer_tolerances": ("table of numbers", "a list of numbers per peer",
                        "{peer = [tol, ...]}: ECCO's tolerances [J per step]", "none"),
    "monolithic_rtol": ("numbers", "a list of tolerances",
                        "[rtol, ...]: the monolithic reference's tolerances (DOP853)", "[1e-4, 1e-6, 1e-8]"),
    "monolithic_cvode_rtol": ("numbers", "a list of tolerances",
                              "[rtol, ...]: the same equations under CVODE", "none"),
    "target_error": ("number", "a number", "the relative error the headline claims compare the masters at",
                     "1e-3"),
    "baseline": ("text", "a master's name (a string)", "the master the headline ratios divide by", "jacobi"),
    "repeats_limit_s": ("number", "a number of seconds",
                        "a case whose one run takes longer than this [s] runs once", "5"),
}


def bench_problems(table: dict) -> list[str]:
    """The ``[bench]`` table's keys it does not have and values not of their shape
    (``BENCH_KEYS``), each by its full name (``bench.steps.jacobi``): numbers are numbers,
    never booleans or strings."""
    problems = []
    for key, value in table.items():
        if key not in BENCH_KEYS:
            problems.append(f"bench.{key}: no such key{did_you_mean(key, BENCH_KEYS)} (a [bench] table has: "
                            f"{', '.join(BENCH_KEYS)})")
            continue
        shape, what, _, _ = BENCH_KEYS[key]
        if shape.startswith("table of ") and not isinstance(value, dict):
            problems.append(f"bench.{key} = {units.kind_of_value(value)}: expected a table of {what}")
            continue
        entries = value.items() if shape.startswith("table of ") else [(None, value)]
        element = shape.removeprefix("table of ")
        for inner, entry in entries:
            label = f"bench.{key}" + (f".{inner}" if inner is not None else "")
            if element == "text":
                wrong = None if isinstance(entry, str) else units.kind_of_value(entry)
            elif element == "number":
                wrong = None if units.is_number(entry) else units.kind_of_value(entry)
            elif not isinstance(entry, list):
                wrong = units.kind_of_value(entry)
            else:
                wrong = next((f"a list (item {k}: {units.kind_of_value(x)})" for k, x in enumerate(entry)
                              if not units.is_number(x)), None)
            if wrong is not None:
                problems.append(f"{label} = {wrong}: expected {what.replace(' per master', '').replace(' per peer', '')}")
    return problems
