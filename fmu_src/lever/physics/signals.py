"""Prescribed signals of time: inputs a scene drives (the coupling's misalignment) and
tabulated loads (``load.TabulatedLoad``)."""
from __future__ import annotations

import bisect
from typing import Sequence

from .parameters import ParameterError, parse_table


class TimeTable:
    """``y(t)`` from points ``(t_i, y_i)``: linear between points, the end values held
    outside; ``rate(t)`` its slope (0 outside, the right-hand slope at a point)."""

    def __init__(self, points: Sequence[tuple[float, float]], name: str = "table", what: str = "value"):
        pts = [(float(t), float(y)) for t, y in points]
        if len(pts) < 2:
            raise ParameterError(name, f"parameter '{name}' needs at least 2 (time, {what}) points, got {len(pts)}")
        if any(b[0] <= a[0] for a, b in zip(pts, pts[1:])):
            raise ParameterError(name, f"parameter '{name}': times must be strictly increasing")
        self.points = pts
        self._t = [p[0] for p in pts]
        self._y = [p[1] for p in pts]

    @classmethod
    def parse(cls, text: str, name: str = "table", scale: float = 1.0) -> "TimeTable":
        return cls([(t, y * scale) for t, y in parse_table(text, name)], name)

    def _segment(self, t):
        return min(max(bisect.bisect_right(self._t, t) - 1, 0), len(self._t) - 2)

    def value(self, t: float) -> float:
        ts, ys = self._t, self._y
        if t <= ts[0]:
            return ys[0]
        if t >= ts[-1]:
            return ys[-1]
        k = self._segment(t)
        return ys[k] + (ys[k + 1] - ys[k]) * (t - ts[k]) / (ts[k + 1] - ts[k])

    def rate(self, t: float) -> float:
        ts, ys = self._t, self._y
        if t < ts[0] or t >= ts[-1]:
            return 0.0
        k = self._segment(t)
        return (ys[k + 1] - ys[k]) / (ts[k + 1] - ts[k])

    def next_time(self, t: float) -> float | None:
        """The first of the table's times after ``t`` (where the rate jumps), or None."""
        k = bisect.bisect_right(self._t, t)
        return self._t[k] if k < len(self._t) else None
