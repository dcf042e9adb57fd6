"""Loads, engine characteristics and the shaft integrator (docs/physics.md#engine, #loads;
lever.physics.load, lever.physics.engine, lever.physics.shaft)."""
from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import quad, solve_ivp

from lever.physics import component_parameters
from lever.physics.engine import LinearCharacteristic, TabulatedCharacteristic
from lever.physics.load import (ConstantLoad, FourierLoad, RandomLoad, TabulatedLoad, load_model,
                                read_harmonics)
from lever.physics.numerics import SeededUniform
from lever.physics.parameters import ParameterError
from lever.physics.shaft import Shaft

REPO = Path(__file__).resolve().parents[2]
HARMONICS = REPO / "resources" / "data" / "monograph" / "harmonics_driven.csv"

STEPS = [(0.0, 1e-6), (0.3, 0.05), (1.7, 0.05), (2.345, 1e-6), (5.0, 1e-3), (2.0, 0.5), (9.99, 0.05)]


def close(a: float, b: float, scale: float, tol: float = 1e-9) -> bool:
    return abs(a - b) <= tol * max(abs(b), scale)


def quad_integrals(resistance, t, h, points=None):
    """int_t^{t+h} Mc(u) du and int_t^{t+h} (t + h - u) Mc(u) du by adaptive quadrature."""
    kw = dict(epsabs=0.0, epsrel=1e-12, limit=400)
    if points:
        kw["points"] = points
    first = quad(resistance, t, t + h, **kw)[0]
    second = quad(lambda u: (t + h - u) * resistance(u), t, t + h, **kw)[0]
    return first, second


# --------------------------------------------------------------------------------------
# Random load
# --------------------------------------------------------------------------------------


def over(method):
    """A scalar method of the physics mapped over numpy arrays (the physics takes scalars:
    it runs in the FMUs on the standard library alone)."""
    return np.vectorize(method, otypes=[float])


def multisine(load: RandomLoad, t: np.ndarray) -> np.ndarray:
    """The random load's resistance over an array, from its drawn tones, with numpy."""
    return load.mean + sum(a * np.sin(f * t + p) for a, f, p in zip(load.weights, load.frequencies, load.phases))


def test_random_load_is_reproducible_by_seed():
    t = np.linspace(0.0, 10.0, 20001)
    a, b = RandomLoad(107.5, 8.8, seed=7), RandomLoad(107.5, 8.8, seed=7)
    assert np.array_equal(over(a.resistance)(t, 0.0, 0.0), over(b.resistance)(t, 0.0, 0.0))
    assert a.frequencies == b.frequencies and a.phases == b.phases and a.weights == b.weights
    assert a.integrals(1.0, 0.01) == b.integrals(1.0, 0.01)
    c = RandomLoad(107.5, 8.8, seed=8)
    assert not np.allclose(over(a.resistance)(t, 0.0, 0.0), over(c.resistance)(t, 0.0, 0.0))
    # through the shared constructor, as the FMU and the reference build it
    d = load_model("random", 107.5, 8.8, seed=7)
    assert np.array_equal(over(a.resistance)(t, 0.0, 0.0), over(d.resistance)(t, 0.0, 0.0))


def within_ulps(values, expected, ulps: int) -> bool:
    """Each value within ``ulps`` units in the last place of the expected one."""
    return len(values) == len(expected) and all(
        abs(v - e) <= ulps * math.ulp(e) for v, e in zip(values, expected))


@pytest.mark.parametrize("seed", [0, 1, 2, 3, 7, 99, 123456, 2 ** 31 - 1])
@pytest.mark.parametrize("tones", [1, 6, 7, 8, 9, 40, 129, 256])
def test_random_load_draws_are_numpys_default_rng_bit_for_bit(seed, tones):
    # The physics draws with its own PCG64/SeedSequence (lever.physics.numerics) since the
    # FMUs left numpy: every seeded load is the one numpy drew before.  Exact where the
    # operations are exact on every CPU: the stream of uniform doubles (integer arithmetic,
    # one multiply and one add), the standard library's exp of them, numpy's pairwise sum
    # (a fixed order of additions at every SIMD level).  np.exp is not exact: numpy sends
    # it to SIMD code on CPUs with AVX-512, which differs from libm's exp in the last bits,
    # so the exponentials are compared with numpy's to a few ulps.
    band_low, band_high, amplitude = 2.0, 450.0, 8.8
    rng = np.random.default_rng(seed)
    logs = rng.uniform(math.log(band_low), math.log(band_high), tones)
    phases = rng.uniform(0.0, 2.0 * math.pi, tones)
    weights = rng.uniform(0.5, 1.0, tones)
    mine = SeededUniform(seed)
    assert mine.uniform(math.log(band_low), math.log(band_high), tones) == logs.tolist()
    assert mine.uniform(0.0, 2.0 * math.pi, tones) == phases.tolist()
    assert mine.uniform(0.5, 1.0, tones) == weights.tolist()
    load = RandomLoad(107.5, amplitude, seed, tones, band_low, band_high)
    assert load.frequencies == [math.exp(x) for x in logs.tolist()]
    assert within_ulps(load.frequencies, np.exp(logs).tolist(), 4)
    assert load.phases == phases.tolist()
    assert load.weights == (amplitude * weights / weights.sum()).tolist()


def test_random_load_scalar_resistance_is_the_multisine():
    load = RandomLoad(107.5, 8.8, seed=3)
    t = np.linspace(0.0, 3.0, 301)
    values = multisine(load, t)
    for k in range(0, len(t), 17):
        assert load.resistance(float(t[k]), 0.0, 0.0) == pytest.approx(values[k], abs=1e-12)
        assert load.torque(float(t[k]), 0.0, 0.0) == -load.resistance(float(t[k]), 0.0, 0.0)


@pytest.mark.parametrize("seed,tones,band", [(1, 6, (2.0, 450.0)), (2, 6, (2.0, 450.0)), (99, 1, (5.0, 5.0)),
                                             (5, 40, (1.0, 1000.0))])
def test_random_load_stays_within_its_bound(seed, tones, band):
    mean, bound = 107.5, 8.8
    load = RandomLoad(mean, bound, seed=seed, tones=tones, band_low=band[0], band_high=band[1])
    t = np.linspace(0.0, 30.0, 600001)
    deviation = np.abs(multisine(load, t) - mean)
    assert deviation.max() <= bound * (1.0 + 1e-12)
    assert deviation.max() >= 0.3 * bound  # the random part is really there
    assert sum(abs(w) for w in load.weights) == pytest.approx(bound, rel=1e-12)
    assert all(band[0] * (1 - 1e-12) <= f <= band[1] * (1 + 1e-12) for f in load.frequencies)
    assert len(load.frequencies) == tones


def test_random_load_integrals_with_per_step_constants_are_the_direct_formula_bit_for_bit():
    # integrals() takes what depends on the step size alone from a cache (the hot path of
    # the load shaft): the same operations in the same order, so the same bits - also
    # across the cache's overflow (more step sizes than it keeps).
    load = RandomLoad(107.5, 8.8, seed=2, tones=9)

    def direct(t, h):
        from lever.physics.load import _one_minus_sinc_over_y, _sinc
        impulse, second = load.mean * h, 0.5 * load.mean * h * h
        for a, f, p in zip(load.weights, load.frequencies, load.phases):
            x, start = f * h, f * t + p
            impulse += a * h * math.sin(start + 0.5 * x) * _sinc(0.5 * x)
            second += 0.5 * a * h * h * (math.sin(start + 0.25 * x) * _sinc(0.25 * x)
                                         + math.cos(start + 0.5 * x) * _one_minus_sinc_over_y(0.5 * x))
        return impulse, second

    steps = [1e-3, 2.5e-4, 1e-6, 0.05] + [1e-4 * (1.0 + k / 97.0) for k in range(RandomLoad.STEP_CACHE + 5)]
    for k, h in enumerate(steps * 2):
        t = 0.37 * k
        assert load.integrals(t, h) == direct(t, h), (t, h)


def test_random_load_bad_band_is_refused():
    with pytest.raises(ParameterError):
        RandomLoad(100.0, 5.0, band_low=500.0, band_high=100.0)
    with pytest.raises(ParameterError):
        RandomLoad(100.0, 5.0, band_low=0.0)


@pytest.mark.filterwarnings("ignore::scipy.integrate.IntegrationWarning")  # quad near its roundoff limit
@pytest.mark.parametrize("seed", [1, 2, 7])
@pytest.mark.parametrize("t,h", STEPS)
def test_random_load_integrals_are_exact(seed, t, h):
    # Mean 0: the oscillating part alone is compared (a mean would dominate both integrals).
    load = RandomLoad(0.0, 8.8, seed=seed)
    impulse, second = load.integrals(t, h)
    q1, q2 = quad_integrals(lambda u: load.resistance(u, 0.0, 0.0), t, h)
    assert close(impulse, q1, 8.8 * h), (impulse, q1)
    assert close(second, q2, 8.8 * h * h / 2.0), (second, q2)
    # and with the mean (the KAVZ-685 load)
    full = RandomLoad(107.5, 8.8, seed=seed)
    impulse, second = full.integrals(t, h)
    q1, q2 = quad_integrals(lambda u: full.resistance(u, 0.0, 0.0), t, h)
    assert impulse == pytest.approx(q1, rel=1e-9)
    assert second == pytest.approx(q2, rel=1e-9)


def test_constant_load_integrals():
    load = ConstantLoad(107.5)
    assert load.integrals(3.0, 0.01) == pytest.approx((1.075, 0.5 * 107.5 * 1e-4), rel=1e-15)
    assert load.resistance(1.0, 2.0, 3.0) == 107.5 and load.torque(1.0, 2.0, 3.0) == -107.5


# --------------------------------------------------------------------------------------
# Tabulated load
# --------------------------------------------------------------------------------------

LOAD_POINTS = [(0.0, 100.0), (0.1, 120.0), (0.25, 90.0), (0.4, 130.0), (1.0, 130.0), (1.2, 60.0)]


@pytest.mark.parametrize("t,h", [(-0.05, 0.1), (0.05, 0.3), (0.09, 0.02), (0.1, 0.15), (0.3, 0.5),
                                 (0.5, 0.1), (-1.0, 3.0), (1.5, 0.2), (0.1, 1e-6), (0.2499999, 1e-6),
                                 (0.95, 0.05), (0.0, 1.2)])
def test_tabulated_load_integrals_across_breakpoints(t, h):
    load = TabulatedLoad(LOAD_POINTS)
    impulse, second = load.integrals(t, h)
    knots = [p[0] for p in LOAD_POINTS if t < p[0] < t + h]
    q1, q2 = quad_integrals(lambda u: load.resistance(u, 0.0, 0.0), t, h, knots)
    assert impulse == pytest.approx(q1, rel=1e-9)
    assert second == pytest.approx(q2, rel=1e-9)


def test_tabulated_load_interpolates_and_holds_its_ends():
    load = TabulatedLoad.parse("0:100; 0.1:120; 0.25:90; 0.4:130; 1.0:130; 1.2:60")
    assert load.resistance(-5.0, 0.0, 0.0) == 100.0
    assert load.resistance(7.0, 0.0, 0.0) == 60.0
    assert load.resistance(0.05, 0.0, 0.0) == pytest.approx(110.0)
    assert load.resistance(0.175, 0.0, 0.0) == pytest.approx(105.0)
    t = np.linspace(-1.0, 2.0, 3001)
    np.testing.assert_allclose(over(load.resistance)(t, 0.0, 0.0),
                               np.interp(t, [p[0] for p in LOAD_POINTS], [p[1] for p in LOAD_POINTS]),
                               rtol=0, atol=1e-12)


@pytest.mark.parametrize("table", ["0:100", "0.1:100; 0.1:120", "0.2:100; 0.1:120", "0.1:abc; 0.2:3"])
def test_bad_load_tables_are_refused(table):
    with pytest.raises(ParameterError) as info:
        TabulatedLoad.parse(table)
    assert "table" in str(info.value)


# --------------------------------------------------------------------------------------
# Measured (Fourier) load
# --------------------------------------------------------------------------------------


def _harmonics_table():
    with open(HARMONICS, newline="") as f:
        rows = list(csv.DictReader(line for line in f if not line.startswith("#")))
    return [{k: float(v) for k, v in row.items()} for row in rows]


def _series(row, phi):
    value = row["M_mean"]
    n = 1
    while f"a_{n}" in row or f"b_{n}" in row:
        value += row.get(f"a_{n}", 0.0) * math.cos(n * phi) + row.get(f"b_{n}", 0.0) * math.sin(n * phi)
        n += 1
    return value


ANGLES = [0.0, 0.3, 1.0, 2.0, math.pi, 4.5, -1.2, 100.0]


def test_fourier_load_of_cycle_1_reproduces_the_series():
    rows = _harmonics_table()
    assert len(rows) == 6
    row = next(r for r in rows if r["cycle"] == 1.0)
    load = read_harmonics(HARMONICS, 1)
    assert load.mean == 243.29
    assert len(load.cosines) == 6 and len(load.sines) == 6 and load.sines[5] == 0.0
    for phi in ANGLES:
        assert load.resistance(0.0, phi, 39.0) == pytest.approx(_series(row, phi), rel=1e-12)
        assert load.torque(0.0, phi, 39.0) == -load.resistance(0.0, phi, 39.0)
    # cycle given as text works as well
    assert read_harmonics(HARMONICS, "1").resistance(0.0, 1.0, 0.0) == load.resistance(0.0, 1.0, 0.0)


def test_fourier_load_of_the_mean_cycle_reproduces_the_averaged_series():
    rows = _harmonics_table()
    keys = [k for k in rows[0] if k != "cycle"]
    mean_row = {k: sum(r[k] for r in rows) / len(rows) for k in keys}
    load = read_harmonics(HARMONICS, "mean")
    assert load.mean == pytest.approx(mean_row["M_mean"], rel=1e-14)
    for phi in ANGLES:
        assert load.resistance(0.0, phi, 39.0) == pytest.approx(_series(mean_row, phi), rel=1e-12)
    phi = np.array(ANGLES)
    np.testing.assert_allclose(over(load.resistance)(0.0, phi, 0.0), [_series(mean_row, p) for p in ANGLES],
                               rtol=1e-12)
    # Its mean over a revolution is M_mean.
    grid = 2.0 * np.pi * np.arange(256) / 256
    assert np.mean(over(load.resistance)(0.0, grid, 0.0)) == pytest.approx(mean_row["M_mean"], rel=1e-12)


def test_fourier_text_round_trip():
    load = read_harmonics(HARMONICS, 3)
    again = FourierLoad.parse(load.to_text())
    phi = np.linspace(-7.0, 7.0, 141)
    assert np.array_equal(over(again.resistance)(0.0, phi, 0.0), over(load.resistance)(0.0, phi, 0.0))
    model = load_model("fourier", 0.0, fourier=load.to_text())
    assert np.array_equal(over(model.resistance)(0.0, phi, 0.0), over(load.resistance)(0.0, phi, 0.0))


@pytest.mark.parametrize("m", [3, 4, 7, 12, 25, 36])
def test_fourier_series_from_samples_agrees_with_numpys_rfft(m):
    # A direct DFT (math.fsum per term) since the FMUs left numpy: pocketfft's result to
    # rounding, 1e-14 of the ordinates.
    from lever.physics.load import fourier_from_samples
    y = 200.0 + 30.0 * np.random.default_rng(m).standard_normal(m)
    series = fourier_from_samples(y.tolist())
    spectrum = np.fft.rfft(y) / m
    cosines = 2.0 * spectrum[1:].real
    sines = -2.0 * spectrum[1:].imag
    if m % 2 == 0:
        cosines[-1] *= 0.5
        sines = np.append(sines[:-1], 0.0)
    assert series.mean == pytest.approx(spectrum[0].real, rel=1e-15)
    np.testing.assert_allclose(series.cosines, cosines, rtol=0, atol=1e-14 * np.max(np.abs(y)))
    np.testing.assert_allclose(series.sines, sines, rtol=0, atol=1e-14 * np.max(np.abs(y)))


def test_missing_cycle_is_refused():
    with pytest.raises(ParameterError):
        read_harmonics(HARMONICS, 9)


# --------------------------------------------------------------------------------------
# Shafts
# --------------------------------------------------------------------------------------


class Numerical:
    """The same external torque model without its closed form: the shaft falls back to RK4."""

    def __init__(self, model):
        self.model = model

    def torque(self, t, phi, w):
        return self.model.torque(t, phi, w)

    def advance(self, *args):
        return None


def solve_tight(shaft: Shaft, t, phi, w, tau, h):
    def rhs(s, y):
        return [y[1], (shaft.external.torque(s, y[0], y[1]) + tau) / shaft.inertia]

    sol = solve_ivp(rhs, (t, t + h), [phi, w], method="DOP853", rtol=1e-13, atol=1e-13)
    return sol.y[0, -1], sol.y[1, -1]


ENGINES = {
    "linear": LinearCharacteristic(623.0, 14.06),
    "flat": LinearCharacteristic(623.0, 0.0),
    "steep": LinearCharacteristic(2000.0, 500.0),
}


@pytest.mark.parametrize("engine", list(ENGINES))
@pytest.mark.parametrize("h", [1e-6, 1e-3, 0.05, 0.3])
@pytest.mark.parametrize("tau", [-107.5, 0.0, 300.0])
def test_exact_engine_step_matches_fine_rk4_and_solve_ivp(engine, h, tau):
    exact = Shaft(0.128, ENGINES[engine])
    fine = Shaft(0.128, Numerical(ENGINES[engine]), max_substep=min(h, 1e-5) / 4)
    t, phi, w = 1.3, 12.0, 39.0
    phi1, w1, _ = exact.advance(t, phi, w, tau, h)
    phi_rk, w_rk, _ = fine.advance(t, phi, w, tau, h)
    phi_ref, w_ref = solve_tight(exact, t, phi, w, tau, h)
    for value, other in ((phi1, phi_rk), (phi1, phi_ref)):
        assert value == pytest.approx(other, rel=1e-9, abs=1e-9)
    for value, other in ((w1, w_rk), (w1, w_ref)):
        assert value == pytest.approx(other, rel=1e-9, abs=1e-9)
    assert (phi1, w1) != (phi, w)


@pytest.mark.parametrize("seed", [1, 4])
@pytest.mark.parametrize("h", [1e-4, 0.01, 0.05])
def test_exact_random_load_step_matches_solve_ivp(seed, h):
    load = RandomLoad(107.5, 8.8, seed=seed, band_high=450.0)
    shaft = Shaft(0.161, load)
    t, phi, w, tau = 0.7, 3.0, 39.0, 110.0
    phi1, w1, _ = shaft.advance(t, phi, w, tau, h)
    phi_ref, w_ref = solve_tight(shaft, t, phi, w, tau, h)
    assert phi1 == pytest.approx(phi_ref, rel=1e-10, abs=1e-10)
    assert w1 == pytest.approx(w_ref, rel=1e-10, abs=1e-10)


def test_tabulated_load_step_matches_solve_ivp():
    load = TabulatedLoad(LOAD_POINTS)
    shaft = Shaft(0.161, load)
    for t, h in ((0.05, 0.3), (0.0, 1.2), (0.95, 0.1)):
        phi1, w1, _ = shaft.advance(t, 0.0, 39.0, 50.0, h)
        knots = sorted({t, t + h} | {p[0] for p in LOAD_POINTS if t < p[0] < t + h})
        phi, w = 0.0, 39.0
        for a, b in zip(knots, knots[1:]):  # integrate piece by piece: the load has kinks
            phi, w = solve_tight(shaft, a, phi, w, 50.0, b - a)
        assert phi1 == pytest.approx(phi, rel=1e-10)
        assert w1 == pytest.approx(w, rel=1e-10)


def test_fourier_load_shaft_uses_rk4_that_converges():
    shaft = Shaft(0.161, read_harmonics(HARMONICS, "mean"))
    phi1, w1, _ = shaft.advance(0.0, 0.0, 39.0, 240.0, 0.01)
    phi_ref, w_ref = solve_tight(shaft, 0.0, 0.0, 39.0, 240.0, 0.01)
    assert phi1 == pytest.approx(phi_ref, rel=1e-10)
    assert w1 == pytest.approx(w_ref, rel=1e-10)


def test_tabulated_engine_characteristic():
    engine = TabulatedCharacteristic.parse("0:600; 20:650; 39.25:0")
    assert engine.torque(0.0, 0.0, -3.0) == 600.0
    assert engine.torque(0.0, 0.0, 10.0) == pytest.approx(625.0)
    assert engine.torque(0.0, 0.0, 39.25) == pytest.approx(0.0, abs=1e-12)
    assert engine.torque(0.0, 0.0, 40.0) < 0.0  # the falling branch is extended
    shaft = Shaft(0.128, engine, max_substep=1e-4)
    phi1, w1, _ = shaft.advance(0.0, 0.0, 30.0, -100.0, 0.02)
    phi_ref, w_ref = solve_tight(shaft, 0.0, 0.0, 30.0, -100.0, 0.02)
    assert w1 == pytest.approx(w_ref, rel=1e-8)
    assert phi1 == pytest.approx(phi_ref, rel=1e-8)


SHAFTS = {
    "linear-engine": lambda: Shaft(0.128, LinearCharacteristic(623.0, 14.06)),
    "flat-engine": lambda: Shaft(0.128, LinearCharacteristic(623.0, 0.0)),
    "constant-load": lambda: Shaft(0.161, ConstantLoad(107.5)),
    "random-load": lambda: Shaft(0.161, RandomLoad(107.5, 8.8, seed=1)),
    "fourier-load": lambda: Shaft(0.161, read_harmonics(HARMONICS, "mean")),
}


@pytest.mark.parametrize("name", list(SHAFTS))
@pytest.mark.parametrize("h", [1e-3, 0.05])
def test_shaft_energy_identity(name, h):
    shaft = SHAFTS[name]()
    t, phi, w, tau = 0.4, 2.0, 39.0, -60.0 if "engine" in name else 120.0
    phi1, w1, work = shaft.advance(t, phi, w, tau, h)
    assert work == pytest.approx(0.5 * shaft.inertia * (w1 ** 2 - w ** 2) - tau * (phi1 - phi), rel=1e-12)
    # Independently: the work is the integral of M_ext * w along the step's own motion.
    def power(s):
        if s == 0.0:
            return shaft.external.torque(t, phi, w) * w
        p, v, _ = shaft.advance(t, phi, w, tau, s)
        return shaft.external.torque(t + s, p, v) * v

    integral = quad(power, 0.0, h, epsabs=0.0, epsrel=1e-11, limit=200)[0]
    assert work == pytest.approx(integral, rel=2e-8 if name == "fourier-load" else 1e-9)


def test_constant_load_work_is_force_times_angle():
    shaft = Shaft(0.161, ConstantLoad(107.5))
    phi1, w1, work = shaft.advance(0.0, 1.0, 39.0, 100.0, 0.02)
    assert work == pytest.approx(-107.5 * (phi1 - 1.0), rel=1e-10)


def test_component_parameter_shafts_use_the_scene_parameters():
    engine = component_parameters.engine_from({"inertia": 0.2, "stall_torque": 500.0, "torque_slope": 10.0})
    assert engine.inertia == 0.2
    assert engine.external.torque(0.0, 0.0, 30.0) == pytest.approx(200.0)
    load = component_parameters.load_from({"load_kind": "constant", "mean_torque": 55.0})
    assert load.inertia == 0.161 and load.external.torque(0.0, 0.0, 0.0) == -55.0
    with pytest.raises(ParameterError) as info:
        component_parameters.engine_from({"inertia": -1.0})
    assert info.value.name == "inertia"
    with pytest.raises(ParameterError) as info:
        component_parameters.load_from({"load_kind": "sometimes"})
    assert info.value.name == "load_kind"
    with pytest.raises(ParameterError):
        component_parameters.load_from({"no_such_parameter": 1.0})


# --------------------------------------------------------------------------------------
# Ramped coupling torque (first-order hold): exact steps and exact work
# --------------------------------------------------------------------------------------

RAMP_CASES = [
    ("linear engine", lambda: Shaft(0.128, LinearCharacteristic(623.0, 14.06))),
    ("engine, K1 = 0", lambda: Shaft(0.128, LinearCharacteristic(623.0, 0.0))),
    ("engine, tiny K1", lambda: Shaft(0.128, LinearCharacteristic(623.0, 1e-9))),
    ("random load", lambda: Shaft(0.161, RandomLoad(107.5, 8.8, seed=2))),
]


@pytest.mark.parametrize("label, make", RAMP_CASES, ids=[c[0] for c in RAMP_CASES])
@pytest.mark.parametrize("h", [1e-4, 5e-3, 0.2])
def test_ramped_torque_step_is_exact(label, make, h):
    shaft = make()
    t, phi, w, tau, rate = 0.3, 1.0, 39.0, -100.0, 4.0e3
    phi1, w1, work = shaft.advance(t, phi, w, tau, h, rate)

    def rhs(s, y):
        # phi, w and the external work: integral of M_ext * w
        return [y[1], shaft.acceleration(t + s, y[0], y[1], tau + rate * s),
                shaft.rates(t + s, y[0], y[1], 0.0)[1] * y[1]]

    exact = solve_ivp(rhs, (0.0, h), [phi, w, 0.0], method="DOP853", rtol=1e-12, atol=1e-12).y[:, -1]
    assert phi1 == pytest.approx(exact[0], rel=1e-10, abs=1e-10)
    assert w1 == pytest.approx(exact[1], rel=1e-10, abs=1e-10)
    # The external work from the shaft's energy balance with the ramp's work in it: exact
    # up to the Hermite quadrature of the first moment, O(h^5) - at communication steps,
    # not at steps long against the engine's lag I/K1 (9 ms).
    if h <= 5e-3:
        assert work == pytest.approx(exact[2], rel=1e-5)


def test_ramp_of_zero_is_the_held_step():
    shaft = Shaft(0.128, LinearCharacteristic(623.0, 14.06))
    assert shaft.advance(0.0, 0.5, 39.0, -90.0, 1e-3, 0.0) == shaft.advance(0.0, 0.5, 39.0, -90.0, 1e-3)


def _solve_quadratic_torque(shaft: Shaft, t, phi, w, tau, rate, accel, h):
    """The shaft under the coupling torque ``tau + rate*s + accel*s^2/2`` itself (no ramp)."""
    def rhs(s, y):
        q = s - t
        return [y[1], (shaft.external.torque(s, y[0], y[1]) + tau + rate * q + 0.5 * accel * q * q) / shaft.inertia]

    sol = solve_ivp(rhs, (t, t + h), [phi, w], method="DOP853", rtol=1e-13, atol=1e-13)
    return sol.y[0, -1], sol.y[1, -1]


@pytest.mark.parametrize("engine", ["flat", "linear"])
@pytest.mark.parametrize("h", [1e-3, 5e-3])
def test_a_quadratic_torque_steps_as_its_equivalent_ramp(engine, h):
    # tau_accel: the shaft takes the ramp with the quadratic's mean and first moment.  A
    # shaft whose external torque does not depend on its state ("flat") ends exactly where
    # the quadratic itself takes it; with the engine's slope K the angle differs by
    # accel K h^5 / (720 I^2) to first order in K h / I, the speed at second order.
    shaft = Shaft(0.128, ENGINES[engine])
    t, phi, w, tau, rate, accel = 0.4, 3.0, 39.0, -107.0, 2.0e3, 1.5e5
    phi1, w1, _ = shaft.advance(t, phi, w, tau, h, rate, accel)
    phi_ref, w_ref = _solve_quadratic_torque(shaft, t, phi, w, tau, rate, accel, h)
    first_order = accel * ENGINES[engine].slope * h ** 5 / (720.0 * shaft.inertia ** 2)
    assert abs(phi1 - phi_ref) <= 2.0 * first_order + 1e-12, (phi1 - phi_ref, first_order)
    assert abs(w1 - w_ref) <= 2.0 * first_order * ENGINES[engine].slope / shaft.inertia + 1e-11, (w1 - w_ref)
    if engine == "linear":        # the bound is the size of the difference, not a loose cap
        assert abs(phi1 - phi_ref) > 0.3 * first_order


def test_the_equivalent_ramp_has_the_quadratics_mean_and_first_moment():
    from lever.physics.shaft import equivalent_ramp
    tau, rate, accel, h = 12.0, -3.0, 40.0, 0.3
    start, slope = equivalent_ramp(tau, rate, accel, h)
    quadratic = lambda s: tau + rate * s + 0.5 * accel * s * s          # noqa: E731
    ramp = lambda s: start + slope * s                                   # noqa: E731
    assert quad(ramp, 0.0, h)[0] == pytest.approx(quad(quadratic, 0.0, h)[0], rel=1e-14)
    assert quad(lambda s: s * ramp(s), 0.0, h)[0] == pytest.approx(quad(lambda s: s * quadratic(s), 0.0, h)[0],
                                                                  rel=1e-14)
    assert equivalent_ramp(tau, rate, 0.0, h) == (tau, rate)
