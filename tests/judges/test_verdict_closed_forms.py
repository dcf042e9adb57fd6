"""The verdict (harness/judges/verdict.py) held to closed forms on synthetic traces.

The reference is a sum of rotation orders of a shaft turning at a constant speed, the
result the same sum changed in one known way, sampled at the reference's own times (so
what is judged is the change, whatever the verdict's sampling).  What each check must
find follows by hand:

* an order whose phase turns by d while its magnitude stays is off by |e^(i d) - 1| =
  2 sin(d / 2) of its component: it fails beyond the order tolerance, whatever its
  magnitude says, and the check states the magnitude unchanged and the phase turned;
* an order scaled by (1 + e) is off by |e| of its component;
* the mean is the time average: over the window's whole revolutions it is MEAN exactly (the
  trapezoid rule sums each order's cosine over whole periods to zero), not the row average
  (which counts both ends' samples in full), and the mean allowed is ``rtol.mean`` of
  max(|MEAN|, ripple amplitude); the ripple amplitude is allowed ``rtol.amplitude`` of the
  reference's plus the reference's own interpolation error, so the smallest failing mean
  shift and ripple scaling are those;
* a time shift s turns order k by k w s: with the orders alone binding, the smallest
  failing shift is 2 asin(rtol / 2) / (k w) for the highest leading order k, its phase at
  the rotation w s.

The power stated is found by bisection: it fails, and lies at most ``power.RESOLUTION`` of
itself above the smallest change that fails, so it is checked in [x, x / (1 - RESOLUTION)]
for the closed form x.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from harness.judges import verdict as verdicts
from harness.judges.power import RESOLUTION

#: the driven shaft's speed [rad/s]: 5 revolutions a second, 10 in the 2 s window
W = 2 * math.pi * 5.0
T = np.linspace(0.0, 2.0, 4001)
MEAN = 100.0
#: order -> (magnitude, phase [rad]) of the reference's torque; all leading (>= 0.1 of the ripple)
ORDERS = {1: (6.0, 0.3), 2: (2.5, -1.1), 3: (1.5, 2.0)}


def _stated(power, smallest, slack=0.0):
    """The power found by bisection against the closed-form smallest failing change: at or
    above it, at most RESOLUTION of itself above (``slack``: a relative error of ``smallest``)."""
    return smallest * (1 - slack) <= power <= smallest * (1 + slack) / (1 - RESOLUTION)


def _torque(t, orders=ORDERS, mean=MEAN):
    return mean + sum(a * np.cos(k * W * t + p) for k, (a, p) in orders.items())


def _judge(result, rtol=None, speed=None, with_power=False, **kwargs):
    reference = {"coupling.tau2": _torque(T), "load.w": np.full_like(T, W)}
    traces = {"coupling.tau2": result, "load.w": np.full_like(T, W) if speed is None else speed}
    return verdicts.judge(T, traces, T, reference, rotation_signal="load.w", rtol=rtol,
                          kinds={"coupling.tau2": "torque", "load.w": "speed"}, with_power=with_power, **kwargs)


def _signal(verdict, name="coupling.tau2"):
    return next(s for s in verdict.signals if s.name == name)


def _check(signal, quantity):
    return next(c for c in signal.checks if c.quantity == quantity)


def test_the_orders_judged_are_the_leading_ones_at_their_magnitudes():
    verdict = _judge(_torque(T))
    assert verdict.passed and verdict.rotation == pytest.approx(W, rel=1e-12)
    tau = _signal(verdict)
    judged = {c.quantity: c for c in tau.checks if c.quantity.startswith("order")}
    assert set(judged) == {"order 1", "order 2", "order 3"}
    for k, (a, _) in ORDERS.items():
        assert judged[f"order {k}"].reference == pytest.approx(a, rel=0.01)
        assert judged[f"order {k}"].difference == pytest.approx(0.0, abs=1e-9)
        assert judged[f"order {k}"].allowed == pytest.approx(verdicts.DEFAULT_RTOL["order"] * a, rel=0.01)
    # a constant speed's orders are the FFT's round-off: judged against the noise floor
    # (NOISE_FLOOR of its magnitude), so a result off by round-off passes
    noisy = _judge(_torque(T), speed=W * (1 + 1e-12 * np.sin(W * T + 0.4)))
    assert noisy.passed, noisy.failures()
    for check in _signal(noisy, "load.w").checks:
        if check.quantity.startswith("order"):
            assert check.allowed == pytest.approx(verdicts.DEFAULT_RTOL["order"] * verdicts.NOISE_FLOOR * W)



@pytest.mark.parametrize("orders,judged", [
    ({**ORDERS, 4: (0.5, 0.0)}, {1, 2, 3}),     # order 4 below a tenth of the ripple (at least 6), above the floor
    ({1: (0.05, 0.3), 2: (0.02, -1.1)}, set()),  # both leading, below the noise floor (1e-3 of 100.07: 0.1)
])
def test_an_order_is_judged_when_it_leads_the_ripple_and_stands_above_the_noise_floor(orders, judged):
    reference = {"coupling.tau2": _torque(T, orders), "load.w": np.full_like(T, W)}
    verdict = verdicts.judge(T, reference, T, reference, rotation_signal="load.w", with_power=False,
                             kinds={"coupling.tau2": "torque", "load.w": "speed"})
    assert {int(c.quantity.split()[1]) for c in _signal(verdict).checks if c.quantity.startswith("order")} == judged

@pytest.mark.parametrize("degrees", [2.0, -2.0, 4.0, -4.0, 10.0])
def test_a_turned_order_fails_by_its_phase_alone(degrees):
    turned = dict(ORDERS)
    a, p = ORDERS[2]
    turned[2] = (a, p + math.radians(degrees))
    tau = _signal(_judge(_torque(T, turned)))
    order = _check(tau, "order 2")
    off = 2 * math.sin(math.radians(abs(degrees)) / 2)           # |e^(i d) - 1|
    assert order.result == pytest.approx(order.reference, rel=1e-3)     # the magnitude is unchanged
    assert order.difference / order.reference == pytest.approx(off, rel=0.01)
    assert order.passed == (off <= verdicts.DEFAULT_RTOL["order"])
    assert f"phase {degrees:+.2g} deg" in order.detail
    for k in (1, 3):
        assert _check(tau, f"order {k}").passed
    assert tau.passed == order.passed


@pytest.mark.parametrize("scale", [0.97, 1.03, 0.94, 1.06])
def test_a_scaled_order_fails_by_its_magnitude(scale):
    scaled = dict(ORDERS)
    a, p = ORDERS[3]
    scaled[3] = (a * scale, p)
    order = _check(_signal(_judge(_torque(T, scaled))), "order 3")
    assert order.difference / order.reference == pytest.approx(abs(scale - 1), rel=0.01)
    assert order.result / order.reference == pytest.approx(scale, rel=1e-3)
    assert order.passed == (abs(scale - 1) <= verdicts.DEFAULT_RTOL["order"])


def test_the_mean_and_the_amplitude_are_judged_against_their_closed_form_allowances():
    amplitude = (np.ptp(_torque(T))) / 2
    # the time average over whole revolutions, MEAN; the rows' average would be 100.0016 and allow 1.6e-5 more
    allowed_mean = verdicts.DEFAULT_RTOL["mean"] * max(MEAN, amplitude)
    for shift, passes in ((0.9 * allowed_mean, True), (1.1 * allowed_mean, False), (-1.1 * allowed_mean, False)):
        mean = _check(_signal(_judge(_torque(T) + shift)), "mean")
        assert mean.allowed == pytest.approx(allowed_mean, rel=1e-9)
        assert mean.difference == pytest.approx(shift, rel=1e-6) and mean.passed is passes
        assert (mean.reference, mean.result) == (pytest.approx(MEAN, rel=1e-12), pytest.approx(MEAN + shift, rel=1e-12))
    for e, passes in ((0.018, True), (0.022, False), (-0.022, False)):
        check = _check(_signal(_judge(MEAN + (1 + e) * (_torque(T) - MEAN))), "amplitude")
        assert check.reference == pytest.approx(amplitude, rel=1e-12)
        assert check.difference / amplitude == pytest.approx(e, rel=1e-6) and check.passed is passes
        assert check.result == pytest.approx((1 + e) * amplitude, rel=1e-12)


def test_the_stated_power_is_the_smallest_change_that_fails_by_hand():
    amplitude = (np.ptp(_torque(T))) / 2
    tau = _signal(_judge(_torque(T), with_power=True))
    power = tau.power
    # a mean shifted by d moves the time average by d: it fails beyond rtol.mean of max(MEAN, amplitude)
    assert _stated(power.mean, verdicts.DEFAULT_RTOL["mean"] * max(MEAN, amplitude), slack=1e-12), power.mean
    assert power.by["mean"] == ["mean"]
    # a ripple scaled by (1 + e) moves the amplitude by e * amplitude: it fails beyond rtol.amplitude
    # plus the reference's own error (a peak between its samples), here 3e-5 of the amplitude
    assert tau.reference_error < 1e-4 * amplitude
    assert _stated(power.amplitude, verdicts.DEFAULT_RTOL["amplitude"] + tau.reference_error / amplitude,
                   slack=1e-12), power.amplitude
    assert power.by["amplitude"] == ["amplitude"]
    assert power.band == pytest.approx(verdicts.DEFAULT_RTOL["tube"] * 2 * amplitude, rel=1e-9)


def test_the_stated_time_shift_is_where_the_highest_order_turns_past_its_tolerance():
    """With the mean, the amplitude and the tube left loose, only the orders judge a shift:
    order 3 turns fastest, by 3 W s, and fails at 2 sin(3 W s / 2) = rtol."""
    rtol = 0.05
    loose = verdicts.Tolerances([[verdicts.rule("", "mean", 1.0, "API"), verdicts.rule("", "amplitude", 1.0, "API"),
                                  verdicts.rule("", "tube", 10.0, "API"), verdicts.rule("", "order", rtol, "API")]])
    tau = _signal(_judge(_torque(T), rtol=loose, with_power=True))
    power = tau.power
    shift = 2 * math.asin(rtol / 2) / (3 * W)
    # the shifted trace is the reference's interpolant, off by at most its own error at any
    # sample: order 3's fitted component by at most twice that, against the 5 % of it allowed
    slack = 2 * tau.reference_error / (rtol * ORDERS[3][0])
    assert slack < 0.01
    for found in power.signs["shift"]:
        assert _stated(found, shift, slack), (found, shift)
    assert power.phase_deg == pytest.approx(math.degrees(W * power.shift_s), rel=1e-9)
    assert power.by["shift"] == ["order 3"]
    # the power line states the shift (both signs alike here); the phase is in validation.json
    assert f"time shift +-{1e3 * power.shift_s:.3g} ms" in power.describe()


def test_a_mean_tolerance_beyond_the_signals_own_size_is_stated_as_it_is():
    """rtol.mean = 2: the mean may move by twice max(|mean|, amplitude), more than the
    signal's largest value; the power says so rather than "none"."""
    wide = verdicts.Tolerances([[verdicts.rule("", "mean", 2.0, "API"), verdicts.rule("", "tube", 100.0, "API")]])
    power = _signal(_judge(_torque(T), rtol=wide, with_power=True)).power
    amplitude = (np.ptp(_torque(T))) / 2
    assert _stated(power.mean, 2.0 * max(MEAN, amplitude), slack=1e-12), power.mean
    assert not _check(_signal(_judge(_torque(T) + power.mean, rtol=wide, with_power=False)), "mean").passed
    assert f"mean +-{power.mean:.3g}" in power.describe()


def test_what_the_results_sampling_cannot_show_is_stated_and_not_judged():
    """A ripple M + A sin(2 pi f t) sampled once a period, each sample on a crest: the result's
    samples show the reference's mean as M + A and its ripple as 0 (by hand), off by more
    than half of what is allowed (the mean 1e-3 of max(M, A) = 0.1, the ripple 2 % of A
    = 0.2 plus the reference's own error), so neither is judged - each check states the
    reference's own value, the result's, and why - and the signal does not fail on them."""
    m, a, f = 100.0, 10.0, 10.0
    reference_t = np.linspace(0.0, 2.0, 20001)
    t = 0.025 + np.arange(20) / f
    judged = verdicts.judge(t, {"x": m + a * np.sin(2 * np.pi * f * t)}, reference_t,
                            {"x": m + a * np.sin(2 * np.pi * f * reference_t)}, window=(t[0], t[-1]), with_power=False)
    (signal,) = judged.signals
    checks = {c.quantity: c for c in signal.checks}
    mean, ripple = checks["mean"], checks["amplitude"]
    assert mean.judged is False and ripple.judged is False and mean.passed is True and judged.passed
    assert (mean.quantity, mean.reference, mean.difference, mean.allowed) == ("mean", pytest.approx(m, rel=1e-9),
                                                                              pytest.approx(0.0, abs=1e-9),
                                                                              pytest.approx(0.1, rel=1e-9))
    assert mean.result == pytest.approx(m + a, rel=1e-12)
    assert mean.detail == ("not judged: the result's samples (every 100 ms) show the reference's mean as 110, its own "
                           "samples as 100 - off by more than half the 0.1 allowed")
    assert ripple.reference == pytest.approx(a, rel=1e-6) and ripple.result == pytest.approx(0.0, abs=1e-9)
    assert ripple.difference == pytest.approx(0.0, abs=1e-9) and ripple.passed is True     # shown 0, the result's 0
    assert ripple.allowed == pytest.approx(0.02 * a, rel=1e-3)
    assert ripple.detail.startswith("not judged: the result's samples (every 100 ms) show the reference's ripple "
                                    "amplitude as 0, its own samples as 10 - off by more than half the 0.2 allowed")
    # a ripple of 1: the mean shown as 101, off by 1 - still more than half the 0.1 allowed
    small = verdicts.judge(t, {"x": m + np.sin(2 * np.pi * f * t)}, reference_t,
                           {"x": m + np.sin(2 * np.pi * f * reference_t)}, window=(t[0], t[-1]), with_power=False)
    mean, ripple = [c for c in small.signals[0].checks if c.quantity in ("mean", "amplitude")]
    assert ripple.judged is False and ripple.detail.startswith("not judged: the result's samples (every 100 ms) show "
                                                               "the reference's ripple amplitude as 0, its own samples "
                                                               "as 1 - ")     # off by 1: more than half the 0.02
    assert mean.judged is False and mean.detail.startswith("not judged: the result's samples (every 100 ms) show the "
                                                           "reference's mean as 101, its own samples as 100 - "), mean


def _square(t, first_rise):
    """10 N*m, and 11 for 40 ms every 80 ms from ``first_rise`` on."""
    return 10.0 + (np.mod(t - first_rise, 0.08) < 0.04).astype(float)


@pytest.mark.parametrize("rise,passes", [(0.001, True), (0.005, True), (0.009, True), (0.02, False)])
def test_the_reference_places_an_edge_no_closer_than_its_own_samples(rise, passes):
    """A square wave whose edges fall between the reference's samples (every 10 ms, edges at
    5 ms past them): a result sampled every 1 ms with its edges anywhere between the same two
    samples (1 to 9 ms past) is within the tube - the reference cannot say where between
    them the edge is - and one whose edges are a whole reference interval later (20 ms) is
    not: a fifth of its samples sit on the other level."""
    reference_t = np.round(np.arange(0.0, 1.0001, 0.01), 10)
    t = np.round(np.arange(0.0, 1.00001, 0.001), 10)
    judged = verdicts.judge(t, {"x": _square(t, rise)}, reference_t, {"x": _square(reference_t, 0.005)},
                            with_power=False)
    (tube,) = [c for c in judged.signals[0].checks if c.quantity == "tube"]
    assert tube.passed is passes, tube.detail
    assert tube.detail.startswith("0 % of the samples outside" if passes else "19.3 % of the samples outside")



#: a reference sampled unevenly: at 0, 8 and 9 ms past every 10 ms, to 998 ms - intervals of
#: 8, 1 and 1 ms, the first and the last 8 ms long
UNEVEN = np.unique(np.concatenate([np.arange(0, 1000, 10), np.arange(8, 1000, 10), np.arange(9, 990, 10)])) / 1e3


def _square_60(t, first_rise):
    """10 N*m, and 11 for 30 ms every 60 ms from ``first_rise`` on."""
    return 10.0 + (np.mod(t - first_rise, 0.06) < 0.03).astype(float)


@pytest.mark.parametrize("rise,outside", [(0.0015, "0 %"), (0.0075, "0 %"), (0.0085, "3.3 %"), (0.0165, "29.7 %")])
def test_an_unevenly_sampled_reference_places_each_edge_within_the_interval_around_it(rise, outside):
    """The reference (``UNEVEN``) has its edges at 5 ms past every 10 ms (5, 35, ..., 995 ms):
    each inside an 8 ms interval, between its samples at 0 and 8 ms past, the first interval
    and the last among them.  A result every 1 ms whose edges lie anywhere in that interval
    (1.5 or 7.5 ms past) is inside the tube at every sample - the reference can say no more
    of where its edges are - and one whose edges come after the sample at 8 ms (8.5 ms past,
    where the reference is already on the new level) is outside at that sample, 1 ms before
    the next: 33 of the 999 samples (3.3 %); an edge a whole interval late (16.5 ms past), at
    10 of each edge's 30 samples.  The interval is the one around each sample, not the one
    before or after it (1 ms long there) nor any other."""
    t = np.arange(0, 999) / 1e3
    judged = verdicts.judge(t, {"x": _square_60(t, rise)}, UNEVEN, {"x": _square_60(UNEVEN, 0.005)},
                            with_power=False)
    (tube,) = [c for c in judged.signals[0].checks if c.quantity == "tube"]
    assert tube.passed is (outside == "0 %"), tube.detail
    assert tube.detail.startswith(f"{outside} of the samples outside +-0.05 (5 % of the range;"), tube.detail


@pytest.mark.parametrize("spike,passes", [(0.9, True), (1.2, False)])
def test_one_sample_beyond_the_tube_by_more_than_the_references_range_fails(spike, passes):
    """The square wave above, the result on its edges' intervals, one sample (1 of 999: within
    the 1 % allowed outside) on the upper level raised by ``spike``: beyond the tube (5 % of
    the range 1) by spike - 0.05, which within the range (0.85) passes and beyond it (1.15),
    a spike between the reference's samples, fails."""
    t = np.arange(0, 999) / 1e3
    y = _square_60(t, 0.0035)
    y[500] += spike
    assert y[500] == 11.0 + spike
    judged = verdicts.judge(t, {"x": y}, UNEVEN, {"x": _square_60(UNEVEN, 0.005)}, with_power=False)
    (tube,) = [c for c in judged.signals[0].checks if c.quantity == "tube"]
    assert tube.passed is passes, tube.detail
    assert tube.detail.startswith("0.1 % of the samples outside") and "at t = 0.5 s" in tube.detail


@pytest.mark.parametrize("delay,passes", [(0.004, True), (0.012, False)])
def test_a_reference_of_two_samples_places_nothing_closer_than_the_share_of_the_window_a_lag_may_take(delay,
                                                                                                          passes):
    """Two samples, 10 at 0 s and 11 at 1 s: the reference is that straight line and cannot
    place anything between them, but a lag is allowed at most 1 % of the window (10 ms): a
    result every 1 ms delayed by 4 ms passes a tube of 0.1 % of the range that the result's
    own step (1 ms) alone would fail (3 ms * 1 /s = 0.003 beyond its 0.001), and one delayed
    by 12 ms does not (2 ms beyond: 0.002 > 0.001).  One sample, 10: a constant."""
    t = np.arange(0, 1001) / 1e3
    fine = verdicts.Tolerances([[verdicts.rule("", "tube", 0.001, "API")]])
    line = np.array([0.0, 1.0])
    judged = verdicts.judge(t, {"x": 10.0 + np.clip(t - delay, 0.0, None)}, line, {"x": 10.0 + line}, rtol=fine,
                            with_power=False)
    (tube,) = [c for c in judged.signals[0].checks if c.quantity == "tube"]
    assert tube.passed is passes, tube.detail
    constant = verdicts.judge(t, {"x": np.full_like(t, 10.0)}, line[:1], {"x": [10.0]}, window=(0.0, 1.0),
                              with_power=False)
    assert all(c.passed for c in constant.signals[0].checks), [c.detail for c in constant.signals[0].checks]

def test_the_references_own_error_is_its_largest_between_any_two_of_its_samples():
    """A ripple growing over the window (100 + 5 t sin(2 pi 20 t), 20 samples a period): the
    ripple allowed is 2 % of it plus the reference's own error, its interpolant's largest
    error midway between any two of its samples - read from the reference's own estimate
    (``sampled.Reference.error_at``) at every midpoint, the last period's the largest, about
    twice the first half's."""
    from harness.judges import sampled

    reference_t = np.round(np.arange(0.0, 2.00001, 0.0025), 10)
    y = 100.0 + 5.0 * reference_t * np.sin(2 * np.pi * 20.0 * reference_t)
    judged = verdicts.judge(reference_t, {"x": y}, reference_t, {"x": y}, with_power=False)
    (ripple,) = [c for c in judged.signals[0].checks if c.quantity == "amplitude"]
    errors = sampled.Reference(reference_t, y).error_at(0.5 * (reference_t[1:] + reference_t[:-1]))
    own = float(np.max(errors))
    assert own > 1.5 * float(np.max(errors[: len(errors) // 2]))
    assert ripple.allowed == pytest.approx(0.02 * ripple.reference + own, rel=1e-9)
    assert ripple.detail.endswith(f"and the reference's own error {own:.2g})")


_EVERY_MS = np.round(np.arange(0.0, 2.00001, 0.001), 10)
_FIVE_HZ = np.sin(2 * np.pi * 5.0 * _EVERY_MS)


@pytest.mark.parametrize("reference,result,allowed,said,passes", [
    # no ripple at all: the ripple is judged against 2 % of the mean, 100
    (100.0 + 0.0 * _FIVE_HZ, 100.0 + 1.0 * _FIVE_HZ, 2.0, "1 vs 0 (+1, allowed +-2: 2 % of its mean, 100)", True),
    (100.0 + 0.0 * _FIVE_HZ, 100.0 + 3.0 * _FIVE_HZ, 2.0, "3 vs 0 (+3, allowed +-2: 2 % of its mean, 100)", False),
    # a ripple below the noise floor (1e-3 of the largest value, 0.1): 2 % of that floor
    (100.0 + 1e-6 * _FIVE_HZ, 100.0 + 1e-3 * _FIVE_HZ, 0.002, "0.001 vs 1e-06 (+0.000999, allowed +-0.002: 2 % of the "
     "noise floor, 0.1)", True),
    (100.0 + 1e-6 * _FIVE_HZ, 100.0 + 3e-3 * _FIVE_HZ, 0.002, "0.003 vs 1e-06 (+0.003, allowed +-0.002: 2 % of the "
     "noise floor, 0.1)", False)])
def test_a_ripple_next_to_none_is_judged_against_the_mean_or_the_noise_floor(reference, result, allowed, said, passes):
    """By hand: the ripple allowed is 2 % of the reference's ripple, of its mean where it has
    none, and never less than 2 % of the noise floor (1e-3 of its largest value)."""
    judged = verdicts.judge(_EVERY_MS, {"x": result}, _EVERY_MS, {"x": reference}, with_power=False)
    (ripple,) = [c for c in judged.signals[0].checks if c.quantity == "amplitude"]
    assert ripple.allowed == pytest.approx(allowed, rel=1e-6)
    assert (ripple.passed, ripple.detail) == (passes, said)


def test_a_ripple_the_references_samples_cannot_show_is_stated_and_not_judged():
    """A 5 Hz ripple of 10 sampled by the reference five times a period (every 40 ms): its own
    samples show the ripple as 10 sin(72 deg) = 9.51, and between them it errs by more than the
    2 % allowed, so the ripple is not judged; the check states the reference's 9.51 and the
    result's 10 (a result sampled every 1 ms)."""
    reference_t = np.round(np.arange(0.0, 2.00001, 0.04), 10)
    judged = verdicts.judge(_EVERY_MS, {"x": 100.0 + 10.0 * _FIVE_HZ}, reference_t,
                            {"x": 100.0 + 10.0 * np.sin(2 * np.pi * 5.0 * reference_t)}, with_power=False)
    (ripple,) = [c for c in judged.signals[0].checks if c.quantity == "amplitude"]
    assert ripple.judged is False and ripple.passed is True and judged.passed
    assert ripple.quantity == "amplitude"
    shown = 10.0 * math.sin(math.radians(72.0))
    assert ripple.reference == pytest.approx(shown, rel=1e-9)
    assert ripple.result == pytest.approx(10.0, rel=1e-9)
    assert ripple.difference == pytest.approx(10.0 - shown, rel=1e-9)
    from harness.judges import sampled

    own = float(np.max(sampled.Reference(reference_t, 100.0 + 10.0 * np.sin(2 * np.pi * 5.0 * reference_t))
                       .error_at(0.5 * (reference_t[1:] + reference_t[:-1]))))
    assert own > 0.02 * shown
    assert ripple.allowed == pytest.approx(0.02 * shown + own, rel=1e-9)
    assert ripple.detail == (f"not judged: the reference's samples cannot show this ripple's peaks (between them it "
                             f"errs by up to {own:.3g}, more than the {0.02 * shown:.3g} allowed; a denser reference "
                             "judges it)")


def test_a_reference_its_samples_resolve_exactly_adds_no_error_of_its_own():
    """A ramp 10 + 2 t over 2 s: both cubics through its samples are the line itself, so the
    reference's own error is 0 and the ripple (half its range, 2) is allowed 2 % of it alone
    (0.04), said without an own error; the mean 12 to 1e-3 of max(12, 2)."""
    judged = verdicts.judge(_EVERY_MS, {"x": 10.0 + 2.0 * _EVERY_MS}, _EVERY_MS, {"x": 10.0 + 2.0 * _EVERY_MS},
                            with_power=False)
    checks = {c.quantity: c for c in judged.signals[0].checks}
    assert checks["amplitude"].allowed == pytest.approx(0.04, rel=1e-9)
    assert checks["amplitude"].detail == "2 vs 2 (+0 %, allowed +-2 %)"
    assert checks["mean"].detail == "12 vs 12 (+0, allowed +-0.012)"


def test_orders_the_results_sampling_cannot_show_are_stated_and_not_judged():
    """The result sampled every 1/30 s, 6 samples a revolution: its samples resolve order 1
    (judged), but they show the reference's orders 2 and 3 off by more than
    half of the 5 % of each allowed, so those are stated - the reference's own magnitude
    (2.5 and 1.5 by hand), the allowance - and not judged."""
    t = np.round(np.arange(0.0, 2.00001, 1.0 / 30.0), 10)
    judged = verdicts.judge(t, {"coupling.tau2": _torque(t), "load.w": np.full_like(t, W)}, T,
                            {"coupling.tau2": _torque(T), "load.w": np.full_like(T, W)}, rotation_signal="load.w",
                            kinds={"coupling.tau2": "torque", "load.w": "speed"})
    tau = _signal(judged)
    assert _check(tau, "order 1").judged is True and _check(tau, "order 1").passed
    for k in (2, 3):
        order = _check(tau, f"order {k}")
        magnitude = ORDERS[k][0]
        assert order.judged is False and order.passed is True
        assert order.reference == pytest.approx(magnitude, rel=1e-3)
        assert order.allowed == pytest.approx(0.05 * order.reference, rel=1e-9)
        assert order.detail.startswith(f"not judged: the result's samples (every 33.3 ms) show the reference's "
                                       f"order {k} as ")
        assert order.detail.endswith(f", its own samples as {order.reference:.4g} - off by more than half the "
                                     f"{order.allowed:.3g} allowed (of the complex component)")
    # the result is the reference at its samples (to its interpolation there, 1e-6): its order 2 is
    # the one they show of the reference (order 3, at the six samples' Nyquist limit, is not fitted alike)
    order = _check(tau, "order 2")
    assert order.difference == pytest.approx(0.0, abs=1e-5 * ORDERS[2][0])
    assert f"show the reference's order 2 as {order.result:.4g}, its own" in order.detail


def test_an_order_scaled_is_said_as_its_change_in_amplitude_and_of_the_component():
    """Order 2 scaled by 1.02, its phase kept: +2 % in amplitude, the phase unturned, off by
    |1.02 - 1| = 2 % of the component (allowed 5 %)."""
    orders = {**ORDERS, 2: (ORDERS[2][0] * 1.02, ORDERS[2][1])}
    order = _check(_signal(_judge(_torque(T, orders))), "order 2")
    assert order.passed and order.difference == pytest.approx(0.02 * ORDERS[2][0], rel=1e-6)
    amplitude, phase, off = order.detail.split(", ", 2)[0], order.detail.split(", ")[1], order.detail.split(": ")[1]
    assert amplitude == "amplitude +2 %" and off == "off by 2 % of the component (allowed 5 %)"
    assert abs(float(phase.split()[1])) < 1e-9


def test_the_tube_around_a_constant_is_of_its_mean():
    """A constant 100 has no range: its tube is 5 % of the mean (+-5), so a result 0.5 above
    it stays inside (the mean check is what fails it)."""
    judged = verdicts.judge(_EVERY_MS, {"x": 100.5 + 0.0 * _EVERY_MS}, _EVERY_MS, {"x": 100.0 + 0.0 * _EVERY_MS},
                            with_power=False)
    checks = {c.quantity: c for c in judged.signals[0].checks}
    assert checks["tube"].passed and checks["tube"].detail.startswith("0 % of the samples outside +-5 ")
    assert not checks["mean"].passed
