"""Engine static characteristic ``Mg(w1)`` on the drive shaft (docs/physics.md#engine):
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

    @classmethod
    def through(cls, speed: float, resistance: float, slope: float) -> "LinearCharacteristic":
        """The line of slope ``K1`` whose steady speed under ``resistance`` is ``speed``:
        ``M1 = Mc + K1 * w``."""
        return cls(resistance + slope * speed, slope)

    def steady_speed(self, resistance: float) -> float:
        """The speed at which the engine's torque balances ``resistance``: ``(M1 - Mc)/K1``."""
        return (self.stall_torque - resistance) / self.slope

    def torque(self, t, phi, w):
        return self.stall_torque - self.slope * w

    def torque_slope(self, t, phi, w):
        """``dMg/dw = -K1``."""
        return -self.slope

    def advance(self, inertia, t, phi, w, tau, h, tau_rate=0.0):
        """Exact solution over a step with coupling torque ``tau + r s`` (``r`` =
        ``tau_rate``): ``I w' = A + r s - K1 w`` with ``A = M1 + tau``, a first-order lag
        driven by a ramp.  With ``x = K1 h / I`` and the exponential-integrator functions
        ``phi_k`` (below):

            w(h)   = w e^-x + (A h / I) phi_1 + (r h^2 / I) phi_2
            phi(h) = phi + w h phi_1 + (A h^2 / I) phi_2 + (r h^3 / I) phi_3

        which stays exact and well-conditioned down to ``K1 = 0``."""
        drive = self.stall_torque + tau
        x = self.slope * h / inertia
        p1, p2, p3 = _phi_functions(x)
        return (phi + w * h * p1 + (drive * p2 + tau_rate * h * p3) * h * h / inertia,
                w * math.exp(-x) + (drive * p1 + tau_rate * h * p2) * h / inertia)


def _phi_functions(x: float) -> tuple[float, float, float]:
    """``phi_k(x) = sum_j (-x)^j / (j + k)!`` for k = 1, 2, 3: ``(1 - e^-x)/x``,
    ``(x - 1 + e^-x)/x^2``, ``(x^2/2 - x + 1 - e^-x)/x^3``; by series where the closed
    forms cancel."""
    if x < 0.05:
        terms1, terms2, terms3 = 0.0, 0.0, 0.0
        power, factorial = 1.0, 1.0             # (-x)^j and j!
        for j in range(10):
            terms1 += power / (factorial * (j + 1))
            terms2 += power / (factorial * (j + 1) * (j + 2))
            terms3 += power / (factorial * (j + 1) * (j + 2) * (j + 3))
            power *= -x
            factorial *= j + 1
        return terms1, terms2, terms3
    decay = -math.expm1(-x)                   # 1 - e^-x
    p1 = decay / x
    p2 = (1.0 - p1) / x
    p3 = (0.5 - p2) / x
    return p1, p2, p3


class TabulatedCharacteristic:
    """Full static characteristic ``Mg(w)`` from points (speed, torque): start-up
    torque, idle speed, nominal point... (as in the monograph's Fig. 3.9).  Linear
    between points; below the first speed the first torque is held (start-up), above
    the last a falling last segment is extended (the governor's falling branch) and a
    rising one held at its end: no engine's torque grows without bound with its speed
    (extended, a rising segment made the speed run away exponentially)."""

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
        slopes = [(m1 - m0) / (w1 - w0) for (w0, m0), (w1, m1) in zip(pts, pts[1:])]
        if not all(math.isfinite(k) for k in slopes):
            raise ParameterError(name, f"parameter '{name}': the characteristic's slopes overflow: speeds too "
                                 "close together for their torques")
        self._falls = slopes[-1] < 0.0
        self._slopes = slopes
        #: largest |dMg/dw| [N.m.s/rad]: sets the RK4 substep that stays stable
        self.speed_stiffness = max(abs(k) for k in slopes)

    @property
    def speeds(self) -> list[float]:
        """The table's speeds [rad/s], ascending."""
        return list(self._w)

    @property
    def torques(self) -> list[float]:
        """The table's torques [N.m], at ``speeds``."""
        return list(self._m)

    def rate(self, inertia: float) -> float:
        """Fastest rate [1/s] of the shaft's own dynamics (for a stable explicit substep)."""
        return self.speed_stiffness / inertia

    @classmethod
    def parse(cls, text: str, name: str = "characteristic") -> "TabulatedCharacteristic":
        return cls(parse_table(text, name), name)

    def torque(self, t, phi, w):
        ws, ms = self._w, self._m
        if w <= ws[0]:
            return ms[0]
        if w >= ws[-1] and not self._falls:
            return ms[-1]
        k = min(bisect.bisect_right(ws, w) - 1, len(ws) - 2)
        return ms[k] + (ms[k + 1] - ms[k]) * (w - ws[k]) / (ws[k + 1] - ws[k])

    def torque_slope(self, t, phi, w):
        """``dMg/dw``: the slope of the segment ``torque`` interpolates on, 0 where it holds
        an end value.  At a point of the table (a kink) the right-hand slope: the segment
        ``torque`` takes there (the one above the point)."""
        ws = self._w
        if w < ws[0] or (w >= ws[-1] and not self._falls):
            return 0.0
        return self._slopes[min(bisect.bisect_right(ws, w) - 1, len(ws) - 2)]

    def advance(self, inertia, t, phi, w, tau, h, tau_rate=0.0):
        return None  # no closed form: the shaft integrates numerically


#: Full static characteristics a scene may name instead of writing the points out.
#: ``kavz685``: the shape of the monograph's Fig. 3.9 (start-up torque, nominal point,
#: idle) through the figures the monograph states (docs/physics.md#the-table), speed in
#: rad/s : torque in N.m -
#:   0 : 623     start-up torque M_r, taken as the M1 of the monograph's line (3.23)
#:   23.4 : 550  the largest load the text allows the operating mode (section 3.3)
#:   33.6 : 450  measured operating point (alpha = 15 deg); nominal point: the table's
#:               largest power (15.1 kW)
#:   35.3 : 420  measured operating point (alpha = 5 deg)
#:   37.8 : 320  measured operating point
#:   39.25 : 0   idle (no-load) speed: n1 = 374.8 rpm of the no-load run-up (Fig. 4.6a)
#: Between 37.8 and 39.25 rad/s the governor branch: 220 N.m.s/rad, 16 times the
#: line's K1.  The idle point is that run-up's own reading, so a no-load run reaching
#: 374.8 rpm on this table is no validation of it.
NAMED_CHARACTERISTICS = {
    "kavz685": "0:623; 23.4:550; 33.6:450; 35.3:420; 37.8:320; 39.25:0",
}


def engine_characteristic(M1: float, K1: float, table: str = ""):
    """The characteristic an engine uses: the table when given (points, or the name of
    one of ``NAMED_CHARACTERISTICS``), else the linear zone."""
    text = table.strip() if table else ""
    if text and text != "linear":
        if text[0].isalpha() and text not in NAMED_CHARACTERISTICS:
            raise ParameterError("characteristic", f"parameter 'characteristic' = {text!r} is neither 'w:torque; ...' "
                                 f"points nor a named characteristic ({', '.join(NAMED_CHARACTERISTICS)})")
        return TabulatedCharacteristic.parse(NAMED_CHARACTERISTICS.get(text, text))
    return LinearCharacteristic(M1, K1)
