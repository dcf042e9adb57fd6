"""The engineer's verdict on a result against its reference trace (``lever validate``'s
default): per signal, over the judged window, the quantities a driveline engineer checks
first, each against a tolerance relative to that quantity, and the verdict's power.

Judged over the window (by default the span after the scene's start-up transient), at the
reference's samples (the result interpolated there), per signal:

* ``mean``: the mean, within ``rtol.mean`` of ``max(|mean|, amplitude)`` of the reference (a
  signal that swings about zero is judged against its swing);
* ``amplitude``: the ripple amplitude ``(max - min) / 2`` (the run report's), within
  ``rtol.amplitude`` of the reference's;
* ``order k``: the leading rotation orders, the components at k times the driven shaft's
  rotation frequency the run report computes (``metrics.spectrum``; orders whose amplitude
  is at least ``LEADING`` of the signal's ripple amplitude, below half the sampling rate):
  the complex component within ``rtol.order`` of its magnitude (at least ``NOISE_FLOOR`` of the
  signal's largest value), so an amplitude change of
  ``rtol.order`` or a phase change of about ``rtol.order`` rad fails;
* ``tube``: every compared sample within ``rtol.tube`` of the reference's range in the
  window (``max - min`` there, not a start-up spike's), with the horizontal tolerance of one
  result step (``validation.result_window``), at most ``MAX_OUTSIDE`` of the samples outside.

The start-up transient, when the judged span starts before it ends, is judged on its own by
the tube alone (its width relative to the transient's own range): its mean and ripple are no
steady quantities.

The power of each signal's verdict is computed, not asserted: the reference itself,
perturbed - its mean shifted, its ripple scaled about the mean, the trace shifted in time -
and put on the result's time grid, is judged by the same checks, and the smallest
perturbation that fails (either sign; by bisection) is stated.  ``blind_spots`` says in one
sentence what the verdict cannot see.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from harness.judges import metrics
from harness.judges.validation import JudgedSpan, match_columns, result_window, span_problems, value_problems

#: what a tolerance applies to
QUANTITIES = ("mean", "amplitude", "order", "tube")
#: the defaults (docs/validation.md#the-defaults-and-why):
#: mean - a result at the benchmark's accuracy target (RMS error 0.1 % of the mean) has its
#:   mean within 0.1 % (a mean error is at most the RMS error), so 0.1 % passes every such result;
#: amplitude - 2 %: at 0.1 % RMS torque error the error on KAVZ-685's tau2 is 0.11 N*m against
#:   a 6 N*m ripple amplitude (1.8 %), while a changed coupling moves it by 3.6 % (damping +20 %)
#:   and 4.7 % (misalignment 15 -> 20 deg);
#: order - 5 % of each leading order's magnitude (about 3 deg of phase): the leading orders move
#:   less than the peak-to-peak amplitude under a result's own error, more under a model's change;
#: tube - 5 % of the range in the window (a tenth of the ripple amplitude): a catch-all for a
#:   shape the other quantities miss, wide enough not to flag a sound result's sample-level noise.
DEFAULT_RTOL = {"mean": 1e-3, "amplitude": 0.02, "order": 0.05, "tube": 0.05}
#: largest share of the compared samples allowed outside the tube
MAX_OUTSIDE = 0.01
#: the rotation orders looked at, and the share of the ripple amplitude an order's component
#: must have to be judged (a leading one)
ORDERS = (1, 2, 3, 4)
LEADING = 0.1
#: whole revolutions the window must hold for the orders to be judged (the spectrum's
#: resolution: at 2 revolutions its bins are half an order apart)
MIN_REVOLUTIONS = 2.0
#: the kinds of signals a tolerance may name, by the unit of the variable
UNIT_KINDS = {"rad/s": "speed", "N.m": "torque", "rad/s2": "acceleration", "rad": "angle", "J": "energy",
              "W": "power", "": "ratio"}
KINDS = tuple(dict.fromkeys(UNIT_KINDS.values()))


class NothingToJudge(ValueError):
    """The result holds none of the reference's signals (or none of those chosen)."""


def kind_of_unit(unit: str | None) -> str:
    return UNIT_KINDS.get(unit or "", "other")


@dataclass(frozen=True)
class Rule:
    """One tolerance: ``quantity`` of ``target`` (a signal, a kind, or "" for every signal)
    is ``value`` (relative), set by ``source`` ("default", "scene file", "--rtol", "API")."""
    target: str
    quantity: str
    value: float
    source: str


def rule(target: str, quantity: str, value, source: str) -> Rule:
    """A checked ``Rule``: ValueError naming the quantity or value otherwise."""
    if quantity not in QUANTITIES:
        raise ValueError(f"tolerance {target + ':' if target else ''}{quantity}: no such quantity "
                         f"(one of {', '.join(QUANTITIES)})")
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"tolerance {target + ':' if target else ''}{quantity} = {value!r}: expected a number "
                         "(relative, e.g. 0.05 for 5 %)") from None
    if not (math.isfinite(number) and number >= 0):
        raise ValueError(f"tolerance {target + ':' if target else ''}{quantity} = {value!r}: must be a finite "
                         "relative tolerance >= 0 (e.g. 0.05 for 5 %)")
    return Rule(target, quantity, number, source)


def parse_rtol(texts, source: str = "--rtol") -> list[Rule]:
    """``[TARGET:]QUANTITY=VALUE`` texts (``amplitude=0.05``, ``torque:mean=0.002``,
    ``coupling.tau2:order=0.1``): TARGET a signal or a kind (``KINDS``), none: every signal."""
    rules = []
    for text in texts:
        if "=" not in str(text):
            raise ValueError(f"--rtol {text!r}: expected [SIGNAL or KIND:]QUANTITY=VALUE, e.g. amplitude=0.05 "
                             f"or coupling.tau2:mean=0.002 (quantities: {', '.join(QUANTITIES)})")
        left, value = (s.strip() for s in str(text).split("=", 1))
        target, _, quantity = left.rpartition(":")
        rules.append(rule(target.strip(), quantity.strip(), value, source))
    return rules


def rules_from_table(table: dict, source: str = "scene file") -> list[Rule]:
    """A scene's ``[validation]`` table: ``QUANTITY = VALUE`` for every signal, and sub-tables
    named by a kind or a signal (``[validation.torque]``, ``[validation."coupling.tau2"]``)."""
    rules = []
    for key, value in table.items():
        if isinstance(value, dict):
            rules += [rule(key, q, v, source) for q, v in value.items()]
        else:
            rules.append(rule("", key, value, source))
    return rules


@dataclass
class Tolerances:
    """Rules from several sources; a later list overrides an earlier, and within one source a
    signal's rule overrides its kind's, which overrides one for every signal."""
    layers: list[list[Rule]] = field(default_factory=list)

    def of(self, signal: str, kind: str) -> dict[str, tuple[float, str]]:
        out = {q: (v, "default") for q, v in DEFAULT_RTOL.items()}
        for layer in self.layers:
            for target in ("", kind, signal):
                for r in layer:
                    if r.target == target:
                        out[r.quantity] = (r.value, r.source)
        return out

    def unknown_targets(self, signals, kinds=KINDS) -> list[str]:
        """Targets no signal or kind answers to (a misspelt name judges nothing)."""
        known = set(signals) | set(kinds) | {""}
        return sorted({r.target for layer in self.layers for r in layer if r.target not in known})


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


@dataclass
class Power:
    """The smallest change of each kind the verdict fails (None: none it fails)."""
    #: the tube's half-width
    band: float
    #: a shift of the mean, in the signal's unit
    mean: float | None
    #: a scaling of the ripple about the mean, relative
    amplitude: float | None
    #: a shift in time [s], and the phase it is at the first rotation order [deg]
    shift_s: float | None
    phase_deg: float | None
    #: kind of change -> the checks that fail first under it ("mean", "amplitude", "shift")
    by: dict = field(default_factory=dict)

    def describe(self) -> str:
        """"band +-0.566; catches mean +-0.107 (by mean), amplitude +-2 % (by amplitude), phase ..."."""
        def by(kind):
            return f"by {', '.join(self.by[kind])}" if self.by.get(kind) else ""

        def said(value, text, kind):
            return "none" if value is None else f"{text} ({by(kind)})" if by(kind) else text

        mean = said(self.mean, f"+-{self.mean:.3g}" if self.mean is not None else "", "mean")
        amplitude = said(self.amplitude, f"+-{100 * self.amplitude:.2g} %" if self.amplitude is not None else "",
                         "amplitude")
        if self.shift_s is None:
            shift = "time shift none"
        else:
            at = f"{1e3 * self.shift_s:.3g} ms" + (f"; {by('shift')}" if by("shift") else "")
            shift = (f"phase +-{self.phase_deg:.2g} deg at the rotation ({at})" if self.phase_deg is not None
                     else f"time shift +-{at}")
        return f"band +-{self.band:.3g}; catches mean {mean}, amplitude {amplitude}, {shift}"


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

    @property
    def passed(self) -> bool:
        return all(c.passed for c in self.checks)

    @property
    def failed(self) -> list[Check]:
        return [c for c in self.checks if not c.passed]


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
                                     "checks": [{k: number(v) for k, v in vars(c).items()} for c in s.checks],
                                     "power": None if s.power is None else {k: v for k, v in vars(s.power).items()}}
                            for s in self.signals}}


def _percent(x: float) -> str:
    return f"{100 * x:+.3g} %"


#: a quantity smaller than this share of the signal's largest magnitude over the reference is
#: judged against that share instead: below it a reference's figures are the solver's noise
#: (a stalled shaft's speed, 1e-11 rad/s, is no ripple to hold a result to 2 % of)
NOISE_FLOOR = 1e-3


def _allowed_scale(*values: float, magnitude: float = 0.0) -> float:
    """What a relative tolerance is taken of: the first of ``values`` that is not zero (a
    constant signal's amplitude is judged against its mean), at least ``NOISE_FLOOR`` of the
    signal's largest ``magnitude``; 1 in the signal's unit for a signal zero throughout (as
    the FMI cross-check takes one)."""
    first = next((abs(v) for v in values if v != 0 and math.isfinite(v)), 0.0)
    scale = max(first, NOISE_FLOOR * abs(magnitude))
    return scale if scale > 0 else 1.0


@dataclass
class _Frame:
    """What one signal is judged in: the reference's samples in the window, its orders."""
    t: np.ndarray
    y: np.ndarray
    mean: float
    amplitude: float
    span: float
    #: (order, bin index, reference's complex component)
    orders: list
    #: the reference's largest magnitude over its whole span
    magnitude: float


def _frame(t: np.ndarray, y: np.ndarray, rotation: float | None, magnitude: float) -> _Frame:
    mean, amplitude = float(np.mean(y)), float((np.max(y) - np.min(y)) / 2)
    orders = []
    if rotation:
        omega, components = metrics.spectrum(t, y)
        for k in ORDERS:
            i = metrics.peak_index(omega, np.abs(components), (1 - metrics.ORDER_SEARCH) * k * rotation,
                                   (1 + metrics.ORDER_SEARCH) * k * rotation)
            if i is not None and abs(components[i]) >= LEADING * amplitude and abs(components[i]) > 0:
                orders.append((k, i, complex(components[i])))
    return _Frame(t, y, mean, amplitude, 2 * amplitude, orders, magnitude)


def _checks(frame: _Frame, t_res: np.ndarray, y_res: np.ndarray, rtol: dict) -> list[Check]:
    """The steady window's checks of the result ``y_res(t_res)`` against ``frame``."""
    at = np.interp(frame.t, t_res, y_res)
    checks = []
    mean = float(np.mean(at))
    allowed = rtol["mean"][0] * _allowed_scale(max(abs(frame.mean), frame.amplitude), magnitude=frame.magnitude)
    d = mean - frame.mean
    checks.append(Check("mean", frame.mean, mean, d, allowed, abs(d) <= allowed,
                        f"{mean:.6g} vs {frame.mean:.6g} ({d:+.3g}, allowed +-{allowed:.3g})"))
    amplitude = float((np.max(at) - np.min(at)) / 2)
    scale = _allowed_scale(frame.amplitude, frame.mean, magnitude=frame.magnitude)
    allowed = rtol["amplitude"][0] * scale
    d = amplitude - frame.amplitude
    if scale == abs(frame.amplitude):
        detail = (f"{amplitude:.4g} vs {frame.amplitude:.4g} ({_percent(d / scale)}, allowed "
                  f"+-{100 * rtol['amplitude'][0]:.3g} %)")
    else:       # a reference with next to no ripple: the tolerance is of its mean or of the noise floor
        basis = "its mean" if scale == abs(frame.mean) else "the noise floor"
        detail = (f"{amplitude:.4g} vs {frame.amplitude:.4g} ({d:+.3g}, allowed +-{allowed:.3g}: "
                  f"{100 * rtol['amplitude'][0]:.3g} % of {basis}, {scale:.3g})")
    checks.append(Check("amplitude", frame.amplitude, amplitude, d, allowed, abs(d) <= allowed, detail))
    if frame.orders:
        _, components = metrics.spectrum(frame.t, at)
        for k, i, ref in frame.orders:
            got = complex(components[i])
            d = abs(got - ref)
            allowed = rtol["order"][0] * _allowed_scale(abs(ref), magnitude=frame.magnitude)
            phase = math.degrees(np.angle(got / ref)) if got != 0 else math.nan
            checks.append(Check(f"order {k}", abs(ref), abs(got), d, allowed, d <= allowed,
                                f"amplitude {_percent(abs(got) / abs(ref) - 1)}, phase {phase:+.2g} deg: off by "
                                f"{100 * d / abs(ref):.3g} % of the component "
                                f"(allowed {100 * rtol['order'][0]:.3g} %)"))
    width = rtol["tube"][0] * _allowed_scale(frame.span, frame.mean, magnitude=frame.magnitude)
    checks.append(_tube("tube", frame.t, frame.y, t_res, y_res, width, rtol["tube"][0]))
    return checks


def _tube(label: str, t_ref: np.ndarray, y_ref: np.ndarray, t_res: np.ndarray, y_res: np.ndarray, width: float,
          rtol: float) -> Check:
    low, high = result_window(t_res, y_res, t_ref)
    outside = (y_ref < low - width) | (y_ref > high + width) | ~np.isfinite(low) | ~np.isfinite(high)
    share = float(np.count_nonzero(outside)) / len(t_ref) if len(t_ref) else 1.0
    first = f", the first at t = {t_ref[np.flatnonzero(outside)[0]]:.6g} s" if outside.any() else ""
    return Check(label, 0.0, share, share, MAX_OUTSIDE, bool(len(t_ref)) and share <= MAX_OUTSIDE,
                 f"{100 * share:.3g} % of the samples outside +-{width:.3g} ({100 * rtol:.3g} % of the range; "
                 f"allowed {100 * MAX_OUTSIDE:g} %){first}")


def _smallest_failing(fails, start: float, limit: float) -> float | None:
    """The smallest x > 0 with ``fails(x)`` (either sign: the smaller of the two), by
    doubling from ``start`` up to ``limit`` and bisecting; None when nothing up to
    ``limit`` fails."""
    best = None
    for sign in (1.0, -1.0):
        low, high = 0.0, start
        while not fails(sign * high):
            low, high = high, 2 * high
            if high > limit:
                high = None
                break
        if high is None:
            continue
        for _ in range(30):
            middle = 0.5 * (low + high)
            if fails(sign * middle):
                high = middle
            else:
                low = middle
            if high - low <= 1e-4 * high:
                break
        best = high if best is None else max(best, high)
    return best


def power(frame: _Frame, judged, t_all: np.ndarray, y_all: np.ndarray, t_grid: np.ndarray, rtol: dict,
          rotation: float | None) -> Power:
    """The smallest shift of the mean, scaling of the ripple and shift in time of the
    reference (``y_all(t_all)``, put on the result's grid ``t_grid``) that the checks
    ``judged(t, values)`` fail: what a pass of this signal rules out.  Either sign counts (the larger of the two is
    stated, so a change beyond it fails whichever its sign)."""
    base = np.interp(t_grid, t_all, y_all)
    perturbed = {"mean": lambda d: base + d,
                 "amplitude": lambda e: frame.mean + (1 + e) * (base - frame.mean),
                 "shift": lambda s: np.interp(t_grid - s, t_all, y_all)}

    def failing(kind, x):
        return [c.quantity for c in judged(t_grid, perturbed[kind](x)) if not c.passed]

    scale = _allowed_scale(max(abs(frame.mean), frame.amplitude), magnitude=frame.magnitude)
    dt = float(np.median(np.diff(frame.t))) if len(frame.t) > 1 else 1.0
    span = float(frame.t[-1] - frame.t[0])
    found, by = {}, {}
    for kind, first, limit in (("mean", 1e-4 * scale, 1e3 * scale), ("amplitude", 1e-4, 10.0),
                               ("shift", 1e-3 * dt, 0.25 * span)):
        found[kind] = _smallest_failing(lambda x: bool(failing(kind, x)), first, limit)
        if found[kind] is not None:
            by[kind] = sorted(set(failing(kind, found[kind])) | set(failing(kind, -found[kind])))
    shift = found["shift"]
    phase = None if (shift is None or not rotation) else math.degrees(rotation * shift)
    band = rtol["tube"][0] * _allowed_scale(frame.span, frame.mean, magnitude=frame.magnitude)
    return Power(band, found["mean"], found["amplitude"], shift, phase, by)


def _rotation(reference: dict, t: np.ndarray, keep: np.ndarray,
              rotation_signal: str | None) -> tuple[float | None, str]:
    """The driven shaft's mean speed over the window and a sentence on the orders (why none)."""
    if not rotation_signal or rotation_signal not in reference:
        return None, "no rotation orders (no shaft speed in the reference)"
    w = abs(float(np.mean(np.asarray(reference[rotation_signal], dtype=float)[keep])))
    span = float(t[keep][-1] - t[keep][0])
    turns = w * span / (2 * math.pi)
    if turns < MIN_REVOLUTIONS:
        return None, (f"no rotation orders: the window holds {turns:.2g} revolutions of {rotation_signal}, fewer "
                      f"than {MIN_REVOLUTIONS:g}")
    return w, f"orders of {rotation_signal} at {w:.4g} rad/s over {turns:.3g} revolutions"


def judge(times, traces: dict, reference_times, reference: dict, *, window: tuple[float, float] | None = None,
          transient: float | None = None, rtol: Tolerances | None = None, signals=None, kinds: dict | None = None,
          rotation_signal: str | None = None, name: str = "", with_power: bool = True) -> Verdict:
    """The verdict on the result ``traces`` (by column name, at ``times``) against
    ``reference`` (by signal, at ``reference_times``).

    ``window``: the span judged, (start, stop) [s] (default: the reference's); ``transient``:
    the time [s] the start-up transient ends (the steady window starts there; the part before
    it, when the window holds one, is judged by its tube alone); ``rtol``: ``Tolerances``
    (default ``DEFAULT_RTOL``); ``signals``: the reference signals to judge (default: those the
    result has; ``NothingToJudge`` when it has none, ValueError for a chosen one it lacks);
    ``kinds``: signal -> kind (``KINDS``) for tolerances by kind; ``rotation_signal``: the
    driven shaft's speed among the reference's signals, whose orders are judged."""
    verdict = Verdict(name)
    t = np.asarray(times, dtype=float)
    t_ref = np.asarray(reference_times, dtype=float)
    rtol = rtol or Tolerances()
    kinds = kinds or {}
    start, stop = (float(t_ref[0]), float(t_ref[-1])) if window is None else map(float, window)
    steady_start = start if transient is None else min(max(start, float(transient)), stop)
    verdict.span, verdict.whole_span = (start, stop), (float(t_ref[0]), float(t_ref[-1]))
    mapping, _ = match_columns(list(reference), [str(c) for c in traces])
    if signals:
        unknown = [s for s in signals if s not in reference]
        if unknown:
            raise ValueError(f"--signals {', '.join(unknown)}: not a signal of the reference (its signals: "
                             f"{', '.join(reference)})")
        absent = [s for s in signals if s not in mapping]
        if absent:
            raise ValueError(f"--signals {', '.join(absent)}: not in the result (its columns: "
                             f"{', '.join(map(str, traces)) or 'none'})")
        mapping = {s: mapping[s] for s in signals}
    if not mapping:
        raise NothingToJudge(f"the result has none of the reference's signals ({', '.join(reference)}); its columns: "
                             f"{', '.join(map(str, traces)) or 'none'} (a scene's signals are component.variable)")
    verdict.not_judged = [s for s in reference if s not in mapping]
    verdict.chosen = bool(signals)
    extra = sorted(set(map(str, traces)) - set(match_columns(list(reference), [str(c) for c in traces])[0].values()))
    if extra:
        verdict.notes.append("not in the reference (not compared): " + ", ".join(extra))
    unknown_targets = rtol.unknown_targets(list(reference))
    if unknown_targets:
        raise ValueError(f"tolerance for {', '.join(unknown_targets)}: neither a signal of the reference nor a kind "
                         f"(kinds: {', '.join(KINDS)}; signals: {', '.join(reference)})")
    if len(t) < 2:
        verdict.problems.append(f"the result has {len(t)} sample(s); at least two are needed")
        return verdict
    if not np.all(np.isfinite(t)) or np.any(np.diff(t) < 0):
        verdict.problems.append("the result's time column is not finite and increasing")
        return verdict
    verdict.problems += span_problems(t, start, stop)
    slack = 1e-9 * max(1.0, abs(stop))
    keep = (t_ref >= steady_start - slack) & (t_ref <= stop + slack)
    early = (t_ref >= start - slack) & (t_ref < steady_start - slack)
    steady = np.count_nonzero(keep) >= 2
    if not steady and np.count_nonzero(early) < 2:
        verdict.problems.append(f"the window t = {start:g} ... {stop:g} s holds {np.count_nonzero(keep | early)} "
                                "of the reference's samples; at least two are needed")
        return verdict
    if steady:
        verdict.window = (steady_start, stop)
        verdict.transient = (start, steady_start) if np.count_nonzero(early) >= 2 else None
        rotation, orders_said = _rotation(reference, t_ref, keep, rotation_signal)
    else:       # the span ends before the start-up transient does: its tube alone judges it
        keep, early = early | keep, np.zeros_like(keep)
        verdict.transient = (start, stop)
        rotation, orders_said = None, "no rotation orders, no mean, no ripple amplitude: the span is start-up only"
        verdict.notes.append(f"the span judged, t = {start:g} ... {stop:g} s, ends before the start-up transient does "
                             f"(t = {float(transient):g} s): judged by the start-up's tube only")
    verdict.rotation = rotation
    if verdict.problems:
        return verdict
    # the result's samples in the span and one beyond each end (the tube looks one step aside)
    low = max(int(np.searchsorted(t, start - slack, "left")) - 1, 0)
    high = min(int(np.searchsorted(t, stop + slack, "right")) + 1, len(t))
    t_res = t[low:high]
    judged_from = float(t_ref[keep][0])
    grid = t_res[(t_res >= judged_from - slack - _step_at(t, judged_from))
                 & (t_res <= stop + slack + _step_at(t, stop))]
    for signal, column in mapping.items():
        y_all = np.asarray(reference[signal], dtype=float)
        y_res = np.asarray(traces[column], dtype=float)
        verdict.problems += value_problems(signal, t, y_res, y_all)
        y_res = y_res[low:high]
        tolerances = rtol.of(signal, kinds.get(signal, "other"))
        magnitude = float(np.max(np.abs(y_all[np.isfinite(y_all)]), initial=0.0))
        frame = _frame(t_ref[keep], y_all[keep], rotation, magnitude)
        if steady:
            def judged(t_result, y_result, frame=frame, tolerances=tolerances):
                return _checks(frame, t_result, y_result, tolerances)
        else:
            def judged(t_result, y_result, frame=frame, tolerances=tolerances):
                return [_start_up_tube(frame.t, frame.y, t_result, y_result, tolerances, frame.magnitude)]
        checks = judged(t_res, y_res)
        if verdict.transient and steady:
            part = early | (t_ref == t_ref[keep][0])
            checks.append(_start_up_tube(t_ref[part], y_all[part], t_res, y_res, tolerances, magnitude))
        error = np.interp(frame.t, t_res, y_res) - frame.y
        finite = bool(np.all(np.isfinite(error)))
        sv = SignalVerdict(signal, column, kinds.get(signal, "other"), tolerances, checks,
                           power(frame, judged, t_ref, y_all, grid, tolerances, rotation) if with_power and finite
                           else None,
                           float(np.sqrt(np.mean(error ** 2))) if finite else math.inf,
                           float(np.max(np.abs(error))) if finite else math.inf)
        verdict.signals.append(sv)
    verdict.blind_spots = blind_spots(verdict, t_ref[keep], t_res, orders_said)
    return verdict


def _start_up_tube(t_part: np.ndarray, y_part: np.ndarray, t_res: np.ndarray, y_res: np.ndarray, rtol: dict,
                   magnitude: float) -> Check:
    """The start-up transient's tube: as wide as the tube's tolerance of its own range."""
    width = rtol["tube"][0] * _allowed_scale(float(np.ptp(y_part)), float(np.mean(y_part)), magnitude=magnitude)
    return _tube("transient tube", t_part, y_part, t_res, y_res, width, rtol["tube"][0])


def _step_at(t: np.ndarray, at: float) -> float:
    """The result's step around time ``at``."""
    i = int(np.clip(np.searchsorted(t, at), 1, len(t) - 1))
    return float(t[i] - t[i - 1])


def blind_spots(verdict: Verdict, t_window: np.ndarray, t_res: np.ndarray, orders_said: str) -> str:
    """One sentence: what the verdict cannot see on this reference and result."""
    dt_ref = float(np.median(np.diff(t_window)))
    dt_res = float(np.median(np.diff(t_res)))
    dt = max(dt_ref, dt_res)
    whose = "the reference's" if dt_ref >= dt_res else "the result's"
    said = [f"anything faster than {math.pi / dt:.3g} rad/s (half the sampling rate of {whose} {dt:.3g} s samples, "
            "which are what is compared)"]
    if verdict.window and verdict.transient:
        said.append(f"before t = {verdict.window[0]:g} s, anything but a departure from the start-up's tube")
    elif verdict.window and verdict.window[0] > t_window[0]:
        said.append(f"anything before t = {verdict.window[0]:g} s (not judged)")
    said.append(orders_said if orders_said.startswith("no rotation") else
                "a rotation order smaller than a tenth of the ripple amplitude (not judged)")
    said.append("a change smaller than the power stated beside each signal")
    if verdict.not_judged:
        said.append(f"the {len(verdict.not_judged)} signal(s) not judged")
    return "cannot see: " + "; ".join(said)


@dataclass
class ReferenceSettings:
    """What a reference's scene (or FMU) tells the verdict: where its start-up transient
    ends, each signal's kind, the driven shaft's speed, and its ``[validation]`` tolerances."""
    transient: float | None
    kinds: dict
    rotation_signal: str | None
    rules: list


def settings_of(reference) -> ReferenceSettings:
    """``ReferenceSettings`` of a committed reference (``reference_traces.ReferenceTraces``):
    a scene's from its scene file (the transient from its start, ``scene_kinds.roles`` for the
    driven shaft), an FMU's from its model description (no transient, no shaft)."""
    from fmpy import read_model_description

    from harness.description import plan, scene_kinds
    from harness.description import scene as scenes
    from harness.paths import FMUS

    signals = list(reference.outputs.signals)
    if reference.kind == "fmu":
        path = FMUS / f"{reference.name}.fmu"
        units = {}
        if path.exists():
            units = {v.name: v.unit or (v.declaredType.unit if v.declaredType else None)
                     for v in read_model_description(str(path)).modelVariables}
        return ReferenceSettings(None, {s: kind_of_unit(units.get(s)) for s in signals}, None, [])
    scene = scenes.load(reference.name)
    descriptions = plan.descriptions_for(scene)
    kinds = {}
    for signal in signals:
        component, _, variable = signal.partition(".")
        spec = scene.components.get(component)
        description = descriptions.get(spec.fmu) if spec else None
        var = next((v for v in description.modelVariables if v.name == variable), None) if description else None
        unit = (var.unit or (var.declaredType.unit if var.declaredType else None)) if var else None
        kinds[signal] = kind_of_unit(unit)
    load = scene_kinds.roles(scene)[2]
    rotation = f"{load}.w" if load and f"{load}.w" in signals else None
    try:
        rules = rules_from_table(scene.validation, f"scene file ({scene.path.name if scene.path else scene.name})")
    except ValueError as error:
        raise ValueError(f"scene {scene.name}: [validation] {error}") from None
    return ReferenceSettings(scene.experiment.start + scene.experiment.transient, kinds, rotation, rules)
