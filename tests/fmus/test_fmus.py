"""The built FMUs (build/fmus) through the FMI interface: model descriptions, refusal of bad
values, life cycle, independence of instances, agreement with the physics package."""
from __future__ import annotations

import math
from pathlib import Path

import fmpy
import numpy as np
import pytest
from fmpy.validation import validate_fmu

from harness.description import typed_values
from harness.description.fmu_description import read_description, time_derivatives
from harness.engine.component import Component, FmuCallError
from lever.fmus.registry import NAMES as FMU_NAMES
from lever.physics import component_parameters

DEG = math.pi / 180.0
FMI2_ERROR = 3
DIMENSIONLESS = {"support_deformation", "hinge_deformation", "U12", "order_share", "narrowband_share",
                 # the rectifier's friction coefficients, contact and slip states, event count
                 "disc_friction", "ball_friction", "msm_contact", "torsion_contact", "mesh_contact", "disc_slip",
                 "flywheel_stuck", "events"}
COUPLING_INPUTS = {"phi1", "w1", "phi2", "w2", "misalignment"}


@pytest.fixture
def components(fmu_dir):
    """Factory of Components; everything it made is freed at the end of the test."""
    made = []

    def make(fmu: str, name: str = "x") -> Component:
        c = Component(name, Path(fmu_dir) / f"{fmu}.fmu")
        made.append(c)
        return c

    yield make
    for c in made:
        c.free()


def start(c: Component, params: dict | None = None, stop: float = 1.0) -> Component:
    if params:
        c.set_parameters(params)
    c.initialize(0.0, stop)
    c.exit_initialization()
    return c


# --------------------------------------------------------------------------------------
# Model descriptions
# --------------------------------------------------------------------------------------


def test_every_fmu_of_the_registry_is_built(fmu_dir):
    names = {p.stem for p in Path(fmu_dir).glob("*.fmu")}
    assert set(FMU_NAMES) <= names


def test_every_fmu_validates_without_findings(fmu_dir):
    paths = sorted(Path(fmu_dir).glob("*.fmu"))
    assert paths
    for path in paths:
        assert validate_fmu(str(path)) == [], path.name


@pytest.mark.parametrize("fmu", FMU_NAMES)
def test_units_and_descriptions(fmu_dir, fmu):
    md = fmpy.read_model_description(str(Path(fmu_dir) / f"{fmu}.fmu"))
    defined = {u.name for u in md.unitDefinitions}
    assert md.description
    for v in md.modelVariables:
        assert v.description and v.description.strip(), v.name
        if v.type != "Real" or v.causality not in ("parameter", "input", "output"):
            continue
        if v.name in DIMENSIONLESS:
            assert v.unit in (None, "", "1"), v.name
        else:
            assert v.unit, f"{fmu}.{v.name} has no unit"
            assert v.unit in defined, f"{fmu}.{v.name}: unit {v.unit} is not defined"


def test_specific_units_and_ranges(fmu_dir):
    def variables(fmu):
        md = fmpy.read_model_description(str(Path(fmu_dir) / f"{fmu}.fmu"))
        return {v.name: v for v in md.modelVariables}

    coupling, engine, load = variables("LeverCoupling"), variables("EngineShaft"), variables("LoadShaft")
    assert coupling["stiffness"].unit == "N.m/rad" and coupling["damping"].unit == "N.m.s/rad"
    assert coupling["misalignment"].unit == "rad" and coupling["misalignment"].causality == "input"
    assert float(coupling["misalignment"].max) == pytest.approx(75 * DEG)
    assert coupling["tau1"].unit == coupling["tau2"].unit == "N.m"
    assert coupling["elastic_energy"].unit == "J" and coupling["dissipated_power"].unit == "W"
    for shaft in (engine, load):
        assert shaft["inertia"].unit == "kg.m2" and float(shaft["inertia"].min) == 1e-6
        assert shaft["w"].unit == "rad/s" and shaft["phi"].unit == "rad" and shaft["a"].unit == "rad/s2"
        assert shaft["tau"].unit == "N.m" and shaft["tau"].causality == "input"
    assert engine["engine_work"].unit == "J" and load["load_work"].unit == "J"
    # start values are the KAVZ-685 defaults declared in lever.physics.component_parameters
    assert float(engine["inertia"].start) == 0.128 and float(load["inertia"].start) == 0.161
    assert coupling["transfer_mode"].start == component_parameters.DEFAULT_TRANSFER_MODE


def test_output_dependencies(fmu_dir):
    md = fmpy.read_model_description(str(Path(fmu_dir) / "LeverCoupling.fmu"))
    assert {o.variable.name for o in md.outputs} >= {"tau1", "tau2", "U12", "theta"}
    # Each output on the inputs it depends on, not on all of them (which would make false
    # algebraic loops in a generic importer): U12 is a function of the driven angle alone.
    angles = {"phi1", "phi2", "misalignment"}
    expected = {"tau1": COUPLING_INPUTS, "tau2": COUPLING_INPUTS, "U12": {"phi2", "misalignment"},
                "theta": angles, "elastic_energy": angles, "dissipated_power": {"w1", "w2", "phi2", "misalignment"}}
    for output in md.outputs:
        assert {d.name for d in output.dependencies} == expected[output.variable.name], output.variable.name
    for fmu in ("EngineShaft", "LoadShaft"):
        md = fmpy.read_model_description(str(Path(fmu_dir) / f"{fmu}.fmu"))
        assert {o.variable.name for o in md.outputs} >= {"phi", "w", "a"}
        # The state outputs do not depend on the inputs; the acceleration does, on the torque,
        # and so does the load torque (at rest static friction holds the coupling's torque).
        for output in md.outputs:
            depends = {"a"} | ({"load_torque"} if fmu == "LoadShaft" else set())
            expected = ["tau"] if output.variable.name in depends else []
            inputs = [d.name for d in output.dependencies if d.causality == "input"]
            assert inputs == expected, (fmu, output.variable.name)
        # Derivative chains a master can use to predict: w = d(phi)/dt, a = d(w)/dt,
        # tau_rate = d(tau)/dt, tau_accel = d(tau_rate)/dt; and the works' (Model Exchange states).
        derivative_of = time_derivatives(read_description(Path(fmu_dir) / f"{fmu}.fmu"))
        work = {"EngineShaft": {"der(engine_work)": "engine_work", "der(lagged_torque)": "lagged_torque"},
                "LoadShaft": {"der(load_work)": "load_work"}}[fmu]
        assert derivative_of == {"w": "phi", "a": "w", "tau_rate": "tau", "tau_accel": "tau_rate", **work}


# --------------------------------------------------------------------------------------
# Refusing bad values
# --------------------------------------------------------------------------------------

BAD_VALUES = [
    ("EngineShaft", "inertia", -1.0),
    ("LoadShaft", "inertia", -0.161),
    ("EngineShaft", "inertia", 0.0),
    ("LeverCoupling", "stiffness", 0.0),
    ("LeverCoupling", "stiffness", -715.4),
    ("LeverCoupling", "damping", math.nan),
    ("LeverCoupling", "damping", math.inf),
    ("LeverCoupling", "misalignment", 80 * DEG),
    ("LeverCoupling", "misalignment", -1 * DEG),
    ("LeverCoupling", "transfer_mode", "cardan"),
    ("LeverCoupling", "support_deformation", 0.5),
    ("LoadShaft", "load_kind", "sometimes"),
    ("LoadShaft", "tones", 0),
    ("EngineShaft", "max_substep", 0.0),
]


@pytest.mark.parametrize("fmu,name,value", BAD_VALUES)
def test_bad_value_is_refused_and_the_instance_survives(components, fmu, name, value):
    c = components(fmu)
    before = c.get([name]) if c.variable(name).type == "Real" else None
    with pytest.raises(FmuCallError) as info:
        c.set_parameters({name: value})
    error = info.value
    assert error.status == FMI2_ERROR
    text = str(error)
    assert f"'{name}'" in text
    assert "range" in text or "allowed" in text
    # The value was not applied, and the instance goes on working.
    if before is not None:
        assert c.get([name]) == before
    start(c)
    c.do_step(0.0, 1e-3)
    c.do_step(1e-3, 1e-3)
    assert all(math.isfinite(v) for v in c.get([c.description.outputs[0].variable.name]))
    c.free()


def test_do_step_before_initialisation_is_an_error(components):
    for fmu in FMU_NAMES:
        c = components(fmu)
        with pytest.raises(FmuCallError) as info:
            c.do_step(0.0, 1e-3)
        assert info.value.status == FMI2_ERROR
        assert "initialis" in str(info.value)
        start(c)
        c.do_step(0.0, 1e-3)


@pytest.mark.parametrize("h", [-1e-3, 0.0, math.nan, math.inf])
def test_bad_step_size_is_an_error(components, h):
    c = start(components("LoadShaft"), {"mean_torque": 107.5})          # a load: the good step moves w
    c.do_step(0.0, 1e-3)
    state = c.get(["phi", "w"])
    with pytest.raises(FmuCallError) as info:
        c.do_step(1e-3, h)
    assert info.value.status == FMI2_ERROR
    assert "step size" in str(info.value)
    assert c.get(["phi", "w"]) == state
    c.do_step(1e-3, 1e-3)
    assert c.get(["w"]) != [state[1]]


def test_non_contiguous_step_is_an_error(components):
    c = start(components("EngineShaft"))
    c.do_step(0.0, 1e-3)
    with pytest.raises(FmuCallError) as info:
        c.do_step(0.5, 1e-3)
    assert "contiguous" in str(info.value)
    c.do_step(1e-3, 1e-3)


def test_fixed_parameter_cannot_change_after_initialisation(components):
    c = start(components("EngineShaft"), {"inertia": 0.2})
    with pytest.raises(FmuCallError) as info:
        c.set_parameters({"inertia": 0.3})
    assert "inertia" in str(info.value) and "fixed" in str(info.value)
    assert c.get(["inertia"]) == [0.2]


def test_misalignment_beyond_the_kinematic_limit_fails_initialisation_naming_alpha(components):
    c = components("LeverCoupling")
    c.set_parameters({"transfer_mode": "kinematic", "misalignment": 44 * DEG, "support_deformation": 0.1})
    # Entering initialisation succeeds: the importer may still set the misalignment (an
    # input) there, so the combination is judged when initialisation ends.
    c.initialize(0.0, 1.0)
    with pytest.raises(FmuCallError) as info:
        c.exit_initialization()
    assert info.value.status == FMI2_ERROR
    assert "alpha" in str(info.value)
    # No stepping with an uninitialised model.
    with pytest.raises(FmuCallError):
        c.do_step(0.0, 1e-3)
    c.free()


def test_misalignment_corrected_during_initialisation_is_accepted(components):
    c = components("LeverCoupling")
    c.set_parameters({"transfer_mode": "kinematic", "misalignment": 44 * DEG, "support_deformation": 0.1})
    c.initialize(0.0, 1.0)                         # not judged yet (see above)
    c.set_parameters({"misalignment": 20 * DEG})   # an input: may be set in initialisation mode
    c.exit_initialization()
    c.do_step(0.0, 1e-3)
    assert c.get(["misalignment"]) == [20 * DEG]


# --------------------------------------------------------------------------------------
# Instances
# --------------------------------------------------------------------------------------


def run_shaft(c: Component, tau: float, steps: int, h: float = 1e-3, t0: float = 0.0):
    out = []
    vrs, values = c.real_buffer(["tau"])
    values[0] = tau
    c.write(vrs, values)
    for n in range(steps):
        c.do_step(t0 + n * h, h)
        out.append(tuple(c.get(["phi", "w", "a"])))
    return out


def test_two_instances_of_a_shaft_do_not_interfere(components):
    slow = {"load_kind": "constant", "mean_torque": 300.0}
    fast = {"load_kind": "constant", "mean_torque": 50.0, "inertia": 0.3}
    alone_slow = run_shaft(start(components("LoadShaft", "alone_slow"), slow), 100.0, 60)
    alone_fast = run_shaft(start(components("LoadShaft", "alone_fast"), fast), 100.0, 60)
    a = start(components("LoadShaft", "a"), slow)
    b = start(components("LoadShaft", "b"), fast)
    together_a, together_b = [], []
    for n in range(60):  # interleaved, step by step
        together_a += run_shaft(a, 100.0, 1, t0=n * 1e-3)
        together_b += run_shaft(b, 100.0, 1, t0=n * 1e-3)
    assert together_a == alone_slow
    assert together_b == alone_fast
    assert alone_slow[-1][1] != alone_fast[-1][1]
    # Analytic: constant torques, w = w0 + (tau - Mm) t / I.
    assert alone_slow[-1][1] == pytest.approx(39.0 + (100.0 - 300.0) * 0.06 / 0.161, rel=1e-12)
    assert alone_fast[-1][1] == pytest.approx(39.0 + (100.0 - 50.0) * 0.06 / 0.3, rel=1e-12)


def test_two_random_loads_with_different_seeds_differ_and_repeat(components):
    runs = {}
    for name, seed in (("s1", 1), ("s2", 2), ("s1again", 1)):
        runs[name] = run_shaft(start(components("LoadShaft", name), {"seed": seed, "mean_torque": 107.5,
                                                                     "random_amplitude": 8.8}), 107.5, 40)
    assert runs["s1"] == runs["s1again"]
    assert runs["s1"] != runs["s2"]


def test_all_fmus_in_one_process(components):
    """Two engines, two couplings, two loads at once, interleaved; each pair must match
    what one instance does alone."""
    def engine_alone(params):
        return run_shaft(start(components("EngineShaft", "e_alone"), params), -100.0, 30)

    def coupling_values(c, inputs):
        c.set_parameters(inputs)
        return c.get(["tau1", "tau2", "U12", "theta"])

    e1p, e2p = {"stall_torque": 623.0}, {"stall_torque": 400.0, "torque_slope": 5.0}
    c1p = {"stiffness": 715.4, "misalignment": 15 * DEG}
    c2p = {"stiffness": 1200.0, "misalignment": 25 * DEG, "transfer_mode": "scaled"}
    inputs = {"phi1": 3.2, "w1": 39.5, "phi2": 3.0, "w2": 38.0}
    expected_e1, expected_e2 = engine_alone(e1p), engine_alone(e2p)
    expected_c1 = coupling_values(start(components("LeverCoupling", "c_alone"), c1p), inputs)
    expected_c2 = coupling_values(start(components("LeverCoupling", "c_alone"), c2p), inputs)

    e1, e2 = start(components("EngineShaft", "e1"), e1p), start(components("EngineShaft", "e2"), e2p)
    c1, c2 = start(components("LeverCoupling", "c1"), c1p), start(components("LeverCoupling", "c2"), c2p)
    l1, l2 = start(components("LoadShaft", "l1")), start(components("LoadShaft", "l2"), {"mean_torque": 10.0})
    got_e1, got_e2 = [], []
    for n in range(30):
        got_e1 += run_shaft(e1, -100.0, 1, t0=n * 1e-3)
        run_shaft(l1, 100.0, 1, t0=n * 1e-3)
        c1.do_step(n * 1e-3, 1e-3)
        got_e2 += run_shaft(e2, -100.0, 1, t0=n * 1e-3)
        run_shaft(l2, 100.0, 1, t0=n * 1e-3)
        c2.do_step(n * 1e-3, 1e-3)
    assert got_e1 == expected_e1 and got_e2 == expected_e2
    assert expected_e1 != expected_e2
    assert coupling_values(c1, inputs) == expected_c1
    assert coupling_values(c2, inputs) == expected_c2
    assert expected_c1 != expected_c2
    assert l1.get(["w"]) != l2.get(["w"])


def test_state_save_and_restore_continues_bit_identically(components):
    c = start(components("LoadShaft"), {"seed": 3})
    run_shaft(c, 110.0, 20)
    state = c.save_state()
    first = run_shaft(c, 110.0, 20, t0=0.02)
    c.restore_state(state, 0.02)
    again = run_shaft(c, 110.0, 20, t0=0.02)
    c.free_state(state)
    assert again == first


def test_state_restored_after_reset_keeps_the_shaft_state(components):
    c = start(components("LoadShaft"), {"inertia": 0.2, "load_kind": "constant", "mean_torque": 50.0})
    run_shaft(c, 0.0, 100)
    saved = c.get(["phi", "w", "load_work"])
    serialized = c.fmu.serializeFMUstate(c.save_state())
    c.fmu.reset()   # back to the default parameters
    c.fmu.setFMUstate(c.fmu.deSerializeFMUstate(serialized))
    assert c.get(["inertia"]) == [0.2]
    assert c.get(["phi", "w", "load_work"]) == saved


# --------------------------------------------------------------------------------------
# Agreement with the physics package
# --------------------------------------------------------------------------------------

COUPLING_CASES = [
    {},
    {"transfer_mode": "scaled", "misalignment": 20 * DEG},
    {"transfer_mode": "synchronous", "misalignment": 60 * DEG},
    {"transfer_mode": "kinematic", "misalignment": 30 * DEG, "support_deformation": 0.05, "hinge_deformation": 0.05,
     "stiffness": 900.0, "damping": 8.5},
    {"elastic_table": "0.05:10; 0.1:16; 0.2:16.5; 0.3:26.5; 0.45:50", "damping": 0.5},
]
INPUTS = [(0.0, 39.0, 0.0, 39.0), (12.3, 40.1, 12.15, 38.2), (-3.0, -20.0, -2.4, -21.0), (1000.5, 37.0, 1000.0, 36.5),
          (5.0, 0.0, 4.4, 0.0)]
OUTPUTS = ["tau1", "tau2", "U12", "theta", "elastic_energy", "dissipated_power"]


@pytest.mark.parametrize("case", range(len(COUPLING_CASES)))
def test_coupling_fmu_outputs_equal_the_physics(components, case):
    params = COUPLING_CASES[case]
    c = start(components("LeverCoupling"), params)
    physics = component_parameters.coupling_from(params)
    for k, (phi1, w1, phi2, w2) in enumerate(INPUTS):
        c.set_parameters({"phi1": phi1, "w1": w1, "phi2": phi2, "w2": w2})
        r = physics.evaluate(phi1, w1, phi2, w2)
        expected = [r.tau1, r.tau2, r.ratio, r.deflection, r.energy, r.dissipation]
        assert c.get(OUTPUTS) == expected, (params, k)
        c.do_step(k * 1e-3, 1e-3)   # stepping changes nothing: no state
        assert c.get(OUTPUTS) == expected
    # A time-varying misalignment input.
    if params.get("transfer_mode", "kinematic") != "synchronous" and not params.get("elastic_table"):
        alpha = 10 * DEG
        c.set_parameters({"misalignment": alpha})
        r = component_parameters.coupling_from(params, misalignment=alpha).evaluate(*INPUTS[-1])
        assert c.get(["tau1", "tau2", "U12", "theta"]) == [r.tau1, r.tau2, r.ratio, r.deflection]


def test_shaft_fmus_step_like_the_physics(components):
    for fmu, make, params in (("EngineShaft", component_parameters.engine_from, {"stall_torque": 600.0, "w_start": 30.0}),
                              ("LoadShaft", component_parameters.load_from, {"seed": 5, "w_start": 35.0})):
        c = start(components(fmu), params)
        shaft = make(params)
        phi, w = 0.0, params["w_start"]
        for n, tau in enumerate((-120.0, -80.0, 95.0, 130.0)):
            got = run_shaft(c, tau, 1, h=2e-3, t0=n * 2e-3)[-1]
            phi, w, _ = shaft.advance(n * 2e-3, phi, w, tau, 2e-3)
            assert got[:2] == (phi, w), fmu


def test_a_shafts_acceleration_follows_every_torque_written_between_steps(components):
    # Only the acceleration depends on the torque: after a write it is recomputed alone,
    # from the external torque of this time and state, and equals the physics' exactly.
    params = {"seed": 5, "w_start": 35.0}
    c = start(components("LoadShaft"), params)
    shaft = component_parameters.load_from(params)
    vrs, values = c.real_buffer(["tau"])
    c.do_step(0.0, 1e-3)
    phi, w = c.get(["phi", "w"])
    for tau in (100.0, -40.0, 1e12, 250.5):
        values[0] = tau
        c.write(vrs, values)
        assert c.get(["a", "load_torque"]) == [shaft.rates(1e-3, phi, w, tau)[0], -shaft.rates(1e-3, phi, w, tau)[1]]


def test_an_input_at_its_bound_is_taken_and_the_next_float_refused(components):
    c = start(components("EngineShaft"))
    vrs, values = c.real_buffer(["tau"])
    values[0] = 1e12                      # the upper bound of tau, closed
    c.write(vrs, values)
    assert c.get(["tau"]) == [1e12]
    values[0] = math.nextafter(1e12, math.inf)
    with pytest.raises(FmuCallError):
        c.write(vrs, values)
    assert c.get(["tau"]) == [1e12]


# --------------------------------------------------------------------------------------
# The model code on the standard library alone (docs/fmus.md)
# --------------------------------------------------------------------------------------

# Runs an FMU's own Python (its resources folder): "bare", in an interpreter started with
# -I -S (no site-packages) and numpy made unimportable, else with site-packages and numpy
# loaded; initialise, 50 steps with moving inputs, every output after each step, printed
# as repr-exact JSON.
_BARE_RUN = r'''
import json, math, sys
resources, model, bare = sys.argv[1], sys.argv[2], sys.argv[3] == "bare"
if bare:
    sys.modules["numpy"] = None        # "import numpy" anywhere in the model now fails
else:
    import numpy                       # noqa: F401 - present, as in our environment
sys.path.insert(0, resources)
cls = getattr(__import__(open(resources + "/slavemodule.txt").read().strip()), model)
errors = []
slave = cls(instance_name="bare", resources=resources)
slave.log = lambda message, status=None, *rest: errors.append(message) if status and int(status) >= 3 else None
vr = {v.name: ref for ref, v in slave.vars.items()}
inputs = [p.name for p in cls.INPUTS if p.kind == "real"]
outputs = [vr[o.name] for o in cls.OUTPUTS]
slave.setup_experiment(0.0)
slave.enter_initialization_mode()
slave.exit_initialization_mode()
rows, t = [], 0.0
for k in range(50):
    values = {"tau": 80.0 * math.sin(0.3 * k), "tau_rate": 24.0 * math.cos(0.3 * k),
              "tau_accel": -7.2 * math.sin(0.3 * k), "phi1": 0.04 * k + 0.01,
              "w1": 40.0, "phi2": 0.038 * k, "w2": 38.0, "misalignment": 0.26}
    slave.set_real([vr[n] for n in inputs], [values[n] for n in inputs])
    assert slave.do_step(t, 1e-3), errors
    t += 1e-3
    rows.append(slave.get_real(outputs))
print(json.dumps({"rows": rows, "errors": errors, "third_party": sorted(
    m for m, mod in sys.modules.items() if mod is not None and m.split(".")[0] not in sys.stdlib_module_names
    and not m.startswith(("_lever_", "pythonfmu", model)) and m != "__main__")}))
'''


@pytest.mark.parametrize("fmu", FMU_NAMES)
def test_the_model_runs_on_the_standard_library_alone(fmu_dir, fmu, tmp_path):
    """The FMU's Python (model and pythonfmu's Python part, both inside the FMU) in a bare
    interpreter without numpy steps exactly as in our environment, which has numpy."""
    import json
    import subprocess
    import sys
    import zipfile

    with zipfile.ZipFile(Path(fmu_dir) / f"{fmu}.fmu") as archive:
        archive.extractall(tmp_path)
        shipped = [r for r in archive.read("resources/requirements.txt").decode().splitlines()
                   if r.strip() and not r.startswith("#")]
    assert shipped == []
    script = tmp_path / "bare_run.py"
    script.write_text(_BARE_RUN)
    runs = {}
    for label, flags in (("bare", ["-I", "-S"]), ("with numpy", ["-I"])):
        done = subprocess.run([sys.executable, *flags, str(script), str(tmp_path / "resources"), fmu, label],
                              capture_output=True, text=True, timeout=120)
        assert done.returncode == 0, (label, done.stderr[-2000:])
        runs[label] = json.loads(done.stdout)
    bare = runs["bare"]
    assert bare["errors"] == [] and bare["third_party"] == []
    assert all(math.isfinite(x) for row in bare["rows"] for x in row)
    assert bare["rows"] == runs["with numpy"]["rows"]


# --------------------------------------------------------------------------------------
# Serialized states restored into a fresh instance, after fmi2Reset, into another instance
# --------------------------------------------------------------------------------------

#: per FMU: parameters of the run that is saved, parameters of the "other" instance, and
#: the inputs at step k (moving, so that a stale output or input would show)
RESTORE_RUNS = {
    "LeverCoupling": ({"stiffness": 900.0, "support_deformation": 0.04}, {"stiffness": 500.0},
                      lambda k: {"phi1": 0.04 * k + 0.02, "w1": 40.0 + 0.1 * k, "phi2": 0.039 * k, "w2": 38.0,
                                 "misalignment": 0.26 + 0.0007 * k}),
    "EngineShaft": ({"inertia": 0.15}, {"inertia": 0.3},
                    lambda k: {"tau": -100.0 + 20.0 * math.sin(0.3 * k), "tau_rate": 6.0 * math.cos(0.3 * k),
                               "tau_accel": -1.8 * math.sin(0.3 * k)}),
    "LoadShaft": ({"seed": 3, "load_kind": "random"}, {"seed": 4},
                  lambda k: {"tau": 110.0 + 20.0 * math.sin(0.3 * k), "tau_rate": 6.0 * math.cos(0.3 * k),
                             "tau_accel": -1.8 * math.sin(0.3 * k)}),
    "MisalignmentSource": ({"table": "0:0.2; 1:0.3"}, {"table": "0:0.1; 1:0.1"}, lambda k: {}),
    "FreewheelRectifier": ({}, {}, lambda k: {"tau": 0.5 * math.sin(0.2 * k)}),
}


class _Fmi:
    """One fmpy FMU2Slave instance, driven by variable names."""

    def __init__(self, fmu_dir, fmu: str, name: str):
        from fmpy.fmi2 import FMU2Slave
        from harness.engine.component import unzipped

        path = Path(fmu_dir) / f"{fmu}.fmu"
        self.md = fmpy.read_model_description(str(path))
        self.vr = {v.name: v for v in self.md.modelVariables}
        self.slave = FMU2Slave(guid=self.md.guid, unzipDirectory=unzipped(path),
                               modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=name)
        self.slave.instantiate(loggingOn=False)
        self.outputs = [v.valueReference for v in self.md.modelVariables if v.causality == "output"]

    def set(self, values: dict):
        for name, value in values.items():
            typed_values.set_on(self.slave, self.vr[name], value, name)

    def start(self, parameters: dict):
        self.set(parameters)
        self.slave.setupExperiment(startTime=0.0)
        self.slave.enterInitializationMode()
        self.slave.exitInitializationMode()

    def run(self, inputs, first: int, steps: int, h: float = 1e-3) -> list:
        rows = []
        for k in range(first, first + steps):
            self.set(inputs(k))
            self.slave.doStep(k * h, h)
            rows.append(self.slave.getReal(self.outputs))
        return rows

    def free(self):
        self.slave.terminate()
        self.slave.freeInstance()


@pytest.mark.parametrize("defaults", [True, False], ids=["default parameters", "parameters set"])
@pytest.mark.parametrize("into", ["a fresh instance", "an instance after fmi2Reset", "another running instance"])
@pytest.mark.parametrize("fmu", FMU_NAMES)
def test_a_serialized_state_continues_exactly_wherever_it_is_restored(fmu_dir, fmu, into, defaults):
    """FMI 2.0 lets an importer restore a serialized state into any instance of the FMU
    (fmi2Instantiate, fmi2DeSerializeFMUstate, fmi2SetFMUstate, fmi2DoStep): the run goes
    on exactly as the uninterrupted one, outputs bit for bit.  With default parameters a
    fresh instance has nothing to rebuild from them: the model must still be built."""
    parameters, other_parameters, inputs = RESTORE_RUNS[fmu]
    if defaults:
        parameters = {}
    saved = _Fmi(fmu_dir, fmu, "saved")
    target = _Fmi(fmu_dir, fmu, "target")
    try:
        saved.start(parameters)
        saved.run(inputs, 0, 30)
        data = saved.slave.serializeFMUstate(saved.slave.getFMUstate())
        uninterrupted = saved.run(inputs, 30, 30)
        if into != "a fresh instance":
            target.start(other_parameters)
            target.run(lambda k: inputs(k + 7), 0, 12)
            if into == "an instance after fmi2Reset":
                target.slave.reset()
        target.slave.setFMUstate(target.slave.deSerializeFMUstate(data))
        assert target.run(inputs, 30, 30) == uninterrupted
    finally:
        saved.free()
        target.free()


def test_a_state_saved_while_friction_holds_the_load_continues_exactly(fmu_dir):
    """A resisting load's stuck flag is its speed at exactly 0 (lever.physics.friction):
    a state serialized while static friction holds the shaft, restored into a fresh
    instance, goes on through the next breakaways and stops bit for bit as the
    uninterrupted run."""
    parameters = {"load_kind": "constant", "mean_torque": 20.0, "load_direction": "resistive",
                  "friction_torque": 2.0, "breakaway_torque": 3.0, "viscous_damping": 0.1, "w_start": 0.5,
                  "inertia": 0.05}

    def inputs(k):   # swings beyond the 23 N.m held at rest and back: slips, stops, sticks
        return {"tau": 30.0 * math.sin(0.21 * k), "tau_rate": 6.3 * math.cos(0.21 * k)}

    saved, target = _Fmi(fmu_dir, "LoadShaft", "saved"), _Fmi(fmu_dir, "LoadShaft", "target")
    try:
        saved.start(parameters)
        before = saved.run(inputs, 0, 32)
        w = saved.vr["w"].valueReference
        assert saved.slave.getReal([w]) == [0.0]          # held since step 30
        data = saved.slave.serializeFMUstate(saved.slave.getFMUstate())
        uninterrupted = saved.run(inputs, 32, 28)
        target.slave.setFMUstate(target.slave.deSerializeFMUstate(data))
        assert target.run(inputs, 32, 28) == uninterrupted
        speeds = [row[saved.outputs.index(w)] for row in before + uninterrupted]
        assert any(s > 0 for s in speeds) and any(s < 0 for s in speeds) and speeds.count(0.0) >= 10
    finally:
        saved.free()
        target.free()


def test_the_load_shaft_alone_idles_with_its_defaults(fmu_dir):
    """Run stand-alone with no input and its defaults, the driven shaft keeps its start speed
    (no load until one is set) instead of being driven backwards by an unopposed resistance."""
    from fmpy import simulate_fmu

    result = simulate_fmu(str(fmu_dir / "LoadShaft.fmu"), stop_time=1.0, output_interval=1e-3, output=["w", "phi"])
    assert result["w"][0] == 39.0 and np.all(np.abs(result["w"] - 39.0) <= 1e-9), result["w"][-1]
    assert result["phi"][-1] == pytest.approx(39.0, rel=1e-6)


def test_a_state_with_reals_written_as_integers_restores_them_as_floats():
    """A serialized state written by hand or by another tool may spell a real as an integer
    (``"w": 39``); the models keep their reals as floats, which the Model Exchange hot path
    reads as they are: restored, the values are floats, and the run goes on exactly as
    from the state written with floats."""
    import json

    from lever.fmus import shafts
    from lever.fmus.states import STATE_MAGIC

    def started():
        slave = shafts.LoadShaft(instance_name="load", resources=None)
        slave.setup_experiment(0.0)
        slave.enter_initialization_mode()
        slave.exit_initialization_mode()
        return slave

    def with_integers(data: bytes) -> bytes:
        head, payload = data.split(b"\n", 1)
        state = json.loads(payload)
        state["variables"].update(phi=0, w=39, load_work=0)       # the start: 0.0, 39.0, 0.0
        payload = json.dumps(state).encode()
        header = json.loads(head[len(STATE_MAGIC) + 1:])
        header["length"] = len(payload)
        return STATE_MAGIC + b" " + json.dumps(header).encode() + b"\n" + payload

    cls = shafts.LoadShaft
    data = cls._fmu_state_to_bytes(started()._get_fmu_state())
    assert b'"w": 39.0' in data
    runs = []
    for blob in (data, with_integers(data)):
        slave = cls(instance_name="target", resources=None)
        slave._set_fmu_state(cls._fmu_state_from_bytes(blob))
        assert not slave.log_queue, [str(m) for m in slave.log_queue]
        assert all(type(getattr(slave, name)) is float for name in ("phi", "w", "load_work"))
        outputs = [vr for vr, v in slave.vars.items() if v.name in ("phi", "w", "a", "load_torque", "load_work")]
        rows = []
        for k in range(5):
            slave.set_real([slave._vr_of["tau"]], [10.0 * k])
            assert slave.do_step(k * 1e-3, 1e-3)
            rows.append(slave.get_real(outputs))
        runs.append(rows)
    assert runs[0] == runs[1]


@pytest.mark.parametrize("name", FMU_NAMES)
def test_a_deserialized_state_serializes_to_the_same_bytes(fmu_dir, name, tmp_path):
    """fmi2SerializeFMUstate of a state made by fmi2DeSerializeFMUstate gives the bytes it
    was made from (it was fatal once: the instance was lost)."""
    from fmpy.fmi2 import FMU2Slave
    path = str(Path(fmu_dir) / f"{name}.fmu")
    md = fmpy.read_model_description(path)
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=fmpy.extract(path, unzipdir=str(tmp_path)), modelIdentifier=name,
                    instanceName=name)
    fmu.instantiate()
    try:
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        fmu.doStep(0.0, 1e-3)
        state = fmu.getFMUstate()
        blob = fmu.serializeFMUstate(state)
        again = fmu.deSerializeFMUstate(blob)
        assert fmu.serializeFMUstate(again) == blob
        fmu.setFMUstate(again)
        fmu.doStep(1e-3, 1e-3)
        for s in (state, again):
            fmu.freeFMUstate(s)
    finally:
        fmu.terminate()
        fmu.freeInstance()


def test_outputs_read_in_initialisation_follow_the_parameters_set_there(components):
    """A parameter set in Initialization Mode makes the model an output read there comes
    from (never the values of the model before, with OK), as a fresh instance with that
    parameter set before initialisation gives it."""
    fresh = components("EngineShaft", "fresh")
    fresh.set_parameters({"stall_torque": 900.0})
    fresh.initialize(0.0, 1.0)
    expected = fresh.get(["engine_torque", "a"])
    c = components("EngineShaft")
    c.initialize(0.0, 1.0)
    before = c.get(["engine_torque", "a"])
    c.set_parameters({"stall_torque": 900.0})
    assert c.get(["engine_torque", "a"]) == expected != before
    c.exit_initialization()
    assert c.get(["engine_torque", "a"]) == expected


def test_a_description_is_parsed_once_per_content_and_read_afresh_when_the_fmu_changes(fmu_dir, tmp_path):
    """The same model description read again (another run, a copy at another path) is the
    object read first; an FMU rewritten in place with another description - same path, even
    the same size - is read afresh, as its own file says."""
    import shutil
    import zipfile

    original = Path(fmu_dir) / "LeverCoupling.fmu"
    first = read_description(original)
    copy = shutil.copy(original, tmp_path / "LeverCoupling.fmu")
    assert read_description(copy) is first and read_description(original) is first
    with zipfile.ZipFile(original) as z:
        members = {name: z.read(name) for name in z.namelist()}
    xml = members["modelDescription.xml"].decode()
    assert 'description="' in xml
    at = xml.index('description="') + len('description="')
    members["modelDescription.xml"] = (xml[:at] + "X" + xml[at + 1:]).encode()     # one character, same size
    with zipfile.ZipFile(copy, "w") as z:
        for name, data in members.items():
            z.writestr(name, data)
    changed = read_description(copy)
    assert changed is not first and changed.description == "X" + first.description[1:]
    assert time_derivatives(changed) == time_derivatives(first)


def test_a_settled_description_file_is_not_opened_again_and_a_changed_one_is(fmu_dir, tmp_path, monkeypatch):
    """A file read before and unchanged since (its identity: inode, size, times) is not
    opened again; one changed since is read afresh.  Files changed within the last
    ``SETTLED`` seconds are always read (the test above); here every file counts as settled."""
    import shutil
    import zipfile
    from harness.description import fmu_description

    monkeypatch.setattr(fmu_description, "SETTLED", -1.0)
    copy = Path(shutil.copy(Path(fmu_dir) / "LeverCoupling.fmu", tmp_path / "LeverCoupling.fmu"))
    first = read_description(copy)
    opened = []
    real_zipfile = zipfile.ZipFile
    monkeypatch.setattr(zipfile, "ZipFile", lambda *a, **k: opened.append(a) or real_zipfile(*a, **k))
    assert read_description(copy) is first and opened == []
    with real_zipfile(copy) as z:
        members = {name: z.read(name) for name in z.namelist()}
    xml = members["modelDescription.xml"].decode()
    at = xml.index('description="') + len('description="')
    members["modelDescription.xml"] = (xml[:at] + "Changed: " + xml[at:]).encode()
    with real_zipfile(copy, "w") as z:
        for name, data in members.items():
            z.writestr(name, data)
    changed = read_description(copy)
    assert opened and changed is not first and changed.description.startswith("Changed: ")


def test_a_read_of_an_unknown_value_reference_is_an_error_and_reads_go_on(components):
    """fmi2GetReal of a value reference that is no Real variable is an error naming it
    (alone or among known ones, read first or after the same list was read), and the
    known ones read as before after it, alone, in pairs and in any order."""
    import ctypes

    c = start(components("EngineShaft"))
    c.do_step(0.0, 1e-3)
    phi, w = c.vr("phi"), c.vr("w")
    get = c.fmu._functions["fmi2GetReal"]

    def read(vrs):
        out = (ctypes.c_double * len(vrs))()
        status = get(c.fmu.component, (ctypes.c_uint * len(vrs))(*vrs), len(vrs), out)
        return status, list(out)

    assert read([w, phi]) == (0, [c.get(["w"])[0], c.get(["phi"])[0]])
    for vrs in ([99999], [w, 99999], [99999, phi]):
        status, _ = read(vrs)
        assert status == FMI2_ERROR and any("value reference 99999" in m for m in c.messages), vrs
        c.messages.clear()
    assert read([w, phi])[1] == read([w])[1] + read([phi])[1] and read([phi, w])[1] == read([phi])[1] + read([w])[1]
