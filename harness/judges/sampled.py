"""A trace's quantities from its own samples, whatever their times, and a reference as a
function of time (the engineer's verdict, ``harness.judges.verdict``, judges a result with
these).

* ``mean``: the time average, the trapezoid rule over the samples' own times (a result with
  uneven or sparse rows is averaged over the time each row stands for, not row by row);
* ``amplitude``: ``(max - min) / 2`` of the samples;
* ``orders``: the rotation orders by a least-squares fit of ``1, cos(k w t), sin(k w t)`` on
  the samples' own times (no resampling, no uniform grid needed; the fit's matrix is
  factorised once per set of times, so a perturbed trace on the same times costs a product).

``Reference`` is a reference trace as a function of time: a shape-preserving cubic (PCHIP:
no overshoot at a kink or an event) through its samples, with its own interpolation error
estimated from the samples themselves (``error_at``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


def unique_times(t: np.ndarray, y: np.ndarray | None = None):
    """``t`` (and ``y``) with a time repeated at an event kept once, its later sample (the
    value after the event, as fmpy's ``Input`` applies it from there on)."""
    keep = np.ones(len(t), dtype=bool)
    keep[:-1] = np.diff(t) > 0
    return (t[keep], None if y is None else y[keep])


def repeated_rows_dropped(t: np.ndarray, columns: dict) -> tuple[np.ndarray, dict, int]:
    """``t`` and ``columns`` without the rows that repeat the row before them - the same time
    and the same value in every column (a host that writes its last row again at the stop
    time, as OMSimulator's CSV does) - and how many were dropped.  Rows that differ at one
    time are kept: ``times_problem`` judges them."""
    t = np.asarray(t, dtype=float)
    if len(t) < 2:
        return t, columns, 0
    repeat = np.zeros(len(t), dtype=bool)
    repeat[1:] = t[1:] == t[:-1]
    if not repeat.any():
        return t, columns, 0
    values = {name: np.asarray(y, dtype=float) for name, y in columns.items()}
    for y in values.values():
        repeat[1:] &= (y[1:] == y[:-1]) | (np.isnan(y[1:]) & np.isnan(y[:-1]))
    keep = ~repeat
    return t[keep], {name: y[keep] for name, y in values.items()}, int(repeat.sum())


def times_problem(t: np.ndarray, whose: str) -> str | None:
    """Why the time column ``t`` cannot be judged as given (not finite, not sorted, a time
    written three times or more), in a sentence about ``whose`` ("the result's"); None: it can."""
    if not np.all(np.isfinite(t)):
        bad = int(np.flatnonzero(~np.isfinite(t))[0])
        return f"{whose} time column has a non-finite value ({t[bad]}) in row {bad + 1}"
    back = np.flatnonzero(np.diff(t) < 0)
    if back.size:
        i = int(back[0])
        return (f"{whose} times are not sorted: row {i + 2} (t = {t[i + 1]:.6g} s) comes after t = {t[i]:.6g} s; "
                "sort the rows by time (a time repeated at an event is fine)")
    repeated = np.flatnonzero(t[2:] == t[:-2])
    if repeated.size:
        i = int(repeated[0])
        return (f"{whose} time t = {t[i]:.6g} s appears three times or more (rows {i + 1} ...): an event has one "
                "row before it and one after; which rows are meant cannot be told")
    return None


def time_mean(t: np.ndarray, y: np.ndarray) -> float:
    """The time average of ``y(t)`` over ``t[0] ... t[-1]`` (trapezoid rule)."""
    span = float(t[-1] - t[0])
    if span <= 0:
        return float(np.mean(y))
    return float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(t)) / span)


def amplitude(y: np.ndarray) -> float:
    return float((np.max(y) - np.min(y)) / 2)


_FITS: dict = {}


def order_fit(t: np.ndarray, rotation: float, orders) -> "OrderFit":
    """``OrderFit`` on ``t``, made once for the same times (every signal of a result shares
    them; the last few are kept)."""
    key = (len(t), float(t[0]), float(t[-1]), float(np.sum(t)), float(rotation), tuple(orders))
    if key not in _FITS:
        if len(_FITS) > 8:
            _FITS.clear()
        _FITS[key] = OrderFit(t, rotation, orders)
    return _FITS[key]


class OrderFit:
    """The least-squares fit of the rotation ``orders`` at ``rotation`` [rad/s] on the times
    ``t``: ``fit(y)`` -> {order: complex amplitude ``A e^(i phase)``, with the order's term
    ``A cos(k w t + phase)``}."""

    def __init__(self, t: np.ndarray, rotation: float, orders):
        self.orders = tuple(orders)
        columns = [np.ones_like(t)]
        for k in self.orders:
            columns += [np.cos(k * rotation * t), np.sin(k * rotation * t)]
        # least squares by the thin QR factorisation, made once: a fit is then two products
        self._q, self._r = np.linalg.qr(np.column_stack(columns))

    def fit(self, y: np.ndarray) -> dict[int, complex]:
        coefficients = np.linalg.solve(self._r, self._q.T @ y)
        # a cos + b sin = Re((a - i b) e^(i k w t))
        return {k: complex(coefficients[1 + 2 * j], -coefficients[2 + 2 * j]) for j, k in enumerate(self.orders)}


def _hermite(t: np.ndarray, y: np.ndarray, slopes: np.ndarray, at: np.ndarray) -> np.ndarray:
    """The cubic Hermite interpolant through ``(t, y)`` with ``slopes`` there, at ``at``
    (inside ``t[0] ... t[-1]``)."""
    k = np.clip(np.searchsorted(t, at, "right") - 1, 0, len(t) - 2)
    h = t[k + 1] - t[k]
    s = (at - t[k]) / h
    s2, s3 = s * s, s * s * s
    return ((2 * s3 - 3 * s2 + 1) * y[k] + (s3 - 2 * s2 + s) * h * slopes[k]
            + (-2 * s3 + 3 * s2) * y[k + 1] + (s3 - s2) * h * slopes[k + 1])


def _pchip_slopes(h: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """Fritsch-Carlson slopes (as scipy's ``PchipInterpolator``): no overshoot - zero where the
    data turn, a weighted harmonic mean of the neighbouring secants elsewhere."""
    d = np.zeros(len(h) + 1)
    if len(h) == 1:
        d[:] = delta[0]
        return d
    w1, w2 = 2 * h[1:] + h[:-1], h[1:] + 2 * h[:-1]
    same = delta[:-1] * delta[1:] > 0
    with np.errstate(divide="ignore", invalid="ignore"):
        d[1:-1] = np.where(same, (w1 + w2) / (w1 / delta[:-1] + w2 / delta[1:]), 0.0)
    for end, (h0, h1, m0, m1) in ((0, (h[0], h[1], delta[0], delta[1])), (-1, (h[-1], h[-2], delta[-1], delta[-2]))):
        slope = ((2 * h0 + h1) * m0 - h0 * m1) / (h0 + h1)
        if np.sign(slope) != np.sign(m0):
            slope = 0.0
        elif np.sign(m0) != np.sign(m1) and abs(slope) > abs(3 * m0):
            slope = 3 * m0
        d[end] = slope
    return d


def _parabola_slopes(h: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """Each sample's slope of the parabola through it and its neighbours (second order)."""
    d = np.empty(len(h) + 1)
    if len(h) == 1:
        d[:] = delta[0]
        return d
    d[1:-1] = (h[:-1] * delta[1:] + h[1:] * delta[:-1]) / (h[:-1] + h[1:])
    d[0] = delta[0] - h[0] * (delta[1] - delta[0]) / (h[0] + h[1])
    d[-1] = delta[-1] + h[-1] * (delta[-1] - delta[-2]) / (h[-1] + h[-2])
    return d


@dataclass
class Reference:
    """One reference signal as a function of time, from its samples ``t``, ``y``: the
    shape-preserving cubic (PCHIP) through them."""
    t: np.ndarray
    y: np.ndarray

    def __post_init__(self):
        self.t, self.y = unique_times(np.asarray(self.t, dtype=float), np.asarray(self.y, dtype=float))
        if len(self.t) > 1:
            h = np.diff(self.t)
            delta = np.diff(self.y) / h
            self._slopes = _pchip_slopes(h, delta)
            self._second = _parabola_slopes(h, delta) if len(self.t) > 2 else self._slopes

    def __call__(self, times) -> np.ndarray:
        times = np.asarray(times, dtype=float)
        if len(self.t) < 2:
            return np.full(times.shape, float(self.y[0]) if len(self.y) else math.nan)
        return _hermite(self.t, self.y, self._slopes, np.clip(times, self.t[0], self.t[-1]))

    def error_at(self, times) -> np.ndarray:
        """The interpolant's own error at ``times``, estimated as its distance from a second
        cubic through the same samples (slopes of the parabola through each sample and its
        neighbours: second order where PCHIP flattens a turn): zero at the samples, largest
        midway, where the samples resolve the content worst."""
        times = np.asarray(times, dtype=float)
        if len(self.t) < 3:
            return np.full(times.shape, math.nan)
        inside = np.clip(times, self.t[0], self.t[-1])
        return np.abs(_hermite(self.t, self.y, self._second, inside) - _hermite(self.t, self.y, self._slopes, inside))

    def range_around(self, at: np.ndarray, before: np.ndarray, after: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The reference's smallest and largest value over ``at - before ... at + after``
        (each time its own interval): its samples inside and the interpolant at both ends."""
        low_t, high_t = at - before, at + after
        ends = np.stack([self(low_t), self(at), self(high_t)])
        low, high = np.min(ends, axis=0), np.max(ends, axis=0)
        first = np.searchsorted(self.t, low_t, "right")
        last = np.searchsorted(self.t, high_t, "left")
        inner = np.flatnonzero(last > first)
        if inner.size:
            # running extremes over each interval's samples (intervals are short: a result step)
            from numpy.lib.stride_tricks import sliding_window_view

            width = int(np.max(last[inner] - first[inner]))
            padded_low = np.concatenate([self.y, np.full(width, np.inf)])
            padded_high = np.concatenate([self.y, np.full(width, -np.inf)])
            count = last[inner] - first[inner]
            mask = np.arange(width)[None, :] < count[:, None]
            rows_low = sliding_window_view(padded_low, width)[first[inner]]
            rows_high = sliding_window_view(padded_high, width)[first[inner]]
            low[inner] = np.minimum(low[inner], np.min(np.where(mask, rows_low, np.inf), axis=1))
            high[inner] = np.maximum(high[inner], np.max(np.where(mask, rows_high, -np.inf), axis=1))
        return low, high


def median_step(t: np.ndarray) -> float | None:
    """The median step between the distinct times of ``t`` (a time written twice, an event's
    two rows, is no step); None with fewer than two distinct times."""
    steps = np.diff(np.asarray(t, dtype=float))
    steps = steps[steps > 0]
    return float(np.median(steps)) if steps.size else None


#: a step below this share of the trace's usual step (its steps' upper quartile: a host may
#: write most times twice) is a row written again just after the one before (a host that
#: writes each time twice, an event's two rows a hair apart), not its sampling
NEAR_REPEAT = 1e-3


def spacing(t: np.ndarray) -> str:
    """"every 1 ms" or "every 0.5 ... 12 ms" - a trace's sampling in words; rows written again
    within a thousandth of its usual step after the one before are said apart."""
    steps = np.diff(t)
    steps = steps[steps > 0]
    if not steps.size:
        return "one sample"
    repeats = steps < NEAR_REPEAT * float(np.percentile(steps, 75))
    sampling = steps[~repeats]
    low, high = float(np.min(sampling)), float(np.max(sampling))
    said = (f"every {1e3 * float(np.median(sampling)):.3g} ms" if high <= 1.01 * low
            else f"every {1e3 * low:.3g} ... {1e3 * high:.3g} ms")
    if repeats.any():
        said += (f"; {int(repeats.sum())} rows within {float(np.max(steps[repeats])):.2g} s of the row before "
                 "(a time written again)")
    return said
