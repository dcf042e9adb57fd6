"""The few numerical tools the physics needs, on the standard library alone (the FMUs run
in whatever Python the importer has, without numpy):

* ``SeededUniform``: numpy's ``default_rng(seed).uniform`` draw for draw, bit for bit
  (SeedSequence, PCG64, 53-bit doubles), so a seeded load is the same load as numpy's;
* ``pairwise_sum``: numpy's float64 ``sum`` (its pairwise summation), bit for bit;
* ``rfft``/``irfft``: real FFTs of power-of-two length (radix 2; not pocketfft's
  operation order, so they agree with numpy's to rounding, about 1e-16 of the largest
  coefficient);
* ``least_squares``: a small dense least-squares solve by Householder QR.
"""
from __future__ import annotations

import cmath
import math
from typing import Sequence

_MASK32 = 0xFFFFFFFF
_MASK64 = (1 << 64) - 1
_MASK128 = (1 << 128) - 1

# numpy.random.SeedSequence's constants (numpy/random/bit_generator.pyx)
_INIT_A, _MULT_A = 0x43B0D7E5, 0x931E8875
_INIT_B, _MULT_B = 0x8B51F9DD, 0x58F38DED
_MIX_MULT_L, _MIX_MULT_R = 0xCA01F9DD, 0x4973F715
_POOL_SIZE = 4
# PCG64's 128-bit LCG multiplier (pcg64.h, PCG_DEFAULT_MULTIPLIER_128)
_PCG_MULTIPLIER = (2549297995355413924 << 64) + 4865540595714422341


def _seed_pool(seed: int) -> list[int]:
    """SeedSequence(seed).pool: the seed's 32-bit words hashed and mixed into four words."""
    if seed < 0:
        raise ValueError(f"seed {seed} must be >= 0")
    entropy = []
    while True:
        entropy.append(seed & _MASK32)
        seed >>= 32
        if not seed:
            break
    hash_const = _INIT_A

    def hashmix(value):
        nonlocal hash_const
        value ^= hash_const
        hash_const = (hash_const * _MULT_A) & _MASK32
        value = (value * hash_const) & _MASK32
        return value ^ (value >> 16)

    def mix(x, y):
        result = (_MIX_MULT_L * x - _MIX_MULT_R * y) & _MASK32
        return result ^ (result >> 16)

    pool = [hashmix(entropy[i] if i < len(entropy) else 0) for i in range(_POOL_SIZE)]
    for src in range(_POOL_SIZE):
        for dst in range(_POOL_SIZE):
            if src != dst:
                pool[dst] = mix(pool[dst], hashmix(pool[src]))
    for src in range(_POOL_SIZE, len(entropy)):
        for dst in range(_POOL_SIZE):
            pool[dst] = mix(pool[dst], hashmix(entropy[src]))
    return pool


def _generate_state_uint64(pool: list[int], n_words: int) -> list[int]:
    """SeedSequence.generate_state(n_words, np.uint64)."""
    hash_const = _INIT_B
    words = []
    for i in range(2 * n_words):
        value = pool[i % len(pool)] ^ hash_const
        hash_const = (hash_const * _MULT_B) & _MASK32
        value = (value * hash_const) & _MASK32
        words.append(value ^ (value >> 16))
    return [words[2 * i] | (words[2 * i + 1] << 32) for i in range(n_words)]   # little-endian pairs


class SeededUniform:
    """``numpy.random.default_rng(seed)``'s uniform draws: PCG64 (XSL-RR output of a
    128-bit LCG) seeded through SeedSequence, doubles from the top 53 bits."""

    def __init__(self, seed: int):
        s0, s1, i0, i1 = _generate_state_uint64(_seed_pool(int(seed)), 4)
        initstate, initseq = (s0 << 64) | s1, (i0 << 64) | i1
        self._inc = ((initseq << 1) | 1) & _MASK128
        self._state = self._inc                                  # step from state 0
        self._state = (self._state + initstate) & _MASK128
        self._step()

    def _step(self):
        self._state = (self._state * _PCG_MULTIPLIER + self._inc) & _MASK128

    def next_uint64(self) -> int:
        self._step()
        state = self._state
        value = ((state >> 64) ^ state) & _MASK64
        rot = state >> 122
        return ((value >> rot) | (value << (-rot & 63))) & _MASK64

    def random(self) -> float:
        return (self.next_uint64() >> 11) * (1.0 / 9007199254740992.0)

    def uniform(self, low: float, high: float, n: int) -> list[float]:
        span = high - low
        return [low + span * self.random() for _ in range(n)]


def pairwise_sum(values: Sequence[float]) -> float:
    """``float(numpy.sum(values))`` for float64 values: numpy's pairwise summation
    (eight accumulators in blocks of up to 128 values, halves above)."""
    return _pairwise(list(values), 0, len(values), 8)


def pairwise_sum_complex(values: Sequence[complex]) -> complex:
    """``complex(numpy.sum(values))`` for complex128 values: numpy sums the real and the
    imaginary parts side by side, four accumulators each (eight doubles)."""
    return complex(_pairwise([v.real for v in values], 0, len(values), 4),
                   _pairwise([v.imag for v in values], 0, len(values), 4))


def _pairwise(a: list[float], start: int, n: int, lanes: int) -> float:
    """numpy's pairwise_sum over ``a[start:start + n]``; ``lanes`` values make the eight
    doubles of one unrolled block (8 for reals, 4 for one part of complex values)."""
    width = 8 // lanes                      # doubles per value
    if n * width < 8:
        total = 0.0
        for i in range(start, start + n):
            total += a[i]
        return total
    if n * width <= 128:
        r = a[start:start + lanes]
        end = start + (n * width - (n * width) % 8) // width
        i = start + lanes
        while i < end:
            for j in range(lanes):
                r[j] += a[i + j]
            i += lanes
        if lanes == 8:
            total = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
        else:
            total = (r[0] + r[1]) + (r[2] + r[3])
        for k in range(i, start + n):
            total += a[k]
        return total
    half = n * width // 2
    half = (half - half % 8) // width
    return _pairwise(a, start, half, lanes) + _pairwise(a, start + half, n - half, lanes)


# -- FFT ------------------------------------------------------------------------------------------

_TWIDDLES: dict[int, list[complex]] = {}
_REVERSED: dict[int, list[int]] = {}


def _twiddles(n: int) -> list[complex]:
    """``exp(-2 pi i k / n)`` for k < n/2, each from its own angle (no recurrence drift)."""
    table = _TWIDDLES.get(n)
    if table is None:
        table = _TWIDDLES[n] = [cmath.exp(-2j * math.pi * k / n) for k in range(n // 2)]
    return table


def _bit_reversed(n: int) -> list[int]:
    order = _REVERSED.get(n)
    if order is None:
        bits = n.bit_length() - 1
        order = _REVERSED[n] = [int(format(i, f"0{bits}b")[::-1], 2) if bits else 0 for i in range(n)]
    return order


def _fft(values: list[complex]) -> list[complex]:
    """Forward DFT ``X_k = sum_j x_j exp(-2 pi i j k / n)``, n a power of two
    (iterative radix 2, bit-reversed input)."""
    n = len(values)
    a = [values[i] for i in _bit_reversed(n)]
    w = _twiddles(n)
    half = 1
    while half < n:
        size, stride = 2 * half, n // (2 * half)
        for k in range(half):
            factor = w[k * stride]
            for i in range(k, n, size):
                j = i + half
                t = factor * a[j]
                u = a[i]
                a[i], a[j] = u + t, u - t
        half = size
    return a


def _power_of_two(n: int, what: str):
    if n < 2 or n & (n - 1):
        raise ValueError(f"{what}: length {n} is not a power of two >= 2")


def rfft(values: Sequence[float]) -> list[complex]:
    """``numpy.fft.rfft(values)`` (to rounding): the n/2 + 1 non-negative frequency
    terms of a real sequence whose length n is a power of two, by one complex FFT of
    n/2 points (even samples as real, odd as imaginary parts)."""
    n = len(values)
    _power_of_two(n, "rfft")
    m = n // 2
    z = _fft([complex(values[2 * j], values[2 * j + 1]) for j in range(m)])
    w = _twiddles(n)
    out = []
    for k in range(m + 1):
        zk, zc = z[k % m], z[(m - k) % m].conjugate()
        even, odd = 0.5 * (zk + zc), -0.5j * (zk - zc)
        out.append(even + (w[k] if k < m else -1.0) * odd)
    return out


def irfft(spectrum: Sequence[complex], n: int) -> list[float]:
    """``numpy.fft.irfft(spectrum, n)`` (to rounding) for a power-of-two n and
    ``len(spectrum) == n/2 + 1``: the real sequence with that half spectrum."""
    _power_of_two(n, "irfft")
    m = n // 2
    if len(spectrum) != m + 1:
        raise ValueError(f"irfft: {len(spectrum)} terms for length {n} (needs {m + 1})")
    w = _twiddles(n)
    z = []
    for k in range(m):
        xk, xc = spectrum[k], spectrum[m - k].conjugate()
        even = 0.5 * (xk + xc)
        odd = 0.5 * (xk - xc) * w[k].conjugate()
        z.append((even + 1j * odd).conjugate())
    z = _fft(z)
    out = []
    for v in z:
        v = v.conjugate()
        out += [v.real / m, v.imag / m]
    return out


# -- least squares ----------------------------------------------------------------------------------

def least_squares(rows: Sequence[Sequence[float]], rhs: Sequence[float]) -> list[float]:
    """``x`` minimising ``|A x - b|`` for a tall matrix of full column rank, by
    Householder QR (what ``numpy.linalg.lstsq`` gives, to rounding)."""
    a = [list(map(float, r)) for r in rows]
    b = list(map(float, rhs))
    m, n = len(a), len(a[0])
    if m < n:
        raise ValueError(f"least_squares: {m} equations for {n} unknowns")
    for k in range(n):
        norm = math.sqrt(sum(a[i][k] ** 2 for i in range(k, m)))
        if norm == 0.0:
            raise ValueError(f"least_squares: column {k} is linearly dependent on the others")
        alpha = -norm if a[k][k] >= 0.0 else norm
        v = [0.0] * k + [a[k][k] - alpha] + [a[i][k] for i in range(k + 1, m)]
        vv = sum(x * x for x in v[k:])
        for j in range(k, n):
            f = 2.0 * sum(v[i] * a[i][j] for i in range(k, m)) / vv
            for i in range(k, m):
                a[i][j] -= f * v[i]
        f = 2.0 * sum(v[i] * b[i] for i in range(k, m)) / vv
        for i in range(k, m):
            b[i] -= f * v[i]
    x = [0.0] * n
    for k in reversed(range(n)):
        x[k] = (b[k] - sum(a[k][j] * x[j] for j in range(k + 1, n))) / a[k][k]
    return x
