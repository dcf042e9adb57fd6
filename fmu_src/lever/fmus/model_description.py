"""The model description (modelDescription.xml) an adapter's declarations give: pythonfmu's,
with the units, type definitions, ranges and output dependencies it leaves out."""
from __future__ import annotations

import math
from xml.etree.ElementTree import Element, SubElement

from ..physics.parameters import DISPLAY_UNITS, QUANTITIES, UNITS, Parameter
from .declarations import Output
from .values import closed_bounds

#: The tool name of our vendor annotation (FMI 2.0 ``<VendorAnnotations><Tool name=...>``,
#: FMI 3.0 ``<Annotations><Annotation type=...>``), docs/fmus.md.  It carries the
#: time-derivative relations that are not state derivatives ("Time derivatives": importers
#: count a continuous state for every ``derivative`` attribute, so the attribute marks state
#: derivatives only) and names the resource file of configured start values.
ANNOTATION_TOOL = "lever-cosim"
#: The resource (under ``resources/``) from which an FMU takes its parameters' and inputs'
#: start values when it holds one: ``{name: value}`` in JSON, written with a model
#: description whose start values and GUID match ("Configured start values", docs/fmus.md).
START_VALUES_RESOURCE = "lever_start_values.json"


def lever_annotation(relations: dict) -> Element:
    """The one element of our annotation: ``<LeverFmu startValues=...>`` with a
    ``<TimeDerivative variable=... of=...>`` for each item of ``relations`` ({variable: the
    variable it is the time derivative of})."""
    element = Element("LeverFmu", {"startValues": f"resources/{START_VALUES_RESOURCE}"})
    for name, of in relations.items():
        SubElement(element, "TimeDerivative", {"variable": name, "of": of})
    return element


def declared_type(spec) -> tuple[str, str, dict]:
    """The FMI type definition a declared variable refers to: (type name, FMI type
    element, attributes of that element)."""
    kind = getattr(spec, "kind", "real")
    if kind == "real":
        unit = spec.unit or "1"
        quantity = QUANTITIES[unit]
        attrs = {"quantity": quantity}
        if unit != "1":
            attrs["unit"] = unit
            if unit in DISPLAY_UNITS:
                attrs["displayUnit"] = DISPLAY_UNITS[unit]
        return quantity, "Real", attrs
    if kind == "integer":
        return camel_case(spec.name), "Integer", {"quantity": camel_case(spec.name)}
    if spec.choices:
        return camel_case(spec.name), "String", {}
    return "PointTable", "String", {}


def camel_case(name: str) -> str:
    return "".join(part.capitalize() for part in name.split("_"))


class ModelDescription:
    """``to_xml`` of a ``LeverSlave`` (its ``_declared``, ``INPUTS``, ``OUTPUTS``, ``FEEDTHROUGH``)."""

    @classmethod
    def dependencies(cls, output: Output) -> list[str]:
        """The inputs ``output`` depends on directly (its ``depends_on``, else all inputs
        with direct feedthrough, none without)."""
        if output.depends_on is not None:
            return list(output.depends_on)
        return [p.name for p in cls.INPUTS] if cls.FEEDTHROUGH else []

    def to_xml(self, model_options=None) -> Element:
        """pythonfmu's description plus what it leaves out: units (with display units),
        min/max of parameters and inputs, and the output dependencies (outputs depend on
        the inputs only where the element has direct feedthrough)."""
        root = super().to_xml(model_options or {})
        # The FMU loads its Python runtime itself (build/shim): no tool has to be started
        # for it, which is what needsExecutionTool="true" would tell an importer.
        root.find("CoSimulation").set("needsExecutionTool", "false")
        used = sorted({spec.unit for spec in self._declared.values() if spec.unit not in ("", "1")})
        units = Element("UnitDefinitions")
        for name in used:
            define_unit(units, name)
        position = list(root).index(root.find("CoSimulation")) + 1
        root.insert(position, units)
        # One type definition per quantity (and per kind of string), as the Reference-FMUs
        # do; every variable refers to its type.
        types = Element("TypeDefinitions")
        seen = {}
        for spec in self._declared.values():
            name, element, attrs = declared_type(spec)
            if name in seen:
                continue
            seen[name] = True
            description = {"PointTable": "a table of points as text, 'x:y; x:y; ...'"}.get(name)
            if getattr(spec, "choices", None):
                description = "one of " + ", ".join(repr(c) for c in spec.choices)
            simple = SubElement(types, "SimpleType", {"name": name, **({"description": description}
                                                                        if description else {})})
            SubElement(simple, element, attrs)
        root.insert(position + 1, types)

        nodes = root.find("ModelVariables").findall("ScalarVariable")
        index_of = {node.get("name"): i for i, node in enumerate(nodes, start=1)}
        for node in nodes:
            name = node.get("name")
            spec = self._declared.get(name)
            typed = node[0]
            if spec is None:
                continue
            typed.set("declaredType", declared_type(spec)[0])
            if typed.tag not in ("Real", "Integer"):
                continue
            if typed.tag == "Real" and spec.unit not in ("", "1"):
                typed.set("unit", spec.unit)
                if spec.unit in DISPLAY_UNITS:
                    typed.set("displayUnit", DISPLAY_UNITS[spec.unit])
            if isinstance(spec, Parameter):
                # FMI's min and max are inclusive: an open bound is declared as the nearest
                # double inside it, so that the declaration says exactly what is accepted
                as_text = repr if typed.tag == "Real" else (lambda x: str(int(x)))
                low, high = closed_bounds(spec)
                if math.isfinite(spec.low):
                    typed.set("min", as_text(low))
                if math.isfinite(spec.high):
                    typed.set("max", as_text(high))

        relations = {name: spec.derivative_of for name, spec in self._declared.items()
                     if getattr(spec, "derivative_of", "")}
        vendor = Element("VendorAnnotations")
        SubElement(vendor, "Tool", {"name": ANNOTATION_TOOL}).append(lever_annotation(relations))
        root.insert(list(root).index(root.find("ModelVariables")), vendor)

        structure = root.find("ModelStructure")
        for child in list(structure):
            structure.remove(child)
        outputs = SubElement(structure, "Outputs")
        initial = SubElement(structure, "InitialUnknowns")
        for o in self.OUTPUTS:
            sources = self.dependencies(o)
            attrs = {"index": str(index_of[o.name]), "dependencies": " ".join(str(index_of[n]) for n in sources)}
            if sources:
                attrs["dependenciesKind"] = " ".join("dependent" for _ in sources)
            SubElement(outputs, "Unknown", attrs)
            SubElement(initial, "Unknown", dict(attrs))
        return root


def define_unit(units: Element, name: str):
    """``name``'s <Unit> (its SI base-unit exponents, and its display unit if it has one)
    in ``units``, the <UnitDefinitions> element."""
    exponents, _ = UNITS[name]
    unit = SubElement(units, "Unit", {"name": name})
    SubElement(unit, "BaseUnit", {k: str(v) for k, v in exponents.items()})
    if name in DISPLAY_UNITS:
        display = DISPLAY_UNITS[name]
        SubElement(unit, "DisplayUnit", {"name": display, "factor": repr(1.0 / UNITS[display][1])})
