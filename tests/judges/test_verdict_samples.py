"""The engineer's verdict judges the result's own samples: wrong results made by hand from the
committed reference (zeros between its rows, spikes, chatter) fail naming the signal and the
quantity; the exact solution on another grid passes; a result its sampling cannot judge is
refused or its quantity "not judged"; the stated power is true for every committed reference."""
from __future__ import annotations

import numpy as np
import pytest

from harness import api
from harness.formats import reference_traces
from harness.judges import sampled, validation, verdict


@pytest.fixture(scope="module")
def kavz():
    ref = reference_traces.read("kavz685")
    return ref.outputs.times, ref.outputs.signals, verdict.settings_of(ref)


def _judge(kavz, times, traces, **options):
    t, signals, settings = kavz
    options.setdefault("with_power", False)
    return verdict.judge(times, traces, t, signals, transient=settings.transient,
                         rotation_signal=settings.rotation_signal, kinds=settings.kinds, **options)


def _failed(judged) -> set[tuple[str, str]]:
    return {(s.name, c.quantity) for s in judged.signals for c in s.failed}


def test_the_reference_is_dense_enough_to_be_judged_against():
    """Every committed scene reference keeps a sample at least every 1 ms (or its step) and no
    file is larger than 2 MB."""
    for name in reference_traces.all_names():
        path = reference_traces.paths(name)["ref"]
        assert path.stat().st_size < 2e6, name
        t = reference_traces.read(name).outputs.times
        assert np.max(np.diff(t)) <= 1e-3 + 1e-12, name


def test_ninety_percent_zeros_between_the_references_rows_fail_on_the_mean(kavz):
    """The reference's own 10 ms rows with nine rows of zeros between each pair: the result's
    own mean is a tenth of the reference's."""
    t, signals, _ = kavz
    every = np.arange(len(t))
    rows = every % 10 == 0
    traces = {n: np.where(rows, v, 0.0) for n, v in signals.items()}
    judged = _judge(kavz, t, traces)
    assert not judged.passed
    assert ("load.w", "mean") in _failed(judged) and ("coupling.tau2", "mean") in _failed(judged)
    mean = next(c for c in judged.signals[5].checks if c.quantity == "mean")
    assert mean.result == pytest.approx(0.1 * mean.reference, rel=0.05)


def test_single_row_spikes_between_the_references_samples_fail_the_tube(kavz):
    t, signals, _ = kavz
    tau2 = signals["coupling.tau2"].copy()
    spikes = np.arange(3000, 9000, 1500)            # four rows of 10 000 samples
    tau2[spikes] += 1e4
    judged = _judge(kavz, t, {"coupling.tau2": tau2})
    assert _failed(judged) >= {("coupling.tau2", "tube")}
    assert "more than the reference's range" in judged.failures()[-1]
    assert judged.signals[0].max_error == pytest.approx(1e4, rel=1e-3)
    (tube,) = [c for c in judged.signals[0].failed if c.quantity == "tube"]
    assert tube.at in t[spikes]        # where its plot's close-up looks


def test_chatter_on_every_other_row_fails_the_amplitude(kavz):
    t, signals, _ = kavz
    tau2 = signals["coupling.tau2"] + 5.0 * (-1.0) ** np.arange(len(t))
    judged = _judge(kavz, t, {"coupling.tau2": tau2})
    assert ("coupling.tau2", "amplitude") in _failed(judged)


@pytest.mark.parametrize("offset, step", [(5, 10), (0, 12)])
def test_the_exact_solution_on_another_grid_passes(kavz, offset, step):
    """The reference's own rows (1 ms apart, the monolithic solution) taken every 10 ms from
    5 ms on, or every 12 ms: the exact solution on another grid than the reference's 10 ms
    one - it passes; what the grid cannot show is "not judged", not failed."""
    t, signals, _ = kavz
    rows = np.arange(offset, len(t), step)
    # over the span the rows cover (from 5 ms on, the offset grid starts after the reference)
    judged = _judge(kavz, t[rows], {n: v[rows] for n, v in signals.items()}, window=(t[rows[0]], t[rows[-1]]))
    assert judged.passed, judged.failures()
    for s in judged.signals:
        for c in s.checks:
            if c.judged and c.quantity in ("mean", "amplitude"):
                assert abs(c.difference) <= 0.5 * c.allowed, (s.name, c.quantity, c.detail)


def test_a_ripple_faster_than_the_results_sampling_is_not_judged_and_says_why(kavz):
    """engine.a and load.a carry the 415-425 rad/s band; sampled every 20 ms its peaks are not
    seen: the amplitude is "not judged", naming the sampling, never PASS or FAIL."""
    t, signals, _ = kavz
    rows = np.arange(0, len(t), 20)
    judged = _judge(kavz, t[rows], {"load.a": signals["load.a"][rows]})
    (amplitude,) = [c for c in judged.signals[0].checks if c.quantity == "amplitude"]
    assert not amplitude.judged and "every 20 ms" in amplitude.detail
    assert "load.a amplitude: not judged" in judged.blind_spots or "load.a amplitude" in judged.blind_spots


def test_a_result_too_sparse_for_its_window_or_band_is_refused(kavz):
    t, signals, _ = kavz
    sparse = np.array([0.0, 10.0])
    held = {n: np.array([v[0], v[0]]) for n, v in signals.items()}
    with pytest.raises(verdict.UnusableResult, match=r"1 sample\(s\) in the steady window"):
        _judge(kavz, sparse, held)
    with pytest.raises(validation.TooSparse, match="too sparse for the cross-check band"):
        validation.compare_span("x", sparse, held, t, signals, validation.TOLERANCES["cross-check"], 0.0, 10.0)
    with pytest.raises(api.InputError, match="too sparse"):
        api.validate("kavz685", result=(sparse, held), tolerance="cross-check")


def test_unsorted_times_are_refused_and_an_event_pair_is_not(kavz):
    t, signals, _ = kavz
    swapped = t.copy()
    swapped[[100, 101]] = swapped[[101, 100]]
    with pytest.raises(verdict.UnusableResult, match="not sorted: row 102"):
        _judge(kavz, swapped, {"load.w": signals["load.w"]})
    event = np.insert(t, 5000, t[5000])
    assert _judge(kavz, event, {"load.w": np.insert(signals["load.w"], 5000, signals["load.w"][5000])}).passed


def test_a_last_row_written_again_is_read_once_and_three_different_rows_at_a_time_are_refused(kavz):
    # OMSimulator writes the stop time's row three times, the same values each time: one row
    t, signals, _ = kavz
    y = signals["load.w"]
    again = np.concatenate([t, [t[-1], t[-1]]]), np.concatenate([y, [y[-1], y[-1]]])
    judged = _judge(kavz, again[0], {"load.w": again[1]})
    assert judged.passed and any("2 row(s) of the result repeat the row before them" in n for n in judged.notes)
    differ = np.concatenate([y, [y[-1] + 1.0, y[-1]]])
    with pytest.raises(verdict.UnusableResult, match="appears three times or more"):
        _judge(kavz, again[0], {"load.w": differ})


def test_another_tools_column_names_are_matched_and_said(kavz):
    t, signals, _ = kavz
    judged = _judge(kavz, t, {"engine_w": signals["engine.w"], "kavz685.coupling.tau2": signals["coupling.tau2"]})
    assert [s.name for s in judged.signals] == ["engine.w", "coupling.tau2"] and judged.passed
    assert any("engine_w as engine.w" in n and "kavz685.coupling.tau2 as coupling.tau2" in n for n in judged.notes)


def test_the_order_fit_takes_the_samples_own_times():
    """A sum of orders sampled at random times: the least-squares fit gives each component
    (amplitude and phase) as built, by hand."""
    rng = np.random.default_rng(3)
    t = np.sort(rng.uniform(0.0, 2.0, 700))
    w = 37.0
    y = 5.0 + 2.0 * np.cos(w * t + 0.4) + 0.5 * np.cos(3 * w * t - 1.0)
    fitted = sampled.OrderFit(t, w, (1, 2, 3, 4)).fit(y)
    assert fitted[1] == pytest.approx(2.0 * np.exp(0.4j), abs=1e-9)
    assert fitted[3] == pytest.approx(0.5 * np.exp(-1.0j), abs=1e-9)
    assert abs(fitted[2]) < 1e-9
    uneven = np.array([0.0, 1.0, 1.5, 4.0])
    assert sampled.time_mean(uneven, np.array([0.0, 2.0, 2.0, 0.0])) == pytest.approx((1.0 + 1.0 + 2.5) / 4.0)


def _references():
    return reference_traces.all_names()


@pytest.mark.parametrize("name", _references())
def test_the_stated_power_is_true_for_every_committed_reference(name):
    """For every committed reference, each signal: the reference itself passes, and changed by
    1.1 times the stated power of each sign (mean, amplitude, time shift) it fails, by 0.9 times
    it passes - judged by ``verdict.judge``, the path a result takes."""
    ref = reference_traces.read(name)
    settings = verdict.settings_of(ref)
    t, signals = ref.outputs.times, ref.outputs.signals
    options = dict(transient=settings.transient, rotation_signal=settings.rotation_signal, kinds=settings.kinds,
                   rtol=verdict.Tolerances([settings.rules]))
    itself = verdict.judge(t, signals, t, signals, **options)
    assert itself.passed, itself.failures()
    start = itself.window[0]
    for s in itself.signals:
        if s.power is None:
            continue
        reference = sampled.Reference(t, signals[s.name])
        steady = t >= start - 1e-12
        own_t = t[steady]
        mean = sampled.time_mean(own_t, signals[s.name][steady])
        change = {"mean": lambda x: signals[s.name] + np.where(steady, x, 0.0),
                  "amplitude": lambda x: np.where(steady, mean + (1 + x) * (signals[s.name] - mean), signals[s.name]),
                  "shift": lambda x: np.where(steady, reference(t - x), signals[s.name])}
        for kind, make in change.items():
            for sign, stated in zip((1.0, -1.0), s.power.signs[kind]):
                if stated is None:
                    continue
                for factor, passes in ((1.1, False), (0.9, True)):
                    judged = verdict.judge(t, {s.name: make(sign * factor * stated)}, t, signals, with_power=False,
                                           **options)
                    assert judged.passed is passes, (name, s.name, kind, sign, factor, stated, judged.failures())


def _dense(kavz, step: float, doubled: float | None = None):
    """The committed reference through its own interpolant at every ``step`` - a host's dense
    result of the exact solution; ``doubled``: every time written twice, ``doubled`` apart (a
    host writing its outputs before and after each exchange)."""
    t, signals, _ = kavz
    dense_t = np.arange(t[0], t[-1] + 0.5 * step, step)
    traces = {n: sampled.Reference(t, v)(dense_t) for n, v in signals.items()}
    if doubled is not None:
        dense_t = np.repeat(dense_t, 2)
        dense_t[1::2] += doubled
        traces = {n: np.repeat(v, 2) for n, v in traces.items()}
    return dense_t, traces


def test_a_dense_results_power_is_searched_at_a_selection_and_is_true_at_all_its_samples(kavz):
    """A result sampled five times finer than the reference: the power's search judges its
    changes at the samples nearest the reference's own 1 ms grid (saying so), and what it states
    holds for the whole result - 1.1 times each stated change fails, 0.9 times passes, judged at
    every sample."""
    t, signals, settings = kavz
    dense_t, traces = _dense(kavz, 2e-4)
    chosen = ["load.a", "coupling.tau2"]
    itself = _judge(kavz, dense_t, traces, signals=chosen, with_power=True)
    assert itself.passed, itself.failures()
    steady = dense_t >= itself.window[0] - 1e-12
    for s in itself.signals:
        searched, of = s.power.searched_at
        assert of == np.count_nonzero(steady) and searched == pytest.approx(of / 5, rel=0.01)
        assert f"searched at {searched} of the result's {of} samples" in s.power.describe()
        reference = sampled.Reference(t, signals[s.name])
        y = traces[s.name]
        mean = sampled.time_mean(dense_t[steady], y[steady])
        change = {"mean": lambda x: y + np.where(steady, x, 0.0),
                  "amplitude": lambda x: np.where(steady, mean + (1 + x) * (y - mean), y),
                  "shift": lambda x: np.where(steady, reference(dense_t - x), y)}
        for kind, make in change.items():
            stated = s.power.signs[kind][0]
            for factor, passes in ((1.1, False), (0.9, True)):
                judged = _judge(kavz, dense_t, {s.name: make(factor * stated)}, signals=[s.name])
                assert judged.passed is passes, (s.name, kind, factor, stated, judged.failures())


@pytest.mark.parametrize("apart", [0.0, 1e-8])
def test_a_result_with_every_time_written_twice_gets_its_power_in_bounded_time(kavz, apart):
    """A host that writes each row twice, at the same time or 1e-8 s apart (OMSimulator's weak
    coupling does): the steps between its rows are 0 or 1e-8 s half the time, and the power's
    search still starts from the result's true step - the same power as the result written
    once, found in the same number of judgements."""
    once_t, once = _dense(kavz, 1e-3)
    twice_t, twice = _dense(kavz, 1e-3, doubled=apart)
    chosen = ["engine.a"]
    calls = []
    real_checks = verdict._checks

    def counted(*args, **kwargs):
        calls.append(1)
        return real_checks(*args, **kwargs)

    powers = []
    for times, traces in ((once_t, once), (twice_t, twice)):
        calls.clear()
        with pytest.MonkeyPatch.context() as patch:
            patch.setattr(verdict, "_checks", counted)
            (s,) = _judge(kavz, times, traces, signals=chosen, with_power=True).signals
        powers.append((s.power, len(calls)))
    (once_power, once_calls), (twice_power, twice_calls) = powers
    assert twice_power.shift_s == pytest.approx(once_power.shift_s, rel=0.02)
    assert twice_calls <= once_calls + 6


def test_the_powers_search_refuses_a_start_it_cannot_double_from():
    from harness.judges import power

    for start in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="start > 0"):
            power._smallest_failing(lambda x: True, start, 1.0, 1.0)



def test_a_start_up_ringing_lost_fails_its_envelope_and_one_off_in_phase_does_not():
    """kavz685_stiff_1e6 rings at 3745 rad/s through its start-up, sampled 6.7 times a
    period: the start-up's tube, a step either side, spans a third of a period, so a result
    without the ringing would sit inside it. Its envelope - each 8 steps' peak-to-peak against
    the reference's - fails a result whose ringing is gone after 10 ms (a master that damps
    it away, as implicit Euler at this step does), and does not flag one whose ringing runs
    half a period late (a master's phase error)."""
    ref = reference_traces.read("kavz685_stiff_1e6")
    settings = verdict.settings_of(ref)
    t, signals = ref.outputs.times, ref.outputs.signals
    options = dict(transient=settings.transient, rotation_signal=settings.rotation_signal, kinds=settings.kinds,
                   signals=["engine.a"], with_power=False)
    a = signals["engine.a"]
    period = 2 * np.pi / 3745.0
    width = int(round(period / np.median(np.diff(t))))
    smooth = np.convolve(a, np.ones(width) / width, mode="same")
    ringing = a - smooth

    def start_up(result):
        (s,) = verdict.judge(t, {"engine.a": result}, t, signals, **options).signals
        return next(c for c in s.checks if c.quantity == "transient tube")

    assert start_up(a).passed and "envelope" not in start_up(a).detail
    lost = start_up(np.where((t > 0.01) & (t < 0.2), smooth, a))
    assert not lost.passed and "its envelope: in " in lost.detail and lost.at is not None
    late = np.where(t < 0.2, smooth + np.interp(t - 0.5 * period, t, ringing), a)
    assert "envelope" not in start_up(late).detail


@pytest.mark.parametrize("copies", [2, 3])
def test_the_sampling_said_is_the_results_and_rows_written_again_are_said_apart(copies):
    """A host that writes each time twice (or thrice) 1e-8 s apart samples every 0.1 ms: the
    line says so, and counts the rows written again; a uniform, an uneven and an event's
    repeated time (0 s apart) are said as they are."""
    grid = np.arange(0.0, 0.1 + 1e-12, 1e-4)
    again = np.sort(np.concatenate([grid + 1e-8 * k for k in range(copies)]))
    said = sampled.spacing(again)
    assert said.startswith("every 0.1 ms; ") and f"; {(copies - 1) * grid.size} rows within 1e-08 s" in said
    assert sampled.spacing(grid) == "every 0.1 ms"
    assert sampled.spacing(np.array([0.0, 1e-3, 1e-3, 2e-3, 5e-3])) == "every 1 ... 3 ms"
    assert sampled.spacing(np.array([0.0, 0.0])) == "one sample"
