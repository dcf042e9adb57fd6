"""A run seen over the shaft's angle, as the monograph draws it (its figures are over one
revolution, not over time): the last whole revolutions of a shaft in a trace, the mean
speed over whole revolutions, and the time a run-up takes to settle."""
from __future__ import annotations

import math

import numpy as np

TWO_PI = 2.0 * math.pi


def last_revolutions(phi: np.ndarray, count: int = 1) -> slice:
    """The samples of the last ``count`` whole revolutions of a shaft turning forwards or
    backwards: from the last sample at or past a multiple of 2 pi (counted from the angle
    at the start) to the first sample ``count`` revolutions before it, both ends included.
    An empty slice when the trace holds fewer whole revolutions."""
    phi = np.asarray(phi, dtype=float)
    if len(phi) < 2 or count < 1:
        return slice(0, 0)
    turns = (phi - phi[0]) / TWO_PI
    direction = 1.0 if turns[-1] >= 0.0 else -1.0
    turns = direction * turns
    whole = math.floor(turns[-1] + 1e-12)          # revolutions completed by the end
    if whole < count:
        return slice(0, 0)
    # the first samples at or past the end mark and at or past the start mark
    end = int(np.argmax(turns >= whole - 1e-12))
    start = int(np.argmax(turns >= whole - count - 1e-12))
    return slice(start, end + 1)


def revolution_angle(phi: np.ndarray, window: slice) -> np.ndarray:
    """The angle [rad] into the window's first revolution, from 0 (as the monograph's
    abscissa phi2 = 0 ... 2 pi ...)."""
    phi = np.asarray(phi, dtype=float)[window]
    return np.abs(phi - phi[0])


def mean_speed(times: np.ndarray, phi: np.ndarray, count: int = 1) -> float:
    """Mean speed [rad/s] over the last ``count`` whole revolutions: the angle turned over
    the time it took (the speed a revolution counter reads); NaN without that many."""
    window = last_revolutions(phi, count)
    if window.stop - window.start < 2:
        return math.nan
    t, p = np.asarray(times)[window], np.asarray(phi)[window]
    return float((p[-1] - p[0]) / (t[-1] - t[0]))


def settling_time(times: np.ndarray, speed: np.ndarray, final: float, band: float = 0.02) -> float:
    """The time after which ``speed`` stays within ``band`` (relative) of ``final``: the
    sample after the last one outside; the first time when it never leaves; NaN when the
    last sample is still outside (not settled within the run)."""
    speed = np.asarray(speed, dtype=float)
    outside = np.nonzero(np.abs(speed - final) > band * abs(final))[0]
    if not len(outside):
        return float(times[0])
    if outside[-1] == len(speed) - 1:
        return math.nan
    return float(times[outside[-1] + 1])
