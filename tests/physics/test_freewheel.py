"""The freewheel rectifier (docs/physics.md#freewheel-rectifier): its physics (energy balance, gaps,
engagement and free-wheeling, stick/slip), its FMU through FMI, the stop-mode scene end
to end, and the FMU's agreement with the monolithic reference."""
from __future__ import annotations

import json
import math
from pathlib import Path

import fmpy
import numpy as np
import pytest
from fmpy.validation import validate_fmu

from harness.description.fmu_description import read_description, time_derivatives
from harness.judges import rectifier as fw_harness
from harness.judges import monolithic
from harness.description import scene as scenes
from harness.engine.component import Component, FmuCallError
from harness.engine.run import simulate
from lever.physics import component_parameters
from lever.physics.freewheel import contact_side
from lever.physics.parameters import ParameterError

FMI2_ERROR = 3
#: the scene's stop mode: Table 1 with the output held by a resistance above any mesh torque
STOP = {"resistance_torque": 1000.0}
PERIOD = 2.0 * math.pi / 42.41


def model(**overrides):
    return component_parameters.freewheel_from({**STOP, **overrides})


def run_physics(m, stop, h=1e-3, y=None, disc=None, fly=None):
    """Step the physics as the FMU does; rows of named outputs every ``h``."""
    if y is None:
        y, disc, fly = m.start()
    rows, t, events = [m.named_outputs(0.0, y, disc, fly, 0.0)], 0.0, 0
    for k in range(1, int(round(stop / h)) + 1):
        y, disc, fly, n = m.advance(t, h, y, disc, fly)
        events += n
        t = k * h
        rows.append(m.named_outputs(t, y, disc, fly, 0.0, events))
    return {key: np.array([r[key] for r in rows]) for key in rows[0]}


def residual(tr):
    stored = tr["kinetic_energy"] + tr["elastic_energy"]
    return tr["input_work"] - tr["output_work"] - (stored - stored[0]) - tr["dissipated_energy"]


# --------------------------------------------------------------------------------------
# Physics
# --------------------------------------------------------------------------------------

def test_defaults_are_the_papers_table_1():
    p = {q.name: q.default for q in component_parameters.FREEWHEEL}
    assert (p["half_coupling_inertia"], p["driven_parts_inertia"], p["torsion_end_inertia"]) == (0.000202, 0.000217,
                                                                                                0.0014)
    assert p["flywheel_inertia"] == 5.0 and p["input_speed"] == 42.41 and p["rocker_amplitude"] == 0.103
    assert (p["ramp_angle"], p["contact_radius"], p["friction_pairs"]) == (0.3054, 0.026, 9)
    assert (p["disc_friction"], p["ball_friction"], p["drag_torque"], p["drag_damping"]) == (0.05, 0.001, 0.85, 0.075)
    assert p["spring_force"] == 6.0
    assert [math.degrees(p[k]) for k in ("msm_gap", "torsion_gap", "mesh_gap")] == pytest.approx([1.74, 2.23, 1.1])
    assert (p["msm_stiffness"], p["torsion_stiffness"], p["mesh_stiffness"]) == (10313.0, 3798.0, 25000.0)
    assert p["torsion_damping"] == p["mesh_damping"] == 0.3
    for q in component_parameters.FREEWHEEL:
        assert q.description and (q.kind != "real" or q.unit), q.name


def test_self_locking_figure_of_the_paper():
    tan_a, nf = model().self_locking()
    assert tan_a / 9 == pytest.approx(0.035, abs=5e-4)     # "f_min = 0.035 at alpha = 17.5 deg, n = 9"
    assert tan_a < nf


def test_gap_edges_and_ramp_torque():
    m = model()
    assert [contact_side(d, 0.1) for d in (0.01, 0.0, -0.05, -0.1, -0.11)] == [1, 0, 0, 0, -1]
    t_p = m.t_p
    assert t_p == pytest.approx(2 * 6.0 * 0.026 * math.tan(0.3054))
    # in the axial gap only the return springs act; engaged: C_fi; at the pocket's end: C_b
    assert m._ramp(-0.5 * m.z1, 0.0)[0] == t_p
    assert m._ramp(1e-3, 0.0)[0] == pytest.approx(t_p + m.c_fi * 1e-3)
    assert m._ramp(-m.z1 - 1e-3, 0.0)[0] == pytest.approx(t_p - m.c_b * 1e-3)
    # continuous at both edges, and the balls' friction makes loading dearer than unloading
    for edge in (0.0, -m.z1):
        assert m._ramp(edge + 1e-12, 0.0)[0] == pytest.approx(m._ramp(edge - 1e-12, 0.0)[0], abs=1e-6)
    loading, unloading = m._ramp(0.01, 1.0)[0], m._ramp(0.01, -1.0)[0]
    assert loading > m._ramp(0.01, 0.0)[0] > unloading
    assert m._ramp(0.01, 1.0)[1] > 0 and m._ramp(0.01, -1.0)[1] > 0     # the loss is a loss both ways
    # the discs' capacity: n f_s / tan(alpha) times the ramps' elastic torque, plus the drag
    assert m._ramp(0.01, 0.0)[2] == pytest.approx(9 * 0.05 / math.tan(0.3054) * m.c_fi * 0.01 + 0.85)


def test_bad_parameter_combination_is_refused_by_name():
    with pytest.raises(ParameterError) as info:
        component_parameters.freewheel_from({"ball_friction": 0.9, "ramp_angle": 1.2})
    assert info.value.name == "ball_friction" and "ball_friction" in str(info.value)
    with pytest.raises(ParameterError) as info:
        component_parameters.freewheel_from({"torsion_gap": 2.0})
    assert "torsion_gap" in str(info.value) and "[0, 1] rad" in str(info.value)


@pytest.fixture(scope="module")
def stop_mode_cycle():
    m = model()
    return m, run_physics(m, PERIOD)


def test_energy_balance_of_the_stop_mode_cycle(stop_mode_cycle):
    _, tr = stop_mode_cycle
    largest = np.max(tr["input_work"])
    assert largest > 10.0                        # the stroke winds the torsion shaft up
    assert np.max(np.abs(residual(tr))) < 1e-7 * largest
    assert tr["output_work"][-1] == 0.0          # the output is held


def test_energy_balance_with_the_output_free_and_a_slipping_brake():
    for overrides in ({"resistance_torque": 0.0}, {"resistance_torque": 150.0}):
        m = model(**overrides)
        tr = run_physics(m, 0.12)
        assert np.max(np.abs(residual(tr))) < 1e-7 * np.max(tr["input_work"]), overrides
        assert np.max(tr["w"]) > 0.1, overrides          # the output was driven
        if overrides["resistance_torque"]:
            assert tr["output_work"][-1] > 0.0          # the brake took work while it slipped


def test_engagement_on_the_forward_stroke_only_and_torque_after_the_gaps(stop_mode_cycle):
    m, tr = stop_mode_cycle
    engaged = tr["msm_contact"] > 0
    assert engaged.any() and not engaged.all()
    first = int(np.argmax(engaged))
    # the ramps first touch after the rocker took up at least the axial gap z1, on its forward stroke
    assert tr["rocker_angle"][first] > m.z1 and tr["rocker_speed"][first] > 0
    # no torque beyond the return springs before that
    assert np.all(np.abs(tr["rocker_torque"][:first]) < 1.0)
    # the main engagement carries the torque through the torsion shaft and the mesh to the held output
    assert np.max(tr["torsion_torque"]) > 200.0 and np.max(tr["mesh_torque"]) > 200.0
    assert np.max(tr["torsion_twist"]) > 0.05 and np.all(tr["phi"] == 0.0) and np.all(tr["flywheel_stuck"] == 1.0)
    # free-wheeling on the back stroke: the rocker drags the half-couplings back through the
    # pocket ends while the discs slip (w2 < w3)
    back = (tr["rocker_speed"] < -1.0) & (tr["msm_contact"] < 0)
    assert back.any()
    assert np.any(tr["disc_slip"][back] == -1.0)


def test_the_discs_hold_under_load_and_slip_below_the_self_locking_friction(stop_mode_cycle):
    _, tr = stop_mode_cycle
    loaded = tr["rocker_torque"] > 50.0
    assert loaded.any() and np.all(tr["disc_slip"][loaded] == 0.0)
    assert np.all(np.abs(tr["disc_torque"][loaded]) <= tr["disc_capacity"][loaded] + 1e-9)
    # f_s below tan(alpha)/n = 0.035: the ramps push harder than the discs can hold, so the
    # discs slip as soon as the ramps engage, passing their capacity (plus the drag's
    # viscous part), and the freewheel transmits next to nothing
    m = model(disc_friction=0.02)
    weak = run_physics(m, 0.5 * PERIOD, h=2e-4)
    slipping = (weak["disc_slip"] != 0) & (weak["msm_contact"] > 0)
    assert slipping.any()
    slip_speed = weak["half_coupling_speed"][slipping] - weak["driven_speed"][slipping]
    assert weak["disc_torque"][slipping] == pytest.approx(
        np.sign(slip_speed) * weak["disc_capacity"][slipping] + m.k_v * slip_speed, rel=1e-9)
    assert np.max(weak["torsion_torque"]) < 0.05 * np.max(tr["torsion_torque"])


def test_an_overrunning_output_is_not_driven():
    """The driven side may turn faster than the rocker: with the driven parts, torsion
    shaft and output started above the rocker's peak speed, the chain free-wheels through a
    whole cycle (the discs slip) and the ramps never engage."""
    m = model(resistance_torque=0.0)
    y, disc, fly = m.start()
    y = [y[0], 0.0, y[2], 10.0, y[4], 10.0, y[6], 10.0] + y[8:]
    tr = run_physics(m, PERIOD, y=y, disc=-1, fly=fly)      # the discs slip: w2 < w3
    assert np.all(tr["msm_contact"] <= 0)
    # the rocker only holds the half-couplings against the discs' drag, M_v + k_v |w2 - w3|
    assert np.max(np.abs(tr["rocker_torque"])) < 0.85 + 0.075 * 15.0 + 1.0
    assert np.all(tr["disc_slip"] == -1.0)
    assert tr["w"][-1] == pytest.approx(10.0, abs=0.05)     # only the drag and the dampers act on it
    assert np.max(np.abs(residual(tr))) < 1e-8 * np.max(tr["kinetic_energy"])


def test_communication_points_do_not_change_the_solution():
    """Events are located inside the substeps, so one long step and many short ones agree."""
    m = model()
    a = run_physics(m, 0.06, h=0.06)
    b = run_physics(m, 0.06, h=5e-4)
    for key in ("half_coupling_speed", "driven_speed", "torsion_torque", "rocker_torque"):
        assert a[key][-1] == pytest.approx(b[key][-1], rel=1e-5, abs=1e-5 * max(1.0, np.max(np.abs(b[key])))), key


def test_chattering_is_reported_not_looped():
    m = model(max_events=1)
    y, disc, fly = m.start()
    with pytest.raises(RuntimeError) as info:
        m.advance(0.0, 0.1, y, disc, fly)
    assert "events in one step" in str(info.value)


# --------------------------------------------------------------------------------------
# The FMU through FMI
# --------------------------------------------------------------------------------------

@pytest.fixture
def rectifier(fmu_dir):
    made = []

    def make(params=None, initialise=True):
        c = Component("rectifier", Path(fmu_dir) / "FreewheelRectifier.fmu")
        made.append(c)
        if params:
            c.set_parameters(params)
        if initialise:
            c.initialize(0.0, 1.0)
            c.exit_initialization()
        return c

    yield make
    for c in made:
        c.free()


def test_fmu_validates_and_declares_units_ranges_and_a_shaft_port(fmu_dir):
    path = Path(fmu_dir) / "FreewheelRectifier.fmu"
    assert validate_fmu(str(path)) == []
    md = fmpy.read_model_description(str(path))
    variables = {v.name: v for v in md.modelVariables}
    for q in component_parameters.FREEWHEEL:
        v = variables[q.name]
        assert v.causality == "parameter" and v.description
        assert v.min is not None and v.max is not None, q.name
    assert variables["msm_gap"].unit == "rad" and variables["contact_radius"].unit == "m"
    assert variables["spring_force"].unit == "N" and variables["mesh_stiffness"].unit == "N.m/rad"
    derivative_of = time_derivatives(read_description(path))
    # the port's chain, and each Model Exchange state's derivative
    bodies = {f"{b}_{k}": f"{b}_{j}" for b in ("half_coupling", "driven", "torsion_end")
              for j, k in (("angle", "speed"), ("speed", "acceleration"))}
    energies = {f"der({e})": e for e in ("input_work", "output_work", "dissipated_energy")}
    assert derivative_of == {"w": "phi", "a": "w", "tau_rate": "tau", **bodies, **energies}
    for output in md.outputs:
        expected = ["tau"] if output.variable.name in ("a", "resistance") else []
        inputs = [d.name for d in output.dependencies if d.causality == "input"]
        assert inputs == expected, output.variable.name
    # the physics reports exactly the FMU's outputs
    m = model()
    y, disc, fly = m.start()
    assert set(m.named_outputs(0.0, y, disc, fly, 0.0)) == {o.variable.name for o in md.outputs}


@pytest.mark.parametrize("name,value", [("msm_gap", 2.0), ("torsion_stiffness", 0.0), ("flywheel_inertia", -5.0),
                                        ("disc_friction", math.nan), ("friction_pairs", 0)])
def test_fmu_refuses_bad_values_naming_the_variable_and_range(rectifier, name, value):
    c = rectifier(initialise=False)
    with pytest.raises(FmuCallError) as info:
        c.set_parameters({name: value})
    assert info.value.status == FMI2_ERROR
    assert f"'{name}'" in str(info.value) and ("range" in str(info.value) or "allowed" in str(info.value))
    c.initialize(0.0, 1.0)
    c.exit_initialization()
    c.do_step(0.0, 1e-3)                         # the instance survives with its default


def test_fmu_refuses_a_bad_combination_at_initialisation(rectifier):
    c = rectifier({"ball_friction": 0.9, "ramp_angle": 1.2}, initialise=False)
    c.initialize(0.0, 1.0)
    with pytest.raises(FmuCallError) as info:
        c.exit_initialization()
    assert "ball_friction" in str(info.value)


def test_fmu_steps_as_the_physics_and_restores_its_state(rectifier):
    c = rectifier(STOP)
    names = ["half_coupling_speed", "torsion_torque", "events", "input_work"]
    for k in range(40):
        c.do_step(k * 1e-3, 1e-3)
    state = c.save_state()
    for k in range(40, 80):
        c.do_step(k * 1e-3, 1e-3)
    first = c.get(names)
    c.restore_state(state, 0.04)
    for k in range(40, 80):
        c.do_step(k * 1e-3, 1e-3)
    assert c.get(names) == first
    c.free_state(state)
    physics = run_physics(model(), 0.08)
    assert first[:2] == pytest.approx([physics["half_coupling_speed"][-1], physics["torsion_torque"][-1]], rel=1e-12)


def test_fmu_port_torque_drives_the_output_shaft(rectifier):
    c = rectifier({"resistance_torque": 0.0})
    c.do_step(0.0, 1e-3)
    a0 = c.get(["a"])[0]
    c.set_parameters({"tau": -50.0})
    assert c.get(["a"])[0] - a0 == pytest.approx(-50.0 / 5.0)
    w0 = c.get(["w"])[0]
    c.do_step(1e-3, 1e-2)
    # backwards, into the mesh's backlash: only the port torque (and the mesh damper) moves the flywheel
    assert c.get(["w"])[0] - w0 == pytest.approx(-50.0 / 5.0 * 1e-2, rel=5e-3)


# --------------------------------------------------------------------------------------
# The scene, end to end, and the reference
# --------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def short_scene_run(fmu_dir, tmp_path_factory):
    spec = scenes.load("freewheel_rectifier").with_overrides([f"experiment.stop={1.1 * PERIOD}"])
    result = simulate(spec, fmu_dir=fmu_dir)
    ref = monolithic.solve(spec, result.times, use_cache=False)
    return spec, result, ref, tmp_path_factory.mktemp("freewheel")


def test_scene_reproduces_the_stop_mode_test(short_scene_run):
    spec, result, ref, out = short_scene_run
    assert result.ok, result.failure
    assert spec.components["rectifier"].parameters["input_speed"] == 42.41
    from harness.formats import report
    summary = report.write(out, result, ref)
    fw = summary["freewheel"]
    assert fw["phases"] and fw["phases"][0]["peak_torsion_torque_Nm"] > 200.0
    assert fw["gap_transitions"]["msm (z1)"]["opened"] >= 1
    assert all(g["closed_drive_flank"] >= 1 for g in fw["gap_transitions"].values())
    assert summary["energy_balance"]["worst_residual_relative"] < 1e-7
    text = (out / "report.md").read_text()
    for heading in ("Engagement and free-wheeling", "The gaps closing and opening", "Energy balance",
                    "Kinematics beside the source's description", "Against the monolithic reference"):
        assert heading in text, heading
    for name in ("kinematics.png", "gaps.png", "torques.png", "energy.png", "vs_reference.png"):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
    saved = json.loads((out / "summary.json").read_text())
    assert saved["scene"] == "freewheel_rectifier" and saved["ok"] is True


def test_fmu_agrees_with_the_monolithic_reference(short_scene_run):
    spec, result, ref, _ = short_scene_run
    assert ref.info["events"] > 10                  # the reference restarted at located events
    errs = fw_harness.errors(spec, result.times, result.traces, ref)
    assert set(errs) == set(fw_harness.COMPARED)
    for var, e in errs.items():
        assert e["rms_relative"] < 1e-4, (var, e)
        assert e["max_relative"] < 1e-2, (var, e)
    # the reference's own energy balance closes to its tolerance
    assert fw_harness.analyse(spec, ref.times, ref.traces)["energy_balance"]["worst_residual_relative"] < 1e-8


def test_scene_refuses_a_value_out_of_range_before_running():
    from harness.engine.system import SceneInvalid

    spec = scenes.load("freewheel_rectifier").with_overrides(["rectifier.msm_gap=5 deg", "rectifier.mesh_gap=2"])
    with pytest.raises(SceneInvalid) as info:
        simulate(spec)
    assert "rectifier.mesh_gap" in str(info.value) and "[0, 1]" in str(info.value)
    assert "msm_gap" not in str(info.value)        # 5 deg is allowed



@pytest.mark.parametrize("master", ["trapezoidal-newton", "adaptive"])
def test_coupling_iterating_masters_are_refused_on_the_one_fmu_scene(fmu_dir, master):
    spec = scenes.load("freewheel_rectifier").with_overrides(["experiment.stop=0.01"])
    result = simulate(spec, master, fmu_dir=fmu_dir)
    assert not result.ok and result.failure_stage == "initialisation"
    assert "connects none" in result.failure and "jacobi" in result.failure
    assert len(simulate(spec, "jacobi-quadratic", fmu_dir=fmu_dir).times) == 51   # extrapolation just steps it


def test_the_committed_scene_leaves_no_input_unconnected_and_keeps_its_reference(fmu_dir):
    """The output shaft's input is held at 0 in the scene (no downstream element): no
    warning on every run, and the reference (which covers tau = 0) still solves it; a
    held torque other than 0 is no case the reference covers."""
    from harness.description.plan import descriptions_for

    spec = scenes.load("freewheel_rectifier")
    assert scenes.unconnected_inputs(spec, descriptions_for(spec, fmu_dir)) == []
    short = spec.with_overrides(["experiment.stop=0.01"])
    assert monolithic.solve(short, np.linspace(0.0, 0.01, 11), use_cache=False).traces
    with pytest.raises(monolithic.ReferenceUnavailable, match="tau = 0"):
        monolithic.solve(short.with_overrides(["rectifier.tau=5"]), np.linspace(0.0, 0.01, 11), use_cache=False)
