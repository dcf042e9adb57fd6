"""The revolution helpers behind the run plots over the shaft's angle and the run-up
table (harness/judges/revolutions.py), on synthetic traces whose answers are known."""
from __future__ import annotations

import math

import numpy as np
import pytest

from harness.judges import revolutions


def test_the_last_whole_revolution_of_a_steady_shaft():
    # 10 rad/s for 2 s, sampled every 1 ms: 3.18 revolutions, the third ends at t = 6 pi/10
    t = np.arange(0.0, 2.0 + 1e-12, 1e-3)
    phi = 10.0 * t
    window = revolutions.last_revolutions(phi, 1)
    assert t[window.start] == pytest.approx(4 * math.pi / 10, abs=1e-3)
    assert t[window.stop - 1] == pytest.approx(6 * math.pi / 10, abs=1e-3)
    angle = revolutions.revolution_angle(phi, window)
    assert angle[0] == 0.0 and angle[-1] == pytest.approx(2 * math.pi, abs=0.01)
    three = revolutions.last_revolutions(phi, 3)
    assert t[three.start] == 0.0 and three.stop == window.stop
    assert revolutions.last_revolutions(phi, 4) == slice(0, 0)     # only 3 whole ones


def test_a_fluctuating_and_a_reversed_shaft():
    t = np.linspace(0.0, 1.0, 20001)
    phi = -(39.0 * t + 0.3 * np.sin(39.0 * t))        # backwards, speed 39 +- 11.7 rad/s
    window = revolutions.last_revolutions(phi, 2)
    turned = phi[window.stop - 1] - phi[window.start]
    assert turned == pytest.approx(-4 * math.pi, abs=0.02)
    # the mean over whole revolutions is the mean speed whatever the fluctuation's phase
    assert revolutions.mean_speed(t, phi, 2) == pytest.approx(-39.0, rel=2e-3)


def test_settling_time():
    t = np.linspace(0.0, 1.0, 1001)
    w = 40.0 * (1.0 - np.exp(-t / 0.1))       # first order, tau = 0.1 s: within 2 % after 0.1 ln 50
    assert revolutions.settling_time(t, w, 40.0, 0.02) == pytest.approx(0.1 * math.log(50.0), abs=1.5e-3)
    assert revolutions.settling_time(t, np.full_like(t, 40.0), 40.0) == 0.0
    assert math.isnan(revolutions.settling_time(t, 39.0 * t, 40.0))   # 2.5 % short at the end


def _synthetic_run(stop: float, w2: float = 10.0):
    """kavz685's names on made-up traces: the driven shaft at ``w2`` rad/s, U12 and the
    torques known functions of its angle (no phi recorded: the angle is integrated)."""
    from harness.description import scene
    spec = scene.load("kavz685")
    t = np.arange(0.0, stop + 5e-4, 1e-3)
    phi = w2 * t
    traces = {"load.w": np.full_like(t, w2), "engine.w": w2 * (1.0 + 0.01 * np.cos(2 * phi)),
              "engine.a": -0.02 * w2 * w2 * np.sin(2 * phi), "load.a": np.zeros_like(t),
              "coupling.U12": 1.0 + 0.01 * np.cos(2 * phi), "coupling.tau1": -(100.0 + 5.0 * np.sin(phi)),
              "coupling.tau2": 100.0 + 6.0 * np.sin(phi)}
    return spec, t, traces


def test_the_plots_over_the_angle_show_the_last_revolutions():
    from harness.formats import report
    spec, t, traces = _synthetic_run(2.0)          # 3.18 revolutions at 10 rad/s
    views = report.angle_views(spec, t, traces)
    one = views["revolution"]
    assert one["count"] == 1
    assert one["angle"][0] == 0.0 and one["angle"][-1] == pytest.approx(360.0, abs=0.6)   # 1 ms = 0.57 deg
    assert one["t"][0] == pytest.approx(4 * math.pi / 10, abs=1e-3)                     # the third revolution
    # the plotted data are the traces over that revolution, -tau1 as the drive side transmits it
    phi = 10.0 * one["t"]                             # the angle of each plotted sample
    np.testing.assert_allclose(one["angle"], np.degrees(phi - phi[0]), atol=1e-9)
    np.testing.assert_allclose(one["U12"], 1.0 + 0.01 * np.cos(2 * phi), atol=1e-9)
    np.testing.assert_allclose(one["-tau1"], 100.0 + 5.0 * np.sin(phi), atol=1e-9)
    np.testing.assert_allclose(one["tau2"], 100.0 + 6.0 * np.sin(phi), atol=1e-9)
    many = views["revolutions"]
    assert many["count"] == report.REVOLUTIONS_SHOWN == 3
    assert many["angle"][-1] == pytest.approx(1080.0, abs=0.6) and set(many) >= {"w1", "w2", "a1", "a2"}
    # a shorter run shows what it has; one with no whole revolution shows nothing
    spec, t, traces = _synthetic_run(1.0)           # 1.59 revolutions
    views = report.angle_views(spec, t, traces)
    assert views["revolutions"]["count"] == 1 and views["revolution"]["count"] == 1
    spec, t, traces = _synthetic_run(0.5)
    assert report.angle_views(spec, t, traces) == {"revolution": None, "revolutions": None, "u12": None}


def test_the_plot_files_over_the_angle(tmp_path):
    from harness.formats import report
    spec, t, traces = _synthetic_run(2.0)
    report.plot_over_angle(tmp_path, spec, t, traces, "synthetic")
    for name in ("revolution.png", "revolutions.png"):
        data = (tmp_path / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000, name
