"""The parameters of each component, with the KAVZ-685 values (MODEL.md section 6) as
defaults, and the constructors that turn a parameter dict into physics objects.

The FMU adapters declare their FMI variables from these lists and build their models with
these constructors; the monolithic reference solver does the same, so both always model
the same equations with the same numbers.
"""
from __future__ import annotations

import math

from .coupling import LeverCoupling, build_coupling
from .elastic import TabulatedElasticLaw
from .engine import engine_characteristic
from .kinematics import GEOMETRIC_LIMIT, MODES
from .load import LOAD_KINDS, FourierLoad, TabulatedLoad, load_model
from .parameters import Parameter, check_all
from .shaft import Shaft

INF = math.inf

#: The transfer-function mode of the KAVZ-685 scene and of the coupling FMU's default.
#: Chosen by comparing both modes with the monograph's reported amplitudes and the
#: measurements (docs/decisions.md): "kinematic".
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
              "empty for the linear zone M1 - K1*w", kind="string", parser=lambda text: engine_characteristic(0, 0, text)),
    Parameter("phi_start", 0.0, "rad", "drive shaft angle at the start", -1e9, 1e9),
    Parameter("w_start", 39.0, "rad/s", "drive shaft speed at the start", -1e5, 1e5),
    Parameter("max_substep", 2.5e-4, "s", "largest internal integration step where no closed form applies",
              0.0, 1.0, low_open=True),
)

LOAD = (
    Parameter("inertia", 0.161, "kg.m2", "reduced moment of inertia I2 of the driven shaft", 1e-6, 1e6),
    Parameter("load_kind", "random", "", "technological load: constant, random (mean + seeded band-limited part), "
              "fourier (angle-periodic series) or table (time series)", kind="string", choices=LOAD_KINDS),
    Parameter("mean_torque", 107.5, "N.m", "mean technological resistance Mm", -1e6, 1e6),
    Parameter("random_amplitude", 8.8, "N.m", "bound dM of the random part: |Mc - Mm| <= dM", 0.0, 1e6),
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
)


def coupling_from(values: dict, misalignment: float | None = None) -> LeverCoupling:
    p = check_all(COUPLING, {k: v for k, v in values.items() if k != "misalignment"})
    alpha = MISALIGNMENT.check(values.get("misalignment", MISALIGNMENT.default) if misalignment is None
                               else misalignment)
    return build_coupling(p["transfer_mode"], alpha, p["support_deformation"], p["hinge_deformation"],
                          p["stiffness"], p["damping"], p["elastic_table"])


def engine_from(values: dict) -> Shaft:
    p = check_all(ENGINE, values)
    return Shaft(p["inertia"], engine_characteristic(p["stall_torque"], p["torque_slope"], p["characteristic"]),
                 p["max_substep"])


def load_from(values: dict) -> Shaft:
    p = check_all(LOAD, values)
    load = load_model(p["load_kind"], p["mean_torque"], p["random_amplitude"], p["seed"], p["tones"],
                      p["band_low"], p["band_high"], p["fourier"], p["table"])
    return Shaft(p["inertia"], load, p["max_substep"])


def start_state(values: dict, declared) -> tuple[float, float]:
    p = check_all(declared, values)
    return p["phi_start"], p["w_start"]
