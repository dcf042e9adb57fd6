"""Technological load on the driven shaft (docs/physics.md#loads): ``I2 * a2 = tau2 - Mc``.

Each load gives its resistance ``Mc`` (positive when it opposes positive rotation) and,
as a shaft's external torque model, ``torque = -Mc``.  Loads that depend on time only
(constant, random, tabulated) integrate in closed form over a step, so the load shaft is
exact for them; the angle-periodic measured load is integrated numerically, and the
spectrum load's shaft-order term alone (``SpectrumLoad.advance_split``).

The random part is a deterministic function of time for a given seed, the same whatever
the step or the master, so every master, every engine and the monolithic reference see
exactly the same load.
"""
from __future__ import annotations

import cmath
import csv
import math
from pathlib import Path
from typing import NamedTuple, Sequence

from .numerics import SeededUniform, pairwise_sum
from .parameters import TABLE_LIMIT, ParameterError, parse_table
from .signals import TimeTable

LOAD_KINDS = ("constant", "random", "fourier", "table")


def _sinc(y: float) -> float:
    return 1.0 - y * y / 6.0 + y ** 4 / 120.0 if abs(y) < 1e-3 else math.sin(y) / y


def _one_minus_sinc_over_y(y: float) -> float:
    """(1 - sin(y)/y) / y without cancellation."""
    if abs(y) < 1e-2:
        y2 = y * y
        return y * (1.0 / 6.0 - y2 / 120.0 + y2 * y2 / 5040.0)
    return (y - math.sin(y)) / (y * y)


def _first_integral(f: float, s: float) -> complex:
    """``int_0^s e^{i f r} dr = s e^{i f s/2} sinc(f s/2)``, without cancellation."""
    return s * cmath.exp(0.5j * f * s) * _sinc(0.5 * f * s)


def _second_integral(f: float, s: float) -> complex:
    """``int_0^s (s - r) e^{i f r} dr = s^2 (e^{iy} - 1 - iy)/(iy)^2`` with ``y = f s``: its
    real part ``s^2 (1 - cos y)/y^2 = s^2 sinc(y/2)^2 / 2``, its imaginary part
    ``s^2 (y - sin y)/y^2``, both without cancellation (RandomLoad's closed form writes the
    same terms)."""
    y = f * s
    return s * s * complex(0.5 * _sinc(0.5 * y) ** 2, _one_minus_sinc_over_y(y))


class _TimeLoad:
    """A load that depends on time only: exact shaft steps from its first and second
    time integrals over the step."""

    def torque(self, t, phi, w):
        return -self.resistance(t, phi, w)

    def resistance_slope(self, t, phi, w):
        """``dMc/dphi``: none, the load depends on time only (nor on ``w``)."""
        return 0.0

    def advance(self, inertia, t, phi, w, tau, h, tau_rate=0.0):
        """Exact step with coupling torque ``tau + tau_rate * s``."""
        impulse, second = self.integrals(t, h)
        return (phi + w * h + ((0.5 * tau + tau_rate * h / 6.0) * h * h - second) / inertia,
                w + ((tau + 0.5 * tau_rate * h) * h - impulse) / inertia)


class ConstantLoad(_TimeLoad):
    def __init__(self, mean: float):
        self.mean = float(mean)

    def resistance(self, t, phi, w):
        return self.mean

    def integrals(self, t, h):
        return self.mean * h, 0.5 * self.mean * h * h


class RandomLoad(_TimeLoad):
    """``Mc = Mm + dM * sum_k a_k sin(w_k t + psi_k)``, a seeded band-limited multisine.

    ``tones`` frequencies are drawn log-uniformly in ``[band_low, band_high]`` rad/s with
    random phases and weights; the weights are normalised to ``sum |a_k| = 1`` so that
    ``|Mc - Mm| <= dM`` always holds: ``dM`` is the bound the monograph writes as
    ``Mm +- dM``.  The default band (2...450 rad/s) spans the shaft rotation frequency and
    the 415-425 rad/s component of the monograph's oscillograms.
    """

    def __init__(self, mean: float, amplitude: float, seed: int = 1, tones: int = 6,
                 band_low: float = 2.0, band_high: float = 450.0):
        if not 0.0 < band_low <= band_high:
            raise ParameterError("band_low", f"parameter 'band_low' = {band_low} must be > 0 and "
                                 f"<= band_high = {band_high} rad/s")
        self.mean = float(mean)
        self.amplitude = float(amplitude)
        # numpy's default_rng(seed) draw for draw (lever.physics.numerics): the same load as
        # when the physics used numpy, and in every host whatever its Python has installed
        rng = SeededUniform(int(seed))
        self.frequencies = [math.exp(x) for x in rng.uniform(math.log(band_low), math.log(band_high), int(tones))]
        self.phases = rng.uniform(0.0, 2.0 * math.pi, int(tones))
        weights = rng.uniform(0.5, 1.0, int(tones))
        total = pairwise_sum(weights)
        self.weights = [self.amplitude * w / total for w in weights]
        self._tones = list(zip(self.weights, self.frequencies, self.phases))
        self._per_step: dict[float, list] = {}   # step size -> what integrals() needs of each tone

    #: step sizes whose per-tone constants are kept (an adaptive master takes many)
    STEP_CACHE = 64

    def _step_constants(self, h: float) -> list:
        """Per tone what ``integrals`` needs that depends on the step size only, computed
        once per step size: the same operations, so the same numbers."""
        constants = self._per_step.get(h)
        if constants is None:
            if len(self._per_step) >= self.STEP_CACHE:
                self._per_step.clear()
            constants = self._per_step[h] = [
                (f, p, a * h, 0.5 * a * h * h, 0.5 * (f * h), 0.25 * (f * h), _sinc(0.5 * (f * h)),
                 _sinc(0.25 * (f * h)), _one_minus_sinc_over_y(0.5 * (f * h)))
                for a, f, p in self._tones]
        return constants

    def resistance(self, t, phi, w):
        return self.mean + sum(a * math.sin(f * t + p) for a, f, p in self._tones)

    def integrals(self, t, h):
        impulse = self.mean * h
        second = 0.5 * self.mean * h * h
        for f, p, ah, aah, half, quarter, sinc_half, sinc_quarter, rest_half in self._step_constants(h):
            start = f * t + p
            impulse += ah * math.sin(start + half) * sinc_half
            second += aah * (math.sin(start + quarter) * sinc_quarter + math.cos(start + half) * rest_half)
        return impulse, second


class Spectrum(NamedTuple):
    """What the random part (``load_kind = "random"``) makes of its bound ``dM`` when it
    carries the spectrum of the oscillograms (a share above 0)
    (docs/physics.md#the-oscillograms-spectrum: the oscillograms show a component at the
    shaft's rotation frequency and one at 415-425 rad/s):
    ``order_share * dM * sin(order * phi + order_phase)``, locked to the
    driven shaft's angle, ``narrowband_tones`` seeded tones in
    ``[narrowband_low, narrowband_high]`` rad/s whose weights sum to
    ``narrowband_share * dM``, and the broad multisine with the rest of ``dM``.  Both shares
    0: the broad multisine alone, ``RandomLoad`` as it always was."""
    order: int = 1
    order_share: float = 0.0
    order_phase: float = 0.0
    narrowband_share: float = 0.0
    narrowband_low: float = 415.0
    narrowband_high: float = 425.0
    narrowband_tones: int = 5


class SpectrumLoad(RandomLoad):
    """``Mc = Mm + A_k sin(k phi + psi) + (narrow band) + (broad multisine)``, the three
    amplitudes summing to the bound ``dM``, so ``|Mc - Mm| <= dM`` holds as for
    ``RandomLoad``: ``A_k = order_share * dM``, the narrow band's weights sum to
    ``narrowband_share * dM``, the broad multisine (``RandomLoad``'s tones for the seed, drawn
    first) is bounded by the rest.  The narrow band's frequencies (uniform in its band),
    phases and weights are the seed's next draws.  A deterministic function of time and the
    driven angle for a given seed.  With ``order_share = 0`` the load depends on time only and
    the shaft steps exactly (closed-form integrals over all tones); otherwise exactly in
    time and by RK4 on the order term alone (``advance_split``)."""

    def __init__(self, mean: float, amplitude: float, seed: int, tones: int, band_low: float, band_high: float,
                 spectrum: Spectrum):
        shares = spectrum.order_share + spectrum.narrowband_share
        if not shares <= 1.0:
            raise ParameterError("narrowband_share", f"parameter 'narrowband_share' = {spectrum.narrowband_share:g} "
                                 f"and 'order_share' = {spectrum.order_share:g} sum to {shares:g}: the shares of "
                                 "the bound dM may sum to 1 at most")
        low, high = spectrum.narrowband_low, spectrum.narrowband_high
        if not 0.0 < low <= high:
            raise ParameterError("narrowband_low", f"parameter 'narrowband_low' = {low} must be > 0 and <= "
                                 f"narrowband_high = {high} rad/s")
        super().__init__(mean, amplitude * max(0.0, 1.0 - shares), seed, tones, band_low, band_high)
        rng = SeededUniform(int(seed))
        rng.uniform(0.0, 1.0, 3 * int(tones))          # the broad multisine's draws
        n = int(spectrum.narrowband_tones)
        frequencies = rng.uniform(low, high, n)
        phases = rng.uniform(0.0, 2.0 * math.pi, n)
        weights = rng.uniform(0.5, 1.0, n)
        total = pairwise_sum(weights)
        band = spectrum.narrowband_share * amplitude
        self.narrowband = [(band * w / total, f, p) for w, f, p in zip(weights, frequencies, phases)]
        self._tones = self._tones + self.narrowband
        self.spectrum = spectrum
        self.bound = float(amplitude)                  # dM: |Mc - Mm| <= dM
        self.order = int(spectrum.order)
        self.order_amplitude = spectrum.order_share * amplitude
        self.order_phase = float(spectrum.order_phase)
        #: bound of |dMc/dphi| [N.m/rad]: sets the RK4 substep that stays stable
        self.angle_stiffness = self.order * self.order_amplitude
        # Tones of weight 0 (a share of 1 leaves the broad multisine none) add exact zeros:
        # left out, the same sums.
        self._live_tones = [tone for tone in self._tones if tone[0] != 0.0]
        # The time part at the last time asked: a step's end is its outputs' time and the
        # next step's start (a ramped torque's work evaluates the load at both ends).
        self._last_time = self._last_part = math.nan
        self._kernels: dict[float, list] = {}

    def rate(self, inertia: float) -> float:
        return math.sqrt(self.angle_stiffness / inertia)

    def time_part(self, t: float) -> float:
        """``Mm`` plus the tones at time ``t`` [N.m]: the part of ``Mc`` that does not
        depend on the angle."""
        if t == self._last_time:
            return self._last_part
        value = self.mean + sum(a * math.sin(f * t + p) for a, f, p in self._live_tones)
        self._last_time, self._last_part = t, value
        return value

    def resistance(self, t, phi, w):
        return self.time_part(t) + self.order_amplitude * math.sin(self.order * phi + self.order_phase)

    def resistance_slope(self, t, phi, w):
        """``dMc/dphi`` of the shaft-order term ``A_k sin(k phi + psi)``."""
        return self.order_amplitude * self.order * math.cos(self.order * phi + self.order_phase)

    def advance(self, inertia, t, phi, w, tau, h, tau_rate=0.0):
        if self.order_amplitude:
            return None     # depends on the angle: the shaft steps by advance_split
        return super().advance(inertia, t, phi, w, tau, h, tau_rate)

    #: largest change of the order term's phase ``k * phi`` in one RK4 substep [rad]
    PHASE_STEP = 0.25

    def phase_rate(self, w: float) -> float:
        """How fast the order term's phase turns at speed ``w`` [rad/s]: with ``PHASE_STEP``
        it bounds the substep of ``advance_split``."""
        return abs(self.order * w) if self.order_amplitude else 0.0

    def advance_split(self, inertia, t, phi, w, tau, h, tau_rate, substeps):
        """State ``(phi, w)`` after ``h`` with coupling torque ``tau + tau_rate * s``, in
        ``substeps`` equal substeps: the motion under the coupling torque and the part of
        ``Mc`` that depends on time only is exact (its first and second time integrals,
        the tones' in closed form), the order term's effect on it by classical RK4.

        Over a substep of ``d`` from ``(phi0, w0)`` the time part alone gives
        ``phi_T(s) = phi0 + w0 s + P(s)``, ``w_T(s) = w0 + W(s)``; the deviation ``(x, v)``
        from it obeys ``x' = v``, ``I v' = -A sin(k (phi_T + x) + psi)``, ``x(0) = v(0) = 0``,
        which RK4 integrates with nodes at ``0, d/2, d``.  The narrow band (415-425 rad/s)
        is thereby exact at any substep; what the substep must resolve is only the order
        term, which turns at ``k w`` (``PHASE_STEP`` per substep at most).  Without an order
        term the deviation is zero and the step equals the closed form to rounding."""
        d = h / substeps
        kernels = self._split_kernels(d)
        amplitude, order, phase = self.order_amplitude / inertia, self.order, self.order_phase
        mean, sin = self.mean, math.sin
        # each tone's phasor a * e^{i (f t + p)} at the substep's start, turned on by e^{i f d}
        phasors = [a * cmath.exp(1j * (f * t + p)) for a, f, p in self._live_tones]
        half2, d2 = 0.125 * d * d, 0.5 * d * d
        for j in range(substeps):
            torque = tau + tau_rate * (j * d) - mean        # the polynomial part at the substep's start
            impulse = second_half = second = 0.0
            for z, (_, e1, e2_half, e2) in zip(phasors, kernels):
                impulse += (z * e1).imag
                second_half += (z * e2_half).imag
                second += (z * e2).imag
            change = (torque * d + 0.5 * tau_rate * d * d - impulse) / inertia                  # W(d)
            lift_half = (torque * half2 + tau_rate * d * d * d / 48.0 - second_half) / inertia  # P(d/2)
            lift = (torque * d2 + tau_rate * d * d * d / 6.0 - second) / inertia                # P(d)
            middle = phi + 0.5 * d * w + lift_half
            g1 = -amplitude * sin(order * phi + phase)
            g2 = -amplitude * sin(order * middle + phase)
            g3 = -amplitude * sin(order * (middle + 0.25 * d * d * g1) + phase)
            g4 = -amplitude * sin(order * (phi + d * w + lift + d2 * g2) + phase)
            phi, w = (phi + d * w + lift + d * d * (g1 + g2 + g3) / 6.0,
                      w + change + d * (g1 + 2.0 * g2 + 2.0 * g3 + g4) / 6.0)
            if j + 1 < substeps:
                phasors = [z * kernel[0] for z, kernel in zip(phasors, kernels)]
        return phi, w

    def _split_kernels(self, d: float) -> list:
        """Per live tone, for substeps of ``d``: ``e^{i f d}`` and the integrals
        ``E1(d) = int_0^d e^{i f r} dr``, ``E2(s) = int_0^s (s - r) e^{i f r} dr`` at
        ``s = d/2`` and ``d`` (a tone's integrals over a substep are ``Im(z E)``), kept per
        substep size like ``_step_constants``."""
        kernels = self._kernels.get(d)
        if kernels is None:
            if len(self._kernels) >= self.STEP_CACHE:
                self._kernels.clear()
            kernels = self._kernels[d] = [(cmath.exp(1j * f * d), _first_integral(f, d), _second_integral(f, 0.5 * d),
                                           _second_integral(f, d)) for _, f, _ in self._live_tones]
        return kernels


class TabulatedLoad(_TimeLoad):
    """Resistance from a time series (time, torque): linear between points, the end
    values held outside."""

    def __init__(self, points: Sequence[tuple[float, float]], name: str = "table"):
        self.table = TimeTable(points, name, "torque")
        self._t, self._m = self.table._t, self.table._y
        self.mean = sum(self._m) / len(self._m)

    @property
    def torques(self) -> list[float]:
        """The table's torques [N.m]: the resistance ranges over them (linear between)."""
        return list(self._m)

    @classmethod
    def parse(cls, text: str, name: str = "table") -> "TabulatedLoad":
        return cls(parse_table(text, name), name)

    def resistance(self, t, phi, w):
        return self.table.value(t)

    def integrals(self, t, h):
        """Exact integrals of the piecewise-linear function: ``int M`` and
        ``int (t1 - u) M(u) du`` over [t, t + h], walking the pieces."""
        t1 = t + h
        breaks = [t] + [x for x in self._t if t < x < t1] + [t1]
        impulse = second = 0.0
        for a, b in zip(breaks, breaks[1:]):
            ma, mb = self.resistance(a, 0.0, 0.0), self.resistance(b, 0.0, 0.0)
            d = b - a
            impulse += 0.5 * (ma + mb) * d
            # int_a^b (t1 - u) M(u) du with M linear: exact by Simpson (cubic integrand... quadratic here)
            mid = 0.5 * (a + b)
            second += d / 6.0 * ((t1 - a) * ma + 4.0 * (t1 - mid) * 0.5 * (ma + mb) + (t1 - b) * mb)
        return impulse, second


class FourierLoad:
    """Angle-periodic measured resistance (Table 4.13, series (4.4)):
    ``Mc(phi2) = M_mean + sum_n a_n cos(n phi2) + b_n sin(n phi2)``."""

    def __init__(self, mean: float, cosines: Sequence[float], sines: Sequence[float]):
        n = max(len(cosines), len(sines))
        a = list(cosines) + [0.0] * (n - len(cosines))
        b = list(sines) + [0.0] * (n - len(sines))
        self.mean = float(mean)
        self.cosines, self.sines = a, b
        # a cos + b sin = Re((a - i b) e^{i n phi}); Horner from the highest harmonic.
        self._c = [complex(ak, -bk) for ak, bk in zip(a, b)][::-1]
        #: bound of |dMc/dphi| [N.m/rad]: sets the RK4 substep that stays stable
        self.angle_stiffness = sum(n * math.hypot(ak, bk) for n, (ak, bk) in enumerate(zip(a, b), start=1))

    def rate(self, inertia: float) -> float:
        """Fastest rate [1/s] of the shaft's own dynamics (for a stable explicit substep)."""
        return math.sqrt(self.angle_stiffness / inertia)

    @classmethod
    def parse(cls, text: str, name: str = "fourier") -> "FourierLoad":
        """``"M_mean; a1:b1; a2:b2; ..."``: the mean, then one (cos, sin) pair a harmonic."""
        rows = [r.strip() for r in text.replace("\n", ";").split(";") if r.strip()]
        if len(rows) < 2:
            raise ParameterError(name, f"parameter '{name}' needs the mean and at least one harmonic 'a:b'")
        try:
            mean = float(rows[0])
        except ValueError:
            raise ParameterError(name, f"parameter '{name}': the first entry {rows[0]!r} must be the mean torque") from None
        if not abs(mean) <= TABLE_LIMIT:
            raise ParameterError(name, f"parameter '{name}': the mean torque {rows[0]!r} must be finite and within "
                                 f"+-{TABLE_LIMIT:g}")
        pairs = parse_table(";".join(rows[1:]), name)
        return cls(mean, [p[0] for p in pairs], [p[1] for p in pairs])

    def to_text(self) -> str:
        return "; ".join([repr(self.mean)] + [f"{a!r}:{b!r}" for a, b in zip(self.cosines, self.sines)])

    def resistance(self, t, phi, w):
        z = cmath.exp(1j * phi)
        acc = 0j
        for c in self._c:
            acc = acc * z + c
        return self.mean + (acc * z).real

    def resistance_slope(self, t, phi, w):
        """``dMc/dphi2 = Re sum_n i n (a_n - i b_n) e^{i n phi}``, term by term."""
        z = cmath.exp(1j * phi)
        acc = 0j
        for n, c in zip(range(len(self._c), 0, -1), self._c):
            acc = acc * z + 1j * n * c
        return (acc * z).real

    def torque(self, t, phi, w):
        return -self.resistance(t, phi, w)

    def advance(self, inertia, t, phi, w, tau, h, tau_rate=0.0):
        return None  # depends on the angle: the shaft integrates numerically


def fourier_from_samples(values: Sequence[float]) -> FourierLoad:
    """The series (4.4) through ``m`` equally spaced ordinates over one revolution (the
    first at angle 0), by the monograph's (4.2)-(4.3): the mean and harmonics up to
    ``m // 2``.  For even ``m`` the highest harmonic's sine is undetermined by the samples
    and left out (as Tables 4.12-4.13 print no b_6) and its cosine is halved, so that the
    series passes exactly through every ordinate."""
    y = [float(v) for v in values]
    m = len(y)
    if m < 3 or not all(math.isfinite(v) for v in y):
        raise ParameterError("fourier", f"a Fourier series needs at least 3 finite ordinates, got {values!r}")
    # The discrete Fourier transform written out (m is a table's handful of ordinates):
    # numpy's rfft to rounding, each twiddle from its own angle.
    spectrum = []
    for k in range(m // 2 + 1):
        terms = [v * cmath.exp(-2j * math.pi * (k * j % m) / m) for j, v in enumerate(y)]
        spectrum.append(complex(math.fsum(z.real for z in terms), math.fsum(z.imag for z in terms)) / m)
    cosines = [2.0 * c.real for c in spectrum[1:]]
    sines = [-2.0 * c.imag for c in spectrum[1:]]
    if m % 2 == 0:
        cosines[-1] *= 0.5
        sines = sines[:-1]
    return FourierLoad(spectrum[0].real, cosines, sines)


def read_harmonics(path: Path | str, cycle: str | int = "mean") -> FourierLoad:
    """Fourier coefficients from a table in the monograph's format (Tables 4.12/4.13:
    columns cycle, M_mean, a_1..a_n, b_1..b_m).  ``cycle`` is a cycle number or "mean"
    (the average of all cycles' coefficients)."""
    rows = []
    with open(path, newline="") as f:
        lines = [line for line in f if not line.lstrip().startswith("#")]
    for row in csv.DictReader(lines):
        rows.append({k.strip(): float(v) for k, v in row.items() if v not in (None, "")})
    if not rows:
        raise ParameterError("fourier", f"{path}: no rows")
    if cycle != "mean":
        rows = [r for r in rows if int(r["cycle"]) == int(cycle)]
        if not rows:
            raise ParameterError("fourier", f"{path}: no cycle {cycle}")
    n_cos = len([k for k in rows[0] if k.startswith("a_")])
    n_sin = len([k for k in rows[0] if k.startswith("b_")])

    def avg(key):
        return sum(r.get(key, 0.0) for r in rows) / len(rows)

    return FourierLoad(avg("M_mean"), [avg(f"a_{n}") for n in range(1, n_cos + 1)],
                       [avg(f"b_{n}") for n in range(1, n_sin + 1)])


def load_model(kind: str, Mm: float, dM: float = 0.0, seed: int = 1, tones: int = 6,
               band_low: float = 2.0, band_high: float = 450.0, fourier: str = "", table: str = "",
               spectrum: Spectrum = Spectrum()):
    """The one constructor of a load, shared by the FMU, the reference solver and the tests."""
    if kind == "constant":
        return ConstantLoad(Mm)
    if kind == "random":
        if spectrum.order_share or spectrum.narrowband_share:
            return SpectrumLoad(Mm, dM, seed, tones, band_low, band_high, spectrum)
        return RandomLoad(Mm, dM, seed, tones, band_low, band_high)
    if kind == "fourier":
        return FourierLoad.parse(fourier)
    if kind == "table":
        return TabulatedLoad.parse(table)
    raise ParameterError("load_kind", f"parameter 'load_kind' = {kind!r} is not allowed: it must be one of "
                         + ", ".join(LOAD_KINDS))
