"""The engineer's verdict on a result against its reference (``lever validate``'s default):
per signal, over the judged window, the quantities a driveline engineer checks first, each
against a tolerance relative to that quantity, and the verdict's power.

Every sample of the result in the window is judged, at its own time; the reference is taken
at those times (``sampled.Reference``: an interpolant through its dense samples, its own
error estimated).  Each quantity is computed by one estimator (``harness.judges.sampled``)
from the result's samples and from the reference at the same times, and the two compared:

* ``mean``: the time average, within ``rtol.mean`` of ``max(|mean|, amplitude)`` of the
  reference (a signal that swings about zero is judged against its swing);
* ``amplitude``: the ripple amplitude ``(max - min) / 2``, within ``rtol.amplitude`` of the
  reference's;
* ``order k``: the leading rotation orders (k times the driven shaft's mean speed; orders
  whose amplitude is at least ``LEADING`` of the ripple amplitude), least-squares fitted on
  the samples' own times: the complex component within ``rtol.order`` of its magnitude (at least
  ``NOISE_FLOOR`` of the signal's largest value, as for the mean and amplitude), so an
  amplitude change of ``rtol.order`` or a phase change of about ``rtol.order`` rad fails;
* ``tube``: every sample within ``rtol.tube`` of the reference's range in the window of the
  reference over one step either side - the result's (an importer one step late passes) or the
  reference's, whichever is longer (it places an event no closer) - at most
  ``MAX_OUTSIDE`` of the samples outside and none beyond the tube by more than that range.

A quantity the result's sampling cannot show is not judged, and says why: when the same
estimator on the reference at the result's times differs from it on the reference's own
samples by more than half the tolerance (a ripple faster than the result's sampling, orders in
too short or too sparse a window), a pass or fail would be the sampling's, not the result's.

The start-up transient, when the judged span starts before it ends, is judged on its own by
the tube alone (its width relative to the transient's own range).

The power of each signal's verdict is computed, not asserted, through the same path: the
reference itself at the result's times, perturbed - its mean shifted, its ripple scaled about
the mean, the trace shifted in time - is judged by the same checks, and the smallest
perturbation of each sign that fails (by bisection) is stated.  ``blind_spots`` says in one
sentence what the verdict cannot see.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from harness.judges import sampled
from harness.judges.power import Power, power  # noqa: F401  (the verdict's power, re-exported)
from harness.judges.tolerances import (DEFAULT_RTOL, KINDS, NOISE_FLOOR, QUANTITIES, UNIT_KINDS,  # noqa: F401
                                       ReferenceSettings, Rule, Tolerances, allowed_scale as _allowed_scale,
                                       kind_of_unit, parse_rtol, rule, rules_from_table, settings_of)
from harness.judges.validation import JudgedSpan, match_columns, span_problems, value_problems

#: largest share of the compared samples allowed outside the tube
MAX_OUTSIDE = 0.01
#: the rotation orders looked at, and the share of the ripple amplitude an order's component
#: must have to be judged (a leading one)
ORDERS = (1, 2, 3, 4)
LEADING = 0.1
#: whole revolutions the window must hold for the orders to be judged
MIN_REVOLUTIONS = 2.0
#: the fewest result samples a judged window takes (fewer: refused, not judged)
MIN_SAMPLES = 10
#: the tube's horizontal tolerance is one result step, at most this share of the window (a
#: sparse result's step would otherwise make the tube the reference's whole range)
MAX_LAG_SHARE = 0.01
#: a quantity is judged when the reference at the result's times shows it within this share
#: of its tolerance of the reference's own value
SHOWN = 0.5
#: the most samples the power's search judges its changes at: a denser result's power is
#: searched at its samples nearest a grid as fine as the reference's own samples (or as this
#: allows), each with the tube it has in the verdict - a change of the reference holds nothing
#: finer than the reference, and a search judges each change some hundred times
POWER_SAMPLES = 20_000


class NothingToJudge(ValueError):
    """The result holds none of the reference's signals (or none of those chosen)."""


class UnusableResult(ValueError):
    """A result that cannot be judged as given: times not sorted, too few samples for the
    window.  Bad input, not a failed verdict."""


@dataclass
class Check:
    """One quantity of one signal: the reference's and the result's value, what is allowed."""
    quantity: str
    reference: float
    result: float
    #: the difference judged (for an order: the complex difference's magnitude)
    difference: float
    allowed: float
    passed: bool
    #: the same in words, e.g. "+4.65 % (allowed +-2 %)"
    detail: str = ""
    #: False: the result's sampling cannot show this quantity (``detail`` says why); it
    #: neither passes nor fails the signal
    judged: bool = True
    #: a tube's: the time [s] of its sample farthest beyond it (None: none beyond it)
    at: float | None = None
    #: a second criterion's failure in a few words (the start-up's envelope)
    also: str = ""


@dataclass
class SignalVerdict:
    name: str
    column: str
    kind: str
    #: quantity -> (relative tolerance, where it came from)
    rtol: dict
    checks: list[Check]
    power: Power | None
    rms_error: float
    max_error: float
    #: the reference's own interpolation error at the result's times (NaN: not known)
    reference_error: float = math.nan
    #: the signal's unit (None: not known)
    unit: str | None = None

    @property
    def passed(self) -> bool:
        return all(c.passed for c in self.checks if c.judged)

    @property
    def failed(self) -> list[Check]:
        return [c for c in self.checks if c.judged and not c.passed]

    @property
    def unjudged(self) -> list[Check]:
        return [c for c in self.checks if not c.judged]


@dataclass
class Verdict(JudgedSpan):
    """The verdict on one result: per judged signal, and about the result as a whole."""
    name: str
    signals: list[SignalVerdict] = field(default_factory=list)
    #: reference signals not judged (absent from the result, or not chosen: ``chosen``)
    not_judged: list[str] = field(default_factory=list)
    chosen: bool = False
    #: what fails the whole result (span not covered, NaN, ...)
    problems: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    #: the steady window judged and the transient part judged by its tube (None: not judged)
    window: tuple[float, float] | None = None
    transient: tuple[float, float] | None = None
    #: the driven shaft's mean speed in the window [rad/s] (None: no orders)
    rotation: float | None = None
    #: one sentence: what this verdict cannot see
    blind_spots: str = ""
    #: the span judged (start-up included) and the reference's whole span [s]
    span: tuple[float, float] | None = None
    whole_span: tuple[float, float] | None = None
    #: which reference judged the result, and its own error, in words
    reference: str = ""
    #: the result's sampling in the window, in words
    sampling: str = ""

    KIND = "lever"

    def counted(self) -> str:
        passing = sum(s.passed for s in self.signals)
        return (f"{len(self.signals)} signals judged, {passing} pass"
                + (f", {len(self.not_judged)} not judged" if self.not_judged else ""))

    def failure_line(self, s) -> str:
        return "; ".join(f"{c.quantity} {c.detail}" for c in s.failed)

    def failures(self) -> list[str]:
        """"coupling.tau2 amplitude +4.65 % (allowed +-2 %)", one per failed check."""
        return [f"{s.name} {c.quantity} {c.detail}" for s in self.signals for c in s.failed]

    def to_dict(self) -> dict:
        def number(x):
            return None if isinstance(x, float) and not math.isfinite(x) else x
        return {"name": self.name, "passed": self.passed, "verdict": "lever (engineer's quantities)",
                "reference": self.reference, "sampling": self.sampling,
                "window_s": list(self.window) if self.window else None,
                "transient_s": list(self.transient) if self.transient else None,
                "span_s": list(self.span) if self.span else None,
                "reference_span_s": list(self.whole_span) if self.whole_span else None,
                "rotation_rad_s": self.rotation, "blind_spots": self.blind_spots,
                "not_judged": list(self.not_judged), "problems": list(self.problems), "notes": list(self.notes),
                "failures": self.failures(),
                "signals": {s.name: {"column": s.column, "kind": s.kind, "passed": s.passed,
                                     "rtol": {q: {"value": v, "source": src} for q, (v, src) in s.rtol.items()},
                                     "rms_error": number(s.rms_error), "max_error": number(s.max_error),
                                     "reference_error": number(s.reference_error),
                                     "unit": s.unit,
                                     "checks": [{k: number(v) for k, v in vars(c).items()} for c in s.checks],
                                     "power": None if s.power is None else {k: v for k, v in vars(s.power).items()}}
                            for s in self.signals}}


def _percent(x: float) -> str:
    return f"{100 * x:+.3g} %"


def _lags(t: np.ndarray, cap: float) -> tuple[np.ndarray, np.ndarray]:
    """Each sample's step before and after (the tube's horizontal tolerance), at most ``cap``."""
    steps = np.diff(t)
    before = np.concatenate([steps[:1], steps]) if len(steps) else np.zeros(len(t))
    after = np.concatenate([steps, steps[-1:]]) if len(steps) else np.zeros(len(t))
    return np.minimum(before, cap), np.minimum(after, cap)


@dataclass
class _Frame:
    """What one signal is judged in over a part of the span: the result's times there, the
    reference's quantities on its own samples and at those times, the tube's bounds."""
    t: np.ndarray
    #: the reference at the result's times
    at: np.ndarray
    #: the reference's own samples in the part (its quantities' true values)
    own_t: np.ndarray
    own_y: np.ndarray
    mean: float
    amplitude: float
    magnitude: float
    #: the reference's range over one result step about each sample
    low: np.ndarray
    high: np.ndarray
    #: the reference's own interpolation error at each result time
    error: np.ndarray
    #: the reference's own interpolation error midway between its samples in the part (the
    #: most it errs anywhere there)
    own_error: float = 0.0
    #: the reference's mean and amplitude at the result's times
    shown_mean: float = math.nan
    shown_amplitude: float = math.nan
    fit: sampled.OrderFit | None = None
    #: (order, the reference's component on its own samples, at the result's times)
    orders: list = field(default_factory=list)
    #: the samples of the result in the part, where these are a selection of them
    of_samples: int | None = None


def _own_samples(ref: sampled.Reference, start: float, stop: float) -> tuple[np.ndarray, np.ndarray]:
    inside = (ref.t > start) & (ref.t < stop)
    t = np.concatenate([[start], ref.t[inside], [stop]])
    return t, ref(t)


def _frame(ref: sampled.Reference, t: np.ndarray, start: float, stop: float, rotation: float | None,
           magnitude: float, lag_cap: float) -> _Frame:
    own_t, own_y = _own_samples(ref, start, stop)
    at = ref(t)
    before, after = _lags(t, lag_cap)
    # nor can the reference place an event closer than its own samples around it
    k = np.clip(np.searchsorted(ref.t, t, "right") - 1, 0, max(len(ref.t) - 2, 0))
    spacing = np.minimum(ref.t[k + 1] - ref.t[k], lag_cap) if len(ref.t) > 1 else np.zeros(len(t))
    before, after = np.maximum(before, spacing), np.maximum(after, spacing)
    low, high = ref.range_around(t, before, after)
    error = np.nan_to_num(ref.error_at(t), nan=0.0)
    midway = 0.5 * (own_t[1:] + own_t[:-1])
    frame = _Frame(t, at, own_t, own_y, sampled.time_mean(own_t, own_y), sampled.amplitude(own_y), magnitude,
                   low, high, error, float(np.nan_to_num(np.max(ref.error_at(midway), initial=0.0))),
                   sampled.time_mean(t, at), sampled.amplitude(at))
    if rotation:
        own = sampled.order_fit(own_t, rotation, ORDERS).fit(own_y)
        frame.fit = sampled.order_fit(t, rotation, ORDERS)
        shown = frame.fit.fit(at)
        frame.orders = [(k, own[k], shown[k]) for k in ORDERS
                        if abs(own[k]) >= LEADING * frame.amplitude and abs(own[k]) > NOISE_FLOOR * magnitude]
    return frame


def _power_frame(frame: _Frame, ref: sampled.Reference, rotation: float | None,
                 most: int = POWER_SAMPLES) -> _Frame:
    """``frame``, or for a result sampled finer than the reference (or at more than ``most``
    samples) the same frame at the result's samples nearest a grid of the reference's own
    spacing (at least the window's span / ``most``): each kept sample keeps its tube bounds
    and the reference's error there; the reference's quantities as those samples show them are
    worked out anew."""
    t = frame.t
    if len(t) < 2:
        return frame
    spacing = max(sampled.median_step(ref.t[(ref.t >= t[0]) & (ref.t <= t[-1])]) or 0.0,
                  float(t[-1] - t[0]) / most)
    grid = np.arange(t[0], t[-1], spacing) if spacing > 0 else t
    keep = np.unique(np.append(np.clip(np.searchsorted(t, grid), 0, len(t) - 1), len(t) - 1))
    if len(keep) >= 0.9 * len(t):
        return frame
    kept_t, at = t[keep], frame.at[keep]
    thinned = _Frame(kept_t, at, frame.own_t, frame.own_y, frame.mean, frame.amplitude, frame.magnitude,
                     frame.low[keep], frame.high[keep], frame.error[keep], frame.own_error,
                     sampled.time_mean(kept_t, at), sampled.amplitude(at), of_samples=len(t))
    if frame.fit is not None:
        thinned.fit = sampled.order_fit(kept_t, rotation, ORDERS)
        shown = thinned.fit.fit(at)
        thinned.orders = [(k, own, shown[k]) for k, own, _ in frame.orders]
    return thinned


def _unshown(quantity: str, own: float, shown: float, allowed: float, sampling: str) -> str:
    return (f"not judged: the result's samples ({sampling}) show the reference's {quantity} as {shown:.4g}, its own "
            f"samples as {own:.4g} - off by more than half the {allowed:.3g} allowed")


def _checks(frame: _Frame, y: np.ndarray, rtol: dict, sampling: str) -> list[Check]:
    """The steady window's checks of the result's samples ``y`` (at ``frame.t``)."""
    checks = []
    scale = _allowed_scale(max(abs(frame.mean), frame.amplitude), magnitude=frame.magnitude)
    allowed = rtol["mean"][0] * scale
    shown, mean = frame.shown_mean, sampled.time_mean(frame.t, y)
    d = mean - shown
    if abs(shown - frame.mean) > SHOWN * allowed:
        checks.append(Check("mean", frame.mean, mean, d, allowed, True,
                            _unshown("mean", frame.mean, shown, allowed, sampling), judged=False))
    else:
        checks.append(Check("mean", shown, mean, d, allowed, abs(d) <= allowed,
                            f"{mean:.6g} vs {shown:.6g} ({d:+.3g}, allowed +-{allowed:.3g})"))
    scale = _allowed_scale(frame.amplitude, frame.mean, magnitude=frame.magnitude)
    # a peak between the reference's samples is known to its own error only
    allowed = rtol["amplitude"][0] * scale + frame.own_error
    shown, amplitude = frame.shown_amplitude, sampled.amplitude(y)
    d = amplitude - shown
    if frame.own_error > rtol["amplitude"][0] * scale:
        checks.append(Check("amplitude", frame.amplitude, amplitude, d, allowed, True,
                            f"not judged: the reference's samples cannot show this ripple's peaks (between them it "
                            f"errs by up to {frame.own_error:.3g}, more than the {rtol['amplitude'][0] * scale:.3g} "
                            "allowed; a denser reference judges it)", judged=False))
    elif abs(shown - frame.amplitude) > SHOWN * allowed:
        checks.append(Check("amplitude", frame.amplitude, amplitude, d, allowed, True,
                            _unshown("ripple amplitude", frame.amplitude, shown, allowed, sampling), judged=False))
    else:
        if scale == abs(frame.amplitude):
            detail = (f"{amplitude:.4g} vs {shown:.4g} ({_percent(d / scale)}, allowed "
                      f"+-{100 * rtol['amplitude'][0]:.3g} %"
                      + (f" and the reference's own error {frame.own_error:.2g}" if frame.own_error else "") + ")")
        else:       # a reference with next to no ripple: the tolerance is of its mean or of the noise floor
            basis = "its mean" if scale == abs(frame.mean) else "the noise floor"
            detail = (f"{amplitude:.4g} vs {shown:.4g} ({d:+.3g}, allowed +-{allowed:.3g}: "
                      f"{100 * rtol['amplitude'][0]:.3g} % of {basis}, {scale:.3g})")
        checks.append(Check("amplitude", shown, amplitude, d, allowed, abs(d) <= allowed, detail))
    if frame.orders:
        got_all = frame.fit.fit(y)
        for k, own, shown in frame.orders:
            got = got_all[k]
            allowed = rtol["order"][0] * _allowed_scale(abs(own), magnitude=frame.magnitude)
            d = abs(got - shown)
            if abs(shown - own) > SHOWN * allowed:
                checks.append(Check(f"order {k}", abs(own), abs(got), d, allowed, True,
                                    _unshown(f"order {k}", abs(own), abs(shown), allowed, sampling)
                                    + " (of the complex component)", judged=False))
                continue
            phase = math.degrees(np.angle(got / shown)) if got != 0 else math.nan
            checks.append(Check(f"order {k}", abs(shown), abs(got), d, allowed, d <= allowed,
                                f"amplitude {_percent(abs(got) / abs(shown) - 1)}, phase {phase:+.2g} deg: off by "
                                f"{100 * d / abs(shown):.3g} % of the component "
                                f"(allowed {100 * rtol['order'][0]:.3g} %)"))
    width = rtol["tube"][0] * _allowed_scale(2 * frame.amplitude, frame.mean, magnitude=frame.magnitude)
    checks.append(_tube("tube", frame, y, width, 2 * frame.amplitude, rtol["tube"][0]))
    return checks


def _tube(label: str, frame: _Frame, y: np.ndarray, width: float, range_: float, rtol: float) -> Check:
    """Every sample within ``width`` (plus the reference's own error) of the reference's range
    over one result step about its time; at most ``MAX_OUTSIDE`` outside, none beyond the tube
    by more than the reference's range there (a spike between the reference's samples)."""
    width = width + frame.error         # a reference between its samples is known no better than this
    excess = np.maximum(frame.low - width - y, y - frame.high - width)
    excess = np.where(np.isfinite(y), excess, np.inf)
    outside = excess > 0
    share = float(np.count_nonzero(outside)) / len(y) if len(y) else 1.0
    worst = float(np.max(excess)) if len(y) else math.inf
    limit = max(range_, float(np.max(width)) if len(y) else 0.0)
    passed = bool(len(y)) and share <= MAX_OUTSIDE and worst <= limit
    first, at = "", None
    if outside.any():
        i = int(np.argmax(excess))
        at = float(frame.t[i])
        first = (f", the farthest {worst:.3g} beyond it at t = {frame.t[i]:.6g} s"
                 + (f" (more than the reference's range {limit:.3g})" if worst > limit else ""))
    widest = float(np.max(width)) if len(y) else 0.0
    own = float(np.max(frame.error)) if len(y) else 0.0
    return Check(label, 0.0, share, share, MAX_OUTSIDE, passed,
                 f"{100 * share:.3g} % of the samples outside +-{widest - own:.3g} ({100 * rtol:.3g} % of the range"
                 + (f"; plus the reference's own error between its samples, up to {own:.2g}" if own else "")
                 + f"; allowed {100 * MAX_OUTSIDE:g} %){first}", at=at)


def _start_up_tube(frame: _Frame, y: np.ndarray, rtol: dict) -> Check:
    """The start-up transient's tube: as wide as the tube's tolerance of its own range; and
    its envelope (``_envelope_misses``): a ringing near the sampling rate fits the tube's
    range over a step either side whether the result rings or not."""
    range_ = float(np.ptp(frame.own_y))
    width = rtol["tube"][0] * _allowed_scale(range_, frame.mean, magnitude=frame.magnitude)
    check = _tube("transient tube", frame, y, width, range_, rtol["tube"][0])
    missed, windows, window, first = _envelope_misses(frame, y, width)
    if windows and missed / windows > MAX_OUTSIDE:
        check.passed = False
        check.at = first if check.at is None else check.at
        check.also = f"envelope off in {missed} of {windows} spans"
        check.detail += (f"; its envelope: in {missed} of {windows} spans of {1e3 * window:.3g} ms the result's "
                         f"peak-to-peak is off the reference's by more than twice the tube, the first at "
                         f"t = {first:.6g} s (a ringing lost, grown or damped otherwise)")
    return check


#: the start-up's envelope is compared over spans of this many result steps
ENVELOPE_STEPS = 8


def _envelope_misses(frame: _Frame, y: np.ndarray, width: float) -> tuple[int, int, float, float | None]:
    """In consecutive spans of ``ENVELOPE_STEPS`` result steps, the result's peak-to-peak
    against the reference's: at least its peak-to-peak at the result's times, at most its
    range over a step either side, each less or more twice the tube's ``width`` and the
    reference's own error.  Returns the spans missed, the spans, their length [s] and the
    first missed span's start (None: none)."""
    step = sampled.median_step(frame.t)
    if len(y) < 2 or step is None:
        return 0, 0, 0.0, None
    window = ENVELOPE_STEPS * step
    span = np.floor((frame.t - frame.t[0]) / window).astype(int)
    starts = np.flatnonzero(np.diff(span, prepend=-1))
    counts = np.diff(np.append(starts, len(y)))
    highest, lowest = np.maximum.reduceat, np.minimum.reduceat
    result = highest(y, starts) - lowest(y, starts)
    shown = highest(frame.at, starts) - lowest(frame.at, starts)
    widest = highest(frame.high, starts) - lowest(frame.low, starts)
    slack = 2 * (width + highest(frame.error, starts))
    with np.errstate(invalid="ignore"):
        missed = ((result < shown - slack) | (result > widest + slack) | ~np.isfinite(result)) & (counts >= 2)
    first = float(frame.t[starts[np.argmax(missed)]]) if missed.any() else None
    return int(np.count_nonzero(missed)), int(np.count_nonzero(counts >= 2)), window, first


def _rotation(references: dict, start: float, stop: float,
              rotation_signal: str | None) -> tuple[float | None, str]:
    """The driven shaft's mean speed over the window and a sentence on the orders (why none)."""
    if not rotation_signal or rotation_signal not in references:
        return None, "no rotation orders (no shaft speed in the reference)"
    t, y = _own_samples(references[rotation_signal], start, stop)
    w = abs(sampled.time_mean(t, y))
    turns = w * (stop - start) / (2 * math.pi)
    if turns < MIN_REVOLUTIONS:
        return None, (f"no rotation orders: the window holds {turns:.2g} revolutions of {rotation_signal}, fewer "
                      f"than {MIN_REVOLUTIONS:g}")
    return w, f"orders of {rotation_signal} at {w:.4g} rad/s over {turns:.3g} revolutions"


def judge(times, traces: dict, reference_times, reference: dict, *, window: tuple[float, float] | None = None,
          transient: float | None = None, rtol: Tolerances | None = None, signals=None, kinds: dict | None = None,
          rotation_signal: str | None = None, name: str = "", with_power: bool = True,
          units: dict | None = None) -> Verdict:
    """The verdict on the result ``traces`` (by column name, at ``times``) against
    ``reference`` (by signal, at ``reference_times``: dense enough to resolve its content).

    ``window``: the span judged, (start, stop) [s] (default: the reference's); ``transient``:
    the time [s] the start-up transient ends (the steady window starts there; the part before
    it, when the window holds one, is judged by its tube alone); ``rtol``: ``Tolerances``
    (default ``DEFAULT_RTOL``); ``signals``: the reference signals to judge (default: those the
    result has; ``NothingToJudge`` when it has none, ValueError for a chosen one it lacks);
    ``kinds``: signal -> kind (``KINDS``) for tolerances by kind; ``rotation_signal``: the
    driven shaft's speed among the reference's signals, whose orders are judged; ``units``:
    signal -> unit (for what is said and drawn).  ``UnusableResult`` for a result whose times
    are not sorted or that has fewer than ``MIN_SAMPLES`` samples in a part of the window it is
    to be judged over."""
    verdict = Verdict(name)
    t, traces, repeated = sampled.repeated_rows_dropped(times, traces)
    if repeated:
        verdict.notes.append(f"{repeated} row(s) of the result repeat the row before them (the same time and "
                             "values): read once")
    t_ref = np.asarray(reference_times, dtype=float)
    rtol = rtol or Tolerances()
    kinds = kinds or {}
    start, stop = (float(t_ref[0]), float(t_ref[-1])) if window is None else map(float, window)
    steady_start = start if transient is None else min(max(start, float(transient)), stop)
    verdict.span, verdict.whole_span = (start, stop), (float(t_ref[0]), float(t_ref[-1]))
    columns = [str(c) for c in traces]
    mapping, _, matched = match_columns(list(reference), columns, said=True)
    if signals:
        unknown = [s for s in signals if s not in reference]
        if unknown:
            raise ValueError(f"--signals {', '.join(unknown)}: not a signal of the reference (its signals: "
                             f"{', '.join(reference)})")
        absent = [s for s in signals if s not in mapping]
        if absent:
            raise ValueError(f"--signals {', '.join(absent)}: not in the result (its columns: "
                             f"{', '.join(columns) or 'none'})")
        mapping = {s: mapping[s] for s in signals}
    if not mapping:
        raise NothingToJudge(f"the result has none of the reference's signals ({', '.join(reference)}); its columns: "
                             f"{', '.join(columns) or 'none'} (a scene's signals are component.variable; "
                             "component_variable and <model>.component.variable are matched too)")
    verdict.not_judged = [s for s in reference if s not in mapping]
    verdict.chosen = bool(signals)
    if matched:
        verdict.notes.append("columns matched by another tool's naming: " + ", ".join(matched))
    extra = sorted(set(columns) - set(match_columns(list(reference), columns)[0].values()))
    if extra:
        verdict.notes.append("not in the reference (not compared): " + ", ".join(extra))
    unknown_targets = rtol.unknown_targets(list(reference))
    if unknown_targets:
        raise ValueError(f"tolerance for {', '.join(unknown_targets)}: neither a signal of the reference nor a kind "
                         f"(kinds: {', '.join(KINDS)}; signals: {', '.join(reference)})")
    if len(t) < 2:
        raise UnusableResult(f"the result has {len(t)} sample(s); at least {MIN_SAMPLES} in the window are needed")
    problem = sampled.times_problem(t, "the result's")
    if problem:
        raise UnusableResult(problem)
    verdict.problems += span_problems(t, start, stop)
    if verdict.problems:
        return verdict
    slack = 1e-9 * max(1.0, abs(stop))
    steady = stop - steady_start > slack
    parts = {}
    if steady:
        parts["steady"] = (steady_start, stop)
        if steady_start - start > slack:
            parts["transient"] = (start, steady_start)
    else:       # the span ends before the start-up transient does: its tube alone judges it
        parts["transient"] = (start, stop)
        verdict.notes.append(f"the span judged, t = {start:g} ... {stop:g} s, ends before the start-up transient does "
                             f"(t = {float(transient):g} s): judged by the start-up's tube only")
    picks = {}
    for part, (low, high) in parts.items():
        pick = (t >= low - slack) & (t <= high + slack) if part == "steady" else (t >= low - slack) & (t < high - slack)
        count = int(np.count_nonzero(pick))
        if count < MIN_SAMPLES:
            what = "steady window" if part == "steady" else "start-up transient"
            raise UnusableResult(f"the result has {count} sample(s) in the {what}, t = {low:g} ... {high:g} s; "
                                 f"at least {MIN_SAMPLES} are needed to judge it (a denser result, or --window "
                                 "over a span it samples)")
        picks[part] = pick
    verdict.window = parts.get("steady")
    verdict.transient = parts.get("transient")
    references = {s: sampled.Reference(t_ref, np.asarray(reference[s], dtype=float))
                  for s in set(mapping) | ({rotation_signal} & set(reference))}
    if steady:
        rotation, orders_said = _rotation(references, steady_start, stop, rotation_signal)
    else:
        rotation, orders_said = None, "no rotation orders, no mean, no ripple amplitude: the span is start-up only"
    verdict.rotation = rotation
    window_t = t[picks.get("steady", picks.get("transient"))]
    verdict.sampling = sampled.spacing(window_t)
    in_span = (t >= start - slack) & (t <= stop + slack)
    for signal, column in mapping.items():
        ref = references[signal]
        y_all = np.asarray(traces[column], dtype=float)
        verdict.problems += value_problems(signal, t, y_all, ref.y)
        tolerances = rtol.of(signal, kinds.get(signal, "other"))
        magnitude = float(np.max(np.abs(ref.y[np.isfinite(ref.y)]), initial=0.0))
        checks, frame = [], None
        for part, (low, high) in parts.items():
            t_part = t[picks[part]]
            part_frame = _frame(ref, t_part, low, high, rotation if part == "steady" else None, magnitude,
                                MAX_LAG_SHARE * (high - low))
            if part == "steady":
                frame = part_frame
                checks += _checks(part_frame, y_all[picks[part]], tolerances, verdict.sampling)
            else:
                checks.append(_start_up_tube(part_frame, y_all[picks[part]], tolerances))
        with np.errstate(over="ignore", invalid="ignore"):
            error = y_all[in_span] - ref(t[in_span])
        finite = bool(np.all(np.isfinite(error)))
        judged = search = None
        if frame is not None:
            search = _power_frame(frame, ref, rotation)

            def judged(values, frame=search, tolerances=tolerances):
                return _checks(frame, values, tolerances, verdict.sampling)
        sv = SignalVerdict(signal, column, kinds.get(signal, "other"), tolerances, checks,
                           power(search, judged, ref, tolerances, rotation) if with_power and finite and judged
                           else None,
                           float(np.sqrt(np.mean(error ** 2))) if finite else math.inf,
                           float(np.max(np.abs(error))) if finite else math.inf,
                           frame.own_error if frame is not None else math.nan,
                           (units or {}).get(signal))
        verdict.signals.append(sv)
    verdict.blind_spots = blind_spots(verdict, t_ref, window_t, orders_said)
    return verdict


def blind_spots(verdict: Verdict, t_ref: np.ndarray, t_res: np.ndarray, orders_said: str) -> str:
    """One sentence: what the verdict cannot see on this reference and result."""
    dt_res = float(np.max(np.diff(t_res))) if len(t_res) > 1 else math.inf
    said = [f"anything faster than {math.pi / dt_res:.3g} rad/s (half the sampling rate of the result's samples, "
            f"{verdict.sampling}, each compared with the reference at its time)"]
    if verdict.window and verdict.transient:
        said.append(f"before t = {verdict.window[0]:g} s, anything but a departure from the start-up's tube")
    elif verdict.window and verdict.span and verdict.window[0] > verdict.span[0]:
        said.append(f"anything before t = {verdict.window[0]:g} s (not judged)")
    said.append(orders_said if orders_said.startswith("no rotation") else
                "a rotation order smaller than a tenth of the ripple amplitude (not judged)")
    unjudged = sorted({f"{s.name} {c.quantity}" for s in verdict.signals for c in s.unjudged})
    if unjudged:
        said.append(f"what the result's sampling cannot show ({', '.join(unjudged)}: not judged)")
    said.append("a change smaller than the power stated beside each signal")
    if verdict.not_judged:
        said.append(f"the {len(verdict.not_judged)} signal(s) not judged")
    return "cannot see: " + "; ".join(said)
