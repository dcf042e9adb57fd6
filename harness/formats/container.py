"""A scene as one FMU: fmpy's container FMU (``fmpy.container_fmu``) holding the scene's
FMUs, wired as the scene says, usable as one block in a larger co-simulation.

The container is fmpy's native FMU (FMI 2.0 co-simulation, ``container_fmu.so``): at
each of its fixed internal steps it steps every component and then copies the
connected values in the order of the connections, which we give as the harness
propagates (shaft states to the coupling, then the coupling's torques to the shafts):
the container computes what the harness's ``jacobi`` master computes.  It exposes the
scene's recorded outputs, and the scene's parameter values are its start values.
fmpy's container cannot get or set its state, so it does not declare it.

Our components run Python inside the container's process (pythonfmu); a host loading
the container needs what any of our FMUs needs (README, "Host requirements").
"""
from __future__ import annotations

import json
import re
import shutil
import tempfile
import uuid
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

from harness.description import scene as scenes
from harness.description import typed_values
from harness.paths import FMUS
from harness.description.plan import converted, descriptions_for, fmu_path
from harness.engine.system import SceneInvalid, dependency_order, feedthrough_components


def container_name(item: str) -> str:
    """The container FMU's variable name for the scene's ``component.variable``."""
    return re.sub(r"[^A-Za-z0-9_]", "_", item)


def build_container(scene: scenes.Scene, out: Path, fmu_dir: Path = FMUS) -> Path:
    """Write ``scene`` as the container FMU ``out``; return its path."""
    from fmpy.container_fmu import Configuration
    from fmpy.container_fmu.cli import create_container_fmu
    from fmpy.container_fmu.config import Component, Connection
    from fmpy.model_description import CoSimulation, DefaultExperiment, ModelDescription, ModelVariable, Unknown

    descriptions = descriptions_for(scene, fmu_dir)
    findings = scenes.validate(scene, descriptions)
    if findings:
        raise SceneInvalid(scene.name, findings)
    e = scene.experiment
    components = {name: Component(name=name, filename=fmu_path(spec.fmu, fmu_dir, e.fmi), modelDescription=descriptions[spec.fmu])
                  for name, spec in scene.components.items()}
    variables = {name: {v.name: v for v in descriptions[spec.fmu].modelVariables}
                 for name, spec in scene.components.items()}
    # Connections in propagation order: the sources without feedthrough first.
    order = dependency_order(scene, feedthrough_components(
        scene, {n: descriptions[s.fmu] for n, s in scene.components.items()}))
    connections = [Connection(startElement=components[c.source], startConnectors=[variables[c.source][c.output]],
                              endElement=components[c.target], endConnectors=[variables[c.target][c.input]])
                   for source in order for c in scene.connections if c.source == source]
    model_variables, mappings = [], {}
    for name, spec in scene.components.items():
        for param, raw in spec.parameters.items():
            inner = variables[name][param]
            label = f"{name}.{param}"
            _, start = typed_values.literal(inner, converted(inner, raw, label), label)
            outer = ModelVariable(name=container_name(f"{name}.{param}"), type=inner.type, causality="parameter",
                                  variability="fixed", initial="exact", description=f"{name}: {inner.description}")
            outer.start = start
            outer.unit = inner.unit
            model_variables.append(outer)
            mappings[outer] = [(components[name], inner)]
    for item in scene.record:
        comp, _, var = item.partition(".")
        inner = variables[comp][var]
        outer = ModelVariable(name=container_name(item), type="Real", causality="output", variability="continuous",
                              initial="calculated", description=f"{comp}: {inner.description}")
        outer.unit = inner.unit
        model_variables.append(outer)
        mappings[outer] = [(components[comp], inner)]
    # The components' units and types, once each: every container variable keeps its
    # component variable's unit and type.
    units, types = {}, {}
    for description in descriptions.values():
        units.update({u.name: u for u in description.unitDefinitions})
        types.update({t.name: t for t in description.typeDefinitions})
    for outer, [(component, inner)] in mappings.items():
        if inner.declaredType is not None:
            outer.declaredType = types[inner.declaredType.name]
    md = ModelDescription(fmiVersion="2.0", modelName=f"{scene.name}_container",
                          instantiationToken="{" + str(uuid.uuid4()) + "}",
                          description=f"container FMU of scene {scene.name}: {scene.description}",
                          generationTool="lever-cosim (fmpy container_fmu)",
                          coSimulation=CoSimulation(modelIdentifier="container_fmu", fixedInternalStepSize=e.step,
                                                    canHandleVariableCommunicationStepSize=True),
                          defaultExperiment=DefaultExperiment(startTime=str(e.start), stopTime=str(e.stop),
                                                              stepSize=str(e.step)),
                          modelVariables=model_variables, unitDefinitions=list(units.values()),
                          typeDefinitions=list(types.values()))
    md.outputs = [Unknown(variable=v, dependencies=[]) for v in model_variables if v.causality == "output"]
    md.initialUnknowns = [Unknown(variable=v, dependencies=[]) for v in model_variables if v.causality == "output"]
    config = Configuration(parallelDoStep=False, modelDescription=md, components=list(components.values()),
                           connections=connections, variableMappings=mappings)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix="lever-container-"))
    try:
        (work / "unzipped").mkdir()
        create_container_fmu(config, work / "unzipped", out)
        _repair(out)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return out


#: FMI 2 type names -> the container's (fmpy 0.3.32 writes FMI 2 connection types as they
#: are, which its container binary does not read: "unknown variant `Real`")
_CONTAINER_TYPES = {"Real": "Float64", "Integer": "Int32", "Enumeration": "Int32"}


def _repair(fmu: Path):
    """Fix what fmpy 0.3.32's ``create_container_fmu`` writes wrong: FMI 2 type names in
    the connections of ``resources/container.json``; value references from 0, where its
    container binary keeps 0 for the time and numbers the variables from 1 (unrepaired,
    reading a variable gives the one before it); and an empty ``Container.zip`` (the
    archive packed into itself)."""
    tmp = fmu.with_name(fmu.name + ".tmp")
    with zipfile.ZipFile(fmu) as source, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as target:
        for info in source.infolist():
            if info.filename == "Container.zip":
                continue
            data = source.read(info)
            if info.filename == "resources/container.json":
                config = json.loads(data)
                for connection in config["connections"]:
                    connection["variableType"] = _CONTAINER_TYPES.get(connection["variableType"],
                                                                      connection["variableType"])
                data = json.dumps(config, indent=1).encode()
            elif info.filename == "modelDescription.xml":
                root = ET.fromstring(data)
                for variable in root.iter("ScalarVariable"):
                    variable.set("valueReference", str(int(variable.get("valueReference")) + 1))
                data = ET.tostring(root, encoding="utf-8", xml_declaration=True)
            target.writestr(info, data)
    tmp.replace(fmu)
