"""The OSP Interface Specification side of a scene: the variable groups our FMUs declare
in ``<Model>_OspModelDescription.xml`` (written by the build next to each FMU), which of
the scene's connections they cover, the power bonds they make, and the scene as an
``OspSystemStructure.xml`` that libcosim loads (its connections flange to flange:
``VariableGroupConnection``).
"""
from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

from harness.description import scene as scenes
from harness.description import typed_values
from harness.paths import FMUS
from harness.description.plan import converted, fmu_path

SYSTEM_NAMESPACE = "http://opensimulationplatform.com/MSMI/OSPSystemStructure"
#: OSP-IS bond groups: kind -> (effort group, flow group)
BOND_KINDS = {"AngularMechanicalPort": ("Torque", "AngularVelocity"),
              "LinearMechanicalPort": ("Force", "LinearVelocity")}


@dataclass(frozen=True)
class Group:
    """A top-level variable group: its kind (``AngularMechanicalPort``, ...), name, and
    its variables in declaration order (nested groups flattened)."""
    kind: str
    name: str
    variables: tuple[str, ...]


def description_path(fmu: Path) -> Path:
    return fmu.with_name(f"{fmu.stem}_OspModelDescription.xml")


def read_groups(path: Path) -> list[Group]:
    """The top-level variable groups of an OSP model description."""
    def local(tag):
        return tag.rsplit("}", 1)[-1]

    root = ET.parse(path).getroot()
    groups = next((g for g in root if local(g.tag) == "VariableGroups"), None)
    if groups is None:
        return []
    return [Group(local(g.tag), g.get("name"),
                  tuple(v.get("ref") for v in g.iter() if local(v.tag) == "Variable"))
            for g in groups]


def scene_groups(scene: scenes.Scene, fmu_dir: Path = FMUS) -> dict[str, list[Group]]:
    """Component -> its FMU's variable groups (empty when the FMU has no OSP description)."""
    out = {}
    for name, spec in scene.components.items():
        path = description_path(fmu_path(spec.fmu, fmu_dir, scene.experiment.fmi))
        out[name] = read_groups(path) if path.exists() else []
    return out


@dataclass(frozen=True)
class GroupConnection:
    a: str
    a_group: Group
    b: str
    b_group: Group
    #: the scene's connections this group connection stands for
    connections: tuple[scenes.Connection, ...]


def group_connections(scene: scenes.Scene, groups: dict[str, list[Group]]) \
        -> tuple[list[GroupConnection], list[scenes.Connection]]:
    """The group connections that carry the scene's connections (two groups of the same
    kind whose variables are connected pairwise, either way), and the connections no
    group covers."""
    by_pair = {}
    for c in scene.connections:
        by_pair[(c.source, c.output, c.target, c.input)] = c
        by_pair[(c.target, c.input, c.source, c.output)] = c
    found, covered = [], set()
    names = list(scene.components)
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            for ga in groups.get(a, []):
                for gb in groups.get(b, []):
                    if ga.kind != gb.kind or len(ga.variables) != len(gb.variables) or not ga.variables:
                        continue
                    pairs = [by_pair.get((a, va, b, vb)) for va, vb in zip(ga.variables, gb.variables)]
                    if all(pairs) and not covered.intersection(pairs):
                        found.append(GroupConnection(a, ga, b, gb, tuple(pairs)))
                        covered.update(pairs)
    return found, [c for c in scene.connections if c not in covered]


def power_bonds(scene: scenes.Scene, groups: dict[str, list[Group]]) -> list[tuple[str, str, str, str, str, str]]:
    """The power bonds of the scene's port connections, as ``harness.peers.libcosim`` hands them to
    libcosim's ECCO: ``(a, a_effort_input, a_flow_output, b, b_effort_output,
    b_flow_input)`` where ``a`` takes the effort (torque) and gives the flow (speed)."""
    bonds = []
    for gc in group_connections(scene, groups)[0]:
        if gc.a_group.kind not in BOND_KINDS:
            continue
        effort_a, flow_a = gc.a_group.variables
        effort_b, flow_b = gc.b_group.variables
        effort = next(c for c in gc.connections if {(c.source, c.output), (c.target, c.input)}
                      == {(gc.a, effort_a), (gc.b, effort_b)})
        if effort.target == gc.a:      # a takes the torque
            bonds.append((gc.a, effort_a, flow_a, gc.b, effort_b, flow_b))
        else:
            bonds.append((gc.b, effort_b, flow_b, gc.a, effort_a, flow_a))
    return bonds


def system_structure(scene: scenes.Scene, fmu_dir: Path = FMUS) -> str:
    """The scene as an ``OspSystemStructure.xml`` (FMUs by absolute path, so the file may
    be written anywhere): parameters as initial values, connections flange to flange
    where the FMUs declare ports, variable to variable elsewhere."""
    from harness.description.plan import descriptions_for

    descriptions = descriptions_for(scene, fmu_dir)
    root = ET.Element("OspSystemStructure", {"xmlns": SYSTEM_NAMESPACE, "version": "0.1"})
    ET.SubElement(root, "StartTime").text = repr(float(scene.experiment.start))
    ET.SubElement(root, "BaseStepSize").text = repr(float(scene.experiment.step))
    ET.SubElement(root, "Algorithm").text = "fixedStep"
    simulators = ET.SubElement(root, "Simulators")
    for name, spec in scene.components.items():
        simulator = ET.SubElement(simulators, "Simulator", {
            "name": name, "source": str(fmu_path(spec.fmu, fmu_dir, scene.experiment.fmi).resolve())})
        if spec.parameters:
            variables = {v.name: v for v in descriptions[spec.fmu].modelVariables}
            initial = ET.SubElement(simulator, "InitialValues")
            for param, raw in spec.parameters.items():
                label = f"{name}.{param}"
                kind, text = typed_values.literal(variables[param], converted(variables[param], raw, label), label)
                ET.SubElement(ET.SubElement(initial, "InitialValue", {"variable": param}), kind, {"value": text})
    connections = ET.SubElement(root, "Connections")
    covered, rest = group_connections(scene, scene_groups(scene, fmu_dir))
    for c in rest:
        connection = ET.SubElement(connections, "VariableConnection")
        ET.SubElement(connection, "Variable", {"simulator": c.source, "name": c.output})
        ET.SubElement(connection, "Variable", {"simulator": c.target, "name": c.input})
    for gc in covered:
        connection = ET.SubElement(connections, "VariableGroupConnection")
        ET.SubElement(connection, "VariableGroup", {"simulator": gc.a, "name": gc.a_group.name})
        ET.SubElement(connection, "VariableGroup", {"simulator": gc.b, "name": gc.b_group.name})
    ET.indent(root)
    return '<?xml version="1.0" encoding="utf-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"
