"""The load shaft's stop, hold, breakaway and second stop, alone in fmpy, in both interfaces
and both FMI editions, against the motion worked out by hand.

The shaft (I = 0.161 kg*m^2, w = 10 rad/s at the start) is driven by tau = 400 N*m against a
brake (``load_direction = "resistive"``) of 700 N*m, released to 300 N*m over 0.30-0.31 s and
applied again over 0.60-0.61 s, with Coulomb friction Fc = 5 N*m and breakaway 8 N*m:

* slipping forwards, I dw/dt = 400 - 700 - 5 = -305: stops at t1 = 10 I / 305 = 5.279 ms;
* held while |net| = 400 <= brake + 8; the brake 700 - 40000 (t - 0.3) reaches 392 at
  tb = 0.3 + 308/40000 = 0.3077 s: it breaks away forwards (the direction of the net torque);
* slipping, I dw/dt = 400 - brake - 5: 40000 (t - 0.3) - 305 up to 0.31 s, 95 to 0.6 s,
  95 - 40000 (t - 0.6) to 0.61 s, -305 after: stops again at t2 = 0.61 + I w(0.61) / 305
  = 0.6973 s and is held (400 <= 708) to the end.
"""
from __future__ import annotations

import fmpy
import numpy as np
import pytest

from harness.paths import fmi3_dir

INERTIA, DRIVE, FRICTION, HOLD_EXTRA, W0 = 0.161, 400.0, 5.0, 8.0, 10.0
PARAMETERS = {"load_kind": "table", "table": "0:700; 0.3:700; 0.31:300; 0.6:300; 0.61:700",
              "load_direction": "resistive", "friction_torque": FRICTION, "breakaway_torque": HOLD_EXTRA,
              "inertia": INERTIA, "w_start": W0}
RAMP = 40000.0                                      # N*m/s, the brake's slope on its ramps
T1 = W0 * INERTIA / 305.0
TB = 0.3 + 308.0 / RAMP


def speed(t: float) -> float:
    """The shaft's speed by hand (the module docstring)."""
    if t <= T1:
        return W0 - 305.0 * t / INERTIA
    if t <= TB:
        return 0.0
    s = min(t, 0.31)
    w = (0.5 * RAMP * ((s - 0.3) ** 2 - (TB - 0.3) ** 2) - 305.0 * (s - TB)) / INERTIA
    if t <= 0.31:
        return w
    w += 95.0 * (min(t, 0.6) - 0.31) / INERTIA
    if t <= 0.6:
        return w
    s = min(t, 0.61)
    w += (95.0 * (s - 0.6) - 0.5 * RAMP * (s - 0.6) ** 2) / INERTIA
    if t <= 0.61:
        return w
    return max(w - 305.0 * (t - 0.61) / INERTIA, 0.0)


def t2() -> float:
    return 0.61 + INERTIA * speed(0.61) / 305.0


@pytest.mark.parametrize("edition", ["FMI 2.0", "FMI 3.0"])
@pytest.mark.parametrize("kind", ["ModelExchange", "CoSimulation"])
def test_stop_hold_breakaway_and_stop_again(fmu_dir, edition, kind):
    folder = fmu_dir if edition == "FMI 2.0" else fmi3_dir(fmu_dir)
    drive = np.array([(0.0, DRIVE, 0.0, 0.0), (10.0, DRIVE, 0.0, 0.0)],
                     dtype=[("time", float), ("tau", float), ("tau_rate", float), ("tau_accel", float)])
    result = fmpy.simulate_fmu(str(folder / "LoadShaft.fmu"), fmi_type=kind, solver="CVode", stop_time=1.0,
                               output_interval=1e-3, step_size=1e-3, relative_tolerance=1e-8, input=drive,
                               output=["w", "a", "load_torque"], start_values=PARAMETERS)
    t, w = result["time"], result["w"]
    assert 0.005 < T1 < 0.006 and 0.3076 < TB < 0.3078 and 0.69 < t2() < 0.70
    # held: at rest exactly, static friction giving the drive back
    for start, end in ((0.006, 0.307), (t2() + 1e-3, 1.0)):
        held = (t >= start) & (t <= end)
        assert np.all(w[held] == 0.0), f"held over {start:.4g}-{end:.4g} s, yet w = {w[held][w[held] != 0][:2]}"
        assert np.all(result["a"][held] == 0.0) and np.all(result["load_torque"][held] == DRIVE)
    # broke away forwards, at the breakaway worked out by hand
    assert t[np.argmax((t > 0.3) & (w > 0.0))] == pytest.approx(0.308, abs=1e-9)
    # the whole motion: CVode's 1e-8 and the FMU's located events leave well under 1e-6 of the
    # largest speed (172 rad/s); a stop or breakaway a step off moves it by 0.3 rad/s and more
    exact = np.array([speed(x) for x in t])
    assert np.max(np.abs(w - exact)) <= 1e-6 * np.max(exact)
