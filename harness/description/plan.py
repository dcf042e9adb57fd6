"""A scene checked once: what the engine runs and the reference solves.

``check`` turns a loaded scene (and ``--set`` overrides) into a ``Plan``: every finding
made (``refusals``: the scene cannot run; ``unconnected``: inputs held at their start
values), the FMU files and their model descriptions, the start values converted to the
FMUs' units, what a run records, the ``[limits]`` in SI units, the scene's kind, and the
physics objects its reference and divergence bounds are derived from, with the values the
physics checked.  The engine and the monolithic reference take the plan and do not come
back to the scene's checks; judges handed the scene take its driveline's plan
(``driveline_of``, made once per scene object), so a run checks each component's values once.

A plan is made whether or not the scene is sound: a scene with refusals has no start
values, and the physics that could not be built holds the error its building raised
(``Built``), raised again where the physics is used, as it was raised there before the
plan.
"""
from __future__ import annotations

import copy
import weakref
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any, Callable, Mapping


from lever.physics import component_parameters
from lever.physics.parameters import check_all

from harness.description import scene_kinds, typed_values, units
from harness.description.fmu_description import read_description
from harness.description import scene as scenes
from harness.paths import FMUS, fmi3_dir


@dataclass(frozen=True)
class Built:
    """A value built from a scene's values, or the error building it raised (``get``
    raises it again: where the value is used, not where the plan is made)."""
    value: Any = None
    error: Exception | None = None

    def get(self):
        if self.error is not None:
            raise self.error
        return self.value


def _build(make: Callable[[], Any]) -> Built:
    try:
        return Built(make())
    except Exception as error:  # noqa: BLE001 - kept and raised where the value is used
        return Built(error=error)


@dataclass(frozen=True)
class DrivelinePlan:
    """A driveline's physics as its FMUs build them (lever.physics.component_parameters), for the
    monolithic reference and the divergence guard."""
    roles: scene_kinds.Driveline
    #: ``scene_kinds.DrivelinePhysics`` (engine shaft, coupling, load shaft)
    physics: Built
    #: the engine shaft's and the load shaft's values checked against their declarations
    #: (``component_parameters.ENGINE``, ``LOAD``: every parameter, defaults filled in)
    engine: Built
    load: Built
    #: the coupling's checked values and misalignment (``component_parameters.check_coupling``)
    coupling: Built
    #: ``((phi1, w1), (phi2, w2))``: the engine's and the load's start angle and speed
    start: Built
    #: the connection driving the coupling's misalignment input, if one does
    misalignment_driver: scenes.Connection | None
    #: ``(MisalignmentSource, CouplingFamily)`` when a MisalignmentSource's ``misalignment``
    #: drives the coupling, else None
    misalignment: Built


@dataclass(frozen=True)
class RectifierPlan:
    """The freewheel rectifier of a scene: its component, its physics object and the values
    the scene holds its inputs at (``scene_kinds.rectifier_model``, ``scene_kinds.rectifier_inputs``)."""
    name: str
    model: Built
    inputs: Built


@dataclass(frozen=True)
class Plan:
    """A checked scene (see the module docstring); made by ``check`` only."""
    scene: scenes.Scene
    name: str
    #: the scene's experiment (times in s, the master)
    experiment: scenes.Experiment
    fmu_dir: Path
    #: component -> its FMU file
    paths: Mapping[str, Path]
    #: FMU (as the scene names it) -> its fmpy model description, for the files that exist
    descriptions: Mapping[str, Any]
    #: component -> {variable: value in the FMU's unit}, in the scene's order (empty when refused)
    start_values: Mapping[str, Mapping[str, Any]]
    connections: tuple[scenes.Connection, ...]
    #: what a run records: the scene's list and what its features need
    recorded: tuple[str, ...]
    #: findings that refuse the run (``scenes.validate``); empty when the scene can run
    refusals: tuple[str, ...]
    #: inputs no connection drives and the scene gives no value (a warning)
    unconnected: tuple[str, ...]
    #: the ``[limits]`` in rad/s, N*m and 1 (``Built``: a dict)
    limits: Built
    #: ``scene_kinds.kind_of``: "driveline", "rectifier" or None
    kind: str | None
    #: the engine shaft, coupling and load shaft names (None: missing)
    roles: tuple[str | None, str | None, str | None]
    #: the driveline's physics, when the scene has the engine - coupling - load chain
    driveline: DrivelinePlan | None
    #: why the standard driveline's reference and energy balance do not describe the scene
    #: (``scene_kinds.driveline_problem``; None: they do, and ``driveline`` is set)
    driveline_problem: str | None
    #: the freewheel rectifier, when the scene has one
    rectifier: RectifierPlan | None
    #: connections whose dimension could not be checked: a side declares no unit
    #: (``scenes.unchecked_connections``; a note, not a refusal)
    unchecked: tuple[str, ...] = ()



def fmu_path(fmu: str, fmu_dir: Path = FMUS, fmi: int = 2) -> Path:
    """The file of a component's ``fmu``: a path as given (``X.fmu``), a name in ``fmu_dir``
    (its FMI 3.0 edition, ``fmi`` 3: in ``harness.paths.fmi3_dir(fmu_dir)``)."""
    if scenes.is_fmu_path(fmu):
        return Path(fmu)
    return (fmi3_dir(fmu_dir) if fmi == 3 else Path(fmu_dir)) / f"{fmu}.fmu"


def descriptions_for(scene: scenes.Scene, fmu_dir: Path = FMUS) -> dict:
    """The model descriptions of the scene's FMUs (by FMU as the scene names it) whose files
    exist (the edition ``scene.experiment.fmi`` of those named by name)."""
    out = {}
    for spec in scene.components.values():
        path = fmu_path(spec.fmu, fmu_dir, scene.experiment.fmi)
        if spec.fmu not in out and path.exists():
            out[spec.fmu] = read_description(path)
    return out


def converted(var, value, label: str):
    """A scene's ``value`` for the model variable ``var`` as the FMU takes it: a number with
    a unit converted to the variable's unit (``scenes.validate`` has checked its dimension),
    a harmonics or samples table to its text; other values as they are."""
    real = typed_values.kind(var) == "Real"
    if real or isinstance(value, dict):
        return scenes.quantity(value, label, (var.unit or "") if real else None)
    return value


def recorded_names(scene: scenes.Scene) -> list[str]:
    """What a run records: the scene's list, plus what its features need."""
    names = list(scene.record)
    if "energy_balance" in scene.features:
        names += [n for n in scene_kinds.energy_variables(scene) if n not in names]
    return names


def check(scene: scenes.Scene, overrides=(), fmu_dir: Path = FMUS) -> Plan:
    """The ``Plan`` of ``scene`` with the ``--set`` ``overrides`` applied (``SceneError``
    for an override that names nothing), its FMUs in ``fmu_dir`` (or at their paths)."""
    if overrides:
        scene = scene.with_overrides(list(overrides))
    descriptions = descriptions_for(scene, fmu_dir)
    refusals = tuple(scenes.validate(scene, descriptions))
    start_values = {}
    if not refusals:
        for name, spec in scene.components.items():
            variables = {v.name: v for v in descriptions[spec.fmu].modelVariables}
            start_values[name] = MappingProxyType(
                {k: converted(variables[k], v, f"{name}.{k}") for k, v in spec.parameters.items()})
    rectifier = scene_kinds.rectifier(scene)
    return Plan(scene=scene, name=scene.name, experiment=scene.experiment, fmu_dir=Path(fmu_dir),
                paths=MappingProxyType({n: fmu_path(c.fmu, fmu_dir, scene.experiment.fmi)
                                        for n, c in scene.components.items()}),
                descriptions=MappingProxyType(descriptions), start_values=MappingProxyType(start_values),
                connections=tuple(scene.connections), recorded=tuple(recorded_names(scene)), refusals=refusals,
                unconnected=tuple(scenes.unconnected_inputs(scene, descriptions)),
                unchecked=tuple(scenes.unchecked_connections(scene, descriptions)),
                limits=_build(lambda: MappingProxyType({k: float(scenes.quantity(v, f"limits.{k}"))
                                                        for k, v in scene.limits.items()})), kind=scene_kinds.kind_of(scene), roles=scene_kinds.roles(scene),
                driveline=driveline_of(scene) if scene_kinds.is_driveline(scene) else None,
                driveline_problem=scene_kinds.driveline_problem(scene),
                rectifier=RectifierPlan(rectifier, _build(lambda: scene_kinds.rectifier_model(scene)),
                                        _build(lambda: scene_kinds.rectifier_inputs(scene))) if rectifier else None)


#: ``driveline_of``'s plans: id(scene) -> (a weak reference to the scene, what its plan was made from, the plan)
_DRIVELINES: dict[int, tuple[weakref.ref, Any, DrivelinePlan]] = {}


def _made_from(scene: scenes.Scene):
    """What a scene's driveline plan is made from: a scene changed since is planned anew."""
    return copy.deepcopy(({n: (c.fmu, c.parameters) for n, c in scene.components.items()}, scene.connections))


def driveline_of(scene: scenes.Scene) -> DrivelinePlan:
    """The driveline's physics of ``scene`` (``scene_kinds.NotADriveline`` for another kind),
    made once for the scene object: the plan and the judges handed the scene (the stability
    advice, the energy balance) read the same, each component's values checked once."""
    made_from = _made_from(scene)
    held = _DRIVELINES.get(id(scene))
    if held is not None and held[0]() is scene and held[1] == made_from:
        return held[2]
    driveline = _driveline(scene)
    key = id(scene)
    _DRIVELINES[key] = (weakref.ref(scene, lambda _: _DRIVELINES.pop(key, None)), made_from, driveline)
    return driveline


def _driveline(scene: scenes.Scene) -> DrivelinePlan:
    names = scene_kinds.driveline(scene)
    driver = next((c for c in scene.connections if c.target == names.coupling and c.input == "misalignment"), None)
    engine = _build(lambda: check_all(component_parameters.ENGINE, scene_kinds.parameters(scene, names.engine)))
    coupling = _build(lambda: component_parameters.check_coupling(scene_kinds.parameters(scene, names.coupling)))
    load = _build(lambda: check_all(component_parameters.LOAD, scene_kinds.parameters(scene, names.load)))

    def physics():
        return scene_kinds.DrivelinePhysics(names, component_parameters.engine_of(engine.get()),
                                            component_parameters.coupling_of(*coupling.get()),
                                            component_parameters.load_of(load.get()))

    def start():
        return ((engine.get()["phi_start"], engine.get()["w_start"]),
                (load.get()["phi_start"], load.get()["w_start"]))

    def misalignment():
        if (driver is None or scenes.fmu_name(scene.components[driver.source].fmu) != "MisalignmentSource"
                or driver.output != "misalignment"):
            return None
        return (component_parameters.misalignment_source_from(scene_kinds.parameters(scene, driver.source)),
                component_parameters.coupling_family_of(*coupling.get()))

    return DrivelinePlan(names, _build(physics), engine, load, coupling, _build(start), driver, _build(misalignment))


#: where a run's parameter value came from (``parameter_record``)
FROM_SET, FROM_SCENE, FROM_DEFAULT = "--set", "scene file", "default"


def _shown(value) -> str:
    """A parameter's value as a report shows it: a number as written, a quantity with its
    unit ("20 deg"), a table (a Fourier series, measured samples) by what it is."""
    if isinstance(value, dict):
        return "table (" + ", ".join(sorted(value)) + ")"
    if isinstance(value, float):
        return f"{value:.9g}"
    return str(value)


def parameter_record(scene: scenes.Scene, fmu_dir: Path = FMUS) -> dict[str, dict]:
    """Every parameter a run of ``scene`` sets or leaves to its FMU, by ``component.name``:
    its ``value`` (as given, with its unit), and where it came from (``source``: ``--set``,
    the scene file, or the FMU's default, its start value in the model description), and
    the experiment's fields the run changed with ``--set`` (``experiment.stop``, ...)."""
    record = {}
    descriptions = descriptions_for(scene, fmu_dir)
    for name, spec in scene.components.items():
        description = descriptions.get(spec.fmu)
        parameters = [v for v in description.modelVariables if v.causality == "parameter"] if description else []
        for var in parameters:
            key = f"{name}.{var.name}"
            unit = units.declared_unit(var)
            if var.name in spec.parameters:
                source = FROM_SET if key in scene.overrides else FROM_SCENE
                value = spec.parameters[var.name]
                shown = _shown(value) + (f" {unit}" if unit and isinstance(value, (int, float))
                                         and not isinstance(value, bool) else "")
                record[key] = {"value": shown, "source": source}
            else:
                record[key] = {"value": f"{var.start}{' ' + unit if unit and var.start is not None else ''}",
                               "source": FROM_DEFAULT}
        for param, value in spec.parameters.items():        # a value the description does not list
            record.setdefault(f"{name}.{param}", {"value": _shown(value),
                                                   "source": FROM_SET if f"{name}.{param}" in scene.overrides
                                                   else FROM_SCENE})
    for key, raw in scene.overrides.items():
        if not key.split(".", 1)[0] in scene.components:
            record[key] = {"value": raw, "source": FROM_SET}
    return record


def overridden(record: dict) -> dict[str, str]:
    """The ``--set`` values of a ``parameter_record``: name -> value."""
    return {k: v["value"] for k, v in record.items() if v["source"] == FROM_SET}
