"""Every figure the benchmark and the run report compute, on constructed traces whose answer
is worked out by hand: a case's errors (the worse of the two shafts, an error only in a
speed, only after or only before the start-up transient), the error scales, the
statistics after the transient, the energy balance and the spectrum's two components.

The grid: 0 to 1 s in 1 ms, 1001 points.  The RMS is a time average with trapezoidal
weights, so a difference d on the points from t = 0.5 s on (the interior point at 0.5 s
weighs a whole step, the last half of one) has the RMS d * sqrt(0.5005), and on the points
before it (the first weighs half a step) d * sqrt(0.4995)."""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from harness.description import scene as scenes
from harness.judges import metrics, monolithic
from harness.studies.bench import Case, table_row
from harness.studies.bench import timing

TIMES = np.linspace(0.0, 1.0, 1001)
TRANSIENT = 0.5
#: the reference: the driven shaft a little slower, the engine's torque the reaction
REFERENCE = {"engine.w": 40.0, "load.w": 38.0, "coupling.tau1": -90.0, "coupling.tau2": 100.0}
SPEED, TORQUE = 40.0, 100.0         # the error scales: the mean speed of w1, the mean |tau2|
AFTER = math.sqrt(0.5005)           # RMS share of a difference on t >= 0.5 s
BEFORE = math.sqrt(0.4995)          # ... on t < 0.5 s


@pytest.fixture(scope="module")
def scene() -> scenes.Scene:
    return scenes.load("kavz685").with_overrides(["experiment.stop=1.0", f"experiment.transient={TRANSIENT}"])


def reference() -> dict:
    return {name: np.full(TIMES.shape, value) for name, value in REFERENCE.items()}


def run_with(**differences) -> dict:
    """The reference's traces plus a difference per short name (a number or an array)."""
    short = {"w1": "engine.w", "w2": "load.w", "tau1": "coupling.tau1", "tau2": "coupling.tau2"}
    traces = reference()
    for name, d in differences.items():
        traces[short[name]] = traces[short[name]] + d
    return traces


AFTER_TRANSIENT = np.where(TIMES >= TRANSIENT, 1.0, 0.0)


# (differences, the case's errors by hand: tau_rms, tau_max, w_rms, w_max, then after the transient)
CASES = {
    # the driven shaft worse in both: the benchmark must not read the engine's side alone
    "driven shaft worse": (dict(w1=0.2, w2=0.4, tau1=1.0, tau2=3.0),
                           (0.03, 0.03, 0.01, 0.01), (0.03, 0.03, 0.01, 0.01)),
    # nor the driven shaft's alone
    "engine shaft worse": (dict(w1=0.4, w2=-0.2, tau1=-3.0, tau2=1.0),
                           (0.03, 0.03, 0.01, 0.01), (0.03, 0.03, 0.01, 0.01)),
    "only a speed": (dict(w2=-0.4), (0.0, 0.0, 0.01, 0.01), (0.0, 0.0, 0.01, 0.01)),
    "only after the transient": (dict(tau2=3.0 * AFTER_TRANSIENT, w2=0.4 * AFTER_TRANSIENT),
                                 (0.03 * AFTER, 0.03, 0.01 * AFTER, 0.01), (0.03, 0.03, 0.01, 0.01)),
    "only before the transient": (dict(tau1=3.0 * (1.0 - AFTER_TRANSIENT), w1=0.4 * (1.0 - AFTER_TRANSIENT)),
                                  (0.03 * BEFORE, 0.03, 0.01 * BEFORE, 0.01), (0.0, 0.0, 0.0, 0.0)),
}
KEYS = ("tau_rms", "tau_max", "w_rms", "w_max")


@pytest.mark.parametrize("label", list(CASES))
def test_a_benchmark_case_is_judged_by_the_worse_shaft(scene, monkeypatch, label):
    differences, whole, after = CASES[label]
    monkeypatch.setattr(monolithic, "solve", lambda scene, times, *a, **k: SimpleNamespace(times=TIMES,
                                                                                          traces=reference(), info={}))
    case = Case("jacobi", "master", 1e-3)
    timing._judge(case, scene, TIMES, run_with(**differences))
    expected = {**dict(zip(KEYS, whole)), **{f"{k}_after_transient": v for k, v in zip(KEYS, after)}}
    assert case.errors == pytest.approx(expected, rel=1e-12, abs=1e-15), label
    assert case.energy_residual is None           # no energy traces: no residual, not a made-up one
    # the table shows them under their names
    row = table_row(case)
    for key in ("tau_rms", "tau_max", "w_rms", "w_max", "tau_rms_after_transient", "w_rms_after_transient"):
        assert row[key] == case.errors[key]


def test_the_errors_by_signal_and_their_scales(scene):
    # what the run report shows (error_vs_reference): each shaft's own error, scaled by the
    # reference's mean engine speed and mean driven torque
    assert metrics.error_scales(scene, reference()) == {"engine.w": SPEED, "load.w": SPEED,
                                                        "coupling.tau1": TORQUE, "coupling.tau2": TORQUE}
    bump = np.zeros(TIMES.shape)
    bump[700] = -5.0                                 # one point: max 5, RMS 5 sqrt(dt)
    e = metrics.driveline_errors(scene, TIMES, run_with(w1=0.2, w2=0.4, tau1=1.0, tau2=bump), TIMES, reference())
    assert e["engine.w"] == pytest.approx({"rms": 0.2, "max": 0.2, "rms_relative": 0.2 / SPEED,
                                     "max_relative": 0.2 / SPEED, "scale": SPEED}, rel=1e-12)
    assert e["load.w"] == pytest.approx({"rms": 0.4, "max": 0.4, "rms_relative": 0.4 / SPEED,
                                     "max_relative": 0.4 / SPEED, "scale": SPEED}, rel=1e-12)
    assert e["coupling.tau1"]["rms"] == pytest.approx(1.0, rel=1e-12)
    assert e["coupling.tau2"] == pytest.approx({"rms": 5.0 * math.sqrt(1e-3), "max": 5.0,
                                       "rms_relative": 5.0 * math.sqrt(1e-3) / TORQUE,
                                       "max_relative": 5.0 / TORQUE, "scale": TORQUE}, rel=1e-9)
    # after a time: the bump at 0.7 s is in, a bump at 0.3 s is not
    late = metrics.driveline_errors(scene, TIMES, run_with(tau2=np.roll(bump, -400)), TIMES, reference(), after=0.5)
    assert late["coupling.tau2"]["max"] == 0.0 and late["engine.w"]["rms"] == 0.0
    # a variable grid weighs each point by the time it stands for, not by its count
    uneven = np.array([0.0, 0.1, 1.0])
    ref = {n: np.zeros(3) for n in REFERENCE}
    ref["coupling.tau2"] = np.ones(3)
    run = {**ref, "engine.w": np.array([0.0, 3.0, 0.0])}
    e = metrics.errors(uneven, run, uneven, ref, ["engine.w"], {"engine.w": 1.0})
    # trapezoid weights 0.05, 0.5, 0.45 (of 1 s): RMS = 3 sqrt(0.5)
    assert e["engine.w"]["rms"] == pytest.approx(3.0 * math.sqrt(0.5), rel=1e-12)
    # the grids must agree, to 1e-9 s, late in a run as early
    for offset in (1e-3, 5e-9, np.where(TIMES > 0.5, 5e-9, 0.0)):
        with pytest.raises(ValueError, match="same time grid"):
            metrics.errors(TIMES, run_with(), TIMES + offset, reference(), ["engine.w"], {})
    assert metrics.errors(TIMES, run_with(), TIMES + 5e-10, reference(), ["engine.w"], {})["engine.w"]["max"] == 0.0


def test_errors_over_what_both_grids_hold():
    ref = {n: v[:501] for n, v in reference().items()}
    late = run_with(w1=AFTER_TRANSIENT)
    # a run longer than its reference is judged where both are: up to 0.5 s, where w1 is
    # off only at the last point (weight half a step of 0.5 s: RMS sqrt(0.0005 / 0.5))
    e = metrics.errors(TIMES, late, TIMES[:501], ref, ["missing", "engine.w"], {})
    assert e["engine.w"]["max"] == 1.0 and e["engine.w"]["rms"] == pytest.approx(math.sqrt(0.001), rel=1e-12)
    # a name without a scale is judged in its own unit; one the reference lacks is left out
    assert e["engine.w"]["scale"] == 1.0 and e["engine.w"]["rms_relative"] == e["engine.w"]["rms"]
    assert "missing" not in e
    late["only.run"] = np.zeros(TIMES.shape)
    assert list(metrics.errors(TIMES, late, TIMES, reference(), ["only.run", "engine.w"], {})) == ["engine.w"]
    # after a time that is a grid point: that point is in
    bump = run_with(w2=np.where(TIMES == TIMES[500], 2.0, 0.0))
    assert metrics.errors(TIMES, bump, TIMES, reference(), ["load.w"], {}, after=TIMES[500])["load.w"]["max"] == 2.0
    # one point: its difference; two: the mean square of both
    one = metrics.errors(TIMES[:1], run_with(w1=3.0), TIMES[:1], reference(), ["engine.w"], {})
    assert (one["engine.w"]["rms"], one["engine.w"]["max"]) == (3.0, 3.0)
    two = metrics.errors(TIMES[:2], run_with(w1=np.where(TIMES == 0.0, 3.0, 4.0)), TIMES[:2], reference(),
                         ["engine.w"], {})
    assert two["engine.w"]["rms"] == pytest.approx(math.sqrt(12.5), rel=1e-12)
    # a variable grid of four points: trapezoid weights 0.05, 0.15, 0.45, 0.35
    uneven = np.array([0.0, 0.1, 0.3, 1.0])
    for k, weight in enumerate((0.05, 0.15, 0.45, 0.35)):
        run = {"x": np.where(np.arange(4) == k, 2.0, 0.0)}
        assert metrics.errors(uneven, run, uneven, {"x": np.zeros(4)}, ["x"], {})["x"]["rms"] == \
            pytest.approx(2.0 * math.sqrt(weight), rel=1e-12)


def test_errors_scaled_by_a_longer_reference(scene):
    # the scales from another run of the reference (a longer one), not the one compared with
    longer = {**reference(), "engine.w": np.full(TIMES.shape, 80.0)}
    e = metrics.driveline_errors(scene, TIMES, run_with(w1=0.4), TIMES, reference(), scale_reference=longer)
    assert e["engine.w"]["scale"] == 80.0 and e["engine.w"]["rms_relative"] == pytest.approx(0.4 / 80.0, rel=1e-12)


def test_statistics_after_the_transient():
    y = np.full(TIMES.shape, 100.0)                  # before the transient: left out
    keep = TIMES >= TRANSIENT
    y[keep] = [50.0] + [38.0, 42.0] * 250            # the point at the transient itself is in
    mean = (50.0 + 250 * 80.0) / 501
    centred = np.where(keep, 0.0, 100.0)
    centred[keep] = [0.0] + [-2.0, 2.0] * 250
    s = metrics.statistics(TIMES, {"load.w": y, "coupling.tau2": y + 10.0, "engine.w": centred},
                           ["x", "load.w", "coupling.tau2", "engine.w"], TRANSIENT)
    assert s["load.w"] == pytest.approx({"mean": mean, "min": 38.0, "max": 50.0, "amplitude": 6.0,
                                         "unevenness": 12.0 / mean}, rel=1e-12)
    # unevenness is a speed's figure only, and only where the speed has a mean
    assert "unevenness" not in s["coupling.tau2"] and s["coupling.tau2"]["amplitude"] == 6.0
    assert s["engine.w"]["mean"] == 0.0
    assert "unevenness" not in s["engine.w"]
    assert "x" not in s
    # one point after the transient: its value, no spread
    last = metrics.statistics(TIMES, {"load.w": y}, ["load.w"], 1.0)["load.w"]
    assert last == {"mean": 42.0, "min": 42.0, "max": 42.0, "amplitude": 0.0, "unevenness": 0.0}


def test_the_energy_balance(scene):
    # I1 = 0.128, I2 = 0.161 kg m^2 (the scene's)
    t = np.array([0.0, 1.0, 2.0])
    traces = {"engine.w": np.array([40.0, 41.0, 42.0]), "load.w": np.array([40.0, 39.0, 38.0]),
              "engine.engine_work": np.array([100.0, 600.0, 1100.0]), "load.load_work": np.array([50.0, 350.0, 650.0]),
              "coupling.elastic_energy": np.array([5.0, 6.0, 7.0]),
              "coupling.dissipated_power": np.array([10.0, 20.0, 10.0])}
    kinetic = 0.5 * 0.128 * (42.0 ** 2 - 40.0 ** 2) + 0.5 * 0.161 * (38.0 ** 2 - 40.0 ** 2)
    lost = 30.0                                      # trapezoids: (10 + 20)/2 + (20 + 10)/2
    residual = 1000.0 - 600.0 - kinetic - 2.0 - lost
    b = metrics.energy_balance(scene, t, traces)
    assert b == pytest.approx({"work_in_J": 1000.0, "work_out_J": 600.0, "kinetic_change_J": kinetic,
                               "elastic_change_J": 2.0, "dissipated_J": lost, "residual_J": residual,
                               "residual_relative": abs(residual) / 1000.0}, rel=1e-12)
    # the cumulative dissipation, where given (the reference's) or recorded (a streamed run), is taken as it is
    given = metrics.energy_balance(scene, t, traces, dissipated=np.array([1.0, 4.0, 9.0]))
    assert given["dissipated_J"] == 8.0 and given["residual_J"] == pytest.approx(residual + lost - 8.0, rel=1e-12)
    recorded = metrics.energy_balance(scene, t, {**traces, "coupling.dissipated_energy": np.array([1.0, 4.0, 9.0])})
    assert recorded["dissipated_J"] == 8.0
    # no work in: no share of it
    idle = metrics.energy_balance(scene, t, {**traces, "engine.engine_work": np.full(3, 100.0)})
    assert idle["work_in_J"] == 0.0 and math.isnan(idle["residual_relative"])


def test_the_spectrums_two_components():
    # 4096 points over 2 pi s: every whole rad/s is a bin
    n = 4096
    t = np.arange(n) * (2.0 * np.pi / n)
    torque = 100.0 + 5.0 * np.sin(40.0 * t) + 2.0 * np.cos(420.0 * t)
    omega, amplitude = metrics.amplitude_spectrum(t, torque)
    assert omega[40] == pytest.approx(40.0) and omega[420] == pytest.approx(420.0)
    # np.hanning's window (symmetric, not periodic) leaks 1/n of a bin's amplitude
    assert amplitude[40] == pytest.approx(5.0, rel=2e-3) and amplitude[420] == pytest.approx(2.0, rel=2e-3)
    assert amplitude[0] < 1e-3          # the mean removed (kept, the 100 N*m would read 200)
    found = metrics.spectral_components(t, {"load.w": np.full(n, 40.0), "coupling.tau2": torque},
                                        ["coupling.tau2"], "load.w")
    assert found["rotation_frequency_rad_s"] == 40.0
    assert found["coupling.tau2"]["rotation"]["frequency_rad_s"] == pytest.approx(40.0)
    assert found["coupling.tau2"]["rotation"]["amplitude"] == pytest.approx(5.0, rel=2e-3)
    assert found["coupling.tau2"]["band"]["frequency_rad_s"] == pytest.approx(420.0)
    assert found["coupling.tau2"]["band"]["amplitude"] == pytest.approx(2.0, rel=2e-3)


def test_the_spectrum_after_the_transient_and_around_a_reversed_shaft():
    # 8192 points over 4 pi s; after the transient (2 pi s) 4096 of them, every whole rad/s a bin
    n = 8192
    t = np.arange(n) * (2.0 * np.pi / 4096)
    transient = 2.0 * np.pi
    torque = (100.0 + 5.0 * np.sin(38.0 * t) + 7.0 * np.sin(20.0 * t) + 9.0 * np.sin(60.0 * t)
              + 2.0 * np.cos(420.0 * t) + np.where(t < transient, 30.0 * np.sin(40.0 * t), 0.0))
    speed = np.where(t < transient, -10.0, -40.0)      # its mean after the transient only
    found = metrics.spectral_components(t, {"load.w": speed, "coupling.tau2": torque},
                                        ["missing", "coupling.tau2"], "load.w", transient)
    # the shaft turns backwards at 40 rad/s: its frequency's window is 36...44 rad/s; the
    # 40 rad/s tone of the transient, the 20 and 60 rad/s ones outside the window are not it
    assert found["rotation_frequency_rad_s"] == -40.0
    rotation = found["coupling.tau2"]["rotation"]
    assert rotation["frequency_rad_s"] == pytest.approx(38.0) and rotation["amplitude"] == pytest.approx(5.0, rel=2e-3)
    assert found["coupling.tau2"]["band"]["amplitude"] == pytest.approx(2.0, rel=2e-3)


def test_a_spectrum_of_a_variable_step_trace_and_of_a_short_one():
    # a variable-step trace (1 ms, then 2 ms steps) is put on a grid of its median step first:
    # read as if evenly spaced, its second half would play the tone at twice its frequency
    t = np.concatenate([np.arange(0.0, 3.0, 1e-3), np.arange(3.0, 6.0, 2e-3)])
    omega, amplitude = metrics.amplitude_spectrum(t, 5.0 * np.sin(40.0 * t))
    assert omega[1] - omega[0] == pytest.approx(2.0 * np.pi / (len(omega) * 2 - 2) / 1e-3, rel=1e-3)
    peak = np.argmax(amplitude)
    assert omega[peak] == pytest.approx(40.0, abs=omega[1]) and amplitude[peak] == pytest.approx(5.0, rel=0.05)
    # eight points are a spectrum, seven are none
    eight = np.arange(8) * 1e-3
    assert len(metrics.amplitude_spectrum(eight, np.sin(eight))[0]) == 5
    assert [len(a) for a in metrics.amplitude_spectrum(eight[:7], np.sin(eight[:7]))] == [0, 0]
