"""Scenes: declarative descriptions of a co-simulation (``resources/scenes/*.toml``).

A scene names its components (which FMU, which parameter values), its connections
(``"engine.phi -> coupling.phi1"``), the experiment (start, stop, step, master), what to
record, and the features it wants (``reference``: solve the same equations unsplit;
``energy_balance``: account for every joule).  Only what a scene declares is
instantiated, computed and recorded.

Values may carry a unit, ``"15 deg"`` or ``"374.8 rpm"``; they are converted to SI.
``validate`` is a pure function returning findings (empty when the scene is sound).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from harness.description import typed_values, units
from harness.description.arguments import SET, Argument
from harness.description.fmu_description import time_derivatives
# the scene file as written (read, shape and types checked): its names are this module's too
from harness.description.scene_file import (MERGED, OWN, SceneError, check_shape, did_you_mean, extend,  # noqa: F401
                                            fmu_name, is_fmu_path, read_data, resolve)
from harness.description.tables import MeasuredDataError, load_series, read_table
from harness.paths import DATA

FEATURES = ("reference", "energy_balance", "plots")
#: the ``[limits]`` a scene may set for the divergence guard (harness.engine.guard)
LIMIT_KEYS = ("speed", "torque", "margin")
LIMIT_UNITS = {"speed": "rad/s", "torque": "N.m", "margin": "1"}


@dataclass(frozen=True)
class Connection:
    source: str
    output: str
    target: str
    input: str

    def __str__(self):
        return f"{self.source}.{self.output} -> {self.target}.{self.input}"


@dataclass
class ComponentSpec:
    #: an FMU of ours by name (``EngineShaft``: build/fmus or the scene's ``fmu_dir``), or
    #: any FMU by path (``"/abs/X.fmu"``; in a scene file also relative to the file)
    fmu: str
    parameters: dict[str, Any] = field(default_factory=dict)


@dataclass
class Experiment:
    stop: float = 10.0
    step: float = 1e-3
    start: float = 0.0
    master: str = "gauss-seidel"
    #: start-up time left out of amplitude statistics [s]; unstated: ``default_transient``
    #: of the experiment's length, following it when --set changes start or stop
    transient: float | None = None
    #: refuse the run when an input is left unconnected (and not given a value), instead
    #: of naming it and running on with its start value (``strict = true``, ``--strict``)
    strict: bool = False
    #: the FMI edition of the FMUs the scene names by name: 2 (build/fmus) or 3 (their FMI
    #: 3.0 editions, build/fmus3); an FMU by path is what its file is
    fmi: int = 2
    #: the relative tolerance of the scene's own master, where it takes one (an adaptive
    #: master's error per step, an iterative one's coupling iteration, me-cvode's CVODE
    #: rtol); unstated: the master's default.  Another master run on the scene keeps its own.
    tolerance: float | None = None

    def __post_init__(self):
        self.transient_follows_length = self.transient is None
        if self.transient is None:
            self.transient = default_transient(self.start, self.stop)
        #: what ``Scene.with_overrides`` did to the scene's transient to fit a shortened run
        #: (a sentence for the user and the report), else None
        self.transient_note: str | None = None


def default_transient(start: float, stop: float) -> float:
    """The start-up transient a scene that states none gets: 2 s, or a fifth of a run
    shorter than 10 s (a run of 2 s or less keeps statistics over its last 80 %)."""
    try:
        return min(2.0, 0.2 * (float(stop) - float(start)))
    except (TypeError, ValueError):
        return 2.0


#: the experiment's fields that are times [s]
EXPERIMENT_TIMES = ("start", "stop", "step", "transient")
#: the values of ``experiment.fmi``
FMI_EDITIONS = (2, 3)


@dataclass
class Scene:
    name: str
    description: str
    components: dict[str, ComponentSpec]
    connections: list[Connection]
    experiment: Experiment
    record: list[str]
    features: set[str]
    path: Path | None = None
    notes: str = ""
    #: the work-precision benchmark's plan for this scene (``[bench]`` table; see harness.studies.bench)
    bench: dict = field(default_factory=dict)
    #: where the scene's FMUs are when not in build/fmus (a scene loaded from an SSP archive)
    fmu_dir: Path | None = None
    #: overrides of the divergence guard's physical bounds (``[limits]``: speed, torque,
    #: margin; see harness.engine.guard)
    limits: dict = field(default_factory=dict)
    #: ``lever validate``'s tolerances for this scene's reference (``[validation]``: quantity =
    #: relative tolerance, sub-tables by kind or signal; see harness.judges.verdict)
    validation: dict = field(default_factory=dict)
    #: the ``--set`` assignments applied (``with_overrides``): name -> the value as given;
    #: where the values came from, not what the scene is (equal scenes compare equal)
    overrides: dict = field(default_factory=dict, compare=False)

    def __repr__(self) -> str:
        """In a line or two (a notebook's output): the components, the experiment, the
        overrides and the file, not the notes and tables."""
        e = self.experiment
        text = (f"Scene({self.name}: {len(self.components)} components ("
                + ", ".join(f"{n} {fmu_name(c.fmu)}" for n, c in self.components.items())
                + f"), {len(self.connections)} connections, t = {e.start:g} ... {e.stop:g} s, step {e.step:g} s, "
                f"master {e.master}" + (f" (tolerance {e.tolerance:g})" if e.tolerance is not None else "")
                + f", {len(self.record)} signals recorded"
                + (f", --set {'; '.join(f'{k} = {v}' for k, v in self.overrides.items())}" if self.overrides else "")
                + (f", from {self.path}" if self.path else "") + ")")
        return text if len(text) <= 2000 else text[:1995] + "...)"

    def component_of(self, fmu: str) -> str | None:
        """Name of the (first) component built from FMU ``fmu``."""
        return next((n for n, c in self.components.items() if fmu_name(c.fmu) == fmu), None)

    def with_overrides(self, assignments: list[str], argument: Argument = SET) -> "Scene":
        """Apply ``component.parameter=value`` (or ``parameter=value`` when exactly one
        component has it) and ``experiment.field=value`` assignments; a refusal names
        ``argument`` as the caller gave it (``--set``, or the API's ``overrides``)."""
        components = {n: ComponentSpec(c.fmu, dict(c.parameters)) for n, c in self.components.items()}
        experiment = replace(self.experiment)
        limits = dict(self.limits)
        overrides = dict(self.overrides)
        for assignment in assignments:
            if "=" not in assignment:
                raise SceneError(f"{argument.given(repr(assignment))}: expected name=value")
            key, raw = (s.strip() for s in assignment.split("=", 1))
            value = coerce(raw)
            if key.startswith("limits."):
                overrides[key] = raw
                limits[key.split(".", 1)[1]] = value
                continue
            if key.startswith("experiment."):
                attr = key.split(".", 1)[1]
                setattr(experiment, attr, experiment_value(attr, value, argument.item(key)))
                overrides[key] = raw
                continue
            if "." in key:
                comp, param = key.split(".", 1)
                if comp not in components:
                    raise SceneError(f"{argument.item(key)}: no component '{comp}' in scene {self.name}"
                                     f"{did_you_mean(comp, components)} (components: {', '.join(components)})")
                components[comp].parameters[param] = value
                overrides[key] = raw
            else:
                components_with = [n for n, c in components.items() if key in c.parameters]
                if len(components_with) != 1:
                    raise SceneError(f"{argument.item(key)}: name the component, e.g. coupling.{key}=... "
                                     f"({'ambiguous: ' + ', '.join(components_with) if components_with else 'not set in the scene'})")
                components[components_with[0]].parameters[key] = value
                overrides[f"{components_with[0]}.{key}"] = raw
        transient_set = any(a.split("=", 1)[0].strip() == "experiment.transient" for a in assignments)
        if self.experiment.transient_follows_length and not transient_set:
            experiment.transient = default_transient(experiment.start, experiment.stop)
            experiment.transient_follows_length = True
        elif not transient_set:
            experiment.transient_follows_length = False
            if (experiment.start, experiment.stop) == (self.experiment.start, self.experiment.stop):
                experiment.transient_note = self.experiment.transient_note
            _fit_transient(self.experiment, experiment)
        set_keys = {a.split("=", 1)[0].strip() for a in assignments}
        if experiment.master != self.experiment.master and "experiment.tolerance" not in set_keys:
            experiment.tolerance = None     # the scene's tolerance was its own master's
        return replace(self, components=components, experiment=experiment, limits=limits, overrides=overrides)


def _fit_transient(scene: Experiment, run: Experiment):
    """A run made shorter than its scene (``--stop``, ``--set experiment.stop``) keeps the
    scene's start-up transient when that fits; when it does not, the transient takes the
    same share of the shortened run as of the scene's, and ``run.transient_note`` says so.
    A transient the user sets is left to ``experiment_findings`` (strict)."""
    try:
        before, after = float(scene.stop - scene.start), float(run.stop - run.start)
        if not all(math.isfinite(v) for v in (before, after, scene.transient, run.transient)):
            return
    except (TypeError, ValueError):
        return      # unsound times: experiment_findings names them
    if after <= 0 or before <= 0 or run.transient < after or not 0 <= scene.transient < before:
        return
    run.transient = scene.transient * after / before
    run.transient_note = (f"the scene's start-up transient of {scene.transient:g} s does not fit a run of "
                          f"{after:g} s: statistics after {run.transient:.4g} s instead (the same share, "
                          f"{100 * scene.transient / before:.3g} % of the run; --set experiment.transient=T "
                          "chooses it)")


def coerce(raw: str):
    """A ``--set`` value as written: an integer, a number, true/false, or a string (quotes
    stripped)."""
    if raw in ("true", "false"):
        return raw == "true"
    try:
        return int(raw)
    except ValueError:
        pass
    try:
        return float(raw)
    except ValueError:
        return raw.strip("'\"")


def quantity(value, name: str = "value", unit: str | None = None):
    """A number, or a string ``"<number> <unit>"`` converted to ``unit`` (the variable's,
    e.g. "N.m/rad"; None: the SI base units kg, m, s, rad) - a unit of another dimension
    is refused (``SceneError``, harness.description.units); other strings as is.
    A table ``{harmonics = "monograph/harmonics_driven.csv", cycle = "mean"}`` becomes
    the load's Fourier series text (file relative to resources/data); so does
    ``{samples = "monograph/torque_driven_7V-14MVS.csv", cycle = "mean"}``, the series
    through a measured torque table's ordinates (harness.studies.measured)."""
    if isinstance(value, dict) and "samples" in value:
        return samples_parameter(value, name)
    if isinstance(value, dict) and "harmonics" in value:
        from lever.physics.load import read_harmonics
        if not isinstance(value["harmonics"], str) or not isinstance(value.get("cycle", "mean"), str):
            raise SceneError(f"{name}: harmonics = {value['harmonics']!r}, cycle = {value.get('cycle')!r}: "
                             "expected a file name and a cycle name (strings)")
        path = DATA / value["harmonics"]
        if not path.is_file():
            raise SceneError(f"{name}: no harmonics file {path}")
        try:
            return read_harmonics(path, value.get("cycle", "mean")).to_text()
        except (ValueError, KeyError, OSError, UnicodeDecodeError) as error:
            raise SceneError(f"{name}: the harmonics file {path} cannot be read ({error})") from None
    if isinstance(value, str) and units.split(value) is not None:
        try:
            return units.convert(value, unit)
        except units.UnitProblem as problem:
            if unit is not None:
                raise SceneError(f"{name} = {value!r}: {problem}") from None
            # no variable to check against here: left as written, and refused by
            # ``value_findings`` if its variable is a number
    return value


def samples_parameter(value: dict, name: str) -> str:
    """A scene's ``fourier = {samples = "<table>.csv", cycle = "mean"}``: the load series
    through a measured table's ordinates (path relative to resources/data)."""
    if not isinstance(value["samples"], str) or not isinstance(value.get("cycle", "mean"), str):
        raise SceneError(f"{name}: samples = {value['samples']!r}, cycle = {value.get('cycle')!r}: expected a "
                         "file name and a cycle name (strings)")
    path = DATA / value["samples"]
    try:
        return load_series(read_table(path), value.get("cycle", "mean")).to_text()
    except MeasuredDataError as error:
        raise SceneError(f"{name}: {error}") from None


def experiment_value(field_name: str, value, label: str):
    """The experiment's field ``field_name`` from a scene's or ``--set``'s ``value``: a time
    (a number in s, or "<number> <time unit>": "500 ms"), the master's name, ``strict``
    (true/false), ``fmi`` (2 or 3) or ``tolerance`` (a number; its range is
    ``experiment_findings``'); ``SceneError`` naming ``label`` and what is allowed otherwise."""
    if field_name == "master":
        if not isinstance(value, str):
            raise SceneError(f"{label} = {units.kind_of_value(value)}: expected the name of a master (a string)")
        return value
    if field_name == "strict":
        if not isinstance(value, bool):
            raise SceneError(f"{label} = {units.kind_of_value(value)}: expected true or false")
        return value
    if field_name == "fmi":
        if not isinstance(value, int) or isinstance(value, bool) or value not in FMI_EDITIONS:
            raise SceneError(f"{label} = {units.kind_of_value(value)}: expected 2 or 3 (the FMI edition of the "
                             "FMUs named by name: 2 in build/fmus, 3 in build/fmus3)")
        return int(value)
    if field_name == "tolerance":
        if not units.is_number(value):
            raise SceneError(f"{label} = {units.kind_of_value(value)}: expected a relative tolerance in (0, 1), "
                             "e.g. 1e-4")
        return float(value)
    if field_name not in EXPERIMENT_TIMES:
        fields = EXPERIMENT_TIMES + ("master", "strict", "fmi", "tolerance")
        raise SceneError(f"{label}: the experiment has no field '{field_name}'{did_you_mean(field_name, fields)} "
                         f"(fields: {', '.join(fields)})")
    if isinstance(value, str):
        value = quantity(value, label, "s")
    if not units.is_number(value):
        raise SceneError(f"{label} = {units.kind_of_value(value)}: expected a time in seconds (a number, "
                         "or a number with a time unit, e.g. '500 ms')")
    return float(value)


def load(name_or_path: str | Path) -> Scene:
    """A scene by name (resources/scenes) or from a .toml file (a variant with what it
    takes from its base, ``read_data``)."""
    if str(name_or_path).endswith(".ssp"):
        raise SceneError(f"{name_or_path}: an SSP archive - read it with harness.formats.ssp.read_scene "
                         "(the lever commands take one as SCENE)")
    path = resolve(name_or_path)
    data = read_data(path)
    if "components" not in data:
        raise SceneError(f"{path}: no [components] table (a scene names its FMUs there)")
    try:
        components = {name: ComponentSpec(spec["fmu"], dict(spec.get("parameters", {})))
                      for name, spec in data["components"].items()}
        connections = [parse_connection(text) for text in data.get("connections", [])]
        experiment = Experiment(**{k: experiment_value(k, v, f"{path.name}: experiment.{k}")
                                   for k, v in data.get("experiment", {}).items()})
    except KeyError as error:
        raise SceneError(f"{path}: malformed scene (missing {error})") from None
    return Scene(name=data.get("name", path.stem), description=data.get("description", ""),
                 components=components, connections=connections, experiment=experiment,
                 record=list(data.get("record", [])), features=set(data.get("features", [])), path=path,
                 notes=data.get("notes", ""), bench=dict(data.get("bench", {})),
                 limits=dict(data.get("limits", {})), validation=dict(data.get("validation", {})))


def parse_connection(text: str) -> Connection:
    try:
        left, right = (s.strip() for s in text.split("->"))
        source, output = left.split(".", 1)
        target, input_ = right.split(".", 1)
    except ValueError:
        raise SceneError(f"connection {text!r}: expected 'component.output -> component.input'") from None
    return Connection(source, output, target, input_)


def validate(scene: Scene, descriptions: dict) -> list[str]:
    """Findings about ``scene`` given the model descriptions of its FMUs (by FMU name).
    Empty when the scene can run."""
    findings = []
    variables = {}
    for name, spec in scene.components.items():
        md = descriptions.get(spec.fmu)
        if md is None and is_fmu_path(spec.fmu):
            findings.append(f"component '{name}': no FMU file {spec.fmu}")
            continue
        if md is None:
            findings.append(f"component '{name}': unknown FMU '{spec.fmu}' (known: {', '.join(descriptions)})")
            continue
        variables[name] = {v.name: v for v in md.modelVariables}
        for param, value in spec.parameters.items():
            var = variables[name].get(param)
            if var is None:
                settable = [v for v, mv in variables[name].items() if mv.causality in ("parameter", "input")]
                findings.append(f"component '{name}': {spec.fmu} has no variable '{param}'"
                                f"{did_you_mean(param, settable)}")
            elif var.causality not in ("parameter", "input"):
                findings.append(f"component '{name}': '{param}' is an {var.causality}, not a parameter or input")
            else:
                findings += value_findings(f"{name}.{param}", var, value)
    driven = {}
    for c in scene.connections:
        for comp, var, causality in ((c.source, c.output, "output"), (c.target, c.input, "input")):
            if comp not in scene.components:
                findings.append(f"connection '{c}': no component '{comp}'")
            elif comp in variables and var not in variables[comp]:
                findings.append(f"connection '{c}': {comp} has no variable '{var}'")
            elif comp in variables and variables[comp][var].causality != causality:
                findings.append(f"connection '{c}': {comp}.{var} is an {variables[comp][var].causality}, "
                                f"expected an {causality}")
        findings += connection_findings(c, variables)
        key = (c.target, c.input)
        if key in driven:
            findings.append(f"connection '{c}': {c.target}.{c.input} is already driven by '{driven[key]}'")
        driven[key] = c
    for item in scene.record:
        comp, _, var = item.partition(".")
        if comp not in scene.components:
            findings.append(f"record '{item}': no component '{comp}'")
        elif comp in variables and var not in variables[comp]:
            findings.append(f"record '{item}': {comp} has no variable '{var}'")
        elif comp in variables and variables[comp][var].causality != "output":
            outputs = ", ".join(v for v, mv in variables[comp].items() if mv.causality == "output")
            findings.append(f"record '{item}': {comp}.{var} is an {variables[comp][var].causality}; only outputs "
                            f"are recorded (outputs of {comp}: {outputs})")
    findings += experiment_findings(scene.experiment)
    if scene.experiment.strict and (unconnected := unconnected_inputs(scene, descriptions)):
        findings.append("experiment.strict: " + unconnected_message(unconnected))
    findings += _check_limits(scene.limits)
    for feature in scene.features - set(FEATURES):
        findings.append(f"unknown feature '{feature}' (known: {', '.join(FEATURES)})")
    return findings


def step_problem(step: float, label: str = "experiment.step") -> str | None:
    """The one check of a communication step (a scene's, ``--step``, a master's): finite
    and > 0 s.  None when it is."""
    if not (math.isfinite(step) and step > 0):
        return f"{label} = {step} must be > 0 s"
    return None


def experiment_findings(e: Experiment) -> list[str]:
    """Findings about an experiment's values (empty when they are sound)."""
    findings = [problem for problem in [step_problem(e.step)] if problem]
    if not math.isfinite(e.start):
        findings.append(f"experiment.start = {e.start} must be a finite time [s]")
    elif not (math.isfinite(e.stop) and e.stop > e.start):
        findings.append(f"experiment.stop = {e.stop} must be > experiment.start = {e.start} s")
    elif e.step > e.stop - e.start:
        findings.append(f"experiment.step = {e.step} s is longer than the experiment ({e.stop - e.start} s)")
    elif e.step > 0 and math.isfinite(e.step) and e.step < TIME_RESOLUTION * max(abs(e.start), abs(e.stop)):
        # a time t holds only ~16 digits: at t = 1e9 s a 1 ms step is lost to rounding in
        # the 7th digit, and every FMU and the reference integrate across steps of that length
        findings.append(f"experiment.start = {e.start:g} s, stop = {e.stop:g} s: a step of {e.step:g} s is below "
                        f"{TIME_RESOLUTION:g} of the time, too fine for the times to resolve (allowed: step >= "
                        f"{TIME_RESOLUTION:g} x max(|start|, |stop|), here "
                        f"{TIME_RESOLUTION * max(abs(e.start), abs(e.stop)):g} s; or start nearer 0)")
    if not 0.0 <= e.transient < e.stop - e.start:
        findings.append(f"experiment.transient = {e.transient} s must be in [0, stop - start)")
    if e.tolerance is not None and not (math.isfinite(e.tolerance) and 0.0 < e.tolerance < 1.0):
        findings.append(f"experiment.tolerance = {e.tolerance} must be in (0, 1) (a relative tolerance)")
    return findings


#: the smallest step relative to the experiment's times (see ``experiment_findings``)
TIME_RESOLUTION = 1e-9


def _check_limits(limits: dict) -> list[str]:
    """The ``[limits]`` table: speed [rad/s], torque [N*m], margin, each > 0 (inf allowed)."""
    findings = []
    for key, raw in limits.items():
        if key not in LIMIT_KEYS:
            findings.append(f"limits.{key}: unknown limit (known: {', '.join(LIMIT_KEYS)})")
            continue
        unit = LIMIT_UNITS[key]
        try:
            value = quantity(raw, f"limits.{key}", unit)
        except SceneError as error:
            findings.append(str(error))
            continue
        if not units.is_number(value):
            findings.append(f"limits.{key} = {units.kind_of_value(raw)}: expected a number in {unit} "
                            "(or inf, or a number with a unit of the same dimension)")
            continue
        if not value > 0.0:
            findings.append(f"limits.{key} = {value:g} must be > 0 (inf: check finiteness only)")
    return findings


#: FMI 3.0's types that carry the same values as FMI 2.0's (a 64-bit float, a 32-bit
#: integer): connected to each other, an FMI 2.0 FMU's with an FMI 3.0 one's
_WIRE = {"Real": "Real", "Float64": "Real", "Integer": "Integer", "Int32": "Integer"}


def connection_findings(c: Connection, variables: dict) -> list[str]:
    """A connection between variables of different quantities (both declare units, of
    different dimensions: a torque into a speed) is a finding; so is one between different
    types.  A side that declares no unit has an unknown unit (FMI): the connection is made
    and ``unchecked_connections`` names it."""
    try:
        out, into = variables[c.source][c.output], variables[c.target][c.input]
    except KeyError:
        return []            # a missing variable is already a finding
    if _WIRE.get(out.type, out.type) != _WIRE.get(into.type, into.type):
        return [f"connection '{c}': {c.source}.{c.output} is a {out.type}, {c.target}.{c.input} a {into.type}"]
    if _WIRE.get(out.type) != "Real":
        return []
    if units.declared_unit(out) is None or units.declared_unit(into) is None:
        return []           # an unknown unit: connected, and named by ``unchecked_connections``
    try:
        same = units.same_dimension(units.declared_unit(out), units.declared_unit(into))
    except units.UnitProblem as problem:
        return [f"connection '{c}': {problem}"]
    if same:
        return []
    what = lambda mv: f"{units.declared_unit(mv)}, {units.dimension(units.declared_unit(mv))}"
    return [f"connection '{c}': {c.source}.{c.output} is a different quantity ({what(out)}) from "
            f"{c.target}.{c.input} ({what(into)}); only variables of the same dimension are connected"]


def unchecked_connections(scene: Scene, descriptions: dict) -> list[str]:
    """The Real connections whose dimension cannot be checked because a side declares no
    unit (an unknown unit in FMI), each as ``"a.x -> b.y (a.x declares no unit)"``."""
    variables = {name: {v.name: v for v in descriptions[spec.fmu].modelVariables}
                 for name, spec in scene.components.items() if spec.fmu in descriptions}
    found = []
    for c in scene.connections:
        try:
            sides = ((f"{c.source}.{c.output}", variables[c.source][c.output]),
                     (f"{c.target}.{c.input}", variables[c.target][c.input]))
        except KeyError:
            continue        # a missing variable is a finding of ``validate``
        if any(_WIRE.get(v.type) != "Real" for _, v in sides):
            continue
        bare = [label for label, v in sides if units.declared_unit(v) is None]
        if bare:
            found.append(f"{c} ({' and '.join(bare)} declare{'s' if len(bare) == 1 else ''} no unit)")
    return found


def unchecked_message(connections: list[str]) -> str:
    """The one sentence naming the connections whose dimension could not be checked."""
    return (f"{len(connections)} connection{'s' if len(connections) > 1 else ''} not checked for dimension, "
            f"a side declaring no unit (an unknown unit in FMI): {'; '.join(connections)}")


def unconnected_inputs(scene: Scene, descriptions: dict) -> list[str]:
    """The inputs (``component.input``) that no connection drives and the scene gives no
    value: they stay at their start value for the whole run.  An input that is the time
    derivative of another input (a shaft's ``tau_rate``: ``fmu_description.time_derivatives``)
    follows that one and is not counted."""
    driven = {(c.target, c.input) for c in scene.connections}
    found = []
    for name, spec in scene.components.items():
        md = descriptions.get(spec.fmu)
        if md is None:
            continue
        rates = time_derivatives(md)
        for v in md.modelVariables:
            if (v.causality == "input" and v.name not in rates and (name, v.name) not in driven
                    and v.name not in spec.parameters):
                found.append(f"{name}.{v.name}")
    return found


def unconnected_message(inputs: list[str]) -> str:
    """The sentence naming the unconnected inputs."""
    return (f"input{'s' if len(inputs) > 1 else ''} {', '.join(inputs)} "
            f"{'are' if len(inputs) > 1 else 'is'} connected to nothing and not set: held at the start value "
            "for the whole run (connect it, give it a value among the component's parameters, or run with "
            "experiment.strict = true / --strict to refuse such a scene)")


def value_findings(label: str, var, value) -> list[str]:
    """Findings about ``value`` for the model variable ``var``: its type (strict: a TOML
    boolean is no number, a fraction no integer, a list, table or date no parameter), its
    unit (a value with a unit must be of the variable's dimension) and its [min, max]."""
    given = units.kind_of_value(value)
    if isinstance(value, dict) and ("samples" in value or "harmonics" in value):
        try:
            value = quantity(value, label)
        except SceneError as error:
            return [str(error)]
    if typed_values.kind(var) != "Real":
        return typed_values.findings(label, var, value, given)
    unit_text = f" {var.unit}" if var.unit else ""
    if isinstance(value, str):
        if units.split(value) is None:
            return [f"{label} = {value!r}: expected a number in{unit_text or ' 1 (no unit)'} or a number with a "
                    f"unit of the same dimension (e.g. '15 deg' for an angle)"]
        try:
            value = units.convert(value, var.unit or "")
        except units.UnitProblem as problem:
            return [f"{label} = {given}: {problem}; {label} is in{unit_text or ' 1 (no unit)'} ({var.description})"]
    if not units.is_number(value):
        return [f"{label} = {given}: expected a number in{unit_text or ' 1 (no unit)'} (or a string with a unit, "
                "e.g. '15 deg')"]
    if not math.isfinite(float(value)):
        return [f"{label} = {value} is not finite"]
    low = float(var.min) if var.min is not None else -math.inf
    high = float(var.max) if var.max is not None else math.inf
    if not low <= float(value) <= high:
        return [f"{label} = {value:.6g}{unit_text} is outside its allowed range [{low:.6g}, {high:.6g}]{unit_text} "
                f"({var.description})"]
    return []
