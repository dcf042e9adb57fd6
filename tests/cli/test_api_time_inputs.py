"""What the API takes as a time, and what it refuses (harness/api/inputs.py).

A time is a real number of seconds (an int, a float, a numpy scalar) or a string with a
time unit as a scene's overrides take it; nothing else.  ``True`` is an int to Python, and
1 to arithmetic: a reader that took it would run 1 s where the user made a mistake.  Each
refusal is an ``InputError`` naming the argument, raised before anything runs."""
from __future__ import annotations

import fractions
import math

import numpy as np
import pytest

from harness import api
from harness.api import inputs

#: values no time is: booleans (Python's and numpy's), containers, complex, bytes, other objects
NOT_A_TIME = [True, False, np.bool_(True), np.bool_(False), [1.0], (1.0,), {"stop": 1.0}, {1.0}, 1 + 0j, b"1",
              object(), np.array([1.0])]


def _id(value) -> str:
    """A test id the same in every pytest-xdist worker (an object's repr holds its address)."""
    return type(value).__name__ if type(value) is object else repr(value)
#: strings no time is: other dimensions, not a number, not finite
NOT_A_TIME_TEXT = ["1 kg", "one second", "", "nan", "inf", "-inf", "1 ms ms"]
#: what is a time, and its value in seconds, worked out by hand
TIMES = [(1, 1.0), (0.25, 0.25), (np.float32(0.5), 0.5), (np.float64(0.7), 0.7), (np.int64(2), 2.0),
         (fractions.Fraction(1, 4), 0.25), ("0.5", 0.5), (" 2 ", 2.0), ("1 ms", 1e-3), ("250 ms", 0.25),
         ("0.5 s", 0.5), ("2 min", 120.0)]


@pytest.mark.parametrize("value", NOT_A_TIME + NOT_A_TIME_TEXT, ids=_id)
def test_seconds_refuses_what_is_no_time_and_names_the_argument(value):
    with pytest.raises(inputs.InputError, match=r"^the_argument=.*: (expected a (finite )?time in seconds|a value in "
                                                r".* cannot be a value in s)"):
        inputs.seconds(value, "the_argument")


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf, np.float64("nan")], ids=_id)
def test_seconds_refuses_a_number_that_is_not_finite(value):
    with pytest.raises(inputs.InputError, match=r"^stop=-?(nan|inf): expected a finite time in seconds$"):
        inputs.seconds(value, "stop")


@pytest.mark.parametrize("value,expected", TIMES, ids=_id)
def test_seconds_reads_a_time_in_seconds(value, expected):
    got = inputs.seconds(value, "stop")
    assert type(got) is float and got == pytest.approx(expected, rel=1e-7)


def test_none_means_not_given():
    assert inputs.seconds(None, "stop") is None and inputs.step(None) is None


@pytest.mark.parametrize("value", [True, np.bool_(True), "1", 1 + 0j, [1]], ids=_id)
def test_number_and_count_refuse_booleans_and_what_is_no_number(value):
    with pytest.raises(inputs.InputError, match=r"^tolerance=.*: expected a number$"):
        inputs.number(value, "tolerance")
    with pytest.raises(inputs.InputError, match=r"^repeats=.*: expected a whole number in \[1, 20\]$"):
        inputs.count(value, "repeats", 1, 20)
    with pytest.raises(inputs.InputError, match=r"^repeats=.*: expected a whole number >= 1$"):
        inputs.count(value, "repeats", 1)


def test_a_refusal_quotes_the_value_it_refuses():
    for refuse, text in ((lambda: inputs.number(True, "tolerance"), "tolerance=True: expected a number"),
                         (lambda: inputs.count([3], "repeats", 1, 20), "repeats=[3]: expected a whole number in [1, 20]"),
                         (lambda: inputs.seconds(b"1", "stop"), "stop=b'1': expected a time in seconds (a number, or a "
                                                                 "string with a time unit, e.g. '1 ms')")):
        with pytest.raises(inputs.InputError) as refused:
            refuse()
        assert str(refused.value) == text or str(refused.value).startswith(text + ":")


def test_number_and_count_read_numbers_and_counts_within_their_range():
    assert inputs.number(np.float32(0.5), "x") == 0.5 and type(inputs.number(3, "x")) is float
    assert inputs.count(np.int64(3), "n", 1, 20) == 3 and inputs.count(1, "n", 1, 20) == 1
    assert inputs.count(20, "n", 1, 20) == 20 and inputs.count(10 ** 6, "n", 1) == 10 ** 6
    for outside in (0, 21):
        with pytest.raises(inputs.InputError, match=rf"^n={outside}: must be in \[1, 20\]$"):
            inputs.count(outside, "n", 1, 20)
    with pytest.raises(inputs.InputError, match=r"^n=0: must be >= 1$"):
        inputs.count(0, "n", 1)
    with pytest.raises(inputs.InputError, match="whole number"):
        inputs.count(2.0, "n", 1, 20)


@pytest.mark.parametrize("value", [True, False, [0.001], "1 kg", 0.0, -1e-3], ids=_id)
def test_a_step_that_is_no_positive_time_is_refused(value):
    with pytest.raises(inputs.InputError, match="step"):
        inputs.step(value)


@pytest.mark.parametrize("window,expected", [((0, "500 ms"), (0.0, 0.5)), ([None, 2], (None, 2.0)),
                                             ("0:500 ms", (0.0, 0.5)), (":1", (None, 1.0))])
def test_a_window_reads_both_sides_as_times(window, expected):
    assert inputs.window(window) == expected


@pytest.mark.parametrize("window", [(True, 1.0), (0.0, False), (0.0, [1.0]), (0.0,), "1", "2:1", "a:b"], ids=_id)
def test_a_window_with_a_side_that_is_no_time_is_refused(window):
    with pytest.raises(inputs.InputError, match="window"):
        inputs.window(window)


@pytest.mark.parametrize("argument", ["stop", "step"])
@pytest.mark.parametrize("value", [True, np.bool_(False), [0.1], {"s": 0.1}], ids=_id)
def test_the_api_refuses_them_before_anything_runs(argument, value, monkeypatch):
    from harness.engine import run as engine_run

    def never(*args, **kwargs):
        raise AssertionError("a run started")

    monkeypatch.setattr(engine_run, "simulate", never)
    with pytest.raises(inputs.InputError, match=rf"^{argument}="):
        api.run("kavz685", **{argument: value}, reference=False, plots=False)
    if argument == "stop":
        with pytest.raises(inputs.InputError, match=r"^stop="):
            api.load("kavz685", stop=value)


def test_a_time_given_with_a_unit_is_the_runs_stop():
    assert api.load("kavz685", stop="20 ms").experiment.stop == pytest.approx(0.02, rel=1e-12)
    assert api.load("kavz685", stop=np.float32(0.25)).experiment.stop == pytest.approx(0.25, rel=1e-7)


@pytest.mark.parametrize("value,label,said", [(0.0, "step", "step = 0.0 must be > 0 s"),
                                              ("-1 ms", "step", "step = -0.001 must be > 0 s"),
                                              (-2, "max_step", "max_step = -2.0 must be > 0 s")])
def test_a_step_refused_is_named_as_the_caller_named_it(value, label, said):
    """The refusal names the argument the caller handed (``step``), not the scene file's
    ``experiment.step``, with the value in seconds."""
    with pytest.raises(inputs.InputError) as refused:
        inputs.step(value, label) if label != "step" else inputs.step(value)
    assert str(refused.value) == said
