"""The coupling's kinematics: transfer function U12 and position function Phi
(docs/physics.md#kinematics; lever.physics.kinematics)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from lever.physics.kinematics import MODES, TransferFunction, reported_amplitude, transfer_function
from lever.physics.parameters import ParameterError

DEG = math.pi / 180.0
N_REV = 4096
REVOLUTION = 2.0 * np.pi * np.arange(N_REV) / N_REV   # uniform points over one revolution
# Angles off the uniform grid, several revolutions, both signs.
ANGLES = np.linspace(-13.0, 29.0, 1777)

ALPHAS_DEG = (0.0, 1.0, 5.0, 10.0, 15.0, 20.0, 25.0, 30.0, 35.0, 40.0)
DEFORMATIONS = (0.0, 0.02, 0.05, 0.09)


def over(method):
    """A scalar method of the physics mapped over numpy arrays (the physics takes scalars:
    it runs in the FMUs on the standard library alone)."""
    return np.vectorize(method)


def kinematically_defined(alpha_deg: float, support: float, margin_deg: float = 0.0) -> bool:
    """alpha + asin(D2s/l2) below 45 deg (where the half-coupling function g exists)."""
    return alpha_deg * DEG + math.asin(support) < (45.0 - margin_deg) * DEG


def g(phi, alpha):
    """The half-coupling function (docs/physics.md#the-half-coupling-function), written out independently."""
    s2 = math.sin(alpha) ** 2
    return np.sqrt((1.0 - 2.0 * s2 * np.cos(2.0 * phi)) / (1.0 - 2.0 * s2 * np.cos(phi) ** 2))


# --------------------------------------------------------------------------------------
# U12 = 1 identically where the coupling is synchronous
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("mode", MODES)
def test_zero_misalignment_is_synchronous_in_every_mode(mode):
    for support, hinge in ((0.03, 0.03), (0.09, 0.0), (0.0, 0.09), (0.49, 0.49)):
        tf = TransferFunction(mode, 0.0, support, hinge)
        position, ratio = over(tf.evaluate)(ANGLES)
        assert np.array_equal(ratio, np.ones_like(ANGLES))
        assert np.array_equal(position, ANGLES)
        assert tf.evaluate(1.25) == (1.25, 1.0)
        assert tf.amplitude == 0.0


@pytest.mark.parametrize("mode", ["kinematic", "scaled"])
@pytest.mark.parametrize("alpha_deg", [5.0, 20.0, 44.0, 60.0, 74.9])
def test_no_deformation_is_synchronous(mode, alpha_deg):
    # Without elastic deformation both halves are mirror images: U12 = 1 at any alpha
    # (even beyond 45 deg, where g is undefined, since g is then not needed).
    tf = TransferFunction(mode, alpha_deg * DEG, 0.0, 0.0)
    position, ratio = over(tf.evaluate)(ANGLES)
    assert np.array_equal(ratio, np.ones_like(ANGLES))
    assert np.array_equal(position, ANGLES)
    assert tf.ratio(0.7) == 1.0


@pytest.mark.parametrize("alpha_deg", [0.0, 15.0, 40.0, 60.0, 74.99])
def test_synchronous_mode_is_always_one(alpha_deg):
    for support, hinge in ((0.0, 0.0), (0.03, 0.03), (0.3, 0.45)):
        tf = TransferFunction("synchronous", alpha_deg * DEG, support, hinge)
        position, ratio = over(tf.evaluate)(ANGLES)
        assert np.array_equal(ratio, np.ones_like(ANGLES))
        assert np.array_equal(position, ANGLES)
        assert tf.amplitude == 0.0


def test_deformation_and_misalignment_give_a_non_constant_ratio():
    # The counterpart of the tests above: otherwise "U12 == 1" would pass trivially.
    for mode in ("kinematic", "scaled"):
        for support, hinge in ((0.03, 0.03), (0.05, 0.0), (0.0, 0.05)):
            tf = TransferFunction(mode, 15.0 * DEG, support, hinge)
            ratio = over(tf.ratio)(REVOLUTION)
            # scaled too when only one deformation is zero, as the kinematic mode: a fit that
            # vanished with either deformation would give U12 = 1 there
            assert ratio.max() - ratio.min() > 1e-3, (mode, support, hinge)


@pytest.mark.parametrize("support,hinge", [(0.03, 0.0), (0.0, 0.03), (0.09, 0.0), (0.0, 0.09), (0.0, 0.0),
                                           (0.03, 0.03)])
@pytest.mark.parametrize("alpha_deg", [0.0, 5.0, 20.0])
def test_scaled_and_kinematic_are_synchronous_in_the_same_cases(alpha_deg, support, hinge):
    kinematic = TransferFunction("kinematic", alpha_deg * DEG, support, hinge)
    scaled = TransferFunction("scaled", alpha_deg * DEG, support, hinge)
    assert (kinematic.amplitude == 0.0) == (scaled.amplitude == 0.0), (kinematic, scaled)


def test_u12_is_continuous_as_alpha_goes_to_zero():
    # U12 = 1 exactly at alpha = 0 (docs/physics.md#kinematics); with the support's full tilt
    # asin(0.03) = 1.7 deg (nothing to tilt against) the kinematic mode would tend to
    # 1 +- 4.5e-4 as alpha -> 0+.  The tilt is at most alpha: the ripple vanishes with alpha as
    # 1.5 alpha^2 (measured: 1.5e-6 at 1e-3 rad, 1.5e-4 at 1e-2 rad, 4.6e-4 at 1 deg); the
    # scaled mode's as its fit's sin(alpha)^0.73 (1.5e-5 at 1e-6 rad, 2.4e-3 at 1e-3 rad).
    for mode in ("kinematic", "scaled"):
        assert TransferFunction(mode, 0.0, 0.03, 0.03).amplitude == 0.0
    kinematic = [TransferFunction("kinematic", alpha, 0.03, 0.03).amplitude for alpha in (1e-3, 1e-2, 1 * DEG)]
    assert 1e-6 < kinematic[0] < 3e-6 and 1e-4 < kinematic[1] < 3e-4 and 3e-4 < kinematic[2] < 9e-4
    scaled = [TransferFunction("scaled", alpha, 0.03, 0.03).amplitude for alpha in (1e-6, 1e-3)]
    assert 0.0 < scaled[0] < 4e-5 and scaled[0] < scaled[1] < 5e-3
    tiny = TransferFunction("kinematic", 1e-6, 0.03, 0.03)
    assert all(abs(tiny.ratio(x) - 1.0) < 1e-11 for x in REVOLUTION)
    # away from zero the tilt is the full asin(D2s/l2): docs/physics.md's figures hold (below)
    assert TransferFunction("kinematic", 5 * DEG, 0.03, 0.03).tilt == math.asin(0.03)


# --------------------------------------------------------------------------------------
# Unit mean, periodicity, Phi' = U12
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("mode", ["kinematic", "scaled"])
@pytest.mark.parametrize("alpha_deg", ALPHAS_DEG)
def test_unit_mean_over_a_revolution(mode, alpha_deg):
    checked = 0
    for support in DEFORMATIONS:
        for hinge in DEFORMATIONS:
            if not kinematically_defined(alpha_deg, support):
                continue
            tf = TransferFunction(mode, alpha_deg * DEG, support, hinge)
            # A uniform N-point mean is exact for harmonics below N (no aliasing).
            assert len(tf.coefficients) < N_REV
            ratio = over(tf.ratio)(REVOLUTION)
            assert np.all(np.isfinite(ratio))
            assert abs(np.mean(ratio) - 1.0) <= 1e-12, (support, hinge)
            checked += 1
    assert checked >= 12


def _periodicity_and_derivative_cases():
    for mode in ("kinematic", "scaled"):
        for alpha_deg, support, hinge in ((5.0, 0.03, 0.03), (15.0, 0.03, 0.03), (30.0, 0.05, 0.05),
                                          (20.0, 0.09, 0.0), (20.0, 0.0, 0.09), (38.0, 0.09, 0.09)):
            yield mode, alpha_deg, support, hinge


@pytest.mark.parametrize("mode,alpha_deg,support,hinge", list(_periodicity_and_derivative_cases()))
def test_position_function_periodicity_and_origin(mode, alpha_deg, support, hinge):
    tf = TransferFunction(mode, alpha_deg * DEG, support, hinge)
    position = over(tf.position)(ANGLES)
    shifted = over(tf.position)(ANGLES + 2.0 * np.pi)
    np.testing.assert_allclose(shifted, position + 2.0 * np.pi, rtol=0, atol=1e-9)
    np.testing.assert_allclose(over(tf.position)(ANGLES - 2.0 * np.pi), position - 2.0 * np.pi, rtol=0, atol=1e-9)
    # Many revolutions away as well.
    np.testing.assert_allclose(over(tf.position)(ANGLES + 20.0 * np.pi), position + 20.0 * np.pi, rtol=0, atol=1e-9)
    assert abs(tf.position(0.0)) <= 1e-14
    assert abs(tf.position(2.0 * math.pi) - 2.0 * math.pi) <= 1e-12
    # Phi - phi stays bounded (it is periodic): a rigid chain turns both shafts alike.
    assert np.max(np.abs(position - ANGLES)) < 0.5


@pytest.mark.parametrize("mode,alpha_deg,support,hinge", list(_periodicity_and_derivative_cases()))
def test_position_derivative_is_the_transfer_function(mode, alpha_deg, support, hinge):
    tf = TransferFunction(mode, alpha_deg * DEG, support, hinge)
    e = 1e-5
    derivative = (over(tf.position)(ANGLES + e) - over(tf.position)(ANGLES - e)) / (2.0 * e)
    np.testing.assert_allclose(derivative, over(tf.ratio)(ANGLES), rtol=0, atol=1e-6)


def _numpy_coefficients(tf: TransferFunction):
    """The kinematic Fourier coefficients as the physics computed them with numpy (pocketfft)."""
    n = 256
    while True:
        phi = 2.0 * np.pi * np.arange(n) / n
        ratio = g(phi + tf.phase_shift, tf.alpha + tf.tilt) / g(phi, tf.alpha)
        spectrum = np.fft.rfft(ratio) / n
        coefficients = 2.0 * spectrum[1:n // 2] / spectrum[0].real
        if np.abs(coefficients[n // 4:]).max() < TransferFunction.TRUNCATION:
            keep = np.nonzero(np.abs(coefficients) >= TransferFunction.TRUNCATION)[0]
            return coefficients[: keep[-1] + 1]
        n *= 2


@pytest.mark.parametrize("alpha_deg,support,hinge", [(5.0, 0.03, 0.03), (15.0, 0.03, 0.03), (30.0, 0.05, 0.05),
                                                     (20.0, 0.09, 0.02), (38.0, 0.0, 0.09), (42.0, 0.04, 0.09)])
def test_the_standard_library_fft_agrees_with_numpy_to_rounding(alpha_deg, support, hinge):
    # The coefficients come from a radix-2 FFT in pure Python since the FMUs left numpy:
    # another order of operations than pocketfft's, so they differ from numpy's in the
    # last bits (by at most 1.6e-15 over the studied domain), never in their number.
    tf = TransferFunction("kinematic", alpha_deg * DEG, support, hinge)
    expected = _numpy_coefficients(tf)
    assert len(tf.coefficients) == len(expected)
    assert np.max(np.abs(np.array(tf.coefficients) - expected)) <= 1e-14
    samples = np.fft.irfft(np.concatenate([[0.0], expected * 2048.0, np.zeros(2048 - len(expected))]), 4096)
    assert tf.amplitude == pytest.approx((samples.max() - samples.min()) / 2.0, abs=1e-14)
    assert tf.minimum_ratio() == pytest.approx(1.0 + samples.min(), abs=1e-14)


def test_pairwise_sum_is_numpys_sum_bit_for_bit():
    # Exact on every CPU: numpy's float64 sum is the same additions in the same order at
    # each SIMD level (its eight accumulators are what lets the compiler vectorise it
    # without reordering), and each addition is correctly rounded.
    from lever.physics.numerics import pairwise_sum, pairwise_sum_complex
    rng = np.random.default_rng(11)
    for n in list(range(0, 300)) + [1000, 4097]:
        x = rng.standard_normal(n) * 10.0 ** rng.uniform(-5, 5, n)
        z = x + 1j * rng.standard_normal(n)
        assert pairwise_sum(x.tolist()) == float(np.sum(x)), n
        assert pairwise_sum_complex(z.tolist()) == complex(np.sum(z)), n


@pytest.mark.parametrize("n", [2, 4, 64, 256, 4096])
def test_standard_library_real_ffts_agree_with_numpy(n):
    from lever.physics.numerics import irfft, rfft
    x = np.random.default_rng(n).standard_normal(n)
    spectrum = np.fft.rfft(x)
    assert np.max(np.abs(np.array(rfft(x.tolist())) - spectrum)) <= 1e-15 * n * np.max(np.abs(x))
    assert np.max(np.abs(np.array(irfft(spectrum.tolist(), n)) - x)) <= 1e-14 * np.max(np.abs(x))
    with pytest.raises(ValueError, match="power of two"):
        rfft([1.0, 2.0, 3.0])


def test_the_reported_amplitude_fit_agrees_with_scipy():
    # Golden-section searches and Householder QR in pure Python instead of scipy's
    # trust-region least squares on all four constants: the same minimum.
    from scipy.optimize import least_squares
    from lever.physics.kinematics import MONOGRAPH_AMPLITUDES, reported_fit

    def residuals(x):
        logk, p, q, r = x
        return [logk + p * math.log(math.sin(math.radians(al))) + math.log(ds ** q + dh ** r) - math.log(du)
                for al, ds, dh, du in MONOGRAPH_AMPLITUDES]

    found = least_squares(residuals, [0.0, 0.7, 0.5, 0.5], xtol=1e-14, ftol=1e-14, gtol=1e-14).x
    np.testing.assert_allclose(reported_fit(), [math.exp(found[0]), *found[1:]], rtol=1e-5)


# --------------------------------------------------------------------------------------
# The shape and amplitude
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("alpha_deg,support,hinge", [(5.0, 0.03, 0.03), (15.0, 0.03, 0.03), (30.0, 0.05, 0.05),
                                                     (20.0, 0.09, 0.02), (38.0, 0.0, 0.09)])
def test_kinematic_mode_is_the_renormalised_half_coupling_ratio(alpha_deg, support, hinge):
    # docs/physics.md#the-three-modes: U12 ~ g(phi + d_phi, alpha + d_alpha) / g(phi, alpha), renormalised to unit mean.
    alpha = alpha_deg * DEG
    phi = 2.0 * np.pi * np.arange(1 << 15) / (1 << 15)
    raw = g(phi + math.asin(hinge), alpha + math.asin(support)) / g(phi, alpha)
    expected = raw / np.mean(raw)
    tf = TransferFunction("kinematic", alpha, support, hinge)
    np.testing.assert_allclose(over(tf.ratio)(phi), expected, rtol=0, atol=1e-9)


@pytest.mark.parametrize("alpha_deg,deformation,stated", [(5.0, 0.03, 0.003), (30.0, 0.05, 0.022)])
def test_kinematic_amplitude_matches_the_brief(alpha_deg, deformation, stated):
    # docs/physics.md#the-three-modes: about 0.003 at alpha = 5 deg, D/l = 0.03 and about 0.022 at 30 deg, 0.05.
    tf = TransferFunction("kinematic", alpha_deg * DEG, deformation, deformation)
    ratio = over(tf.ratio)(np.linspace(0.0, 2.0 * np.pi, 20001))
    measured = (ratio.max() - ratio.min()) / 2.0
    assert measured == pytest.approx(stated, rel=0.1)
    assert tf.amplitude == pytest.approx(measured, rel=1e-3)


@pytest.mark.parametrize("alpha_deg,support,hinge", [(5.0, 0.03, 0.03), (30.0, 0.05, 0.03), (20.0, 0.02, 0.03),
                                                     (20.0, 0.09, 0.03), (20.0, 0.03, 0.09), (12.0, 0.07, 0.04)])
def test_scaled_amplitude_is_the_reported_amplitude(alpha_deg, support, hinge):
    alpha = alpha_deg * DEG
    target = reported_amplitude(alpha, support, hinge)
    assert target > 0.0
    scaled = TransferFunction("scaled", alpha, support, hinge)
    kinematic = TransferFunction("kinematic", alpha, support, hinge)
    ratio = over(scaled.ratio)(np.linspace(0.0, 2.0 * np.pi, 20001))
    assert (ratio.max() - ratio.min()) / 2.0 == pytest.approx(target, rel=1e-3)
    assert scaled.amplitude == pytest.approx(target, rel=1e-12)
    # Same shape as the kinematic mode: U12 - 1 is a scaled copy.
    factor = target / kinematic.amplitude
    np.testing.assert_allclose(over(scaled.ratio)(ANGLES) - 1.0, factor * (over(kinematic.ratio)(ANGLES) - 1.0),
                               rtol=0, atol=1e-9 * factor)


def test_reported_amplitude_vanishes_without_misalignment_or_deformation():
    assert reported_amplitude(0.0, 0.03, 0.03) == 0.0
    assert reported_amplitude(20 * DEG, 0.0, 0.0) == 0.0
    # either deformation alone displaces the driven half (as in the kinematic mode)
    assert 0.0 < reported_amplitude(20 * DEG, 0.0, 0.03) < reported_amplitude(20 * DEG, 0.03, 0.03)
    assert 0.0 < reported_amplitude(20 * DEG, 0.03, 0.0) < reported_amplitude(20 * DEG, 0.03, 0.03)
    # and grows with alpha and with each deformation
    assert reported_amplitude(10 * DEG, 0.03, 0.03) < reported_amplitude(20 * DEG, 0.03, 0.03)
    assert reported_amplitude(20 * DEG, 0.02, 0.03) < reported_amplitude(20 * DEG, 0.09, 0.03)
    assert reported_amplitude(20 * DEG, 0.03, 0.02) < reported_amplitude(20 * DEG, 0.03, 0.09)


# --------------------------------------------------------------------------------------
# Refusals
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("mode", ["kinematic", "scaled"])
@pytest.mark.parametrize("alpha_deg,support", [(44.0, 0.1), (40.0, 0.09), (45.0, 0.03), (30.0, 0.3),
                                               (50.0, 0.01), (44.99, 0.001)])
def test_alpha_plus_support_tilt_at_45_deg_is_refused(mode, alpha_deg, support):
    assert not kinematically_defined(alpha_deg, support)
    with pytest.raises(ParameterError) as info:
        TransferFunction(mode, alpha_deg * DEG, support, 0.03)
    assert "alpha" in str(info.value)
    assert info.value.name in ("alpha", "misalignment")
    # Synchronous mode has no such limit below 75 deg.
    assert TransferFunction("synchronous", alpha_deg * DEG, support, 0.03).ratio(1.0) == 1.0


def test_just_below_the_kinematic_limit_is_accepted():
    alpha = 45.0 * DEG - math.asin(0.1) - 0.5 * DEG
    tf = TransferFunction("kinematic", alpha, 0.1, 0.03)
    assert abs(np.mean(over(tf.ratio)(REVOLUTION)) - 1.0) <= 1e-12


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("alpha_deg", [75.0, 80.0, 90.0, 180.0])
def test_alpha_at_or_beyond_75_deg_is_refused_in_every_mode(mode, alpha_deg):
    for support, hinge in ((0.0, 0.0), (0.03, 0.03)):
        with pytest.raises(ParameterError) as info:
            TransferFunction(mode, alpha_deg * DEG, support, hinge)
        assert "alpha" in str(info.value) or "misalignment" in str(info.value)


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("alpha", [math.nan, math.inf, -math.inf, -1e-9, -0.1])
def test_non_finite_or_negative_alpha_is_refused(mode, alpha):
    with pytest.raises(ParameterError) as info:
        TransferFunction(mode, alpha, 0.03, 0.03)
    assert info.value.name in ("alpha", "misalignment")


@pytest.mark.parametrize("name,support,hinge", [("support_deformation", math.nan, 0.03),
                                                ("support_deformation", -0.01, 0.03),
                                                ("support_deformation", 0.5, 0.03),
                                                ("hinge_deformation", 0.03, math.inf),
                                                ("hinge_deformation", 0.03, -0.2),
                                                ("hinge_deformation", 0.03, 0.7)])
def test_bad_deformations_are_refused(name, support, hinge):
    for mode in MODES:
        with pytest.raises(ParameterError) as info:
            TransferFunction(mode, 15.0 * DEG, support, hinge)
        assert info.value.name == name
        assert name in str(info.value)


def test_unknown_mode_is_refused():
    with pytest.raises(ParameterError) as info:
        TransferFunction("cardan", 15.0 * DEG, 0.03, 0.03)
    assert info.value.name == "transfer_mode"
    for mode in MODES:
        assert mode in str(info.value)


# --------------------------------------------------------------------------------------
# Properties over the whole studied domain
# --------------------------------------------------------------------------------------


@settings(max_examples=50, deadline=None, derandomize=True, database=None)
@given(alpha_deg=st.floats(0.0, 40.0), support=st.floats(0.0, 0.09), hinge=st.floats(0.0, 0.09),
       mode=st.sampled_from(["kinematic", "scaled"]))
def test_unit_mean_and_periodicity_property(alpha_deg, support, hinge, mode):
    # Keep half a degree from the 45 deg singularity, where the series needs thousands of
    # harmonics (a uniform 4096-point mean would alias them).
    assume(kinematically_defined(alpha_deg, support, margin_deg=0.5))
    tf = TransferFunction(mode, alpha_deg * DEG, support, hinge)
    position, ratio = over(tf.evaluate)(REVOLUTION)
    assert np.all(np.isfinite(ratio)) and np.all(ratio > 0.0)
    assert abs(np.mean(ratio) - 1.0) <= 1e-12
    shifted, shifted_ratio = over(tf.evaluate)(REVOLUTION + 2.0 * np.pi)
    np.testing.assert_allclose(shifted, position + 2.0 * np.pi, rtol=0, atol=1e-9)
    np.testing.assert_allclose(shifted_ratio, ratio, rtol=0, atol=1e-9)
    assert abs(tf.position(0.0)) <= 1e-14


def test_loading_the_physics_does_not_fit_the_reported_amplitudes():
    # Every FMU imports the kinematics: the fit (0.2 s) waits for the scaled mode to need it.
    import subprocess
    import sys
    code = ("import lever.physics, lever.fmus.coupling, lever.physics.kinematics as k; "
            "assert k.reported_fit.cache_info().currsize == 0; "
            "k.TransferFunction('kinematic', 0.26, 0.03, 0.03); assert k.reported_fit.cache_info().currsize == 0; "
            "k.TransferFunction('scaled', 0.26, 0.03, 0.03); assert k.reported_fit.cache_info().currsize == 1")
    subprocess.run([sys.executable, "-c", code], check=True)


@pytest.mark.parametrize("mode", ["kinematic", "scaled", "synchronous"])
def test_a_transfer_function_is_made_once_for_the_same_values_and_is_the_one_made_fresh(mode):
    values = (mode, math.radians(21.0), 0.04, 0.02)
    kept = transfer_function(*values)
    assert transfer_function(*values) is kept
    fresh = TransferFunction(*values)
    assert kept.coefficients == fresh.coefficients and kept.amplitude == fresh.amplitude
    assert [kept.evaluate(0.1 * k) for k in range(64)] == [fresh.evaluate(0.1 * k) for k in range(64)]
    assert transfer_function(mode, math.radians(21.5), 0.04, 0.02) is not kept
