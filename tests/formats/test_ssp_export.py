"""What `lever export-ssp` writes, checked without running an engine: every SSD, SSV and
SSM file valid against the SSP 1.0 XML schemas (the Modelica Association's, as fmpy ships
them), the system annotation OMSimulator needs to add the system at all, and FMUs that
carry the scene's values as their own start values (for engines that apply no parameter
binding, or drop the String ones), with a GUID of their own."""
from __future__ import annotations

import json
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import fmpy
import pytest
from lxml import etree

from harness.description import scene as scenes
from harness.description.plan import descriptions_for, fmu_path
from harness.formats import ssp
from harness.formats.configured_fmu import configure, configured_guid

SCHEMAS = Path(fmpy.__file__).parent / "ssp" / "schema"
SCHEMA_OF = {".ssd": "SystemStructureDescription.xsd", ".ssv": "SystemStructureParameterValues.xsd",
             ".ssm": "SystemStructureParameterMapping.xsd"}
#: what OMSimulator accepts under the SSD's root (oms::Model::importFromSnapshot; any other
#: element: "wrong xml schema detected")
OMS_ROOT_CHILDREN = {"System", "Units", "Enumerations", "DefaultExperiment"}
#: ... under a system (oms::System::importFromSnapshot) and a component
#: (oms::ComponentFMUCS::NewComponent): anything else is "Wrong xml schema detected"
OMS_SYSTEM_CHILDREN = {"Connectors", "ElementGeometry", "ParameterBindings", "Elements", "Connections", "Annotations"}
OMS_COMPONENT_CHILDREN = {"Connectors", "ElementGeometry", "ParameterBindings"}


def _export(tmp_path, overrides=(), name="kavz685") -> Path:
    scene = scenes.load(name).with_overrides(list(overrides))
    return ssp.export(scene, tmp_path / f"{name}.ssp")


@pytest.fixture(scope="module")
def archive(tmp_path_factory, fmu_dir) -> Path:
    return _export(tmp_path_factory.mktemp("ssp"), ["coupling.transfer_mode=scaled"])


def _members(archive: Path) -> dict[str, bytes]:
    with zipfile.ZipFile(archive) as z:
        return {name: z.read(name) for name in z.namelist()}


def test_every_ssd_ssv_and_ssm_file_is_valid_against_the_ssp_schemas(archive):
    members = _members(archive)
    checked = []
    for name, data in members.items():
        schema_file = SCHEMA_OF.get(Path(name).suffix)
        if schema_file is None:
            continue
        schema = etree.XMLSchema(etree.parse(str(SCHEMAS / schema_file)))
        assert schema.validate(etree.fromstring(data)), (name, [str(e) for e in schema.error_log])
        checked.append(name)
    assert "SystemStructure.ssd" in checked and len([n for n in checked if n.endswith(".ssv")]) >= 4


def test_a_schema_violation_is_found():
    """The check above can fail: an SSD with a connection that lacks its end is refused."""
    schema = etree.XMLSchema(etree.parse(str(SCHEMAS / SCHEMA_OF[".ssd"])))
    bad = (f'<ssd:SystemStructureDescription xmlns:ssd="{ssp.SSD}" name="x" version="1.0">'
           '<ssd:System name="x"><ssd:Connections><ssd:Connection startElement="a" startConnector="y"/>'
           '</ssd:Connections></ssd:System></ssd:SystemStructureDescription>')
    assert not schema.validate(etree.fromstring(bad.encode()))


def test_the_ssd_is_what_omsimulator_adds_as_a_weakly_coupled_system(archive):
    """OMSimulator takes the system's kind from the first annotation of the system, if it is
    OpenModelica's (its fixed-step master for a weakly coupled system), and refuses any other
    element under the SSD's root, such as a top-level annotation."""
    root = ET.fromstring(_members(archive)["SystemStructure.ssd"])
    assert {child.tag.split("}")[1] for child in root} <= OMS_ROOT_CHILDREN
    system = root.find(f"{{{ssp.SSD}}}System")
    assert {child.tag.split("}")[1] for child in system} <= OMS_SYSTEM_CHILDREN
    for component in system.iterfind(f"{{{ssp.SSD}}}Elements/{{{ssp.SSD}}}Component"):
        assert {child.tag.split("}")[1] for child in component} <= OMS_COMPONENT_CHILDREN, component.get("name")
    first = system.find(f"{{{ssp.SSD}}}Annotations/{{{ssp.SSC}}}Annotation")
    assert first.get("type") == "org.openmodelica"
    master = first.find(f"{{{ssp.OMS}}}Annotations/{{{ssp.OMS}}}SimulationInformation/{{{ssp.OMS}}}FixedStepMaster")
    assert master.get("description") == "oms-ma"
    assert float(master.get("stepSize")) == scenes.load("kavz685").experiment.step
    # pugixml matches the prefixes as written
    text = _members(archive)["SystemStructure.ssd"].decode()
    assert "<oms:FixedStepMaster " in text and "<ssc:Annotation type=\"org.openmodelica\">" in text


def test_omsimulator_python_reads_every_simulation_information_as_a_named_solver(archive):
    """OMSimulatorPython (utils.parseAnnotations) lists the attributes of every
    oms:SimulationInformation of the system's org.openmodelica annotations as a solver, and its
    generateJson looks each up by s["name"] once a component is given a solver (setSolver): an
    entry without a name is a KeyError before any solver of the user's is found."""
    system = ET.fromstring(_members(archive)["SystemStructure.ssd"]).find(f"{{{ssp.SSD}}}System")
    solvers = [information.attrib
               for annotation in system.findall(f"{{{ssp.SSD}}}Annotations/{{{ssp.SSC}}}Annotation")
               if annotation.get("type") == "org.openmodelica"
               for information in annotation.findall(f"{{{ssp.OMS}}}Annotations/{{{ssp.OMS}}}SimulationInformation")]
    assert solvers, "the export writes OpenModelica's annotation"
    user_solver = {"name": "cvode", "method": "cvode", "tolerance": 1e-6}
    found = next((s for s in solvers + [user_solver] if s["name"] == "cvode"), None)
    assert found is user_solver
    assert [s["name"] for s in solvers] == ["oms-ma"]


def test_the_archive_loads_back_with_its_scene_annotation_where_it_is_now_and_where_it_was(archive, tmp_path):
    loaded = ssp.read_scene(archive)
    assert loaded.experiment.master == scenes.load("kavz685").experiment.master
    assert loaded.record == scenes.load("kavz685").record
    # an archive exported before: the annotation at the top level
    members = _members(archive)
    root = ET.fromstring(members["SystemStructure.ssd"])
    system = root.find(f"{{{ssp.SSD}}}System")
    annotations = system.find(f"{{{ssp.SSD}}}Annotations")
    lever = annotations.find(f"{{{ssp.SSC}}}Annotation[@type='{ssp.LEVER_ANNOTATION}']")
    annotations.remove(lever)
    ET.SubElement(root, f"{{{ssp.SSD}}}Annotations").append(lever)
    members["SystemStructure.ssd"] = ET.tostring(root)
    old = tmp_path / "old.ssp"
    with zipfile.ZipFile(old, "w") as z:
        for name, data in members.items():
            z.writestr(name, data)
    assert ssp.read_scene(old).record == loaded.record


@pytest.mark.parametrize("fmi", [2, 3])
def test_each_fmu_in_the_archive_starts_at_the_scenes_values_with_a_guid_of_its_own(tmp_path, fmu_dir, fmi):
    scene = scenes.load("kavz685").with_overrides(["coupling.transfer_mode=scaled", f"experiment.fmi={fmi}"])
    archive = ssp.export(scene, tmp_path / "k.ssp")
    descriptions = descriptions_for(scene, fmu_dir)
    carried, notes = ssp.carried_values(scene, descriptions, fmu_dir)
    assert not notes and set(carried) == {spec.fmu for spec in scene.components.values()}
    with zipfile.ZipFile(archive) as z:
        for name, spec in scene.components.items():
            member = f"resources/{spec.fmu}.fmu"
            extracted = Path(z.extract(member, tmp_path / "x"))
            md = fmpy.read_model_description(str(extracted), validate=True)
            starts = {v.name: v.start for v in md.modelVariables}
            built = fmpy.read_model_description(str(fmu_path(spec.fmu, fmu_dir, fmi)))
            guid = md.guid if fmi == 2 else md.instantiationToken
            original = built.guid if fmi == 2 else built.instantiationToken
            assert guid != original and guid == configured_guid(original, carried[spec.fmu])
            with zipfile.ZipFile(extracted) as f:
                assert f"guid={guid}\n" in f.read("resources/lever_shim.cfg").decode()
                carried_json = json.loads(f.read("resources/lever_start_values.json"))
            assert carried_json == carried[spec.fmu]
            for param, value in carried[spec.fmu].items():
                assert type(value)(starts[param]) == value, (name, param)
    assert carried["LeverCoupling"]["transfer_mode"] == "scaled"


def test_a_configured_fmu_runs_from_its_values(tmp_path, fmu_dir):
    """The FMU itself starts at them (not only its model description says so): read back
    after instantiation, with nothing set."""
    path = configure(Path(fmu_dir) / "LeverCoupling.fmu", {"stiffness": 812.5, "transfer_mode": "scaled"},
                     tmp_path / "LeverCoupling.fmu")
    md = fmpy.read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu = fmpy.instantiate_fmu(fmpy.extract(str(path), unzipdir=tmp_path / "u"), md)
    try:
        assert fmu.getReal([vr["stiffness"]]) == [812.5]
        assert fmu.getString([vr["transfer_mode"]]) == [b"scaled"]
    finally:
        fmu.freeInstance()


def test_configuring_refuses_what_is_no_parameter_or_does_not_fit(tmp_path, fmu_dir):
    with pytest.raises(ValueError, match="no parameter or input"):
        configure(Path(fmu_dir) / "LeverCoupling.fmu", {"tau1": 1.0}, tmp_path / "a.fmu")
    with pytest.raises(ValueError):
        configure(Path(fmu_dir) / "LeverCoupling.fmu", {"stiffness": "stiff"}, tmp_path / "b.fmu")
    assert not list(tmp_path.iterdir())


def test_an_fmu_two_components_use_with_different_values_is_not_configured_and_the_export_says_so(fmu_dir):
    scene = scenes.load("kavz685")
    load = scene.components["load"]
    scene.components["load2"] = scenes.ComponentSpec(load.fmu, {**load.parameters, "inertia": 2.0})
    carried, notes = ssp.carried_values(scene, descriptions_for(scene, fmu_dir), fmu_dir)
    assert "LoadShaft" not in carried and "EngineShaft" in carried
    assert len(notes) == 1 and "load, load2" in notes[0] and "defaults" in notes[0]


def test_the_printed_fmpy_recipe_asks_for_the_parameter_set_only_where_the_fmus_do_not_carry_the_values(
        tmp_path, fmu_dir):
    scene = scenes.load("kavz685")
    runs, notes = ssp.how_to_run(scene, tmp_path / "k.ssp", fmu_dir)
    assert not notes and "parameter_set" not in runs["fmpy.ssp"]
    assert 'r["time"] += 0.001' in runs["fmpy.ssp"] and "--window 0.001:" in runs["fmpy.ssp"]
    load = scene.components["load"]
    scene.components["load2"] = scenes.ComponentSpec(load.fmu, {**load.parameters, "inertia": 2.0})
    runs, notes = ssp.how_to_run(scene, tmp_path / "k.ssp", fmu_dir)
    assert notes and "parameter_set=read_ssv" in runs["fmpy.ssp"]
