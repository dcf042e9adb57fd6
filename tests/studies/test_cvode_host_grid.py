"""The CVODE host's output grid (harness/studies/cvode_host.py): a row every ``step`` from 0,
and the last exactly at ``stop`` - also where ``stop / step`` is no exact binary number
(0.7 s at 1 ms: 0.7 / 0.001 = 699.999..., 701 rows ending at 0.7 s; 0.3 s at 0.1 s:
2.999..., 4 rows) - a stop that is no whole number of steps (0.25 s at 0.1 s) ends on a shorter last step -
with each row's values those of the closed form of the FMU's motion
at that row's time.

The FMU: the load shaft's Model Exchange edition alone, its drive torque held at
``TAU`` against a constant resistance ``MEAN``, no friction: J dw/dt = TAU - MEAN, so
w(t) = w0 + (TAU - MEAN) t / J and phi(t) = phi0 + w0 t + (TAU - MEAN) t**2 / (2 J)."""
from __future__ import annotations

import numpy as np
import pytest

from harness.studies import cvode_host, me_hosts

J, TAU, MEAN, W0, PHI0 = 0.5, 30.0, 10.0, 3.0, 0.25
START = {"load_kind": "constant", "mean_torque": MEAN, "inertia": J, "w_start": W0, "phi_start": PHI0, "tau": TAU}


@pytest.mark.parametrize("fmi", [2, 3])
@pytest.mark.parametrize("stop,step,rows", [(0.7, 1e-3, 701), (0.3, 0.1, 4), (0.5, 0.1, 6), (0.07, 0.01, 8),
                                            (0.25, 0.1, 4)])
def test_the_rows_are_every_step_and_the_last_is_the_stop(fmi, stop, step, rows, fmu_dir):
    path = (fmu_dir if fmi == 2 else me_hosts.fmi3_dir(fmu_dir)) / "LoadShaft.fmu"
    run = cvode_host.run(path, fmi, START, ["phi", "w"], stop, step)
    assert len(run.times) == rows
    assert run.times[-1] == stop and run.t_end == stop
    grid = np.minimum(np.arange(rows) * step, stop)     # a stop that is no whole number of steps: a last, shorter one
    assert np.allclose(run.times, grid, rtol=0.0, atol=1e-12)
    assert np.all(np.diff(run.times) > 0)
    a = (TAU - MEAN) / J
    t = run.times
    assert np.allclose(run.outputs["w"], W0 + a * t, rtol=1e-6, atol=1e-8)
    assert np.allclose(run.outputs["phi"], PHI0 + W0 * t + a * t ** 2 / 2, rtol=1e-6, atol=1e-8)
    assert run.events == 0 and run.restarts == 0
