"""The parameters of each component, with the KAVZ-685 values (docs/physics.md#kavz-685) as
defaults, and the constructors that turn a parameter dict into physics objects.

The FMU adapters declare their FMI variables from these lists and build their models with
these constructors; the monolithic reference solver does the same, so both always model
the same equations with the same numbers.
"""
from __future__ import annotations

import math

from .coupling import CouplingFamily, LeverCoupling, build_coupling
from .elastic import TabulatedElasticLaw, elastic_law
from .engine import engine_characteristic
from .kinematics import GEOMETRIC_LIMIT, MODES, transfer_function
from .friction import DIRECTIONS, ResistingLoad
from .load import LOAD_KINDS, FourierLoad, Spectrum, TabulatedLoad, load_model
from .parameters import Parameter, ParameterError, check_all
from .signals import TimeTable
from .shaft import LaggedShaft, Shaft

INF = math.inf

#: The transfer-function mode of the KAVZ-685 scene and of the coupling FMU's default.
#: Chosen by comparing both modes with the monograph's reported amplitudes and the
#: measurements (docs/record/decisions.md): "kinematic".
DEFAULT_TRANSFER_MODE = "kinematic"

COUPLING = (
    Parameter("stiffness", 715.4, "N.m/rad", "reduced torsional stiffness c of the elastic elements",
              0.0, 1e9, low_open=True),
    Parameter("damping", 6.35, "N.m.s/rad", "reduced damping (dissipation) coefficient b of the elastic elements",
              0.0, 1e7),
    Parameter("support_deformation", 0.03, "1", "relative deformation D2s/l2 of the driven shaft's elastic support",
              0.0, 0.5, high_open=True),
    Parameter("hinge_deformation", 0.03, "1", "relative deformation D2h/lc2 of the earring-connecting rod elastic hinge",
              0.0, 0.5, high_open=True),
    Parameter("transfer_mode", DEFAULT_TRANSFER_MODE, "", "transfer function U12: synchronous (U12 = 1), kinematic "
              "(from the half-coupling function) or scaled (amplitude of the monograph's Fig. 3.7)",
              kind="string", choices=MODES),
    Parameter("elastic_table", "", "", "nonlinear elastic law T_el(theta) as 'theta:torque; ...' points for "
              "theta >= 0 (rad, N.m), monotone, odd-symmetric; empty for the linear law stiffness*theta",
              kind="string", parser=TabulatedElasticLaw.parse),
)

#: The misalignment is an input (it may vary in time, like Simscape's universal joint);
#: left unconnected it keeps its start value.
MISALIGNMENT = Parameter("misalignment", math.radians(15.0), "rad",
                         "misalignment angle alpha between the drive and driven shaft axes",
                         0.0, GEOMETRIC_LIMIT, high_open=True, fixed=False)

ENGINE = (
    # Inertias from 1e-6 kg.m2 (a 1 cm steel disc; any shaft is far above): below it the
    # accelerations of admissible torques overflow.
    Parameter("inertia", 0.128, "kg.m2", "reduced moment of inertia I1 of the drive shaft", 1e-6, 1e6),
    Parameter("stall_torque", 623.0, "N.m", "M1 of the linearised engine characteristic Mg = M1 - K1*w", -1e6, 1e6),
    Parameter("torque_slope", 14.06, "N.m.s/rad", "K1 of the linearised engine characteristic Mg = M1 - K1*w",
              0.0, 1e6),
    Parameter("characteristic", "", "", "static engine characteristic Mg(w) as 'w:torque; ...' points (rad/s, N.m); "
              "empty for the linear zone M1 - K1*w; 'kavz685' for the monograph's Fig. 3.9 shape (start-up torque, "
              "nominal point, idle)", kind="string", parser=lambda text: engine_characteristic(0, 0, text)),
    # Simscape's Generic Engine: a torque time constant, 0.2 s by default; an engine's
    # torque build-up takes 0.05-0.5 s.  100 s: beyond any engine, still computable.
    Parameter("torque_lag", 0.0, "s", "time constant Te of the engine torque's first-order lag behind the "
              "static characteristic, Te*dM/dt = Mg(w) - M; 0 (or below 1e-6 s): the torque follows the speed "
              "instantly", 0.0, 100.0),
    Parameter("torque_start", 0.0, "N.m", "engine torque M at the start when torque_lag > 0 (0: the throttle "
              "opens at t = 0; Mg(w_start): already in balance); unused when torque_lag = 0", -1e6, 1e6),
    Parameter("phi_start", 0.0, "rad", "drive shaft angle at the start", -1e9, 1e9),
    Parameter("w_start", 39.0, "rad/s", "drive shaft speed at the start", -1e5, 1e5),
    Parameter("max_substep", 2.5e-4, "s", "largest internal integration step where no closed form applies",
              0.0, 1.0, low_open=True),
)

LOAD = (
    Parameter("inertia", 0.161, "kg.m2", "reduced moment of inertia I2 of the driven shaft", 1e-6, 1e6),
    Parameter("load_kind", "random", "", "technological load: constant, random (mean + seeded band-limited part, "
              "which may carry a shaft-order component and a narrow band: order_share, narrowband_share), fourier "
              "(angle-periodic series) or table (time series)", kind="string", choices=LOAD_KINDS),
    # No load by default: the FMU alone idles at w_start instead of being driven backwards by
    # an unopposed resistance; the scenes state their loads (kavz685: 107.5 +- 8.8 N*m).
    Parameter("mean_torque", 0.0, "N.m", "mean technological resistance Mm", -1e6, 1e6),
    Parameter("random_amplitude", 0.0, "N.m", "bound dM of the random part: |Mc - Mm| <= dM", 0.0, 1e6),
    Parameter("seed", 1, "", "seed of the random part (same seed, same load)", 0, 2 ** 31 - 1, kind="integer"),
    Parameter("tones", 6, "", "number of sinusoids in the random part", 1, 256, kind="integer"),
    Parameter("band_low", 2.0, "rad/s", "lowest angular frequency of the random part", 0.0, 1e5, low_open=True),
    Parameter("band_high", 450.0, "rad/s", "highest angular frequency of the random part", 0.0, 1e5, low_open=True),
    Parameter("fourier", "", "", "angle-periodic resistance 'M_mean; a1:b1; a2:b2; ...' (N.m), series (4.4)",
              kind="string", parser=FourierLoad.parse),
    Parameter("table", "", "", "resistance time series 't:torque; ...' (s, N.m), linear, ends held",
              kind="string", parser=TabulatedLoad.parse),
    Parameter("phi_start", 0.0, "rad", "driven shaft angle at the start", -1e9, 1e9),
    Parameter("w_start", 39.0, "rad/s", "driven shaft speed at the start", -1e5, 1e5),
    Parameter("max_substep", 2.5e-4, "s", "largest internal integration step where no closed form applies",
              0.0, 1.0, low_open=True),
    # Resisting loads: friction and the technological resistance as a brake.
    Parameter("load_direction", "active", "", "how Mc acts: active (a torque of fixed direction whatever the "
              "motion, e.g. a hoist) or resistive (a brake: against the motion with magnitude max(Mc, 0), holding "
              "the shaft at rest up to it)", kind="string", choices=DIRECTIONS),
    Parameter("friction_torque", 0.0, "N.m", "Coulomb friction Fc on the driven shaft, against the motion while "
              "it slips", 0.0, 1e6),
    Parameter("breakaway_torque", 0.0, "N.m", "static friction Fs: the largest net torque that does not move "
              "the shaft from rest (Fs >= Fc)", 0.0, 1e6),
    Parameter("viscous_damping", 0.0, "N.m.s/rad", "viscous friction b_v on the driven shaft: torque -b_v*w",
              0.0, 1e6),
    # The spectrum the monograph's oscillograms show (docs/physics.md#the-oscillograms-spectrum), carried by the random
    # part when a share is above 0 (Real parameters only: a String the fmpy.ssp peer cannot set).
    Parameter("order", 1, "", "shaft order k of the angle-locked component (k per revolution of the driven "
              "shaft)", 1, 64, kind="integer"),
    Parameter("order_share", 0.0, "1", "share of the bound dM that the angle-locked component "
              "dM*order_share*sin(k*phi + psi) takes (load_kind random; 0: no such component)", 0.0, 1.0),
    Parameter("order_phase", 0.0, "rad", "phase psi of the angle-locked component", -1e3, 1e3),
    Parameter("narrowband_share", 0.0, "1", "share of the bound dM that the narrow band takes (seeded tones in "
              "narrowband_low...narrowband_high; the broad multisine takes the rest: |Mc - Mm| <= dM)", 0.0, 1.0),
    Parameter("narrowband_low", 415.0, "rad/s", "lowest angular frequency of the narrow band", 0.0, 1e5,
              low_open=True),
    Parameter("narrowband_high", 425.0, "rad/s", "highest angular frequency of the narrow band", 0.0, 1e5,
              low_open=True),
    Parameter("narrowband_tones", 5, "", "number of sinusoids in the narrow band", 1, 256, kind="integer"),
)


def check_coupling(values: dict, misalignment: float | None = None) -> tuple[dict, float]:
    """The coupling's checked values (``COUPLING``) and its checked misalignment
    (``misalignment`` where given, else the ``misalignment`` value, else the default)."""
    p = check_all(COUPLING, {k: v for k, v in values.items() if k != "misalignment"})
    return p, MISALIGNMENT.check(values.get("misalignment", MISALIGNMENT.default) if misalignment is None
                                 else misalignment)


def coupling_from(values: dict, misalignment: float | None = None) -> LeverCoupling:
    return coupling_of(*check_coupling(values, misalignment))


def coupling_of(p: dict, alpha: float) -> LeverCoupling:
    """The coupling from checked values (``check_coupling``) at the misalignment ``alpha``."""
    return build_coupling(p["transfer_mode"], alpha, p["support_deformation"], p["hinge_deformation"],
                          p["stiffness"], p["damping"], p["elastic_table"])


def coupling_family_from(values: dict) -> CouplingFamily:
    """The coupling for a misalignment that varies in time, exact at the start value
    (``values['misalignment']``, else the default)."""
    return coupling_family_of(*check_coupling(values))


def coupling_family_of(p: dict, start: float) -> CouplingFamily:
    """``coupling_family_from`` for checked values (``check_coupling``)."""

    def transfer_at(alpha):
        return transfer_function(p["transfer_mode"], MISALIGNMENT.check(alpha), p["support_deformation"],
                                 p["hinge_deformation"])

    return CouplingFamily(transfer_at, elastic_law(p["stiffness"], p["elastic_table"]), p["damping"], start)


#: A prescribed misalignment alpha(t) (the coupling's misalignment input driven in time).
MISALIGNMENT_SOURCE = (
    Parameter("table", "0:0.2618; 1:0.2618", "", "misalignment angle over time as 't:alpha; ...' points "
              "(s, and rad or deg as table_unit says), linear between points, the end values held",
              kind="string"),
    Parameter("table_unit", "rad", "", "unit of the table's angles", kind="string", choices=("rad", "deg")),
)


def misalignment_source_from(values: dict) -> TimeTable:
    p = check_all(MISALIGNMENT_SOURCE, values)
    scale = math.pi / 180.0 if p["table_unit"] == "deg" else 1.0
    table = TimeTable.parse(p["table"], "table", scale)
    for t, alpha in table.points:
        problem = MISALIGNMENT.problem(alpha)
        if problem:
            raise ParameterError("table", f"parameter 'table': the angle at t = {t:g} s: {problem}")
    return table


#: A torque lag below a microsecond reaches the characteristic within microseconds: no
#: communication step resolves it, so it is taken as none (the engine answers at once)
#: rather than integrated through millions of substeps.
SHORTEST_LAG = 1e-6


def engine_from(values: dict) -> Shaft | LaggedShaft:
    """The drive shaft: a ``Shaft`` whose engine answers instantly (``torque_lag = 0``),
    else a ``LaggedShaft`` whose engine torque is a state."""
    return engine_of(check_all(ENGINE, values))


def engine_of(p: dict) -> Shaft | LaggedShaft:
    """``engine_from`` for values checked against ``ENGINE``."""
    characteristic = engine_characteristic(p["stall_torque"], p["torque_slope"], p["characteristic"])
    if p["torque_lag"] >= SHORTEST_LAG:
        return LaggedShaft(p["inertia"], characteristic, p["torque_lag"], p["torque_start"], p["max_substep"])
    return Shaft(p["inertia"], characteristic, p["max_substep"])


def load_from(values: dict) -> Shaft:
    return load_of(check_all(LOAD, values))


def load_of(p: dict) -> Shaft:
    """``load_from`` for values checked against ``LOAD``."""
    spectrum = Spectrum(p["order"], p["order_share"], p["order_phase"], p["narrowband_share"],
                        p["narrowband_low"], p["narrowband_high"], p["narrowband_tones"])
    load = load_model(p["load_kind"], p["mean_torque"], p["random_amplitude"], p["seed"], p["tones"],
                      p["band_low"], p["band_high"], p["fourier"], p["table"], spectrum)
    resisting = (p["load_direction"] != "active" or p["friction_torque"] or p["breakaway_torque"]
                 or p["viscous_damping"])
    if resisting:
        if p["breakaway_torque"] < p["friction_torque"]:
            raise ParameterError("breakaway_torque", f"parameter 'breakaway_torque' = {p['breakaway_torque']:g} N.m "
                                 f"is below 'friction_torque' = {p['friction_torque']:g} N.m: static friction must "
                                 "hold at least what sliding friction resists (Fs >= Fc)")
        load = ResistingLoad(load, p["load_direction"], p["friction_torque"], p["breakaway_torque"],
                             p["viscous_damping"])
    return Shaft(p["inertia"], load, p["max_substep"])


def start_state(values: dict, declared) -> tuple[float, float]:
    p = check_all(declared, values)
    return p["phi_start"], p["w_start"]


# -- the freewheel rectifier (docs/physics.md#freewheel-rectifier; the paper's Table 1) -------------
# Table 1 gives the gaps in degrees; they are stored in rad (scenes may write "1.74 deg").
FREEWHEEL = (
    Parameter("input_speed", 42.41, "rad/s", "angular frequency omega of the rocker's oscillation (speed of the "
              "transmission's input shaft; 42.41 rad/s = 405 rpm in the stop-mode test)", 0.0, 1e4, low_open=True),
    Parameter("rocker_amplitude", 0.103, "rad", "phi0 in the rocker's motion phi1 = phi0 (1 - cos(omega t))",
              0.0, 1.5, low_open=True),
    Parameter("half_coupling_inertia", 0.000202, "kg.m2", "J2, moment of inertia of ONE half-coupling (there are two)",
              1e-6, 1e3),
    Parameter("driven_parts_inertia", 0.000217, "kg.m2", "J3, moment of inertia of the driven parts of ONE half "
              "(driven discs, output shaft share; there are two)", 1e-6, 1e3),
    Parameter("torsion_end_inertia", 0.0014, "kg.m2", "J4, output end of the torsion shaft with its peripheral gear",
              1e-6, 1e3),
    Parameter("flywheel_inertia", 5.0, "kg.m2", "J5, central gear of the summing gearbox (5: the paper's stop mode; "
              "the real one is 0.00225)", 1e-6, 1e6),
    Parameter("ramp_angle", 0.3054, "rad", "alpha, inclination of the tear-shaped ramps the balls roll on",
              0.0, math.pi / 2.0, low_open=True, high_open=True),
    Parameter("contact_radius", 0.026, "m", "r, radius at which the balls and the discs act", 0.0, 10.0,
              low_open=True),
    Parameter("friction_pairs", 9, "", "n, friction pairs per half-coupling", 1, 1000, kind="integer"),
    Parameter("disc_friction", 0.05, "1", "f_s, sliding (and static) friction coefficient of the discs", 0.0, 2.0),
    Parameter("ball_friction", 0.001, "1", "f_k, rolling friction coefficient of the balls on the ramps", 0.0, 1.0,
              high_open=True),
    Parameter("ball_friction_speed", 0.05, "rad/s", "speed below which the balls' friction sign is regularised "
              "linearly (not in the paper)", 0.0, 1e3, low_open=True),
    Parameter("drag_torque", 0.85, "N.m", "M_v, drag moment of the disc packs at small slip speed (both halves)",
              0.0, 1e5),
    Parameter("drag_damping", 0.075, "N.m.s/rad", "k_v, growth of the disc drag with the slip speed", 0.0, 1e5),
    Parameter("spring_force", 6.0, "N", "P_pr, force of the return spring on each half-coupling", 0.0, 1e6),
    Parameter("msm_gap", math.radians(1.74), "rad", "z1, axial gap of the freewheel as a rocker angle", 0.0, 1.0),
    Parameter("torsion_gap", math.radians(2.23), "rad", "z2, gap in the torsion shaft's splines", 0.0, 1.0),
    Parameter("mesh_gap", math.radians(1.1), "rad", "z3, backlash of the gear mesh", 0.0, 1.0),
    Parameter("msm_stiffness", 10313.0, "N.m/rad", "C_fi, torsional stiffness of the engaged freewheel (ramps, balls, "
              "clamped discs) between the rocker and the half-couplings", 0.0, 1e9, low_open=True),
    Parameter("pocket_stiffness", 10313.0, "N.m/rad", "stiffness of the pockets' ends that drag the half-couplings "
              "back (not in the paper: taken equal to C_fi)", 0.0, 1e9, low_open=True),
    Parameter("torsion_stiffness", 3798.0, "N.m/rad", "C_t, torsional stiffness of the torsion shaft",
              0.0, 1e9, low_open=True),
    Parameter("mesh_stiffness", 25000.0, "N.m/rad", "C_z, torsional stiffness of the gear mesh", 0.0, 1e9,
              low_open=True),
    Parameter("torsion_damping", 0.3, "N.m.s/rad", "k_t, damping of the torsion shaft", 0.0, 1e6),
    Parameter("mesh_damping", 0.3, "N.m.s/rad", "k_z, damping of the gear mesh", 0.0, 1e6),
    Parameter("resistance_torque", 0.0, "N.m", "Mc, Coulomb resistance on the output shaft (stick/slip; a value "
              "above the largest mesh torque holds the output still, as in the stop-mode test)", 0.0, 1e7),
    Parameter("max_substep", 2e-5, "s", "largest internal RK4 substep (events are located inside substeps)",
              0.0, 1e-2, low_open=True),
    Parameter("max_events", 10000, "", "most events (gap edges, stick/slip changes) one communication step may "
              "hold before the FMU reports chattering", 1, 10 ** 9, kind="integer"),
)


def freewheel_from(values: dict):
    from .freewheel import FreewheelRectifier

    return FreewheelRectifier(check_all(FREEWHEEL, values))
