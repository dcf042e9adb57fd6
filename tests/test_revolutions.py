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
