"""The plan's start state and the run's record (harness/description/plan.py).

The start state: the monolithic reference starts where the FMUs start.  With the shafts
at different speeds and angles (``--set load.w_start=30``), the FMUs' first row - what
the FMUs themselves report after initialisation, read through fmpy - is the plan's start,
the reference's first row is the same, and a well-resolved run stays within a small
error of the reference (a reference started from the scene file's speeds would be off by
the speed difference at once).

The record: every kind of ``--set`` - a component's parameter by its full name and by its
short name, an experiment field, a divergence-guard limit - is in summary.json's
overrides, in the report's "Changed with --set" line and heading, and in the plots'
title, each with the value as given."""
from __future__ import annotations

import json

import numpy as np
import pytest

from harness import api
from harness.description import plan as plans
from harness.description import scene as scenes
from harness.engine.run import simulate
from harness.formats.run_files import run_title
from harness.judges import monolithic

APART = ["load.w_start=30", "load.phi_start=0.2", "engine.phi_start=-0.1", "experiment.stop=0.05"]


def test_the_plans_start_is_each_shafts_own(fmu_dir):
    plan = plans.check(scenes.load("kavz685").with_overrides(APART), fmu_dir=fmu_dir)
    assert plan.driveline.start.get() == ((-0.1, 39.0), (0.2, 30.0))
    # the coupling's values as its FMU takes them (kavz685.toml: 15 deg in radians)
    values, alpha = plan.driveline.coupling.get()
    assert alpha == pytest.approx(np.radians(15.0), rel=1e-15)
    assert (values["stiffness"], values["damping"], values["transfer_mode"]) == (715.4, 6.35, "kinematic")


def test_the_reference_starts_where_the_fmus_start_with_the_shafts_apart(fmu_dir):
    from fmpy import simulate_fmu

    plan = plans.check(scenes.load("kavz685").with_overrides(APART), fmu_dir=fmu_dir)
    # each shaft FMU alone, through fmpy: its outputs at the start are its start values
    for component, fmu in (("engine", "EngineShaft"), ("load", "LoadShaft")):
        parameters = dict(plan.scene.components[component].parameters)
        alone = simulate_fmu(str(fmu_dir / f"{fmu}.fmu"), stop_time=1e-3, output_interval=1e-3, output=["phi", "w"],
                             start_values={k: v for k, v in parameters.items() if k in ("phi_start", "w_start")})
        (phi, w), = [(alone["phi"][0], alone["w"][0])]
        assert (phi, w) == plan.driveline.start.get()[0 if component == "engine" else 1]
    run = simulate(plan, "jacobi-quadratic", 1e-4)
    assert run.ok, run.failure
    reference = monolithic.solve(plan, run.times, use_cache=False)
    for signal in ("engine.w", "load.w", "engine.phi", "load.phi"):
        if signal in run.traces:
            assert reference.traces[signal][0] == pytest.approx(run.traces[signal][0], abs=1e-12), signal
    assert reference.traces["load.w"][0] == pytest.approx(30.0, abs=1e-12)
    for signal in ("load.w", "coupling.tau2"):
        scale = float(np.sqrt(np.mean(reference.traces[signal] ** 2)))
        error = float(np.sqrt(np.mean((run.traces[signal] - reference.traces[signal]) ** 2)))
        assert error <= 1e-3 * scale, (signal, error / scale)


#: one of each kind, with the key the record names it by
EVERY_KIND = {"coupling.misalignment": "18 deg", "stiffness": "900", "experiment.stop": "0.02",
              "limits.torque": "1e6", "limits.speed": "1e4"}
RECORDED = {"coupling.misalignment": "18 deg", "coupling.stiffness": "900", "experiment.stop": "0.02",
            "limits.torque": "1e6", "limits.speed": "1e4"}


def test_the_record_of_the_plan_states_every_kind_of_override(fmu_dir):
    scene = scenes.load("kavz685").with_overrides([f"{k}={v}" for k, v in EVERY_KIND.items()])
    record = plans.parameter_record(scene, fmu_dir)
    assert plans.overridden(record) == {k: (v if not k.startswith("coupling.") else record[k]["value"])
                                        for k, v in RECORDED.items()}
    assert record["coupling.stiffness"] == {"value": "900 N.m/rad", "source": "--set"}
    assert record["limits.speed"] == {"value": "1e4", "source": "--set"}
    assert record["coupling.damping"]["source"] == "scene file"
    assert record["engine.torque_lag"]["source"] == "default"
    unchanged = plans.parameter_record(scenes.load("kavz685"), fmu_dir)
    assert plans.overridden(unchanged) == {}


def test_each_value_is_recorded_as_given_with_its_unit_and_its_source(fmu_dir):
    """By hand from kavz685.toml and the FMUs' model descriptions: a number with the
    variable's unit, a string or a count without one, a default as its description's start."""
    scene = scenes.load("kavz685").with_overrides(["engine.w_start=40", "load.load_kind=constant"])
    record = plans.parameter_record(scene, fmu_dir)
    expected = {"engine.inertia": ("0.128 kg.m2", "scene file"), "coupling.transfer_mode": ("kinematic", "scene file"),
                "load.seed": ("1", "scene file"), "coupling.support_deformation": ("0.03", "scene file"),
                "engine.torque_lag": ("0 s", "default"), "load.band_high": ("450 rad/s", "default"),
                "engine.characteristic": ("", "default"), "load.load_direction": ("active", "default"),
                "load.tones": ("6", "default"), "engine.w_start": ("40 rad/s", "--set"),
                "load.load_kind": ("constant", "--set")}
    for key, (value, source) in expected.items():
        assert record[key] == {"value": value, "source": source}, key
    assert plans.overridden(record) == {"engine.w_start": "40 rad/s", "load.load_kind": "constant"}


def test_summary_report_and_titles_state_every_kind_of_override(fmu_dir, tmp_path):
    done = api.run("kavz685", [f"{k}={v}" for k, v in EVERY_KIND.items()], reference=False, out=tmp_path,
                   plots=False, notify=lambda *_: None)
    assert done.ok, done.failure
    summary = json.loads((tmp_path / "summary.json").read_text())
    overrides = summary["overrides"]
    assert set(overrides) == set(RECORDED)
    for key in ("experiment.stop", "limits.torque", "limits.speed"):
        assert overrides[key] == RECORDED[key]
    report = (tmp_path / "report.md").read_text()
    changed = next(line for line in report.splitlines() if line.startswith("Changed with --set:"))
    heading = report.splitlines()[0]
    title = run_title(summary)
    for key, value in overrides.items():
        assert f"**{key} = {value}**" in changed, key
        assert f"{key} = {value}" in title, key
        if not key.startswith("experiment."):
            assert f"{key} = {value}" in heading, key


#: a ramp inside a short run: 15 deg at 0, 17 deg from 5 ms on (linear between)
RAMP = ["tilt.table=0:15; 0.005:17", "experiment.stop=0.01"]


def _driven_by(scene, connection: str | None):
    """``scene`` with its coupling's misalignment driven through ``connection`` (None: not
    driven, the coupling's own angle held)."""
    import dataclasses

    kept = [c for c in scene.connections if c.input != "misalignment"]
    return dataclasses.replace(scene, connections=kept + ([scenes.parse_connection(connection)] if connection else []))


def test_the_reference_follows_the_misalignment_source_that_drives_the_coupling(fmu_dir):
    """The source's angle is the table's, by hand (15.8 deg at 2 ms, two fifths up the ramp), and the
    reference's torque is a fine co-simulation run's (a second method), far from the one
    with the coupling's own 15 deg held."""
    scene = scenes.load("kavz685_misalignment_ramp").with_overrides(RAMP)
    plan = plans.check(scene, fmu_dir=fmu_dir)
    assert plan.driveline.misalignment_driver == scenes.Connection("tilt", "misalignment", "coupling", "misalignment")
    run = simulate(plan, "jacobi-quadratic", 1e-3)
    assert run.ok, run.failure
    reference = monolithic.solve(plan, run.times, use_cache=False)
    alpha = reference.traces["tilt.misalignment"]
    assert np.allclose(alpha, np.radians(np.interp(run.times, [0.0, 0.005], [15.0, 17.0])), rtol=0.0, atol=1e-12)
    assert alpha[2] == pytest.approx(np.radians(15.8), abs=1e-12) and run.times[2] == pytest.approx(0.002)
    assert np.allclose(reference.traces["tilt.misalignment_rate"][(run.times > 0.0) & (run.times < 0.005)],
                       np.radians(2.0 / 0.005), rtol=1e-9)
    held = monolithic.solve(plans.check(_driven_by(scene, None), fmu_dir=fmu_dir), run.times, use_cache=False)
    tau2 = reference.traces["coupling.tau2"]
    scale = float(np.sqrt(np.mean(tau2 ** 2)))
    error = float(np.sqrt(np.mean((run.traces["coupling.tau2"] - tau2) ** 2)))
    apart = float(np.sqrt(np.mean((held.traces["coupling.tau2"] - tau2) ** 2)))
    assert error <= 1e-3 * scale and apart >= 30 * error, (error / scale, apart / scale)


@pytest.mark.parametrize("driver,said", [("tilt.misalignment_rate -> coupling.misalignment", "only from a MisalignmentSource"),
                                         ("engine.phi -> coupling.misalignment", "no solver for it")])
def test_a_misalignment_driven_by_anything_but_a_sources_angle_is_refused_by_the_reference(driver, said, fmu_dir):
    """The reference knows alpha(t) only from a MisalignmentSource's ``misalignment``: another
    output of the source, or another FMU's output, is refused with a sentence naming the
    connection, not solved as if the coupling's own angle held."""
    scene = _driven_by(scenes.load("kavz685_misalignment_ramp").with_overrides(RAMP), driver)
    plan = plans.check(scene, fmu_dir=fmu_dir)
    assert plan.driveline.misalignment_driver == scenes.parse_connection(driver)
    assert plan.driveline.misalignment.get() is None
    with pytest.raises(monolithic.ReferenceUnavailable, match=said) as refused:
        monolithic.solve(plan, np.linspace(0.0, 0.01, 5), use_cache=False)
    assert driver.split(" ")[0] in str(refused.value)


def test_a_copy_of_the_source_under_another_name_is_not_taken_for_it(fmu_dir, tmp_path):
    """A user's FMU (given by path) with an output called ``misalignment`` may compute anything:
    the reference refuses it, whatever its file holds (here a copy of the MisalignmentSource)."""
    import shutil

    copy = tmp_path / "UsersTilt.fmu"
    shutil.copy2(fmu_dir / "MisalignmentSource.fmu", copy)
    scene = scenes.load("kavz685_misalignment_ramp").with_overrides(RAMP)
    scene.components["tilt"] = scenes.ComponentSpec(str(copy), dict(scene.components["tilt"].parameters))
    plan = plans.check(scene, fmu_dir=fmu_dir)
    assert plan.driveline.misalignment_driver is not None
    assert plan.driveline.misalignment.get() is None


def test_a_components_fmu_missing_from_the_folder_leaves_its_record_to_the_scene(fmu_dir, tmp_path):
    """The record reads the FMUs of the folder the run uses: with only the coupling's FMU
    there, the coupling's defaults are listed and the engine's values are the scene's alone
    (as written, no unit: no description says one), none of its defaults."""
    import shutil

    shutil.copy2(fmu_dir / "LeverCoupling.fmu", tmp_path / "LeverCoupling.fmu")
    scene = scenes.load("kavz685")
    record = plans.parameter_record(scene, tmp_path)
    engine = {k: v for k, v in record.items() if k.startswith("engine.")}
    assert engine == {f"engine.{k}": {"value": v, "source": "scene file"}
                      for k, v in (("inertia", "0.128"), ("stall_torque", "623"), ("torque_slope", "14.06"),
                                   ("w_start", "39"))}
    full = plans.parameter_record(scene, fmu_dir)
    coupling = {k: v for k, v in full.items() if k.startswith("coupling.")}
    assert {k: v for k, v in record.items() if k.startswith("coupling.")} == coupling
    assert any(v["source"] == "default" for v in coupling.values())
