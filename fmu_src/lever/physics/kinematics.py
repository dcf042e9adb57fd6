"""Kinematics of the lever-articulated coupling: the transfer function ``U12`` and the
position function ``Phi`` (docs/physics.md#kinematics).

``Phi(phi2)`` is the drive-side angle that a rigid coupling would hold for driven angle
``phi2``; ``U12 = dPhi/dphi2``.  Both are represented by one truncated Fourier series,

    U12(phi) = 1 + Re sum_k C_k e^{i k phi},      Phi(phi) = phi + Re sum_k C_k/(i k) (e^{i k phi} - 1),

so ``U12`` has unit mean and ``Phi(phi + 2 pi) = Phi(phi) + 2 pi`` hold by construction
(no constant term), ``Phi(0) = 0``, and evaluation is one Horner pass in complex
arithmetic.  Scalars only (the FMU runs on the standard library): the harness maps it
over arrays.

The printed driven-half formula (3.14) and transfer function (3.16) are garbled
(docs/physics.md#defects-of-the-sources); they are not used.  The kinematic mode builds
``U12`` from the Cardan-like half-coupling function ``g`` instead.
"""
from __future__ import annotations

import cmath
import functools
import math

from .numerics import irfft, least_squares, pairwise_sum_complex, rfft
from .parameters import ParameterError

#: ``g`` is defined for misalignment angles below 45 deg (its denominator vanishes there).
KINEMATIC_LIMIT = math.pi / 4
#: The coupling's geometric working range (monograph section 2.3; dead position at 90 deg).
GEOMETRIC_LIMIT = math.radians(75.0)

MODES = ("synchronous", "kinematic", "scaled")

# Amplitudes dU12 = (max - min)/2 that the monograph reports from its own (defective)
# formula, Fig. 3.7 / docs/physics.md#the-three-modes: (alpha [deg], D2s/l2, D2h/lc2, dU12).  Where
# the text does not say the other deformation, it is taken as 0.03 (the figure's
# alpha curves are drawn at 0.03): a stated assumption.
MONOGRAPH_AMPLITUDES = (
    (5.0, 0.03, 0.03, 0.065),
    (30.0, 0.05, 0.03, 0.34),
    (20.0, 0.02, 0.03, 0.139),
    (20.0, 0.09, 0.03, 0.264),
    (20.0, 0.03, 0.02, 0.136),
    (20.0, 0.03, 0.09, 0.231),
)


@functools.cache
def reported_fit() -> tuple[float, float, float, float]:
    """Least-squares fit of ``dU = k sin(alpha)^p ((D2s/l2)^q + (D2h/lc2)^r)`` in logs to
    the reported points (on first use, by the scaled mode only: at import it cost every FMU
    about 0.2 s of loading): ``k`` and ``p`` linear for given exponents, ``q`` and ``r`` by
    alternating golden-section searches.  It vanishes at alpha = 0 and when both
    deformations are zero - not when only one is, like the kinematic mode, whose driven
    half is displaced by either deformation alone - and varies smoothly between the few
    printed points (within 18 % of each)."""
    rows = [(math.log(math.sin(math.radians(al))), ds, dh, math.log(du)) for al, ds, dh, du in MONOGRAPH_AMPLITUDES]
    a = [[1.0, ls] for ls, *_ in rows]

    def fitted(q, r):
        y = [ldu - math.log(ds ** q + dh ** r) for _, ds, dh, ldu in rows]
        coef = least_squares(a, y)
        return coef, sum((yi - coef[0] - coef[1] * ai[1]) ** 2 for yi, ai in zip(y, a))

    def search(cost, low=0.02, high=3.0):
        golden = (math.sqrt(5.0) - 1.0) / 2.0
        for _ in range(60):
            x1, x2 = high - golden * (high - low), low + golden * (high - low)
            low, high = (low, x2) if cost(x1) < cost(x2) else (x1, high)
        return 0.5 * (low + high)

    q = r = 0.5
    for _ in range(40):
        q = search(lambda x: fitted(x, r)[1])
        r = search(lambda x: fitted(q, x)[1])
    coef, _ = fitted(q, r)
    return math.exp(coef[0]), coef[1], q, r


def reported_amplitude(alpha: float, support_deformation: float, hinge_deformation: float) -> float:
    """The monograph's reported dU12 (Fig. 3.7), interpolated by ``k sin(alpha)^p
    ((D2s/l2)^q + (D2h/lc2)^r)``.  Zero when alpha is zero or both deformations are (the
    coupling is then synchronous), as the kinematic mode's amplitude is."""
    if alpha <= 0.0 or (support_deformation <= 0.0 and hinge_deformation <= 0.0):
        return 0.0
    k, p, q, r = reported_fit()
    return k * math.sin(alpha) ** p * (support_deformation ** q + hinge_deformation ** r)


def half_coupling_ratio(phi, alpha):
    """Speed ratio of a half-coupling's earring to its shaft, ``w_c / w``, (3.14, first
    line).  Cardan-like, period pi in ``phi``, defined for ``alpha < 45 deg``."""
    s2 = math.sin(alpha) ** 2
    return math.sqrt((1.0 - 2.0 * s2 * math.cos(2.0 * phi)) / (1.0 - 2.0 * s2 * math.cos(phi) ** 2))


class TransferFunction:
    """``U12(phi2)`` and ``Phi(phi2)`` for one misalignment and deformation state.

    ``mode``:
      * ``synchronous``: ``U12 = 1`` (no misalignment effect), alpha in [0, 75) deg;
      * ``kinematic``: ``U12 ~ g(phi + d_phi, alpha + d_alpha) / g(phi, alpha)``,
        renormalised to unit mean, with ``d_alpha = min(asin(D2s/l2), alpha)`` (tilt of the
        driven shaft on its elastic support, at most the misalignment) and ``d_phi = asin(D2h/lc2)`` (phase shift in the
        elastic hinge), (3.13); needs ``alpha + d_alpha < 45 deg``;
      * ``scaled``: the kinematic shape with its amplitude scaled to the monograph's
        reported amplitude (``reported_amplitude``).
    """

    #: Fourier coefficients below this (relative to 1) are dropped.
    TRUNCATION = 1e-13

    def __init__(self, mode: str, alpha: float, support_deformation: float = 0.0,
                 hinge_deformation: float = 0.0):
        if mode not in MODES:
            raise ParameterError("transfer_mode", f"parameter 'transfer_mode' = {mode!r} is not allowed: "
                                 f"it must be one of {', '.join(MODES)}")
        for name, value, high in (("misalignment", alpha, GEOMETRIC_LIMIT),
                                  ("support_deformation", support_deformation, 0.5),
                                  ("hinge_deformation", hinge_deformation, 0.5)):
            if not (math.isfinite(value) and 0.0 <= value < high):
                raise ParameterError(name, f"parameter '{name}' = {value} is outside its allowed range "
                                     f"[0, {high:.6g})" + (" rad (75 deg), the coupling's geometric working range (alpha)" if name == "misalignment" else ""))
        self.mode = mode
        self.alpha = float(alpha)
        self.support_deformation = float(support_deformation)
        self.hinge_deformation = float(hinge_deformation)
        # d_alpha: the support's tilt, no more than the misalignment that loads it, so that
        # U12 -> 1 continuously as alpha -> 0 (the full tilt at alpha -> 0+ would leave a
        # 4.5e-4 ripple there, where U12 = 1 exactly at alpha = 0; docs/record/decisions.md)
        self.tilt = min(math.asin(self.support_deformation), self.alpha)
        self.phase_shift = math.asin(self.hinge_deformation)     # d_phi
        coefficients = []
        if mode != "synchronous" and self.alpha > 0.0 and (self.tilt > 0.0 or self.phase_shift > 0.0):
            coefficients = self._kinematic_coefficients()
            if mode == "scaled" and coefficients:
                target = reported_amplitude(self.alpha, self.support_deformation, self.hinge_deformation)
                factor = target / self._amplitude_of(coefficients)
                coefficients = [c * factor for c in coefficients]
        #: C_k, k = 1, 2, ...: U12 = 1 + Re sum_k C_k e^{i k phi}
        self.coefficients = tuple(coefficients)
        position_coefficients = [c / (1j * k) for k, c in enumerate(coefficients, start=1)]
        # the real part of numpy's (pairwise) sum, as before the physics left numpy
        self._position_offset = pairwise_sum_complex(position_coefficients).real
        self._c = coefficients[::-1]
        self._d = position_coefficients[::-1]
        self.amplitude = self._amplitude_of(coefficients) if coefficients else 0.0
        if coefficients and self.minimum_ratio() <= 0.05:
            raise ParameterError("misalignment", f"parameter 'misalignment' (alpha) = {math.degrees(alpha):.4g} deg gives a transfer "
                                 f"function amplitude {self.amplitude:.3g} in mode {mode!r}: U12 would "
                                 "approach zero (the coupling would lock); reduce alpha or the deformations")

    # -- construction -------------------------------------------------------------------
    def _kinematic_coefficients(self) -> list[complex]:
        if self.alpha + self.tilt >= KINEMATIC_LIMIT:
            raise ParameterError("misalignment", (
                f"parameter 'misalignment' (alpha) = {math.degrees(self.alpha):.4g} deg plus the support tilt "
                f"asin(support_deformation) = {math.degrees(self.tilt):.4g} deg reaches 45 deg, where the "
                f"half-coupling function is undefined; mode {self.mode!r} needs alpha + tilt < 45 deg "
                "(use transfer_mode='synchronous' up to 75 deg)"))
        n = 256
        alpha, tilted, shift = self.alpha, self.alpha + self.tilt, self.phase_shift
        while n <= 1 << 16:
            ratio = []
            for j in range(n):
                phi = 2.0 * math.pi * j / n
                ratio.append(half_coupling_ratio(phi + shift, tilted) / half_coupling_ratio(phi, alpha))
            spectrum = [x / n for x in rfft(ratio)]
            mean = spectrum[0].real
            coefficients = [2.0 * x / mean for x in spectrum[1:n // 2]]  # e^{ik phi} coefficients, k >= 1
            tail = max(abs(c) for c in coefficients[n // 4:])
            if tail < self.TRUNCATION:
                keep = [k for k, c in enumerate(coefficients) if abs(c) >= self.TRUNCATION]
                return coefficients[: keep[-1] + 1] if keep else []
            n *= 2
        raise ParameterError("misalignment", f"parameter 'misalignment' (alpha) = {math.degrees(self.alpha):.4g} deg is too close "
                             "to the 45 deg singularity of the half-coupling function to be represented")

    @staticmethod
    def _samples(coefficients: list[complex]) -> list[float]:
        """``U12 - 1`` at 4096 (or more, for long series) equidistant angles, by one
        inverse FFT (a transfer function is built for every 0.05 deg a time-varying
        misalignment passes: this runs often)."""
        n = 4096
        while n < 4 * len(coefficients):
            n *= 2
        spectrum = [0j] + [c * (n / 2.0) for c in coefficients]
        spectrum += [0j] * (n // 2 + 1 - len(spectrum))
        return irfft(spectrum, n)

    @classmethod
    def _amplitude_of(cls, coefficients: list[complex]) -> float:
        ratio = cls._samples(coefficients)
        return (max(ratio) - min(ratio)) / 2.0

    # -- evaluation ---------------------------------------------------------------------
    def evaluate(self, phi):
        """Return ``(Phi(phi), U12(phi))``."""
        if not self._c:
            return phi, 1.0
        z = cmath.exp(1j * phi)
        ratio = 0j
        position = 0j
        for c, d in zip(self._c, self._d):
            ratio = ratio * z + c
            position = position * z + d
        ratio = ratio * z
        position = position * z
        return phi + position.real - self._position_offset, 1.0 + ratio.real

    def ratio(self, phi):
        """``U12(phi2) = w1/w2`` of a rigid coupling."""
        return self.evaluate(phi)[1]

    def ratio_slope(self, phi):
        """``dU12/dphi2 = Re sum_k i k C_k e^{i k phi}``: the series differentiated term by
        term (exact for the truncated series ``evaluate`` sums).  ``dPhi/dphi2`` is ``U12``
        itself."""
        if not self._c:
            return 0.0
        z = cmath.exp(1j * phi)
        slope = 0j
        for k, c in zip(range(len(self._c), 0, -1), self._c):
            slope = slope * z + 1j * k * c
        return (slope * z).real

    def position(self, phi):
        """``Phi(phi2)``: the drive angle a rigid coupling holds for driven angle ``phi2``."""
        return self.evaluate(phi)[0]

    def minimum_ratio(self) -> float:
        if not self.coefficients:
            return 1.0
        return 1.0 + min(self._samples(self.coefficients))

    def __repr__(self) -> str:
        return (f"TransferFunction(mode={self.mode!r}, alpha={math.degrees(self.alpha):.3g} deg, "
                f"support_deformation={self.support_deformation}, hinge_deformation={self.hinge_deformation}, "
                f"amplitude={self.amplitude:.4g}, harmonics={len(self._c)})")


@functools.lru_cache(maxsize=256)
def transfer_function(mode: str, alpha: float, support_deformation: float = 0.0,
                      hinge_deformation: float = 0.0) -> TransferFunction:
    """``TransferFunction(mode, alpha, ...)``, made once a process for the same values: a
    run builds it in the reference and in the coupling FMU, a study builds it run after run,
    and its Fourier series and samples cost more than the rest of a short run's set-up.  It
    is read, never changed, so one object serves every caller."""
    return TransferFunction(mode, alpha, support_deformation, hinge_deformation)


class BlendedTransferFunction:
    """``U12`` and ``Phi`` between two transfer functions ``lower`` (at ``alpha_low``)
    and ``upper`` (at ``alpha_high``), blended linearly in alpha: what a coupling uses at
    a misalignment that varies in time (see ``coupling.CouplingFamily``).  A convex
    combination of unit-mean functions: ``U12`` keeps its unit mean and ``Phi`` its
    ``Phi(phi + 2 pi) = Phi(phi) + 2 pi``."""

    def __init__(self, lower: TransferFunction, upper: TransferFunction, alpha: float):
        span = upper.alpha - lower.alpha
        self.weight = (alpha - lower.alpha) / span if span else 0.0
        self.lower, self.upper = lower, upper
        self.mode = lower.mode
        self.alpha = float(alpha)

    def evaluate(self, phi):
        p0, u0 = self.lower.evaluate(phi)
        p1, u1 = self.upper.evaluate(phi)
        w = self.weight
        return p0 + w * (p1 - p0), u0 + w * (u1 - u0)

    def ratio(self, phi):
        return self.evaluate(phi)[1]

    def ratio_slope(self, phi):
        """``dU12/dphi2`` of the blend."""
        s0, s1 = self.lower.ratio_slope(phi), self.upper.ratio_slope(phi)
        return s0 + self.weight * (s1 - s0)

    def alpha_slopes(self, phi):
        """``(dPhi/dalpha, dU12/dalpha)``: the blend is linear in alpha between its nodes."""
        p0, u0 = self.lower.evaluate(phi)
        p1, u1 = self.upper.evaluate(phi)
        span = self.upper.alpha - self.lower.alpha
        return (p1 - p0) / span, (u1 - u0) / span

    def position(self, phi):
        return self.evaluate(phi)[0]
