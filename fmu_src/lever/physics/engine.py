"""Engine static characteristic ``Mg(w1)`` on the drive shaft (MODEL.md section 4):
``I1 * a1 = Mg(w1) + tau1``.
"""
from __future__ import annotations

import bisect
import math

from .parameters import ParameterError, parse_table


class LinearCharacteristic:
    """Operating zone AB linearised, (3.23): ``Mg = M1 - K1 * w``."""

    def __init__(self, stall_torque: float, slope: float):
        self.stall_torque = float(stall_torque)   # M1 [N.m]
        self.slope = float(slope)                 # K1 [N.m.s/rad]

    def torque(self, t, phi, w):
        return self.stall_torque - self.slope * w

    def advance(self, inertia, t, phi, w, tau, h):
        """Exact solution over a step with constant coupling torque ``tau``:
        ``I w' = A - K1 w`` with ``A = M1 + tau``, a first-order lag."""
        drive = self.stall_torque + tau
        if self.slope == 0.0:
            return phi + h * w + 0.5 * h * h * drive / inertia, w + h * drive / inertia
        rate = self.slope / inertia
        w_inf = drive / self.slope
        lag = -math.expm1(-rate * h)          # 1 - exp(-rate h), accurate for small steps
        return phi + w_inf * h + (w - w_inf) * lag / rate, w + (w_inf - w) * lag


class TabulatedCharacteristic:
    """Full static characteristic ``Mg(w)`` from points (speed, torque): start-up
    torque, idle speed, nominal point... (as in the monograph's Fig. 3.9).  Linear
    between points; below the first speed the first torque is held (start-up), above
    the last the last segment is extended (the governor's falling branch)."""

    def __init__(self, points, name: str = "characteristic"):
        pts = sorted((float(w), float(m)) for w, m in points)
        if len(pts) < 2:
            raise ParameterError(name, f"parameter '{name}' needs at least 2 (speed, torque) points, got {len(pts)}")
        speeds = [p[0] for p in pts]
        if any(b <= a for a, b in zip(speeds, speeds[1:])):
            raise ParameterError(name, f"parameter '{name}': speeds must be distinct, got {speeds}")
        self.points = pts
        self._w = speeds
        self._m = [p[1] for p in pts]

    @classmethod
    def parse(cls, text: str, name: str = "characteristic") -> "TabulatedCharacteristic":
        return cls(parse_table(text, name), name)

    def torque(self, t, phi, w):
        ws, ms = self._w, self._m
        if w <= ws[0]:
            return ms[0]
        k = min(bisect.bisect_right(ws, w) - 1, len(ws) - 2)
        return ms[k] + (ms[k + 1] - ms[k]) * (w - ws[k]) / (ws[k + 1] - ws[k])

    def advance(self, inertia, t, phi, w, tau, h):
        return None  # no closed form: the shaft integrates numerically


def engine_characteristic(M1: float, K1: float, table: str = ""):
    """The characteristic an engine uses: the table when given, else the linear zone."""
    if table and table.strip() and table.strip() != "linear":
        return TabulatedCharacteristic.parse(table)
    return LinearCharacteristic(M1, K1)
