"""The unsplit driveline integrated by SUNDIALS CVODE (scikit-sundae's binding): BDF for
stiff scenes, Adams for lightly damped ones, with the physics' analytic Jacobian
(``lever.physics.driveline.Driveline.jacobian``) or CVODE's own difference quotients.

The right-hand side is the monolithic reference's (``Driveline.derivatives``); only the
integrator differs.  ``monolithic.solve`` takes it as ``method="CVODE-BDF"`` or
``"CVODE-Adams"`` (docs/record/decisions.md: why CVODE, and why this binding).
"""
from __future__ import annotations

import numpy as np

from harness.judges.solution import ReferenceUnavailable

#: scipy-style method names ``monolithic.solve`` passes on to CVODE
METHODS = {"CVODE-BDF": "BDF", "CVODE-Adams": "Adams"}

#: internal steps CVODE may take between two output times before it gives up (its own
#: default, 500, is too few for a stiff scene's start on a coarse output grid)
MAX_STEPS = 1_000_000


def integrate(driveline, times: np.ndarray, y0, method: str = "BDF", rtol: float = 1e-8, atol: float = 1e-8,
              first_step: float = 0.0, analytic_jacobian: bool = True):
    """``(t, y, counts)``: the driveline's state at ``times`` (columns), and ``counts`` the
    right-hand-side evaluations (all of them, the difference quotients' too: counted
    here, not by CVODE) and Jacobian evaluations."""
    from sksundae.cvode import CVODE

    counts = {"rhs": 0, "jacobian": 0}
    derivatives, jacobian = driveline.derivatives, driveline.jacobian

    def rhs(t, y, yp):
        counts["rhs"] += 1
        yp[:] = derivatives(t, y)

    def jac(t, y, yp, matrix):
        counts["jacobian"] += 1
        matrix[:, :] = jacobian(t, y)

    options = dict(method=method, rtol=rtol, atol=atol, first_step=first_step, max_num_steps=MAX_STEPS)
    if analytic_jacobian:
        options["jacfn"] = jac
    solver = CVODE(rhs, **options)
    times = np.asarray(times, dtype=float)
    solution = solver.solve(times, np.asarray(y0, dtype=float))
    if not solution.success:
        raise ReferenceUnavailable(f"CVODE ({method}) failed at t = {float(np.atleast_1d(solution.t)[-1]):.6g} s: "
                                   f"{solution.message}")
    if not analytic_jacobian:
        counts["jacobian"] = int(solution.njev)
    return np.asarray(solution.t), np.asarray(solution.y).T, counts
