"""Closed forms derived by hand, against the co-simulation of the built FMUs and against the
harness's linear stability analysis; and the stability-edges table of docs/masters-and-stability.md pinned whole.

Nothing here recomputes the expected value with the objects under test: the steady speed
is ``(M1 - Mm)/K1``, the zero-order-hold growth factor is derived below, and the edges
table is the printed one.
"""
from __future__ import annotations

import math
from pathlib import Path
from decimal import Decimal

import numpy as np
import pytest

from harness.description import scene
from harness.engine import run
from harness.judges import stability

pytestmark = pytest.mark.oracle

I1, I2 = 0.128, 0.161            # the KAVZ-685 inertias (docs/physics.md#kavz-685)
I_RED = I1 * I2 / (I1 + I2)


def kavz(*overrides: str) -> scene.Scene:
    return scene.load("kavz685").with_overrides(list(overrides))


# -- steady speed ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("master", ["jacobi", "jacobi-quadratic", "trapezoidal-newton"])
def test_steady_speed_is_m1_minus_mm_over_k1(master):
    """Engine I1 a1 = M1 - K1 w1 + tau1, load I2 a2 = tau2 - Mm, rigid at U12 = 1: at rest in
    the rotating frame both torques balance, M1 - K1 w = Mm, so w = (M1 - Mm)/K1, and the
    coupling carries Mm at the deflection Mm/c.  Values away from the defaults:
    M1 = 500, K1 = 10, Mm = 200, c = 2000 -> w = 30 rad/s, theta = 0.1 rad."""
    M1, K1, Mm, c = 500.0, 10.0, 200.0, 2000.0
    spec = kavz("coupling.transfer_mode=synchronous", "load.load_kind=constant", "load.random_amplitude=0",
                f"engine.stall_torque={M1}", f"engine.torque_slope={K1}", f"load.mean_torque={Mm}",
                f"coupling.stiffness={c}", "experiment.stop=4", "experiment.transient=0")
    result = run.simulate(spec, master=master, step=1e-3)
    assert result.ok, result.failure
    speed = (M1 - Mm) / K1
    # The slowest mode decays as exp(-K1 t/(I1 + I2)) = exp(-34.6 t): 4 s leave e^-138.  The
    # explicit masters land on the closed form to rounding; trapezoidal-newton 9.3e-9 off
    # (measured), allowed 3e-8.
    tolerance = 3e-8 if master == "trapezoidal-newton" else 1e-9
    for name in ("engine.w", "load.w"):
        assert result.traces[name][-1] == pytest.approx(speed, rel=tolerance), (
            f"{master}: steady {name} = {result.traces[name][-1]!r}, the closed form (M1 - Mm)/K1 = {speed}")
    assert result.traces["coupling.theta"][-1] == pytest.approx(Mm / c, rel=tolerance)
    assert result.traces["coupling.tau2"][-1] == pytest.approx(Mm, rel=tolerance)


# -- the zero-order-hold edge of the two-inertia chain, by hand ---------------------------------------------------

def zoh_growth(h_omega: float, zeta: float) -> float:
    """Spectral radius of the zero-order-hold (Jacobi) map of the two-inertia chain whose
    coupling mode is damped by the coupling alone (engine slope K1 = 0), derived by hand.

    Shafts I1, I2 joined by T = c theta + b thetadot (U12 = 1), theta = phi1 - phi2.
    Jacobi holds T_n = c theta_n + b v_n (v = thetadot) over the step and each shaft is
    integrated exactly under its held torque (-T_n on the drive, +T_n on the driven):

        v_{n+1}     = v_n - h T_n / I_red
        theta_{n+1} = theta_n + h v_n - (h^2 / 2) T_n / I_red,     1/I_red = 1/I1 + 1/I2.

    With omega^2 = c/I_red, 2 zeta omega = b/I_red, s = h omega and y = v/omega, the map
    on (theta, y) is

        A = [[1 - s^2/2,  s - zeta s^2],
             [-s,         1 - 2 zeta s]],

    det A = (1 - s^2/2)(1 - 2 zeta s) + s (s - zeta s^2) = 1 - 2 zeta s + s^2/2,
    tr A  = 2 - 2 zeta s - s^2/2.

    While tr^2 < 4 det the eigenvalues are a complex pair of modulus sqrt(det A):

        rho = sqrt(1 - 2 zeta s + s^2/2).

    Undamped (zeta = 0): rho = sqrt(1 + (h omega)^2 / 2) > 1 for every h > 0 - zero-order
    hold is unstable at any step.  Damped: rho < 1 exactly while s < 4 zeta, so the edge
    is h omega_n = 4 zeta (to first order in zeta the same when the engine slope damps the
    mode: the docs' 0.103 at zeta = 0.0258, 0.0327 at 0.0082)."""
    s = h_omega
    det = 1.0 - 2.0 * zeta * s + s * s / 2.0
    trace = 2.0 - 2.0 * zeta * s - s * s / 2.0
    assert trace * trace < 4.0 * det, "outside the complex-pair regime the derivation covers"
    return math.sqrt(det)


@pytest.mark.parametrize("c,b", [(1e5, 0.0), (1e5, 20.0), (715.4, 6.35)])
def test_stability_analysis_gives_the_hand_derived_zoh_growth(c, b):
    model = stability.TwoInertia(I1, I2, 0.0, c, b)
    omega, zeta = math.sqrt(c / I_RED), b / (2.0 * math.sqrt(c * I_RED))
    assert model.omega_n == pytest.approx(omega, rel=1e-12) and model.zeta == pytest.approx(zeta, rel=1e-12)
    for s in (0.01, 0.05, 0.2, 0.8, 1.5):
        # the coupling mode: the complex pair (with K1 = 0 the rigid rotation keeps an eigenvalue 1)
        values = np.linalg.eigvals(stability.one_step_map(model, "jacobi", s / omega)[0])
        rho = float(np.abs(values[np.abs(values.imag) > 1e-12]).max())
        assert rho == pytest.approx(zoh_growth(s, zeta), rel=1e-9), (
            f"zero-order-hold spectral radius at h*omega_n = {s}, zeta = {zeta:.4g}: analysis {rho}, by hand "
            f"{zoh_growth(s, zeta)}")
    edge = stability.stability_edge(model, "jacobi")
    if b == 0.0:
        assert edge == stability.EDGE_RANGE[0], "undamped zero-order hold must be unstable at any step"
    else:
        # the analysis calls rho > 1 + 1e-7 unstable: d(rho^2)/ds = 2 zeta at the edge shifts it by 1e-7/zeta
        assert edge == pytest.approx(4.0 * zeta, abs=2e-7 / zeta), (
            f"zero-order-hold edge {edge}, by hand 4 zeta = {4 * zeta}")


@pytest.mark.parametrize("b,h_omega", [(0.0, 0.2), (0.0, 0.6), (20.0, 0.05), (20.0, 0.3)])
def test_fmu_cosimulation_grows_at_the_hand_derived_zoh_rate(b, h_omega):
    """The real thing: engine, coupling and load FMUs under ``jacobi`` (synchronous transfer,
    constant load, K1 = 0, M1 = Mm so the mean speed stays put).  For a linear 2x2 map A,
    det[x_{n+k}, x_{n+k+1}] = det(A)^k det[x_n, x_{n+1}] exactly, with x = (theta - theta*, v):
    the recorded traces give det A, and rho^2 = det A for the complex pair."""
    c, Mm = 1e5, 107.5
    omega, zeta = math.sqrt(c / I_RED), b / (2.0 * math.sqrt(c * I_RED))
    h = h_omega / omega
    rho = zoh_growth(h_omega, zeta)
    n = 120 if rho < 1.0 else min(120, math.ceil(math.log(30.0) / math.log(rho)))   # grow 30x at most
    spec = kavz("coupling.transfer_mode=synchronous", "load.load_kind=constant", "load.random_amplitude=0",
                f"coupling.stiffness={c}", f"coupling.damping={b}", "engine.torque_slope=0",
                f"engine.stall_torque={Mm}", f"load.mean_torque={Mm}", "engine.phi_start=0.0005",
                "experiment.transient=0", f"experiment.stop={n * h!r}")
    result = run.simulate(spec, master="jacobi", step=h)
    assert result.ok, result.failure
    e = result.traces["coupling.theta"] - Mm / c             # theta* = Mm/c: T* = I_red (M1/I1 + Mm/I2) = Mm
    v = result.traces["engine.w"] - result.traces["load.w"]
    area = e[:-1] * v[1:] - e[1:] * v[:-1]
    k = len(area) - 1 - 10
    det = (area[10 + k] / area[10]) ** (1.0 / k)
    assert math.sqrt(det) == pytest.approx(rho, rel=1e-6), (
        f"jacobi on the FMUs grows by {math.sqrt(det)!r} a step at h*omega_n = {h_omega}, zeta = {zeta:.4g}; "
        f"zero-order hold derived by hand: {rho!r}")


# -- the stability-edges table of the docs, whole ----------------------------------------------------------------------

# docs/masters-and-stability.md "Stability: the map and the advisor", h*omega_n at the edge on the KAVZ-685 masses
# for (c = 715.4, b = 6.35, K1 = 14.06), (c = 1e5, b = 0), (c = 1e6, b = 0); None: stable
# over the whole scanned range (0.001 ... 100).
EDGES_TABLE = {
    "jacobi": ("2.24", "0.103", "0.033"),
    "gauss-seidel": ("1.97", "0.167", "0.053"),
    "jacobi-linear": ("1.18", "0.527", "0.362"),
    "jacobi-quadratic": ("0.642", "0.999", "0.978"),
    "jacobi-midpoint": ("1.56", "2.02", "2.01"),
    "implicit-fixed-point": ("0.573", "1.09", "1.08"),
    "trapezoidal-fixed-point": ("1.04", "1.55", "1.54"),
    "implicit-newton": (None, None, None),
    "trapezoidal-newton": (None, None, None),
}


@pytest.mark.parametrize("master", list(EDGES_TABLE))
def test_stability_edges_table_of_the_docs(master):
    """All 27 cells.  Tolerance: the printed figures are rounded, so the analysis must lie
    within half a unit of the last printed digit (e.g. 0.103 means [0.1025, 0.1035]); the
    edge's own bisection (24 halvings of a 1.3x bracket) is below 1e-7 relative."""
    kavz_model = stability.TwoInertia(I1, I2, 14.06, 715.4, 6.35)
    columns = (kavz_model, kavz_model.with_coupling(1e5, 0.0), kavz_model.with_coupling(1e6, 0.0))
    for printed, model in zip(EDGES_TABLE[master], columns):
        edge = stability.stability_edge(model, master)
        if printed is None:
            assert edge is None, f"{master}: the docs say stable at every step, the analysis finds an edge at {edge}"
            continue
        half_unit = 0.5 * 10.0 ** Decimal(printed).as_tuple().exponent
        assert edge is not None and abs(edge - float(printed)) <= half_unit, (
            f"{master} at c = {model.stiffness:g}, b = {model.damping:g}: stability edge h*omega_n = {edge}, "
            f"the docs' table prints {printed}")


def test_the_docs_print_the_pinned_edges_table():
    """The table a user reads is the one pinned above (a row per master; the iterative and
    Newton masters share rows, their cells joined by ', ')."""
    text = (Path(__file__).resolve().parents[2] / "docs" / "masters-and-stability.md").read_text()
    printed = {}
    for line in text.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) != 4 or not cells[0].startswith("`"):
            continue
        names = [n.strip(" `") for n in cells[0].split("(")[0].split(",")]
        for k, name in enumerate(names):
            values = [c.split(",")[k].strip() if "," in c else c for c in cells[1:]]
            printed[name] = tuple(None if v.startswith("none") else v for v in values)
    assert printed == EDGES_TABLE, "docs/masters-and-stability.md's stability edges differ from the pinned table"
