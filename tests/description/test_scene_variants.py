"""Scenes that extend scenes: a variant names its base (``extends``) and states only what
differs (harness.description.scene.read_data)."""
from dataclasses import replace

import pytest

from harness.description import scene as scenes

#: each committed variant as its base with the variant's changes made by --set
VARIANTS = {
    "kavz685_stiff": ["experiment.step=5e-5", "experiment.master=me-cvode",
                      "coupling.stiffness=1e5", "coupling.damping=0.0", "load.order_share=0.0",
                      "load.narrowband_share=0.0"],
    "kavz685_stiff_1e6": ["experiment.stop=2.0", "experiment.step=2.5e-4", "experiment.master=adaptive-trapezoidal",
                          "experiment.tolerance=1e-4",
                          "experiment.transient=0.5", "coupling.stiffness=1e6", "coupling.damping=0.0"],
    "kavz685_misalignment_edge": ["experiment.stop=2.0", "experiment.transient=0.5", "experiment.step=5e-4",
                                  "coupling.misalignment=43.2 deg", "load.order_share=0.0",
                                  "load.narrowband_share=0.0"],
}


@pytest.mark.parametrize("name, changes", VARIANTS.items())
def test_a_committed_variant_is_its_base_with_its_changes(name, changes):
    variant = scenes.load(name)
    base = scenes.load("kavz685")
    expected = replace(base.with_overrides(changes), name=variant.name, description=variant.description,
                       path=variant.path, notes=variant.notes, bench=variant.bench)
    assert variant == expected
    assert variant.name == name and variant.description != base.description
    assert "extends" in variant.path.read_text()


def _write(folder, name, text):
    (folder / f"{name}.toml").write_text(text)
    return folder / f"{name}.toml"


BASE = """
name = "base"
description = "the base"
notes = "shared notes"
record = ["a.w"]
features = ["reference"]
[experiment]
stop = 2.0
step = 1e-3
master = "jacobi"
[components.a]
fmu = "EngineShaft"
[components.a.parameters]
inertia = 0.1
w_start = 39.0
[limits]
speed = 100.0
[bench]
target_error = 1e-3
[bench.steps]
jacobi = [1e-3]
"""


def test_a_variant_merges_components_experiment_and_limits_and_replaces_the_rest(tmp_path):
    _write(tmp_path, "base", BASE)
    path = _write(tmp_path, "variant", """
extends = "base"
record = ["a.w", "b.w"]
[experiment]
step = 5e-4
[components.a.parameters]
inertia = 0.2
[components.b]
fmu = "LoadShaft"
[limits]
torque = 1e4
[bench]
""")
    variant = scenes.load(path)
    assert variant.name == "variant" and variant.description == ""        # identity is never inherited
    assert variant.notes == "shared notes" and variant.features == {"reference"}
    assert variant.record == ["a.w", "b.w"]                               # a list replaces
    assert (variant.experiment.stop, variant.experiment.step, variant.experiment.master) == (2.0, 5e-4, "jacobi")
    assert variant.components["a"] == scenes.ComponentSpec("EngineShaft", {"inertia": 0.2, "w_start": 39.0})
    assert list(variant.components) == ["a", "b"] and variant.components["b"].fmu == "LoadShaft"
    assert variant.limits == {"speed": 100.0, "torque": 1e4}
    assert variant.bench == {}                                            # an empty table: no plan


def test_variants_chain_and_a_circle_or_a_missing_base_is_a_scene_error(tmp_path):
    _write(tmp_path, "base", BASE)
    _write(tmp_path, "middle", 'extends = "base"\n[experiment]\nstop = 3.0\n')
    leaf = scenes.load(_write(tmp_path, "leaf", 'extends = "middle.toml"\n[experiment]\nstep = 2e-3\n'))
    assert (leaf.experiment.stop, leaf.experiment.step) == (3.0, 2e-3)
    _write(tmp_path, "one", 'extends = "two"\n')
    with pytest.raises(scenes.SceneError, match="extends it back"):
        scenes.load(_write(tmp_path, "two", 'extends = "one"\n'))
    with pytest.raises(scenes.SceneError, match="no scene 'nowhere'"):
        scenes.load(_write(tmp_path, "orphan", 'extends = "nowhere"\n'))
    with pytest.raises(scenes.SceneError, match="expected the name"):
        scenes.load(_write(tmp_path, "odd", "extends = 3\n"))


def test_a_scene_file_read_again_is_read_as_it_is_now_into_a_table_of_its_own(tmp_path):
    """Parsed scene files are kept (a command reads every scene's features): a file edited
    between two reads is read as it is now, and a caller that changes the table it got
    changes no later read."""
    from harness.description import scene_file

    path = tmp_path / "s.toml"
    path.write_text('extends = "kavz685"\n[experiment]\nstop = 0.5\n')
    first = scene_file.read_data(path)
    first["experiment"]["stop"] = 99.0
    first["components"]["coupling"]["parameters"]["stiffness"] = -1.0
    again = scene_file.read_data(path)
    assert again["experiment"]["stop"] == 0.5
    assert again["components"]["coupling"]["parameters"]["stiffness"] == \
        scene_file.read_data(scene_file.SCENES / "kavz685.toml")["components"]["coupling"]["parameters"]["stiffness"] > 0
    path.write_text('extends = "kavz685"\n[experiment]\nstop = 0.25\n')
    assert scene_file.read_data(path)["experiment"]["stop"] == 0.25
