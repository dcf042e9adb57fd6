"""The masters' per-step shortcuts give what the plain computation gives, bit for bit where
they make the same operations (scalar Python floats: the same result on every CPU), and
to rounding where they do not."""
from __future__ import annotations

import math
import random

import numpy as np
import pytest

from harness.description import plan as plans
from harness.description import scene
from harness.engine import run
from harness.engine.masters import explicit
from harness.engine.system import System

MASTERS = {cls.name: cls for cls in (explicit.LinearExtrapolationMaster, explicit.QuadraticExtrapolationMaster)}


def _nodes(rng, n):
    if rng.random() < 0.3:                      # uniform steps, with the rounding of real times
        t, h = rng.uniform(0, 20), 10 ** rng.uniform(-6, -2)
        return [(t - h * (n - k) - t) / h for k in range(n)]
    return sorted(-rng.uniform(0.01, 3.0) * (k + 1) for k in range(n))


@pytest.mark.parametrize("n", [2, 3])
def test_unrolled_lagrange_basis_is_the_product_bit_for_bit(n):
    rng = random.Random(n)
    for _ in range(2000):
        nodes = _nodes(rng, n)
        assert explicit._lagrange_basis(nodes) == explicit._lagrange_product(nodes)


def test_extrapolation_weights_sum_as_sum_does():
    # each weight a sum from 0.0, lowest power first: what sum() over a generator gives
    rng = random.Random(7)
    for _ in range(2000):
        n = rng.choice([1, 2, 3, 4])
        nodes = _nodes(rng, n)
        means, slopes, ends = explicit.extrapolation_weights(nodes, 0.0, 1.0)
        for basis, mean, slope, end in zip(explicit._lagrange_product(nodes), means, slopes, ends):
            assert mean == sum(c / (k + 1) for k, c in enumerate(basis))
            assert slope == 12.0 * sum(c * (1.0 / (k + 2) - 0.5 / (k + 1)) for k, c in enumerate(basis))
            assert end == sum(basis)


def test_a_node_within_1e_10_of_a_key_rounds_to_that_key():
    """What lets a fixed step reuse the last step's derivative weights without rounding
    its scaled nodes again (``ExtrapolatingJacobiMaster._derivatives``)."""
    rng = random.Random(3)
    for _ in range(20000):
        key = round(rng.uniform(-4.0, 0.0), 9) if rng.random() < 0.5 else float(-rng.randint(1, 3))
        node = key + rng.uniform(-0.999e-10, 0.999e-10)
        assert round(node, 9) == key


@pytest.mark.parametrize("name", ["jacobi-linear", "jacobi-quadratic"])
def test_a_fixed_step_reuses_the_weights_the_rounded_key_finds(name, monkeypatch):
    """Every step's derivative weights are the ones the cache holds under the step's
    rounded pattern: the shortcut (in ``_derivatives`` and in the steady step's function)
    never hands on another pattern's.  The weights a step sent ahead with are the last
    ones (``_last_derivatives``), whichever path found them."""
    spec = scene.load("kavz685").with_overrides(["experiment.stop=0.05", "experiment.transient=0"])
    checked = []
    original = explicit.ExtrapolatingJacobiMaster._step_impl

    def checking(self, t, h):
        original(self, t, h)
        history, t_end = self.history, t + h
        if len(history) < self.degree:                      # a start-up step sends nothing ahead
            return
        scale = t_end - history[-1][0]
        times = [p[0] for p in history] + [t_end]
        key = ("d",) + tuple(round((x - t_end) / scale, 9) for x in times)
        assert self._weights_cache[key] is self._last_derivatives[1]
        checked.append(t_end)

    monkeypatch.setattr(explicit.ExtrapolatingJacobiMaster, "_step_impl", checking)
    result = run.simulate(spec, master=name, step=1e-3)
    assert result.ok and len(checked) >= 48


@pytest.mark.parametrize("name", ["jacobi-linear", "jacobi-quadratic"])
def test_the_steady_step_is_the_general_step_call_for_call(name, monkeypatch):
    """The steady step's one function against the step made part by part (``_general_step``
    and ``Master.step``'s reads): the same traces bit for bit and the same FMI calls, on a
    run that varies its step (so the weights change and the steady step hands over)."""
    spec = scene.load("kavz685").with_overrides(["experiment.stop=0.03", "experiment.transient=0"])

    def run_with(steady: bool):
        monkeypatch.setattr(explicit.ExtrapolatingJacobiMaster, "steady_steps", steady)
        plan = plans.check(spec)
        system = System(plan, record=list(plan.recorded))
        system.initialize()
        try:
            driver = MASTERS[name](system, 1e-3)
            assert (driver._whole_step != driver._general_step) is steady
            rows = []
            for h in [1e-3] * 8 + [5e-4] * 6 + [1e-3] * 5 + [2e-3] * 4:
                driver.step(h)
                rows.append(np.ctypeslib.as_array(system.output_block).copy())
            return rows, system.calls_by_kind()
        finally:
            system.free()

    steady_rows, steady_calls = run_with(True)
    general_rows, general_calls = run_with(False)
    assert np.array_equal(np.array(steady_rows), np.array(general_rows))
    assert steady_calls == general_calls


def test_midpoint_prediction_is_the_taylor_sum_to_rounding():
    """The predicted angle and speed against the Taylor polynomial summed exactly
    (math.fsum): rounding apart, the same (Python 3.12's sum() compensates, the
    unrolled sum does not)."""
    spec = scene.load("kavz685").with_overrides(["experiment.stop=0.02", "experiment.transient=0"])
    seen = []
    original = explicit.MidpointPredictionMaster._prediction

    def checking(self):
        predict = original(self)

        def predict_and_check(dt):
            predict(dt)
            factors = (1.0, dt, dt * dt / 2.0, dt * dt * dt / 6.0)
            for target_values, k, values, indices in self._taylor:
                exact = math.fsum(f * values[i] for f, i in zip(factors, indices))
                assert target_values[k] == pytest.approx(exact, rel=1e-12, abs=1e-300)
                seen.append(len(indices))
        return predict_and_check

    monkeypatch = pytest.MonkeyPatch()
    try:
        monkeypatch.setattr(explicit.MidpointPredictionMaster, "_prediction", checking)
        assert run.simulate(spec, master="jacobi-midpoint", step=1e-3).ok
    finally:
        monkeypatch.undo()
    assert set(seen) == {2, 3}          # the angles (phi, w, a) and the speeds (w, a)


def test_recorded_rows_are_the_component_buffers():
    """One copy a row from the system's output block: each recorded column is the value
    its component's buffer held after the step."""
    spec = scene.load("kavz685").with_overrides(["experiment.stop=0.01", "experiment.transient=0"])
    buffered = []

    class Snapshot:
        def started(self, t):
            pass

        def stepped(self, n, t):
            buffered.append({f"{name}.{v}": system.buffers[name][1][system.index[(name, v)]]
                             for name in system.buffers for v in system.exposed[name]})

        def ended(self):
            pass

    original = run.System.__init__

    def keep(self, *args, **kwargs):
        nonlocal system
        original(self, *args, **kwargs)
        system = self

    system = None
    monkeypatch = pytest.MonkeyPatch()
    try:
        monkeypatch.setattr(run.System, "__init__", keep)
        result = run.simulate(spec, master="jacobi-quadratic", step=1e-3, observer=Snapshot())
    finally:
        monkeypatch.undo()
    assert result.ok and len(buffered) == 10
    for name, trace in result.traces.items():
        assert np.array_equal(trace[1:], [row[name] for row in buffered]), name
