"""Judging a result against a reference trace: pure functions returning findings.

The tolerance band is the FMI cross-check convention, as ``fmpy.util.validate_signal``
implements it (reimplemented here, so that the band can be drawn and its figures set;
``tests/judges/test_validate.py`` checks that with the cross-check's figures it gives exactly
fmpy's band and outliers):

1. the reference is resampled linearly onto ``num`` uniformly spaced points over its span;
2. a horizontal tolerance: running minimum and maximum over ``dx`` neighbouring points;
3. a vertical tolerance ``w = dy * (max - min)`` of the resampled reference (for a constant
   reference ``dy * |value|``, or 0.5 when it is zero) added below and above;
4. a result sample strictly inside the band's time span is an outlier when it lies outside
   the band interpolated linearly at its time; the fraction of outliers is judged.

Two sets of figures (``TOLERANCES``):

* ``cross-check``: fmpy's own (1000 points, ``dx`` = 20, ``dy`` = 0.1, fail above 10 %
  outliers).  Its horizontal tolerance is 2 % of the span: on a 10 s scene that is 0.2 s,
  more than two periods of the coupling's torque ripple, so the band is the ripple's
  envelope and cannot tell a changed ripple from the right one.
* ``lever`` (default): ``dy`` = 1 % of the signal's range, no sample outside allowed, and
  the horizontal tolerance of one step *of the result*, judged at the reference's samples:
  a reference sample ``(t, y_ref)`` is matched when the result, over its samples next to
  ``t`` (one either side when ``t`` is a result sample, else the two around it), comes
  within ``w`` of ``y_ref``.  This is the cross-check's band with the roles of the two
  curves exchanged, so that it works for references kept at every k-th step (a 10 s scene
  keeps 1000 rows, not one per communication step): the band must be built on the finer
  curve.  One step is what an importer that reads an output depending on an input before
  it sets the step's inputs is late by - fmpy's ``simulate_fmu`` with a feedthrough FMU,
  the harness's recorded shaft accelerations - and what a variable-step result leaves
  unknown between its samples.

With a reference kept at every k-th step, the ``cross-check`` figures judge the result's
samples between two reference samples against the straight line between them: content
faster than the reference's sampling (the load's tones up to 450 rad/s against a 10 ms
grid) puts some correct samples outside - one more reason for the ``lever`` figures.

Besides the band, every signal gets its RMS and maximum error at the reference's samples
(the result interpolated linearly there), whichever figures judge it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


class TooSparse(ValueError):
    """A result whose samples are further apart than the band can judge: what lies between
    them is never compared, so no verdict can be given."""


@dataclass(frozen=True)
class Tolerance:
    name: str
    #: vertical tolerance, relative to the reference's range over the span
    dy: float
    #: largest fraction of compared samples allowed outside the band
    max_outside: float
    #: the cross-check band's points over the span and running window (in points);
    #: None: the ``lever`` judging (one result step, at the reference's samples)
    num: int | None = None
    dx: int | None = None

    @property
    def cross_check(self) -> bool:
        return self.num is not None

    def describe(self) -> str:
        if self.cross_check:
            how = (f"band on {self.num} points, horizontal {self.dx} points, judged at the result's samples")
        else:
            how = "horizontal one result step, judged at the reference's samples"
        return (f"{self.name}: vertical {100 * self.dy:g} % of each signal's range, {how}, "
                f"at most {100 * self.max_outside:g} % outside")


TOLERANCES = {
    "lever": Tolerance("lever", dy=0.01, max_outside=0.01),
    "cross-check": Tolerance("cross-check", dy=0.1, max_outside=0.1, num=1000, dx=20),
}


@dataclass
class Band:
    """A tolerance band to draw: ``low ... high`` at times ``t``."""
    t: np.ndarray
    low: np.ndarray
    high: np.ndarray
    width: float      # the vertical tolerance w


@dataclass
class SignalFinding:
    name: str
    rms_error: float
    max_error: float
    #: time of the largest error
    max_error_time: float
    fraction_outside: float
    n_compared: int
    band_width: float
    passed: bool
    #: why it failed, in words (empty when it passed)
    problem: str = ""
    #: times of the samples outside the band (for plots; the first 5000)
    outside_times: list = field(default_factory=list, repr=False)


class JudgedSpan:
    """What every verdict on a result says of it as a whole, from its ``signals`` (each with
    ``name`` and ``passed``), ``problems`` and the ``span``/``whole_span`` it judged.  Each
    kind says which it is (``KIND``: ``lever validate --tolerance``'s name for it), what its
    signal count means and why a signal failed, in a line each."""
    KIND = ""

    def counted(self) -> str:
        """"10 signals judged, 8 pass" - what the verdict counts, in its own words."""
        raise NotImplementedError

    def failure_line(self, signal) -> str:
        """Why ``signal`` failed, in one line."""
        raise NotImplementedError

    def describe_span(self) -> str:
        return describe_span(self.span, self.whole_span)

    @property
    def passed(self) -> bool:
        return not self.problems and all(s.passed for s in self.signals)

    @property
    def failed_signals(self) -> list[str]:
        return [s.name for s in self.signals if not s.passed]


@dataclass
class Findings(JudgedSpan):
    """The verdict on one result: per signal, and about the result as a whole."""
    name: str
    tolerance: Tolerance
    signals: list[SignalFinding] = field(default_factory=list)
    #: problems that fail the whole result (missing signals, span not covered, ...)
    problems: list[str] = field(default_factory=list)
    #: remarks that do not fail it (columns the reference does not have, ...)
    notes: list[str] = field(default_factory=list)
    #: the span judged [s] and the reference's whole span (``compare_span``; None: not said)
    span: tuple[float, float] | None = None
    whole_span: tuple[float, float] | None = None

    KIND = "cross-check"

    def counted(self) -> str:
        within = sum(s.passed for s in self.signals)
        return f"{len(self.signals)} signals, {within} within the band ({self.tolerance.describe()})"

    def failure_line(self, s) -> str:
        return (f"{100 * s.fraction_outside:.3g} % of the samples outside +-{s.band_width:.4g}, max error "
                f"{s.max_error:.4g} at t = {s.max_error_time:.4g} s")

    def to_dict(self) -> dict:
        return {"name": self.name, "passed": self.passed, "tolerance": self.tolerance.describe(),
                "span_s": list(self.span) if self.span else None,
                "reference_span_s": list(self.whole_span) if self.whole_span else None,
                "problems": list(self.problems), "notes": list(self.notes),
                "signals": {s.name: {k: _json_number(v) for k, v in vars(s).items() if k not in ("name", "outside_times")}
                            for s in self.signals}}


def describe_span(span, whole) -> str:
    """"t = 0 ... 1 s of the reference's 0 ... 10 s" (or "the reference's whole span, ...")."""
    if span is None:
        return ""
    if whole is None or tuple(span) == tuple(whole):
        return f"the reference's whole span, t = {span[0]:g} ... {span[1]:g} s"
    return f"t = {span[0]:g} ... {span[1]:g} s of the reference's {whole[0]:g} ... {whole[1]:g} s"


def _json_number(value):
    """A value as JSON holds it: a NaN or infinite error (nothing compared, a non-finite
    result) as null, which JSON readers take, not Python's NaN/Infinity, which they refuse."""
    return None if isinstance(value, float) and not math.isfinite(value) else value


def _width(values: np.ndarray, dy: float) -> float:
    low, high = float(np.min(values)), float(np.max(values))
    if low == high:
        return 0.5 if low == 0 else abs(low) * dy
    return (high - low) * dy


def band(t_ref: np.ndarray, y_ref: np.ndarray, num: int = 1000, dx: int = 20, dy: float = 0.1) -> Band:
    """The cross-check's band around ``y_ref(t_ref)``: ``num`` uniform points over the
    reference's span, running min/max over ``dx`` points, widened by ``dy`` times the range."""
    from scipy.ndimage import maximum_filter1d, minimum_filter1d

    t_ref = np.array(t_ref, dtype=float)
    y_ref = np.asarray(y_ref, dtype=float)
    t_band = np.linspace(t_ref[0], t_ref[-1], num)
    # duplicate sample times (an event): the later sample 1e-13 s later, as fmpy does
    for i in range(1, len(t_ref)):
        while t_ref[i - 1] >= t_ref[i]:
            t_ref[i] += 1e-13
    y_band = np.interp(t_band, t_ref, y_ref)
    width = _width(y_band, dy)
    return Band(t_band, minimum_filter1d(y_band, size=dx) - width, maximum_filter1d(y_band, size=dx) + width, width)


def outside(t: np.ndarray, y: np.ndarray, b: Band) -> np.ndarray:
    """Which samples ``y(t)`` lie outside band ``b`` (only samples strictly inside the
    band's time span count, as in the cross-check; a non-finite value is outside)."""
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    low = np.interp(t, b.t, b.low)
    high = np.interp(t, b.t, b.high)
    out = (y < low) | (y > high) | ~np.isfinite(y)
    return out & (t > b.t[0]) & (t < b.t[-1])


def result_window(t: np.ndarray, y: np.ndarray, at: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The result's smallest and largest value over one of its steps around each time in
    ``at``: its samples before, at and after ``at`` when ``at`` is a sample, else the two
    around it.  (Times outside the result's span get its first or last sample.)"""
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    n = len(t)
    slack = 1e-9 * max(1.0, float(np.max(np.abs(t))))
    right = np.clip(np.searchsorted(t, at - slack, side="left"), 0, n - 1)   # first sample >= at
    hit = np.abs(t[right] - at) <= slack
    lo_index = np.clip(right - 1, 0, n - 1)
    hi_index = np.clip(np.where(hit, right + 1, right), 0, n - 1)
    stack = np.stack([y[lo_index], y[right], y[hi_index]])
    return np.min(stack, axis=0), np.max(stack, axis=0)


def compare_signal(name: str, t: np.ndarray, y: np.ndarray, t_ref: np.ndarray, y_ref: np.ndarray,
                   tolerance: Tolerance, scale: np.ndarray | None = None) -> tuple[SignalFinding, Band]:
    """One signal against its reference: errors, fraction outside the band, verdict.
    ``scale``: the values whose range sets the ``lever`` band's width (default ``y_ref``;
    a window passes the whole reference, so that it is judged by the same band)."""
    t, y = np.asarray(t, dtype=float), np.asarray(y, dtype=float)
    t_ref, y_ref = np.asarray(t_ref, dtype=float), np.asarray(y_ref, dtype=float)
    slack = 1e-9 * max(1.0, abs(float(t_ref[-1])))
    # errors at the reference's samples in the result's span (the result interpolated there)
    covered = (t_ref >= t[0] - slack) & (t_ref <= t[-1] + slack)
    t_cmp, y_true = t_ref[covered], y_ref[covered]
    y_cmp = np.interp(t_cmp, t, y)
    if tolerance.cross_check:
        b = band(t_ref, y_ref, tolerance.num, tolerance.dx, tolerance.dy)
        flags_at, flags = t, outside(t, y, b)
        n = len(t)                       # the cross-check divides by all result samples
    else:
        width = _width(y_ref if scale is None else np.asarray(scale, dtype=float), tolerance.dy)
        low, high = result_window(t, y, t_cmp)
        flags = (y_true < low - width) | (y_true > high + width) | ~np.isfinite(low) | ~np.isfinite(high)
        flags_at = t_cmp
        b = Band(t_ref, y_ref - width, y_ref + width, width)
        n = len(t_cmp)
    with np.errstate(over="ignore", invalid="ignore"):     # an absurd sample's error is inf, counted below
        error = y_cmp - y_true
    finite = np.isfinite(error)
    if len(error) and finite.all():
        i = int(np.argmax(np.abs(error)))
        peak, peak_time = float(abs(error[i])), float(t_cmp[i])
        # scaled by the peak: an absurd sample's square would overflow where its RMS does not
        rms = peak * float(np.sqrt(np.mean((error / peak) ** 2))) if peak > 0 else 0.0
    elif len(error):
        rms = peak = math.inf
        peak_time = float(t_cmp[np.flatnonzero(~finite)[0]])
    else:
        rms = peak = peak_time = math.nan
    fraction = float(np.count_nonzero(flags)) / n if n else 1.0
    passed = bool(n) and fraction <= tolerance.max_outside
    problem = ""
    if not n:
        problem = "no sample inside the reference's span"
    elif not passed:
        first = float(flags_at[np.flatnonzero(flags)[0]])
        problem = (f"{100 * fraction:.3g} % of the samples outside the band (allowed "
                   f"{100 * tolerance.max_outside:g} %), the first at t = {first:.6g} s")
    outside_times = [float(x) for x in flags_at[flags][:5000]]
    return SignalFinding(name, rms, peak, peak_time, fraction, n, b.width, passed, problem, outside_times), b


def match_columns(reference_names: list[str], result_names: list[str], said: bool = False):
    """Which result column carries each reference signal: the same name, or else the one
    column another tool names it by - ``<anything>.<name>`` (a single FMU's variables, e.g.
    ``coupling.tau1`` for ``tau1``; a model's prefix, ``kavz685.engine.w``), or the name with
    its dots as underscores, alone or after a prefix (``engine_w``, as a container FMU names
    its outputs).  Returns the mapping and the unmatched names (``said``: and the columns
    matched by another naming, "engine_w as engine.w")."""
    mapping, missing, matched = {}, [], []
    flat = {c: c.replace(".", "_") for c in result_names}
    for name in reference_names:
        if name in result_names:
            mapping[name] = name
            continue
        under = name.replace(".", "_")
        for rule in (lambda c: c.endswith("." + name), lambda c: flat[c] == under,
                     lambda c: flat[c].endswith("_" + under)):
            found = [c for c in result_names if rule(c) and c not in mapping.values()]
            if len(found) == 1:
                mapping[name] = found[0]
                matched.append(f"{found[0]} as {name}")
                break
        else:
            missing.append(name)
    return (mapping, missing, matched) if said else (mapping, missing)


#: a result sample beyond this many times the reference's largest magnitude (plus 1) is no
#: physical value of the signal, whatever the band says (a band forgives a sample its
#: neighbours bracket, and an RMS error of 1e300 overflows)
ABSURD = 1e6


def value_problems(signal: str, times: np.ndarray, values: np.ndarray, reference: np.ndarray) -> list[str]:
    """Problems that fail a result whatever its band: a NaN or infinite sample, or a sample
    absurdly far from anything the reference holds (``ABSURD``)."""
    problems = []
    finite = np.isfinite(values)
    if not finite.all():
        bad = np.flatnonzero(~finite)
        problems.append(f"signal '{signal}' has {len(bad)} non-finite value(s) ({values[bad[0]]} at t = "
                        f"{times[bad[0]]:.6g} s): a result with NaN or inf fails")
    scale = ABSURD * (float(np.max(np.abs(reference[np.isfinite(reference)]), initial=0.0)) + 1.0)
    absurd = finite & (np.abs(np.where(finite, values, 0.0)) > scale)
    if absurd.any():
        first = int(np.flatnonzero(absurd)[0])
        problems.append(f"signal '{signal}' has {int(absurd.sum())} sample(s) beyond {scale:.3g} "
                        f"({ABSURD:g} x the reference's largest magnitude + 1), e.g. {values[first]:.6g} at t = "
                        f"{times[first]:.6g} s: no value of this signal")
    return problems


def span_problems(times: np.ndarray, start: float, stop: float) -> list[str]:
    """What the result's time span (sorted ``times``) leaves out of ``start ... stop``: a
    result that starts late or ends early, saying how much of the span it covers, or one
    whose times miss the span altogether."""
    slack = 1e-9 * max(1.0, abs(start), abs(stop))
    first, last = float(times[0]), float(times[-1])
    if first > stop + slack or last < start - slack:
        return [f"the result's times {first:.6g} ... {last:.6g} s do not overlap the span {start:g} ... {stop:g} s "
                "it is to be judged over: nothing to compare (a time column shifted, or another run's?)"]
    problems = []
    span = stop - start
    covered = (min(last, stop) - max(first, start)) / span if span > 0 else 1.0
    share = f"it covers {max(0.0, min(1.0, covered)):.1%} of {start:g} ... {stop:g} s"
    if first > start + slack:
        problems.append(f"the result starts at t = {first:.6g} s, after the start time ({start:g} s): {share}")
    if last < stop - slack:
        problems.append(f"the result ends at t = {last:.6g} s, before the stop time ({stop:g} s): {share}; "
                        "a window, --window START:STOP, judges a part of the span")
    return problems


def compare(name: str, times: np.ndarray, traces: dict[str, np.ndarray], reference_times: np.ndarray,
            reference: dict[str, np.ndarray], tolerance: Tolerance = TOLERANCES["lever"],
            start: float | None = None, stop: float | None = None,
            scales: dict[str, np.ndarray] | None = None) -> tuple[Findings, dict[str, Band]]:
    """Every signal of ``reference`` against the result ``traces`` (both by name, on their own
    time grids).  The result must cover ``start ... stop`` (default: the reference's span).
    Returns the findings and the band of each compared signal (for plots)."""
    findings = Findings(name, tolerance)
    bands: dict[str, Band] = {}
    times = np.asarray(times, dtype=float)
    reference_times = np.asarray(reference_times, dtype=float)
    start = float(reference_times[0]) if start is None else float(start)
    stop = float(reference_times[-1]) if stop is None else float(stop)
    if len(times) < 2:
        findings.problems.append(f"the result has {len(times)} sample(s); at least two are needed")
        return findings, bands
    if not np.all(np.isfinite(times)):
        bad = int(np.flatnonzero(~np.isfinite(times))[0])
        findings.problems.append(f"the result's time column has a non-finite value ({times[bad]}) in row {bad + 1}")
        return findings, bands
    if np.any(np.diff(times) < 0):
        findings.problems.append("the result's time column is not monotonic")
        return findings, bands
    findings.problems += span_problems(times, start, stop)
    if tolerance.cross_check:
        _dense_enough(times, start, stop, tolerance)
    mapping, missing = match_columns(list(reference), list(traces))
    for signal in missing:
        findings.problems.append(f"signal '{signal}' is missing from the result")
    extra = sorted(set(traces) - set(mapping.values()))
    if extra:
        findings.notes.append("not in the reference (not compared): " + ", ".join(extra))
    for signal, column in mapping.items():
        findings.problems += value_problems(signal, times, np.asarray(traces[column], dtype=float),
                                            np.asarray(reference[signal], dtype=float))
        finding, b = compare_signal(signal, times, traces[column], reference_times, reference[signal], tolerance,
                                    None if scales is None else scales.get(signal))
        findings.signals.append(finding)
        bands[signal] = b
    if tolerance.cross_check and findings.signals:
        findings.notes.append(cross_check_blind_spot(tolerance, reference_times, findings.signals))
    return findings, bands


def _dense_enough(times: np.ndarray, start: float, stop: float, tolerance: Tolerance):
    """``TooSparse`` when the result's longest step inside ``start ... stop`` is longer than
    the band's horizontal tolerance: the band judges the result's samples only, and a result
    that holds its values over a longer step is judged at next to none of its span."""
    window = tolerance.dx * (stop - start) / (tolerance.num - 1)
    inside = times[(times >= start) & (times <= stop)]
    edges = np.concatenate([[start], inside, [stop]])
    longest = float(np.max(np.diff(edges)))
    if longest > window:
        i = int(np.argmax(np.diff(edges)))
        raise TooSparse(f"the result is too sparse for the {tolerance.name} band: its samples at t = {edges[i]:.6g} "
                        f"and {edges[i + 1]:.6g} s are {longest:.3g} s apart, more than the band's horizontal "
                        f"tolerance, {window:.3g} s ({tolerance.dx} of its {tolerance.num} points over "
                        f"{start:g} ... {stop:g} s): what lies between is never compared")


def cross_check_blind_spot(tolerance: Tolerance, reference_times: np.ndarray, signals: list[SignalFinding]) -> str:
    """What the cross-check band can and cannot see on this reference: its running window
    makes it the envelope of anything with a period shorter than the window, and its margin
    hides any change smaller than the margin."""
    span = float(reference_times[-1] - reference_times[0])
    window = tolerance.dx * span / (tolerance.num - 1)
    margins = ", ".join(f"{s.name} +-{s.band_width:.3g}" for s in signals)
    return (f"what the {tolerance.name} band can see: it follows the reference through a running window of "
            f"{window:.3g} s ({tolerance.dx} of {tolerance.num} points over the span), so anything with a shorter "
            f"period (above {2 * math.pi / window:.3g} rad/s: a shaft's rotation, a load's tones) is judged only "
            f"against its envelope - a ripple of another phase, frequency or shape passes; and its margin "
            f"({100 * tolerance.dy:g} % of each signal's range: {margins}) passes any change smaller than that. "
            "It sees a mean or a slow motion moved by more than the margin; the default 'lever' figures judge "
            "the ripple")


def compare_span(name: str, times: np.ndarray, traces: dict[str, np.ndarray], reference_times: np.ndarray,
                 reference: dict[str, np.ndarray], tolerance: Tolerance, start: float, stop: float,
                 whole: tuple[float, float] | None = None) -> tuple[Findings, dict[str, Band]]:
    """``compare`` over ``start ... stop`` [s], a window of the reference's span ``whole``
    (default: the reference's first and last time): only the reference's samples in the
    window are judged, the result needs to cover the window only, and the findings say
    which span was judged.  The ``lever`` band keeps the width it has over the whole
    reference (a window judges fewer samples, not by a narrower band); the cross-check's
    band is built over the window, as the cross-check builds it over what it is given."""
    t_ref = np.asarray(reference_times, dtype=float)
    scales = None
    whole = (float(t_ref[0]), float(t_ref[-1])) if whole is None else (float(whole[0]), float(whole[1]))
    start, stop = float(start), float(stop)
    if (start, stop) != whole:
        slack = 1e-9 * max(1.0, abs(stop))
        keep = (t_ref >= start - slack) & (t_ref <= stop + slack)
        if np.count_nonzero(keep) < 2:
            findings = Findings(name, tolerance, span=(start, stop), whole_span=whole)
            findings.problems.append(f"the window t = {start:g} ... {stop:g} s holds {np.count_nonzero(keep)} of "
                                     "the reference's samples; at least two are needed")
            return findings, {}
        scales = reference
        reference = {k: np.asarray(v, dtype=float)[keep] for k, v in reference.items()}
        t_ref = t_ref[keep]
        t = np.asarray(times, dtype=float)
        if len(t) >= 2 and np.all(np.isfinite(t)) and np.all(np.diff(t) >= 0):
            # the result's samples in the window and one beyond each end: the band's
            # horizontal tolerance looks one result step to either side
            low = max(int(np.searchsorted(t, start - slack, "left")) - 1, 0)
            high = min(int(np.searchsorted(t, stop + slack, "right")) + 1, len(t))
            times, traces = t[low:high], {k: np.asarray(v)[low:high] for k, v in traces.items()}
    findings, bands = compare(name, times, traces, t_ref, reference, tolerance, start, stop, scales)
    findings.span, findings.whole_span = (start, stop), whole
    return findings, bands


def fmpy_max_outside(times: np.ndarray, traces: dict, reference_times: np.ndarray, reference: dict) -> float:
    """fmpy's own verdict, ``fmpy.util.validate_result``: the largest fraction of samples
    outside the cross-check band over all signals (for comparison with ours)."""
    from fmpy.util import validate_result

    names = [n for n in reference if n in traces]
    as_array = lambda t, cols: np.rec.fromarrays([np.asarray(t, float)] + [np.asarray(cols[n], float) for n in names],
                                                 names=["time"] + names)
    return float(validate_result(as_array(times, traces), as_array(reference_times, reference)))
