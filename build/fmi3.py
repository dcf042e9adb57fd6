"""The FMI 3.0 edition of an FMU, made from its FMI 2.0 edition (build/fmus.py calls
``make_fmu3`` for each model; the result lands in ``build/fmus3/<Model>.fmu``).

Both editions run the same Python adapter, the same pythonfmu library and the same FMI 2.0
entry (build/shim/lever_fmi2_shim.c); the FMI 3.0 entry (build/shim/lever_fmi3_shim.c) is
a layer in front of them.  The FMI 3.0 model description is the FMI 2.0 one -- written from
the adapter's declarations (lever.fmus.model_description, lever.fmus.me_description) --
translated element by element, so both editions declare the same variables with the same
value references, units, ranges and dependencies:

* ``ScalarVariable``/``Real`` -> ``Float64``, ``Integer`` -> ``Int32``, ``Boolean``,
  ``String`` (start as a ``<Start value=...>`` child); ``derivative`` names the value
  reference instead of the index; ``VendorAnnotations``/``Tool`` -> ``Annotations``/``Annotation``
  (last); ``SimpleType`` -> ``Float64Type``/``Int32Type``/...;
* FMI 3.0 asks for one independent variable: ``time`` (the next free value reference);
* event indicators are variables in FMI 3.0: ``event_indicator_<k>``, after ``time``, local
  and readable in both interfaces (FMI 3.0 ignores only the ``EventIndicator`` elements in
  Co-Simulation);
* ``ModelStructure``: ``Output``, ``ContinuousStateDerivative``, ``InitialUnknown``,
  ``EventIndicator`` with dependencies as value references.

What the FMI 3.0 entry must know of this (the value references of ``time`` and of the
event indicators, the numbers of states and indicators, the dependencies) it reads from
``resources/lever_fmi3.cfg``, written here from the same translation.
"""
from __future__ import annotations

import os
import tempfile
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

#: FMI 3.0's platform tuple for the binaries (FMI 2.0: linux64)
PLATFORM_DIR = "binaries/x86_64-linux"
#: the FMI 2.0 entry inside the FMI 3.0 FMU; must match INNER_LIBRARY_NAME in lever_fmi3_shim.c
FMI2_ENTRY_NAME = "lever-fmi2-entry.so"
#: must match CONFIG_NAME in lever_fmi3_shim.c
CONFIG_NAME = "resources/lever_fmi3.cfg"

_TYPES = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean", "String": "String"}
_TYPE_ATTRIBUTES = ("declaredType", "quantity", "unit", "displayUnit", "min", "max", "nominal")


def translate(fmi2_xml: bytes) -> tuple[str, str]:
    """(FMI 3.0 modelDescription.xml, text of resources/lever_fmi3.cfg) from the FMI 2.0
    model description of one of our FMUs."""
    src = ET.fromstring(fmi2_xml)
    cs2, me2 = src.find("CoSimulation"), src.find("ModelExchange")
    identifier = cs2.get("modelIdentifier")
    root = ET.Element("fmiModelDescription", {
        "fmiVersion": "3.0", "modelName": src.get("modelName"), "instantiationToken": src.get("guid"),
        "description": src.get("description", ""), "author": src.get("author", ""),
        "version": src.get("version", ""), "license": src.get("license", ""),
        "generationTool": f"lever-cosim build/fmi3.py from {src.get('generationTool')}",
        "generationDateAndTime": src.get("generationDateAndTime", ""),
        "variableNamingConvention": src.get("variableNamingConvention", "structured")})
    common = {"modelIdentifier": identifier, "needsExecutionTool": cs2.get("needsExecutionTool", "false"),
              "canBeInstantiatedOnlyOncePerProcess": "false", "providesDirectionalDerivatives": "true",
              "providesAdjointDerivatives": "true", "providesPerElementDependencies": "false"}
    if me2 is not None:
        ET.SubElement(root, "ModelExchange", {**common, "canGetAndSetFMUState": "false",
                                              "canSerializeFMUState": "false",
                                              "needsCompletedIntegratorStep": "false",
                                              "providesEvaluateDiscreteStates": "false"})
    ET.SubElement(root, "CoSimulation", {
        **common, "canGetAndSetFMUState": cs2.get("canGetAndSetFMUstate", "false"),
        "canSerializeFMUState": cs2.get("canSerializeFMUstate", "false"),
        "canHandleVariableCommunicationStepSize": cs2.get("canHandleVariableCommunicationStepSize", "true"),
        "maxOutputDerivativeOrder": "1", "providesIntermediateUpdate": "false",
        "mightReturnEarlyFromDoStep": "false", "canReturnEarlyAfterIntermediateUpdate": "false",
        "hasEventMode": "false", "providesEvaluateDiscreteStates": "false"})

    units = src.find("UnitDefinitions")
    units = ET.fromstring(ET.tostring(units)) if units is not None else ET.Element("UnitDefinitions")
    if not any(u.get("name") == "s" for u in units):
        unit = ET.SubElement(units, "Unit", {"name": "s"})
        ET.SubElement(unit, "BaseUnit", {"s": "1"})
    root.append(units)

    types = ET.SubElement(root, "TypeDefinitions")
    for simple in src.iterfind("TypeDefinitions/SimpleType"):
        base = simple[0]
        attrs = {"name": simple.get("name")}
        if simple.get("description"):
            attrs["description"] = simple.get("description")
        attrs.update({k: base.get(k) for k in ("quantity", "unit", "displayUnit", "min", "max") if base.get(k)})
        ET.SubElement(types, _TYPES[base.tag] + "Type", attrs)

    categories = ET.SubElement(root, "LogCategories")
    for category in src.iterfind("LogCategories/Category"):
        ET.SubElement(categories, "Category", {
            "name": category.get("name"),
            "description": category.get("description", "").replace("fmi2", "fmi3")})
    experiment = src.find("DefaultExperiment")
    if experiment is not None:
        ET.SubElement(root, "DefaultExperiment", dict(experiment.attrib))

    variables = ET.SubElement(root, "ModelVariables")
    scalars = src.findall("ModelVariables/ScalarVariable")
    vr_of_index = {i: s.get("valueReference") for i, s in enumerate(scalars, start=1)}
    next_vr = max(int(s.get("valueReference")) for s in scalars) + 1
    time_vr = next_vr
    ET.SubElement(variables, "Float64", {
        "name": "time", "valueReference": str(time_vr), "causality": "independent",
        "variability": "continuous", "unit": "s", "description": "simulation time (the independent variable)"})
    for s in scalars:
        typed = s[0]
        attrs = {k: s.get(k) for k in ("name", "valueReference", "description", "causality", "variability",
                                       "initial") if s.get(k) is not None}
        attrs.update({k: typed.get(k) for k in _TYPE_ATTRIBUTES if typed.get(k) is not None})
        if typed.get("derivative") is not None:
            attrs["derivative"] = vr_of_index[int(typed.get("derivative"))]
        start = typed.get("start")
        element = ET.SubElement(variables, _TYPES[typed.tag], attrs)
        if start is not None:
            if typed.tag == "String":
                ET.SubElement(element, "Start", {"value": start})
            else:
                element.set("start", start)

    n_indicators = int(src.get("numberOfEventIndicators", "0") or 0)
    indicator_vr = time_vr + 1
    for k in range(n_indicators):
        ET.SubElement(variables, "Float64", {
            "name": f"event_indicator_{k + 1}", "valueReference": str(indicator_vr + k), "causality": "local",
            "variability": "continuous", "initial": "calculated", "declaredType": "EventIndicator",
            "description": f"event indicator {k + 1} of {n_indicators}: the model has an event where it changes "
                           "sign (Model Exchange); Co-Simulation reads it at the current state, inputs and modes"})
    if n_indicators:
        ET.SubElement(types, "Float64Type", {
            "name": "EventIndicator", "quantity": "Ratio",
            "description": "an event indicator (dimensionless: only its sign matters)"})

    structure = ET.SubElement(root, "ModelStructure")
    config = [f"# Written by build/fmi3.py from {identifier}'s FMI 2.0 model description.",
              f"time={time_vr}"]
    run: dict[str, list[str]] = {}
    initial: dict[str, list[str]] = {}

    def dependencies(unknown) -> list[str]:
        text = (unknown.get("dependencies") or "").split()
        return [vr_of_index[int(i)] for i in text]

    def add(tag, unknown, into):
        vr = vr_of_index[int(unknown.get("index"))]
        deps = dependencies(unknown)
        attrs = {"valueReference": vr}
        if unknown.get("dependencies") is not None:
            attrs["dependencies"] = " ".join(deps)
            if deps:
                attrs["dependenciesKind"] = unknown.get("dependenciesKind")
        ET.SubElement(structure, tag, attrs)
        if into is not None:
            merged = into.setdefault(vr, [])
            merged.extend(d for d in deps if d not in merged)

    for unknown in src.iterfind("ModelStructure/Outputs/Unknown"):
        add("Output", unknown, run)
    derivatives = src.findall("ModelStructure/Derivatives/Unknown")
    for unknown in derivatives:
        add("ContinuousStateDerivative", unknown, run)
    for unknown in src.iterfind("ModelStructure/InitialUnknowns/Unknown"):
        add("InitialUnknown", unknown, initial)
    for k in range(n_indicators):
        ET.SubElement(structure, "EventIndicator", {"valueReference": str(indicator_vr + k)})

    # FMI 2.0's <VendorAnnotations><Tool name=...> is FMI 3.0's <Annotations><Annotation
    # type=...>, the last element of the description
    tools = src.findall("VendorAnnotations/Tool")
    if tools:
        annotations = ET.SubElement(root, "Annotations")
        for tool in tools:
            ET.SubElement(annotations, "Annotation", {"type": tool.get("name")}).extend(
                ET.fromstring(ET.tostring(child)) for child in tool)

    config += [f"states={len(derivatives)}", f"event_indicators={n_indicators} {indicator_vr}"]
    config += [f"run={' '.join([vr, *deps])}" for vr, deps in run.items()]
    config += [f"init={' '.join([vr, *deps])}" for vr, deps in initial.items()]

    ET.indent(root, space="\t")
    xml = '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"
    return xml, "\n".join(config) + "\n"


def _info(name: str, like: zipfile.ZipInfo) -> zipfile.ZipInfo:
    info = zipfile.ZipInfo(name, date_time=like.date_time)
    info.compress_type = zipfile.ZIP_DEFLATED
    info.external_attr = like.external_attr
    info.create_system = like.create_system
    return info


def make_fmu3(fmu2: Path, dest: Path, shim3_so: Path) -> Path:
    """Write the FMI 3.0 edition of the (shimmed) FMI 2.0 FMU ``fmu2`` to ``dest``.

    Copied: resources (the model and pythonfmu's Python part, lever_shim.cfg with the GUID
    that is the instantiation token) and documentation (``_main.html`` also as FMI 3.0's
    ``index.html``); the FMI 2.0 entry and pythonfmu's library move to ``x86_64-linux``
    with the FMI 3.0 entry under the model identifier.  Windows binaries are not copied:
    pythonfmu's DLL there has no entry of ours in front.  Written to a temporary file and
    renamed, so a failure never leaves a half-written FMU.
    """
    fmu2, dest = Path(fmu2), Path(dest)
    dest.parent.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(fmu2) as src:
        fmi2_xml = src.read("modelDescription.xml")
        identifier = ET.fromstring(fmi2_xml).find("CoSimulation").get("modelIdentifier")
        xml, config = translate(fmi2_xml)
        description = src.getinfo("modelDescription.xml")
        fd, tmp_name = tempfile.mkstemp(prefix=dest.name + ".", suffix=".tmp", dir=dest.parent)
        os.close(fd)
        tmp = Path(tmp_name)
        try:
            with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as dst:
                dst.writestr(_info("modelDescription.xml", description), xml)
                for info in src.infolist():
                    name = info.filename
                    if name.startswith(("resources/", "documentation/")):
                        dst.writestr(_info(name, info), src.read(info))
                        if name == "documentation/_main.html":
                            dst.writestr(_info("documentation/index.html", info), src.read(info))
                    elif name == f"binaries/linux64/{identifier}.so":
                        dst.writestr(_info(f"{PLATFORM_DIR}/{FMI2_ENTRY_NAME}", info), src.read(info))
                        dst.writestr(_info(f"{PLATFORM_DIR}/{identifier}.so", info), Path(shim3_so).read_bytes())
                    elif name == "binaries/linux64/pythonfmu-export.so":
                        dst.writestr(_info(f"{PLATFORM_DIR}/pythonfmu-export.so", info), src.read(info))
                dst.writestr(_info(CONFIG_NAME, description), config)
            os.chmod(tmp, 0o644)
            os.replace(tmp, dest)
        except BaseException:
            tmp.unlink(missing_ok=True)
            raise
    return dest
