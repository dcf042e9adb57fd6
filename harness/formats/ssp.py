"""Scenes as SSP archives (System Structure and Parameterization 1.0), the ecosystem's
format for a system of FMUs: ``lever export-ssp SCENE`` writes one, ``lever run x.ssp``
runs one.

An exported archive holds

* ``SystemStructure.ssd``: the components (``resources/<Fmu>.fmu``) with a connector for
  each output and each connected input, the scene's connections, the units, and the default
  experiment (start, stop; its step as OSP's ``FixedStepAlgorithm`` annotation, which
  libcosim reads).  The system's annotations: first OpenModelica's (``org.openmodelica``:
  a weakly coupled system, OMSimulator's fixed-step master at the scene's step - OMSimulator
  reads the first annotation only, and adds no system without it; its SimulationInformation
  carries a name, as OMSimulator's Python package asks of each entry of its solver list),
  then ours (below);
* ``resources/<Fmu>.fmu``, each configured to start at the scene's values
  (``harness.formats.configured_fmu``): an engine that applies no parameter binding (fmpy.ssp
  without a parameter set) or drops some (OMSimulator: Strings) still runs the scene.  An FMU
  that cannot carry them (a foreign one, or one two components use with different values)
  is copied as it is, and the export says which components then need the bindings;
* ``resources/<Fmu>_OspModelDescription.xml``;
* ``resources/<component>.ssv``: each component's parameter set (the values the scene
  gives, in SI), bound to its component (variable names relative to the component, as
  libcosim reads them), every one named ``PARAMETER_SET``: ecos gathers the sets of one
  name across components and applies the one named on its command line
  (``--parameterSet``), so sets named per component could never all be applied;
* ``resources/qualified/parameters.ssv``: the same values in one set, each named
  ``component.parameter`` and bound to nothing: what an engine that ignores the SSD's
  bindings and takes one parameter set as an argument applies - fmpy.ssp 0.3.x, whose
  ``simulate_ssp`` reads the bindings but applies only its ``parameter_set`` argument
  (``QUALIFIED_SET``; a String the archive's FMU starts at is left out of it, as there is
  nothing to set and fmpy.ssp cannot set Strings);
* the system's annotation ``org.lever-cosim.scene`` with what SSP has no place for (master,
  transient, recorded variables, features, notes), so an exported scene loads back as the
  same scene (an archive from before, with it at the top level, loads too; OMSimulator
  refuses an SSD with an annotation there: "wrong xml schema detected").  An SSP from
  elsewhere loads too: it records its connected outputs and asks for no features.

Every SSD and SSV file of an export is valid against the SSP 1.0 XML schemas (tested).
"""
from __future__ import annotations

import json
import shlex
import shutil
import tempfile
import xml.etree.ElementTree as ET
import zipfile
from decimal import Decimal
from pathlib import Path

from lever.physics.parameters import UNITS

from harness.description import scene as scenes
from harness.description import typed_values, units
from harness.paths import FMUS
from harness.engine.component import scratch_folder
from harness.description.plan import converted, descriptions_for, fmu_path
from harness.engine.system import SceneInvalid
from harness.formats.configured_fmu import can_carry_values, configure

SSD = "http://ssp-standard.org/SSP1/SystemStructureDescription"
SSC = "http://ssp-standard.org/SSP1/SystemStructureCommon"
SSV = "http://ssp-standard.org/SSP1/SystemStructureParameterValues"
OSP = "http://opensimulationplatform.com/SSP/OSPAnnotations"
#: OMSimulator's annotation namespace; it reads its elements by the prefix ``oms:``
OMS = "https://raw.githubusercontent.com/OpenModelica/OMSimulator/master/schema/oms.xsd"
OMS_ANNOTATION = "org.openmodelica"
#: OMSimulator's fixed-step master of a weakly coupled system, which the export asks for
OMS_MASTER = "oms-ma"
#: the relative tolerance OMSimulator's fixed-step master is given (its schema requires one; it
#: passes it to fmi2SetupExperiment, and our FMUs, stepping by closed forms and fixed
#: substeps, take none): OMSimulator's own default
OMS_TOLERANCE = 1e-4
LEVER = "https://lever-cosim.org/ssp/scene"
LEVER_ANNOTATION = "org.lever-cosim.scene"
#: the name of every component's parameter set in an exported archive (see above)
PARAMETER_SET = "scene"
#: the member holding every component's values with qualified names (see above)
QUALIFIED_SET = "resources/qualified/parameters.ssv"
OSP_ANNOTATION = "com.opensimulationplatform"
# libcosim and OMSimulator read the SSD with fixed prefixes (boost property trees and
# pugixml know no namespaces).
PREFIXES = {"ssd": SSD, "ssc": SSC, "ssv": SSV, "osp": OSP, "oms": OMS, "lever": LEVER}
for _prefix, _uri in PREFIXES.items():
    ET.register_namespace(_prefix, _uri)

#: the most an archive may unpack to, in bytes and in files (an exported scene: about
#: 5 MB in 15 files); beyond, it is refused before unpacking
MAX_UNPACKED_BYTES = 1 << 30
MAX_FILES = 10_000
#: the variable types an exported archive has connectors for (what libcosim and fmpy.ssp take)
CONNECTOR_TYPES = ("Real", "Integer", "Boolean")
#: FMI 3.0's types whose connectors an SSP 1.0 file declares as the kind they carry
#: (``typed_values.CALL_TYPE``: Float64 as Real, Int32 as Integer)
FMI3_CONNECTOR_TYPES = ("Float64", "Int32")
_BASE_UNITS = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")


def _q(ns: str, tag: str) -> str:
    return f"{{{PREFIXES[ns]}}}{tag}"


def _number(x: float) -> str:
    return repr(float(x))


def is_ssp(path) -> bool:
    return str(path).endswith(".ssp")


def _decimal(x: float) -> str:
    """``x`` as an xs:decimal (no exponent), as OMSimulator's schema types its step."""
    return format(Decimal(repr(float(x))), "f")


# -- what the archive's FMUs carry, and how each engine runs it --------------------------------

def carried_values(scene: scenes.Scene, descriptions: dict, fmu_dir: Path = FMUS) -> tuple[dict, list[str]]:
    """``({FMU: {variable: value}}, notes)``: the values (in the FMU's units) the archive's
    copy of each FMU starts at, and a sentence for each FMU that cannot carry its components'
    values (its components then run at the FMU's defaults in an engine that applies no
    binding, and their Strings at the default in one that drops String bindings)."""
    users: dict[str, list[str]] = {}
    for name, spec in scene.components.items():
        users.setdefault(spec.fmu, []).append(name)
    carried, notes = {}, []
    for fmu, names in users.items():
        md = descriptions[fmu]
        variables = {v.name: v for v in md.modelVariables}
        sets = [{p: converted(variables[p], raw, f"{n}.{p}") for p, raw in scene.components[n].parameters.items()}
                for n in names]
        if not any(sets):
            continue
        strings = [f"{n}.{p}" for n, values in zip(names, sets) for p in values if variables[p].type == "String"]
        then = ("engines that apply no parameter binding (fmpy.ssp without parameter_set) run "
                f"{', '.join(names)} at the FMU's defaults")
        if strings:
            then += f", and engines that drop String bindings (OMSimulator) run {', '.join(strings)} at the default"
        if any(values != sets[0] for values in sets[1:]):
            notes.append(f"components {', '.join(names)} use {fmu} with different values, so its one copy in the "
                         f"archive keeps its defaults: {then}")
        elif not can_carry_values(fmu_path(fmu, fmu_dir, scene.experiment.fmi)):
            notes.append(f"{fmu} takes no configured start values (not one of lever's FMUs): {then}")
        else:
            carried[fmu] = sets[0]
    return carried, notes


def how_to_run(scene: scenes.Scene, archive: Path, fmu_dir: Path = FMUS) -> tuple[dict[str, str], list[str]]:
    """What each engine we name needs to run ``archive``, the export of ``scene``, with its
    values - engine -> a command line, its comment saying why - and the notes of
    ``carried_values`` (the export command and docs/hosts.md say both)."""
    _, notes = carried_values(scene, descriptions_for(scene, fmu_dir), fmu_dir)
    e = scene.experiment
    path = json.dumps(str(archive))
    result = json.dumps(str(Path(archive).with_name(f"{Path(archive).stem}-fmpy-ssp.csv")))
    values = "" if not notes else f", parameter_set=read_ssv({path}, resource={json.dumps(QUALIFIED_SET)})"
    code = ("from fmpy.ssp.simulation import simulate_ssp; "
            + ("from fmpy.ssp.ssd import read_ssv; " if notes else "")
            + f"from fmpy.util import write_csv; r = simulate_ssp({path}, start_time={e.start!r}, "
            f"stop_time={e.stop!r}, step_size={e.step!r}{values}); r[\"time\"] += {e.step!r}; write_csv({result}, r)")
    why = ("the FMUs carry the scene's values" if not notes else
           "simulate_ssp applies no binding of the SSD, only its parameter_set")
    return {
        "lever": f"lever run {shlex.quote(str(archive))}  # reads the bindings",
        "libcosim": f"CosimExecution.from_ssp_file({path}, step_ns)  # reads the bindings",
        "ecos": f"ecos simulate {shlex.quote(str(archive))} --parameterSet {PARAMETER_SET}  # ecos applies only the "
                "set it is told to",
        "fmpy.ssp": f"python -c {shlex.quote(code)} && lever validate --result {shlex.quote(json.loads(result))} "
                    f"{shlex.quote(scene.name)} --window {e.start + e.step!r}:  # {why}; simulate_ssp labels each "
                    "row with the start of the step that made it (+ step_size puts it at the end, where lever's "
                    "results have it) and writes none at the start time (judged from the first step)",
    }, notes


# -- export -------------------------------------------------------------------------------------

def export(scene: scenes.Scene, out: Path, fmu_dir: Path = FMUS) -> Path:
    """Write ``scene`` as the SSP archive ``out``; return its path.  Raises
    ``SceneInvalid`` for a scene the FMUs cannot run."""
    fmu_dir = Path(fmu_dir)
    descriptions = descriptions_for(scene, fmu_dir)
    findings = scenes.validate(scene, descriptions)
    sources = archive_sources(scene, fmu_dir)
    by_member: dict[str, Path] = {}
    fmi = scene.experiment.fmi
    for fmu, member in sources.items():
        other = by_member.setdefault(member, fmu_path(fmu, fmu_dir, fmi))
        if other != fmu_path(fmu, fmu_dir, fmi):
            findings.append(f"two FMU files named {Path(member).name} ({other} and {fmu_path(fmu, fmu_dir, fmi)}): an "
                            "SSP archive holds its FMUs in one folder; rename one")
    for c in scene.connections:
        for comp, var in ((c.source, c.output), (c.target, c.input)):
            md = descriptions.get(scene.components[comp].fmu) if comp in scene.components else None
            kind = next((v.type for v in md.modelVariables if v.name == var), None) if md else None
            if kind is not None and kind not in CONNECTOR_TYPES + FMI3_CONNECTOR_TYPES:
                findings.append(f"connection '{c}': {comp}.{var} is a {kind}; SSP readers (libcosim, fmpy.ssp) "
                                f"connect {', '.join(CONNECTOR_TYPES)} variables only")
    if findings:
        raise SceneInvalid(scene.name, findings)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    carried, _ = carried_values(scene, descriptions, fmu_dir)
    files = {"SystemStructure.ssd": _ssd(scene, descriptions, sources)}
    for name, spec in scene.components.items():
        files[f"resources/{name}.ssv"] = _ssv(spec.parameters, descriptions[spec.fmu], name)
    files[QUALIFIED_SET] = _qualified_ssv(scene, descriptions, carried)
    tmp = out.with_name(out.name + ".tmp")
    with tempfile.TemporaryDirectory(prefix="lever-ssp-export-") as scratch, \
            zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as archive:
        for member, text in files.items():
            archive.writestr(member, text)
        for fmu, member in sources.items():
            source = fmu_path(fmu, fmu_dir, fmi)
            if fmu in carried:
                archive.write(configure(source, carried[fmu], Path(scratch) / source.name), member)
            else:
                archive.write(source, member)
            osp = source.with_name(f"{source.stem}_OspModelDescription.xml")
            if osp.exists():
                archive.write(osp, f"resources/{osp.name}")
    tmp.replace(out)
    return out


def _xml(root: ET.Element) -> bytes:
    ET.indent(root)
    return ET.tostring(root, encoding="utf-8", xml_declaration=True)


def archive_sources(scene: scenes.Scene, fmu_dir: Path = FMUS) -> dict[str, str]:
    """Each of the scene's FMUs (as its components name them: ours by name, others by
    path) -> its member in the archive, ``resources/<file name>``: what the SSD's
    ``source`` says, so the archive resolves it whatever folder the FMU came from."""
    return {fmu: f"resources/{fmu_path(fmu, fmu_dir, scene.experiment.fmi).name}"
            for fmu in dict.fromkeys(spec.fmu for spec in scene.components.values())}


def _ssd(scene: scenes.Scene, descriptions: dict, sources: dict[str, str]) -> bytes:
    root = ET.Element(_q("ssd", "SystemStructureDescription"), {"name": scene.name, "version": "1.0"})
    system = ET.SubElement(root, _q("ssd", "System"), {"name": scene.name, "description": scene.description})
    elements = ET.SubElement(system, _q("ssd", "Elements"))
    used_units = set()
    for name, spec in scene.components.items():
        md = descriptions[spec.fmu]
        component = ET.SubElement(elements, _q("ssd", "Component"), {
            "name": name, "type": "application/x-fmu-sharedlibrary", "source": sources[spec.fmu]})
        connectors = ET.SubElement(component, _q("ssd", "Connectors"))
        # Inputs are connectors where the scene connects them; an unconnected input is
        # set once from the parameter set (fmpy.ssp would set every input connector at
        # every step, to the value a connection gives it or to 0).  String and
        # Enumeration variables get none: libcosim aborts on them and fmpy.ssp refuses them.
        wired = {c.input for c in scene.connections if c.target == name}
        for var in md.modelVariables:
            if not (var.causality == "output" or (var.causality == "input" and var.name in wired)):
                continue
            if var.type not in CONNECTOR_TYPES + FMI3_CONNECTOR_TYPES:
                continue
            kind = typed_values.kind(var)
            connector = ET.SubElement(connectors, _q("ssd", "Connector"), {"name": var.name, "kind": var.causality})
            attrs = {}
            if kind == "Real" and var.unit:
                attrs["unit"] = var.unit
                used_units.add(var.unit)
            ET.SubElement(connector, _q("ssc", kind), attrs)
        bindings = ET.SubElement(component, _q("ssd", "ParameterBindings"))
        ET.SubElement(bindings, _q("ssd", "ParameterBinding"), {
            "type": "application/x-ssp-parameter-set", "source": f"resources/{name}.ssv"})
    connections = ET.SubElement(system, _q("ssd", "Connections"))
    for c in scene.connections:
        ET.SubElement(connections, _q("ssd", "Connection"), {
            "startElement": c.source, "startConnector": c.output, "endElement": c.target, "endConnector": c.input})
    e = scene.experiment
    annotations = ET.SubElement(system, _q("ssd", "Annotations"))
    # OpenModelica's first: OMSimulator reads the first annotation of a system only, and
    # adds no system it cannot tell weakly or strongly coupled
    oms = ET.SubElement(annotations, _q("ssc", "Annotation"), {"type": OMS_ANNOTATION})
    # OMSimulator's Python package reads every SimulationInformation as an entry of its solver
    # list and looks solvers up by name: one without a name makes its setSolver fail (KeyError)
    information = ET.SubElement(ET.SubElement(oms, _q("oms", "Annotations")), _q("oms", "SimulationInformation"),
                                {"name": OMS_MASTER})
    ET.SubElement(information, _q("oms", "FixedStepMaster"), {
        "description": OMS_MASTER, "stepSize": _decimal(e.step), "relativeTolerance": _decimal(OMS_TOLERANCE)})
    _lever_annotation(ET.SubElement(annotations, _q("ssc", "Annotation"), {"type": LEVER_ANNOTATION}), scene)
    if used_units:
        units = ET.SubElement(root, _q("ssd", "Units"))
        for name in sorted(used_units):
            exponents, factor = UNITS[name]
            unit = ET.SubElement(units, _q("ssc", "Unit"), {"name": name})
            ET.SubElement(unit, _q("ssc", "BaseUnit"), {k: str(v) for k, v in exponents.items()})
    experiment = ET.SubElement(root, _q("ssd", "DefaultExperiment"),
                               {"startTime": _number(e.start), "stopTime": _number(e.stop)})
    annotation = ET.SubElement(ET.SubElement(experiment, _q("ssd", "Annotations")), _q("ssc", "Annotation"),
                               {"type": OSP_ANNOTATION})
    ET.SubElement(ET.SubElement(annotation, _q("osp", "Algorithm")), _q("osp", "FixedStepAlgorithm"),
                  {"baseStepSize": _number(e.step)})
    return _xml(root)


def _lever_annotation(annotation: ET.Element, scene: scenes.Scene) -> None:
    e = scene.experiment
    lever = ET.SubElement(annotation, _q("lever", "Scene"), {
        "master": e.master, "step": _number(e.step), "transient": _number(e.transient),
        **({"tolerance": _number(e.tolerance)} if e.tolerance is not None else {}),
        "features": " ".join(sorted(scene.features))})
    for item in scene.record:
        ET.SubElement(lever, _q("lever", "Record"), {"variable": item})
    if scene.notes:
        ET.SubElement(lever, _q("lever", "Notes")).text = scene.notes


def _qualified_ssv(scene: scenes.Scene, descriptions: dict, carried: dict) -> bytes:
    """Every component's values in one set named ``component.parameter`` (``QUALIFIED_SET``),
    but the Strings the archive's FMU starts at (``carried``: ``carried_values``)."""
    root = _parameter_set("qualified")
    for name, spec in scene.components.items():
        md = descriptions[spec.fmu]
        variables = {v.name: v for v in md.modelVariables}
        starts = {v.name: v.start for v in md.modelVariables}
        starts.update(carried.get(spec.fmu, {}))
        values = {param: raw for param, raw in spec.parameters.items()
                  if not (variables[param].type == "String" and str(raw) == str(starts[param] or ""))}
        _parameters(root, values, md, name, qualify=True)
    return _xml(root)


def _parameter_set(name: str) -> ET.Element:
    root = ET.Element(_q("ssv", "ParameterSet"), {"version": "1.0", "name": name})
    ET.SubElement(root, _q("ssv", "Parameters"))
    return root


def _ssv(values: dict, md, component: str) -> bytes:
    root = _parameter_set(PARAMETER_SET)
    _parameters(root, values, md, component)
    return _xml(root)


def _parameters(root: ET.Element, values: dict, md, component: str, qualify: bool = False) -> None:
    variables = {v.name: v for v in md.modelVariables}
    parameters = root.find(_q("ssv", "Parameters"))
    for param, raw in values.items():
        var = variables[param]
        value = converted(var, raw, f"{component}.{param}")
        parameter = ET.SubElement(parameters, _q("ssv", "Parameter"),
                                  {"name": f"{component}.{param}" if qualify else param})
        kind, text = typed_values.literal(var, value, f"{component}.{param}")
        attrs = {"value": text}
        if kind == "Real" and var.unit:
            attrs["unit"] = var.unit
        ET.SubElement(parameter, _q("ssv", kind), attrs)


# -- load ---------------------------------------------------------------------------------------

def unpack(path: Path, max_bytes: int | None = None, max_files: int | None = None) -> Path:
    """A temporary folder holding the archive ``path`` unpacked, removed when the process
    ends (``harness.engine.component.scratch_folder``).  An archive that would unpack to
    more than ``max_bytes`` or ``max_files`` (default ``MAX_UNPACKED_BYTES``,
    ``MAX_FILES``) is refused before anything is written: the sizes its directory
    declares are what unpacking may write (zipfile stops a member at its declared size)."""
    path = Path(path)
    max_bytes = MAX_UNPACKED_BYTES if max_bytes is None else max_bytes
    max_files = MAX_FILES if max_files is None else max_files
    if not path.is_file():
        raise scenes.SceneError(f"no SSP archive {path}")
    try:
        with zipfile.ZipFile(path) as archive:
            members = archive.infolist()
            size = sum(m.file_size for m in members)
            if len(members) > max_files:
                raise scenes.SceneError(f"{path}: the archive holds {len(members):,} files, more than the "
                                        f"{max_files:,} an SSP archive is allowed here; not unpacked")
            if size > max_bytes:
                raise scenes.SceneError(f"{path}: the archive would unpack to {size / 2**20:,.0f} MiB, more than "
                                        f"the {max_bytes / 2**20:,.0f} MiB allowed (a zip bomb?); not unpacked")
            if not any(m.filename == "SystemStructure.ssd" for m in members):
                raise scenes.SceneError(f"{path}: no SystemStructure.ssd in the archive")
            target = scratch_folder(f"lever-ssp-{path.stem[:40]}-")
            try:
                archive.extractall(target)
            except Exception:
                shutil.rmtree(target, ignore_errors=True)
                raise
    except (zipfile.BadZipFile, zipfile.LargeZipFile, OSError, EOFError) as error:
        raise scenes.SceneError(f"{path}: not an SSP archive ({error})") from None
    return target


def read_scene(path: str | Path) -> scenes.Scene:
    """The scene an SSP archive describes, its FMUs unpacked (``Scene.fmu_dir``, a
    temporary folder; removed at once when the archive is refused)."""
    path = Path(path)
    where = unpack(path)
    try:
        return _read_unpacked(path, where)
    except BaseException:
        shutil.rmtree(where, ignore_errors=True)    # a refused archive leaves no unpacked copy
        raise


def _read_unpacked(path: Path, where: Path) -> scenes.Scene:
    try:
        return _scene_from(path, where)
    except scenes.SceneError:
        raise
    except ET.ParseError as error:
        raise scenes.SceneError(f"{path}: an XML file of the archive does not parse: {error}") from None
    except (ValueError, TypeError) as error:
        raise scenes.SceneError(f"{path}: a value in the archive is malformed ({type(error).__name__}: {error}); "
                                "times and steps are numbers in s") from None
    except OSError as error:
        raise scenes.SceneError(f"{path}: a file the archive refers to cannot be read ({error})") from None


def _scene_from(path: Path, where: Path) -> scenes.Scene:
    root = ET.parse(where / "SystemStructure.ssd").getroot()
    ssd_units = defined_units(root)
    system = root.find(_q("ssd", "System"))
    if system is None:
        raise scenes.SceneError(f"{path}: SystemStructure.ssd has no System")
    components, fmu_dirs = {}, set()
    for element in system.iterfind(f"{_q('ssd', 'Elements')}/{_q('ssd', 'Component')}"):
        name, source = element.get("name"), element.get("source", "")
        fmu = (where / source).resolve()
        if not fmu.is_file():
            raise scenes.SceneError(f"{path}: component '{name}': no FMU {source} in the archive")
        fmu_dirs.add(fmu.parent)
        parameters = {}
        for binding in element.iterfind(f"{_q('ssd', 'ParameterBindings')}/{_q('ssd', 'ParameterBinding')}"):
            if binding.get("source"):
                parameter_set = ET.parse(where / binding.get("source")).getroot()
            else:
                parameter_set = binding.find(f"{_q('ssd', 'ParameterValues')}/{_q('ssv', 'ParameterSet')}")
            if parameter_set is not None:
                parameters.update(parameter_values(parameter_set, binding.get("prefix", ""), ssd_units))
        components[name] = scenes.ComponentSpec(fmu.stem, parameters)
    if len(fmu_dirs) > 1:
        raise scenes.SceneError(f"{path}: the harness runs FMUs from one folder; this SSP has them in "
                                f"{', '.join(sorted(str(d.relative_to(where)) for d in fmu_dirs))}")
    connections = [scenes.Connection(c.get("startElement"), c.get("startConnector"), c.get("endElement"),
                                     c.get("endConnector"))
                   for c in system.iterfind(f"{_q('ssd', 'Connections')}/{_q('ssd', 'Connection')}")]
    experiment = scenes.Experiment(master="jacobi")
    default = root.find(_q("ssd", "DefaultExperiment"))
    if default is not None:
        experiment.start = float(default.get("startTime", 0.0))
        if default.get("stopTime") is not None:
            experiment.stop = float(default.get("stopTime"))
        fixed = default.find(f".//{_q('osp', 'FixedStepAlgorithm')}")
        if fixed is not None:
            experiment.step = float(fixed.get("baseStepSize"))
    # the system's annotation; an archive exported before has it at the top level
    lever = next((found for owner in (system, root) if (found := owner.find(
        f"{_q('ssd', 'Annotations')}/{_q('ssc', 'Annotation')}[@type='{LEVER_ANNOTATION}']/{_q('lever', 'Scene')}"))
        is not None), None)
    if lever is not None:
        experiment.master = lever.get("master", experiment.master)
        experiment.step = float(lever.get("step", experiment.step))
        experiment.transient = float(lever.get("transient", experiment.transient))
        if lever.get("tolerance") is not None:
            experiment.tolerance = float(lever.get("tolerance"))
        record = [r.get("variable") for r in lever.iterfind(_q("lever", "Record"))]
        features = set((lever.get("features") or "").split())
        notes = lever.findtext(_q("lever", "Notes"), "")
    else:
        record = list(dict.fromkeys(f"{c.source}.{c.output}" for c in connections))
        features, notes = set(), ""
        experiment.transient = min(experiment.transient, 0.2 * (experiment.stop - experiment.start))
    name = root.get("name") or path.stem
    return scenes.Scene(name=name, description=system.get("description", ""), components=components,
                        connections=connections, experiment=experiment, record=record, features=features,
                        path=path, notes=notes, fmu_dir=fmu_dirs.pop() if fmu_dirs else None)


def parameter_values(parameter_set: ET.Element, prefix: str = "", defined_units: dict | None = None) -> dict:
    """``{name: value}`` of an SSV parameter set.  A Real with a unit is kept as the string
    "<value> <unit>", so that the scene's check converts it to its variable's unit or refuses
    it (a unit of another dimension, or one nobody defines); a unit the SSD defines in its
    ``Units`` (``defined_units``: name -> SI value of one of it, as "<factor> <SI unit>") is
    read by that definition.  Malformed values are a ``SceneError`` naming the parameter."""
    values = {}
    for parameter in parameter_set.iterfind(f"{_q('ssv', 'Parameters')}/{_q('ssv', 'Parameter')}"):
        name = parameter.get("name")
        if prefix and name.startswith(prefix):
            name = name[len(prefix):]
        typed = parameter[0] if len(parameter) else None
        if typed is None:
            continue
        kind, raw = typed.tag.rsplit("}", 1)[-1], typed.get("value")
        values[name] = _typed_value(name, kind, raw, typed.get("unit"), defined_units or {})
    return values


def _typed_value(name: str, kind: str, raw, unit: str | None, defined_units: dict):
    forms = typed_values.LITERAL_FORMS
    if raw is None:
        raise scenes.SceneError(f"SSP parameter {name}: its {kind} has no value attribute")
    if kind not in forms:
        raise scenes.SceneError(f"SSP parameter {name}: unknown type {kind} (known: {', '.join(forms)})")
    try:
        value = typed_values.parse_literal(kind, raw)
    except ValueError:
        raise scenes.SceneError(f"SSP parameter {name} = {raw!r}: expected {forms[kind]} ({kind})") from None
    if kind != "Real" or not unit:
        return value
    # a number with a unit: left as "<value> <unit>" for the scene's check to convert or refuse
    if unit in defined_units and not _pint_knows(unit):
        scale, si = defined_units[unit]
        return f"{value * scale!r} {si}"
    return f"{value!r} {unit}"


def _pint_knows(unit: str) -> bool:
    try:
        units.parse_unit(unit)
        return True
    except units.UnitProblem:
        return False


#: SSP's BaseUnit exponents and the SI unit of each
_SSP_BASE = {"kg": "kg", "m": "m", "s": "s", "A": "A", "K": "K", "mol": "mol", "cd": "cd", "rad": "rad"}


def defined_units(root: ET.Element) -> dict:
    """The SSD's ``Units``: name -> (factor to SI, the SI unit as pint reads it).  A unit
    with an offset is left out (a temperature scale: no parameter of ours)."""
    out = {}
    for unit in root.iterfind(f"{_q('ssd', 'Units')}/{_q('ssc', 'Unit')}"):
        base = unit.find(_q("ssc", "BaseUnit"))
        if base is None or unit.get("name") is None:
            continue
        try:
            if float(base.get("offset", 0.0)) != 0.0:
                continue
            scale = float(base.get("factor", 1.0))
            exponents = {k: int(base.get(k, 0)) for k in _SSP_BASE}
        except ValueError:
            raise scenes.SceneError(f"SSD unit {unit.get('name')!r}: its BaseUnit has a value that is not a number")
        si = "*".join(f"{_SSP_BASE[k]}**{e}" for k, e in exponents.items() if e) or "dimensionless"
        out[unit.get("name")] = (scale, si)
    return out
