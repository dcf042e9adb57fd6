"""Elastic laws of the coupling's rubber elements: ``T_el(theta)`` and its potential
``V(theta)`` (docs/physics.md#elastic-element).

A law is linear (``c * theta``) or tabulated: a monotone (non-decreasing), odd-symmetric
characteristic given by points for ``theta >= 0``, interpolated by a monotone cubic
(PCHIP), so the stiffness is continuous and never negative, and extended beyond the last
point with the last point's slope.  Each law also gives its exact potential energy, which
the energy balance needs.
"""
from __future__ import annotations

import bisect
import math
from typing import Sequence

from .parameters import ParameterError, parse_table


class LinearElasticLaw:
    """``T_el = c * theta``."""

    def __init__(self, stiffness: float):
        if not (math.isfinite(stiffness) and stiffness > 0.0):
            raise ParameterError("stiffness", f"parameter 'stiffness' (c) = {stiffness} is outside its allowed range "
                                 "(0, inf) N.m/rad")
        self.stiffness = float(stiffness)

    def torque(self, theta):
        return self.stiffness * theta

    def energy(self, theta):
        return 0.5 * self.stiffness * theta * theta

    def stiffness_at(self, theta):
        return self.stiffness + 0.0 * theta

    @property
    def nominal_stiffness(self) -> float:
        return self.stiffness


def _pchip_slopes(x: list[float], y: list[float]) -> list[float]:
    """Fritsch-Carlson (Fritsch-Butland harmonic-mean) slopes: monotone data give a
    monotone interpolant.  End slopes by the one-sided three-point formula, limited."""
    h = [b - a for a, b in zip(x, x[1:])]
    delta = [(b - a) / hk for a, b, hk in zip(y, y[1:], h)]
    m = [0.0] * len(y)
    if len(x) == 2:
        return [delta[0]] * len(y)
    for k in range(1, len(x) - 1):
        if delta[k - 1] * delta[k] <= 0.0:
            m[k] = 0.0
        else:
            w1 = 2.0 * h[k] + h[k - 1]
            w2 = h[k] + 2.0 * h[k - 1]
            # both slopes are non-zero here; a tiny one makes its term inf (Python's float
            # division overflows to inf like numpy's) and the harmonic mean tends to 0
            m[k] = (w1 + w2) / (w1 / delta[k - 1] + w2 / delta[k])

    def end(h0, h1, d0, d1):
        s = ((2.0 * h0 + h1) * d0 - h0 * d1) / (h0 + h1)
        if s * d0 <= 0.0:
            return 0.0
        if d0 * d1 <= 0.0 and abs(s) > abs(3.0 * d0):
            return 3.0 * d0
        return s

    m[0] = end(h[0], h[1], delta[0], delta[1])
    m[-1] = end(h[-1], h[-2], delta[-1], delta[-2])
    return m


class TabulatedElasticLaw:
    """Monotone, odd-symmetric characteristic from points ``(theta_i, T_i)``, theta >= 0.

    The table must start at (0, 0) (added when missing), have strictly increasing
    angles and non-decreasing torques, at least two points beyond zero.
    """

    def __init__(self, points: Sequence[tuple[float, float]], name: str = "elastic_table"):
        pts = [(float(a), float(t)) for a, t in points]
        if pts and pts[0][0] == 0.0:
            if pts[0][1] != 0.0:
                raise ParameterError(name, f"parameter '{name}': the torque at zero deflection must be 0 "
                                     f"(the law is odd-symmetric), got {pts[0][1]}")
        else:
            pts.insert(0, (0.0, 0.0))
        if len(pts) < 3:
            raise ParameterError(name, f"parameter '{name}' needs at least 2 points with theta > 0, got {len(pts) - 1}")
        theta = [p[0] for p in pts]
        torque = [p[1] for p in pts]
        if any(b - a <= 0.0 for a, b in zip(theta, theta[1:])):
            raise ParameterError(name, f"parameter '{name}': deflections must be strictly increasing from 0 "
                                 f"(got {theta})")
        if any(b - a < 0.0 for a, b in zip(torque, torque[1:])):
            raise ParameterError(name, f"parameter '{name}': torques must be non-decreasing (a monotone law), "
                                 f"got {torque}")
        if torque[-1] <= 0.0:
            raise ParameterError(name, f"parameter '{name}': the law carries no torque (all torques are 0)")
        self.points = list(zip(theta, torque))
        self._theta = theta
        self._torque = torque
        self._slope = _pchip_slopes(theta, torque)
        # Potential at each knot: exact integral of the cubic Hermite segments.
        energy = [0.0]
        for k in range(len(theta) - 1):
            h = self._theta[k + 1] - self._theta[k]
            y0, y1, m0, m1 = self._torque[k], self._torque[k + 1], self._slope[k], self._slope[k + 1]
            energy.append(energy[-1] + h * (y0 + y1) / 2.0 + h * h * (m0 - m1) / 12.0)
        self._energy = energy
        if not all(math.isfinite(x) for x in self._slope + energy):
            raise ParameterError(name, f"parameter '{name}': the table's slopes or energies overflow (points "
                                 f"{self.points[:4]}...): deflections too close together for their torques")

    @classmethod
    def parse(cls, text: str, name: str = "elastic_table") -> "TabulatedElasticLaw":
        return cls(parse_table(text, name), name)

    @property
    def nominal_stiffness(self) -> float:
        """Secant stiffness over the table, for step-size and stability estimates."""
        return self._torque[-1] / self._theta[-1]

    def _eval(self, x: float):
        """(torque, energy, stiffness) at x >= 0."""
        th = self._theta
        if x >= th[-1]:
            d = x - th[-1]
            m = self._slope[-1]
            return self._torque[-1] + m * d, self._energy[-1] + self._torque[-1] * d + 0.5 * m * d * d, m
        k = max(bisect.bisect_right(th, x) - 1, 0)
        h = th[k + 1] - th[k]
        s = (x - th[k]) / h
        y0, y1, m0, m1 = self._torque[k], self._torque[k + 1], self._slope[k] * h, self._slope[k + 1] * h
        s2, s3 = s * s, s * s * s
        h00, h10, h01, h11 = 2 * s3 - 3 * s2 + 1, s3 - 2 * s2 + s, -2 * s3 + 3 * s2, s3 - s2
        torque = h00 * y0 + h10 * m0 + h01 * y1 + h11 * m1
        # Antiderivatives of the Hermite basis from 0 to s.
        i00 = s3 * s / 2 - s3 + s
        i10 = s3 * s / 4 - 2 * s3 / 3 + s2 / 2
        i01 = -s3 * s / 2 + s3
        i11 = s3 * s / 4 - s3 / 3
        energy = self._energy[k] + h * (i00 * y0 + i10 * m0 + i01 * y1 + i11 * m1)
        d00, d10, d01, d11 = 6 * s2 - 6 * s, 3 * s2 - 4 * s + 1, -6 * s2 + 6 * s, 3 * s2 - 2 * s
        stiffness = (d00 * y0 + d10 * m0 + d01 * y1 + d11 * m1) / h
        return torque, energy, stiffness

    def torque(self, theta):
        t = self._eval(abs(theta))[0]
        return t if theta >= 0.0 else -t

    def energy(self, theta):
        return self._eval(abs(theta))[1]

    def stiffness_at(self, theta):
        return self._eval(abs(theta))[2]


def elastic_law(stiffness: float, table: str = ""):
    """The law a coupling uses: the table when one is given, else linear."""
    if table and table.strip():
        return TabulatedElasticLaw.parse(table)
    return LinearElasticLaw(stiffness)
