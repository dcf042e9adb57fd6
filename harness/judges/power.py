"""The power of the engineer's verdict (``harness.judges.verdict``): the smallest shift of
the mean, scaling of the ripple and shift in time of the reference at the result's times that
the signal's checks fail, each sign on its own, found by bisection through the same checks a
result's samples go through - what a pass of the signal rules out."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from harness.judges.sampled import median_step
from harness.judges.tolerances import allowed_scale as _allowed_scale


@dataclass
class Power:
    """The smallest change of each kind the verdict fails (None: none it fails)."""
    #: the tube's half-width
    band: float
    #: a shift of the mean, in the signal's unit (the larger of the two signs')
    mean: float | None
    #: a scaling of the ripple about the mean, relative
    amplitude: float | None
    #: a shift in time [s], and the phase it is at the first rotation order [deg]
    shift_s: float | None
    phase_deg: float | None
    #: kind of change -> the checks that fail first under it ("mean", "amplitude", "shift")
    by: dict = field(default_factory=dict)
    #: kind -> (smallest failing positive change, smallest failing negative change's size)
    signs: dict = field(default_factory=dict)
    #: (samples the changes were judged at, the result's samples in the window) where the
    #: search took a selection of a dense result's samples; None: all of them
    searched_at: tuple[int, int] | None = None

    def _said(self, kind: str, form) -> str:
        plus, minus = self.signs.get(kind, (None, None))
        if plus is None and minus is None:
            return "none"
        if plus is not None and minus is not None and abs(plus - minus) <= 0.05 * max(plus, minus):
            text = f"+-{form(max(plus, minus))}"
        else:
            text = "/".join(f"{sign}{form(x)}" if x is not None else f"{sign}none" for sign, x in (("+", plus),
                                                                                                 ("-", minus)))
        return text

    def describe(self) -> str:
        """"band +-0.566; catches mean +-0.107, amplitude +-2 %, time shift +-0.31 ms"."""
        mean = self._said("mean", lambda x: f"{x:.3g}")
        amplitude = self._said("amplitude", lambda x: f"{100 * x:.2g} %")
        shift = self._said("shift", lambda x: f"{1e3 * x:.3g} ms")
        said = f"band +-{self.band:.3g}; catches mean {mean}, amplitude {amplitude}, time shift {shift}"
        if self.searched_at:
            said += f" (searched at {self.searched_at[0]} of the result's {self.searched_at[1]} samples)"
        return said


#: multiples of a change found failing at which it is checked again: a verdict may fail a
#: change and pass a larger one (a time shift near an event, a period later); the power stated
#: is the smallest change from which on these all fail
CHECKED_ABOVE = (1.1, 1.5, 2.0, 4.0)
#: the bisection stops when the passing and the failing change are this share of the failing
#: one apart: the change stated fails and is at most this share above the smallest that does
RESOLUTION = 5e-3


def _smallest_failing(fails, start: float, limit: float, sign: float) -> float | None:
    """The smallest x > 0 with ``fails(sign * x)`` and at ``CHECKED_ABOVE`` times it, by
    doubling from ``start`` up to ``limit`` and bisecting; None when no such x up to ``limit``."""
    if not (math.isfinite(start) and math.isfinite(limit) and 0 < start):
        raise ValueError(f"the power's search needs a finite start > 0 and a finite limit (start {start}, "
                         f"limit {limit})")
    low, high = 0.0, start
    while True:
        while not fails(sign * high):
            low, high = high, 2 * high
            if high > limit:
                return None
        for _ in range(40):
            if high - low <= RESOLUTION * high:
                break
            middle = 0.5 * (low + high)
            if fails(sign * middle):
                high = middle
            else:
                low = middle
        passing = next((k * high for k in CHECKED_ABOVE if k * high <= limit and not fails(sign * k * high)), None)
        if passing is None:
            return high
        low, high = passing, 2 * passing       # a larger change passes: search on from there
        if high > limit:
            return None


def power(frame, judged, ref, rtol: dict, rotation: float | None) -> Power:
    """The smallest shift of the mean, scaling of the ripple and shift in time of the
    reference at the result's times that the checks ``judged(values)`` fail, each sign on its
    own: what a pass of this signal rules out."""
    perturbed = {"mean": lambda d: frame.at + d,
                 "amplitude": lambda e: frame.mean + (1 + e) * (frame.at - frame.mean),
                 "shift": lambda s: ref(frame.t - s)}

    def failing(kind, x):
        return [c.quantity for c in judged(perturbed[kind](x)) if c.judged and not c.passed]

    scale = _allowed_scale(max(abs(frame.mean), frame.amplitude), magnitude=frame.magnitude)
    span = float(frame.t[-1] - frame.t[0])
    dt = median_step(frame.t) or max(span, 1.0)
    signs, by = {}, {}
    # the doubling starts a little below where the tolerances put the answer
    for kind, first, limit in (("mean", max(0.25 * rtol["mean"][0], 1e-6) * scale, 1e3 * scale),
                               ("amplitude", max(0.25 * rtol["amplitude"][0], 1e-6), 10.0),
                               ("shift", 0.05 * dt, 0.25 * span)):
        found = tuple(_smallest_failing(lambda x: bool(failing(kind, x)), first, limit, sign) for sign in (1.0, -1.0))
        signs[kind] = found
        failed = set()
        for sign, x in zip((1.0, -1.0), found):
            if x is not None:
                failed |= set(failing(kind, sign * x))
        if failed:
            by[kind] = sorted(failed)

    def larger(kind):
        values = [x for x in signs[kind] if x is not None]
        return max(values) if values else None

    shift = larger("shift")
    phase = None if (shift is None or not rotation) else math.degrees(rotation * shift)
    band = rtol["tube"][0] * _allowed_scale(2 * frame.amplitude, frame.mean, magnitude=frame.magnitude)
    searched_at = None if frame.of_samples is None else (len(frame.t), frame.of_samples)
    return Power(band, larger("mean"), larger("amplitude"), shift, phase, by, signs, searched_at)
