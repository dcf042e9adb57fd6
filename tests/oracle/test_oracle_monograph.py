"""The sources' printed numbers, typed into this file from the texts themselves, against the model.

Sources (docs/physics.md#bibliography): the monograph by Davidbaev, Juraev, Zulpiev and
Davidbaeva (Fig. 3.7's amplitudes, printed in the text of section 3.2 below the figure),
docs/physics.md#the-half-coupling-function and #the-three-modes (the half-coupling
function's and the kinematic construction's amplitudes), the nonlinear elastic coupling
paper by Sydorenko and Kurgan (Table 1, "input parameters of the synthesis of the target
elastic characteristic") and the freewheel rectifier paper by Khudorozhkov and Yurkevich
(Table 1, "input data for the calculation of the dynamics").  Nothing here is read from
the code under test: where the model is compared with a printed figure, the tolerance
says how far the model is allowed to be and why.
"""
from __future__ import annotations

import math
from contextlib import contextmanager

import fmpy
import numpy as np
import pytest
from fmpy.fmi2 import FMU2Slave

from harness.description import scene
from harness.engine import component
from lever.physics import kinematics
from lever.physics.kinematics import TransferFunction, half_coupling_ratio

pytestmark = pytest.mark.oracle

DEG = math.pi / 180.0

# Fig. 3.7, as printed (monograph lines 912-914): (alpha [deg], D2s/l2, D2h/lc2, dU12).
# The text names only the deformation it varies; the other is the figure's 0.03 (a
# stated assumption of docs/record/decisions.md, "Interpolating the reported amplitudes").
FIG_3_7 = (
    (5.0, 0.03, 0.03, 0.065),    # "at alpha = 5 deg ... 0.065 at D2/l2 = 0,03"
    (30.0, 0.05, 0.03, 0.34),    # "to 30 deg at D2/l2 = 0,05 ... reaches 0.34"
    (20.0, 0.02, 0.03, 0.139),   # "at D2/l2 = 0,02 ... dU12 = 0,139 at alpha = 20 deg"
    (20.0, 0.09, 0.03, 0.264),   # "with an increase of D2/l2 to 0.09 ... 0.264"
    (20.0, 0.03, 0.02, 0.136),   # "D2'/lc2 from 0.02 to 0.09 ... from 0.136"
    (20.0, 0.03, 0.09, 0.231),   # "... to 0.231"
)

# The scaled mode interpolates the six points by k sin(alpha)^p (D2s^q + D2h^r), four
# constants (docs/record/decisions.md): it cannot pass through all six.  Measured deviations of
# the scaled U12's amplitude from the printed ones (in the order above): -5.2 %, -17.5 %,
# +0.7 %, +8.0 %, +13.6 %, +3.5 %.  Allowed: 20 % (1.14x the largest).  A mistyped point (0.34 -> 0.034)
# bends the fit by -64 % at that point and by 30-40 % at others.
FIT_TOLERANCE = 0.20


def amplitude(tf: TransferFunction) -> float:
    """(max - min)/2 of U12 over a revolution, sampled here (not the model's own figure)."""
    ratio = np.array([tf.ratio(x) for x in np.linspace(0.0, 2.0 * np.pi, 20001)])
    return float((ratio.max() - ratio.min()) / 2.0)


@contextmanager
def coupling_fmu(fmu_dir, instance: str, parameters: dict):
    """The coupling FMU through fmpy, ``parameters`` set (strings and reals), initialised:
    yields ``(fmu, value references by name)``, terminated and freed after."""
    md = fmpy.read_model_description(str(fmu_dir / "LeverCoupling.fmu"))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=component.unzipped(fmu_dir / "LeverCoupling.fmu"),
                    modelIdentifier=md.coSimulation.modelIdentifier, instanceName=instance)
    fmu.instantiate(callbacks=component.log_callbacks(), loggingOn=False)
    try:
        for name, value in parameters.items():
            if isinstance(value, str):
                fmu.setString([vr[name]], [value])
            else:
                fmu.setReal([vr[name]], [float(value)])
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        yield fmu, vr
        fmu.terminate()
    finally:
        fmu.freeInstance()


@pytest.mark.parametrize("alpha_deg,support,hinge,printed", FIG_3_7)
def test_scaled_mode_reproduces_the_printed_fig_3_7_amplitudes(alpha_deg, support, hinge, printed):
    found = amplitude(TransferFunction("scaled", alpha_deg * DEG, support, hinge))
    assert abs(found / printed - 1.0) <= FIT_TOLERANCE, (
        f"Fig. 3.7 amplitude at alpha = {alpha_deg} deg, D2s/l2 = {support}, D2h/lc2 = {hinge}: the scaled mode "
        f"gives {found:.4g}, the monograph prints {printed}: the monograph's Fig. 3.7 points are mistyped or the "
        "scaled mode's interpolation is wrong")


def test_the_scaled_modes_data_are_the_printed_fig_3_7_points():
    assert sorted(kinematics.MONOGRAPH_AMPLITUDES) == sorted(FIG_3_7), (
        "the monograph's Fig. 3.7 amplitudes in lever.physics.kinematics differ from the printed text")


def test_scaled_mode_through_the_fmu_at_the_30_degree_point(fmu_dir):
    """The coupling FMU in scaled mode, driven over a revolution of phi2 at the
    monograph's 30 deg / 0.05 point: its U12 output's amplitude is the printed 0.34 within
    the fit's tolerance."""
    parameters = {"transfer_mode": "scaled", "misalignment": 30 * DEG, "support_deformation": 0.05,
                  "hinge_deformation": 0.03}
    with coupling_fmu(fmu_dir, "oracle-fig-3-7", parameters) as (fmu, vr):
        ratios = []
        for k, phi in enumerate(np.linspace(0.0, 2.0 * np.pi, 721)):
            fmu.setReal([vr["phi2"]], [phi])
            fmu.doStep(k * 1e-3, 1e-3)
            ratios.append(fmu.getReal([vr["U12"]])[0])
    found = (max(ratios) - min(ratios)) / 2.0
    assert abs(found / 0.34 - 1.0) <= FIT_TOLERANCE, f"coupling FMU, scaled mode: dU12 = {found:.4g}, printed 0.34"


def test_half_coupling_function_amplitudes_of_model_md():
    """docs/physics.md#the-half-coupling-function: g's peak deviation from 1 is 0.030 at 10 deg and 0.22 at 30 deg
    (the text swaps them).  With s2 = sin^2 alpha, g = sqrt((1 - 2 s2 cos 2phi)/(1 - 2 s2 cos^2 phi))
    is 1 at phi = 0 and largest at phi = pi/2, sqrt(1 + 2 s2): the peak deviation is
    sqrt(1 + 2 sin^2 alpha) - 1 = 0.0297 (10 deg), 0.2247 (30 deg)."""
    phi = np.linspace(0.0, 2.0 * np.pi, 20001)
    for alpha_deg, printed in ((10.0, 0.030), (30.0, 0.22)):
        peak = max(half_coupling_ratio(x, alpha_deg * DEG) for x in phi) - 1.0
        assert peak == pytest.approx(math.sqrt(1.0 + 2.0 * math.sin(alpha_deg * DEG) ** 2) - 1.0, rel=1e-9)
        assert peak == pytest.approx(printed, abs=0.005), (alpha_deg, peak)


@pytest.mark.parametrize("alpha_deg,deformation,stated", [(5.0, 0.03, 0.003), (30.0, 0.05, 0.022)])
def test_kinematic_amplitudes_of_model_md(alpha_deg, deformation, stated):
    """docs/physics.md#the-three-modes: the kinematic construction's dU12 is "about 0.003 at alpha = 5 deg,
    D/l = 0.03 and about 0.022 at 30 deg, 0.05" (both deformations equal).  The text gives
    one significant figure's worth ("about"): 5 %."""
    found = amplitude(TransferFunction("kinematic", alpha_deg * DEG, deformation, deformation))
    assert found == pytest.approx(stated, rel=0.05)


# -- the nonlinear law: Table 1 of the nonlinear elastic coupling paper (Sydorenko & Kurgan) ---------------

# Row number: (what, value), as printed (decimal commas made points).
NONLINEAR_TABLE_1 = {
    1: ("moment of the working range [N*m]", 50.0),
    2: ("twist angle of the working range [rad]", 0.45),
    3: ("number of plateaus", 2),
    4: ("moment at the start of plateau 1 [N*m]", 16.0),
    5: ("angle at the start of plateau 1 [rad]", 0.1),
    6: ("minimal moment of plateau 1 [N*m]", 16.0),
    7: ("angle of the minimal moment of plateau 1 [rad]", 0.1),
    8: ("length of plateau 1 [rad]", 0.1),
    9: ("moment at the start of plateau 2 [N*m]", 26.5),
    10: ("angle at the start of plateau 2 [rad]", 0.3),
    11: ("moment of characteristic point Q [N*m]", 10.0),
    12: ("angle of characteristic point Q [rad]", 0.05),
    13: ("moment of characteristic point Q1 [N*m]", 37.0),
    14: ("angle of characteristic point Q1 [rad]", 0.44),
}


def coupling_torque(fmu_dir, parameters: dict, thetas) -> list[float]:
    """T(theta) of the coupling FMU: drive flange at theta, driven at 0, at rest, alpha = 0."""
    with coupling_fmu(fmu_dir, "oracle-nonlinear-law", {**parameters, "misalignment": 0.0, "damping": 0.0}) as (fmu, vr):
        torques = []
        for k, theta in enumerate(thetas):
            fmu.setReal([vr["phi1"], vr["phi2"], vr["w1"], vr["w2"]], [theta, 0.0, 0.0, 0.0])
            fmu.doStep(k * 1e-3, 1e-3)
            torques.append(-fmu.getReal([vr["tau1"]])[0])      # tau1 = -T on the drive shaft
    return torques


def test_plateau_scenes_law_through_the_fmu_is_the_papers_table_1(fmu_dir):
    t = {k: v for k, (_, v) in NONLINEAR_TABLE_1.items()}
    spec = scene.load("kavz685_plateaus")
    table = spec.components["coupling"].parameters["elastic_table"]
    points = [(t[12], t[11]), (t[5], t[4]), (t[10], t[9]), (t[14], t[13]), (t[2], t[1])]
    plateau_1 = np.linspace(t[5], t[5] + t[8], 11)
    thetas = [a for a, _ in points] + list(plateau_1) + [-a for a, _ in points]
    torque = coupling_torque(fmu_dir, {"elastic_table": table, "transfer_mode": "synchronous"}, thetas)
    n = len(points)
    # The characteristic passes through the printed points (a monotone cubic through the
    # knots: exact to rounding) and is odd-symmetric.
    for (angle, moment), found, mirrored in zip(points, torque[:n], torque[-n:]):
        assert found == pytest.approx(moment, rel=1e-9), (
            f"nonlinear law's Table 1: T({angle} rad) = {found:.6g} N*m through the FMU, the paper prints {moment}")
        assert mirrored == pytest.approx(-moment, rel=1e-9), f"T(-{angle}) = {mirrored}: the law is not odd"
    # Plateau 1: from 0.1 rad over its printed length 0.1 rad the moment stays at its
    # printed minimum 16 N*m; the scene assumes a rise of 0.5 N*m (its notes), nothing more.
    inside = torque[n:n + len(plateau_1)]
    assert min(inside) >= t[6] - 1e-9 and max(inside) <= t[6] + 0.5 + 1e-9, (
        f"plateau 1 of the nonlinear law's Table 1 is not flat at {t[6]} N*m over {t[8]} rad: {inside}")


# -- the freewheel: Table 1 of the freewheel rectifier paper (Khudorozhkov & Yurkevich) ---------------------

# Parameter -> value as printed (gaps in degrees there; stored in rad).  m2 = 0.28 kg
# (mass of a half-coupling) has no parameter: the model's axial dynamics use P_pr and the
# ramps' geometry only (docs/physics.md#freewheel-rectifier says why).
FREEWHEEL_TABLE_1 = {
    "disc_friction": 0.05,             # f_s
    "ball_friction": 0.001,            # f_k
    "ramp_angle": 0.3054,              # alpha, rad
    "contact_radius": 0.026,           # r, m
    "friction_pairs": 9,               # n
    "drag_torque": 0.85,               # M_v, N*m
    "drag_damping": 0.075,             # k_v, N*m/(rad/s)
    "spring_force": 6.0,               # P_pr, N
    "msm_gap": 1.74 * DEG,             # Z1, deg
    "torsion_gap": 2.23 * DEG,         # Z2, deg
    "mesh_gap": 1.1 * DEG,             # Z3, deg
    "half_coupling_inertia": 0.000202,  # J2
    "driven_parts_inertia": 0.000217,   # J3
    "torsion_end_inertia": 0.0014,      # J4
    "flywheel_inertia": 5.0,            # J5 (stop mode; real 0.00225)
    "rocker_amplitude": 0.103,          # F10, rad
    "mesh_damping": 0.3,                # k_z
    "torsion_damping": 0.3,             # k_t
    "torsion_stiffness": 3798.0,        # C_t, N*m/rad
    "mesh_stiffness": 25000.0,          # C_z, N*m/rad
    "msm_stiffness": 10313.0,           # C_fi, N*m/rad
    "input_speed": 42.41,               # the stop-mode test at 405 rpm (the paper's test)
}


def test_freewheel_fmu_and_scene_carry_the_papers_table_1(fmu_dir):
    md = fmpy.read_model_description(str(fmu_dir / "FreewheelRectifier.fmu"))
    start = {v.name: v.start for v in md.modelVariables if v.causality == "parameter"}
    spec = scene.load("freewheel_rectifier")
    in_scene = {k: scene.quantity(v) for k, v in spec.components["rectifier"].parameters.items()}
    assert 405 * 2 * math.pi / 60 == pytest.approx(FREEWHEEL_TABLE_1["input_speed"], abs=5e-3)
    for name, printed in FREEWHEEL_TABLE_1.items():
        assert float(start[name]) == pytest.approx(printed, rel=1e-12), (
            f"freewheel paper's Table 1: {name} = {printed}, the FMU's default is {start[name]}")
        assert float(in_scene[name]) == pytest.approx(printed, rel=1e-12), (
            f"freewheel paper's Table 1: {name} = {printed}, the scene sets {in_scene[name]}")
