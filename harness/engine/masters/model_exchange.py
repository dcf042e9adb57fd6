"""The strongly coupled master: the FMUs in Model Exchange, their states integrated together
by SUNDIALS CVODE (scikit-sundae), as one system of ordinary differential equations.

No communication step splits the coupling: the right-hand side at ``(t, x)`` sets the time
and every FMU's continuous states, runs the system's compiled propagation (each FMU's
outputs read in dependency order and written to the inputs they feed, the direct-feedthrough
ones after their sources) and reads each FMU's derivatives.  CVODE chooses its own steps
and order to ``tolerance``; the run is recorded on its output grid (the communication step
the run is given) from CVODE's dense output, so the traces have the grid of every other
master's.

The system Jacobian comes from the FMUs' ``fmi2GetDirectionalDerivative``: each FMU's
partials of its derivatives ``f`` and connected outputs ``y = g(x, u)`` with respect to its
states ``x`` and connected inputs ``u`` (one call per state and input), assembled as

    J = df/dx + df/du (I - dg/du)^-1 dg/dx        (u = y along the connections)

or, with ``jacobian="difference-quotients"``, CVODE's own difference quotients of the
right-hand side (one evaluation per state each time it forms a Jacobian).  A scene with an
algebraic loop between direct-feedthrough FMUs is refused before it runs
(``harness.engine.system.dependency_order`` names the loop); without one ``dg/du`` is
nilpotent, so ``I - dg/du`` is invertible and one propagation in dependency order exact.

Events: the FMUs' event indicators are CVODE's root functions - those that can change sign:
an FMU that declares how many of its indicators can (``live_event_indicators``, an Integer
calculated parameter: ours do) has only those searched, since each root-function
evaluation costs an evaluation of every FMU at a point of its own; at a root, and at a time
event an FMU announces (``nextEventTime``), every FMU enters event mode, the discrete states
are updated until none needs another round (``fmi2NewDiscreteStates``, the values
propagated after each), the FMUs return to continuous time and CVODE restarts from the
states they report.

Adams or BDF (``method="auto"``, the default): ``choose_method`` on the eigenvalues of the
system Jacobian at the start - BDF where a mode decays much faster than anything else in
the system moves (stiff), Adams otherwise (BDF damps a lightly damped oscillation
numerically).  ``lever run`` passes the choice the linear stability analysis makes on the
scene's driveline (``harness.judges.stability.cvode_method``, the same rule on its
two-inertia model) and says it in the run's notes; the run's counters say which and why (``method``, ``method_reason``), and what it took:
``rhs`` right-hand sides (the difference quotients' included), ``jacobians`` CVODE formed,
``directional_jacobians`` assembled from directional derivatives (the method choice's one
included), ``root_functions`` searched and ``dead_indicators`` left out, ``events`` and
``time_events``.
"""
from __future__ import annotations

import ctypes
import math
import os

import numpy as np

from harness.engine.masters.base import Master, MasterFailure
from harness.engine.me_component import set_time_call
from harness.engine.system import MODEL_EXCHANGE, System

#: internal steps CVODE may take between two output points before it gives up
MAX_STEPS = 1_000_000
#: rounds of fmi2NewDiscreteStates at one event before the event is said not to settle
MAX_EVENT_ROUNDS = 100
#: ``choose_method``: a mode decaying this many times faster than the system's fastest
#: other motion makes the system stiff
STIFF_RATIO = 10.0
#: CVODE's absolute tolerance as a share of its relative one (the monolithic CVODE's too)
ATOL_SHARE = 1e-2
METHODS = ("auto", "BDF", "Adams")
JACOBIANS = ("analytic", "difference-quotients")


def choose_method(eigenvalues, what: str = "the system") -> tuple[str, str]:
    """``(method, why)``: CVODE's BDF where a mode decays at least ``STIFF_RATIO`` times
    faster than anything else in ``what`` moves (the fastest other mode's rate, any
    mode's frequency), Adams otherwise.  Adams' stability region would hold its steps to
    the fast decay; BDF's takes it in any step, but damps a lightly damped oscillation
    numerically, which Adams follows."""
    lam = np.asarray(eigenvalues, dtype=complex)
    modes = [z for z in lam if z.imag >= 0.0 and abs(z) > 0.0]
    if not modes:
        return "Adams", f"{what} has no mode that moves (all eigenvalues zero): nothing stiff"
    fast = max(modes, key=lambda z: -z.real)
    others = [abs(z) for z in modes if z is not fast]
    scale = max([abs(z.imag) for z in modes] + others + [0.0])
    decay = -fast.real
    if decay > 0.0 and (scale == 0.0 or decay >= STIFF_RATIO * scale):
        return "BDF", (f"stiff: a mode of {what} decays at {decay:.4g} 1/s, "
                       + (f"{decay / scale:.3g} times faster than anything else in it moves ({scale:.4g} 1/s)"
                          if scale else "and nothing else in it moves")
                       + "; Adams' steps would be held to that decay, BDF's are not")
    return "Adams", (f"not stiff: the fastest decay in {what}, {max(decay, 0.0):.4g} 1/s, is less than "
                     f"{STIFF_RATIO:g} times the fastest motion in it ({scale:.4g} 1/s); Adams follows a lightly "
                     "damped oscillation that BDF would damp numerically")


class ModelExchangeCvodeMaster(Master):
    """The FMUs' equations integrated together by CVODE (see the module docstring).

    Options: ``tolerance`` (CVODE's relative tolerance, default 1e-6; the absolute one is
    ``ATOL_SHARE`` of it), ``method`` ("auto", "BDF", "Adams"), ``jacobian`` ("analytic":
    from the FMUs' directional derivatives; "difference-quotients": CVODE's own),
    ``max_step`` (CVODE's largest internal step [s], default unbounded)."""

    name = "me-cvode"
    order = 0           # variable order, chosen by CVODE to its tolerance
    description = ("Model Exchange: the FMUs' states integrated together by CVODE (Adams or BDF), "
                   "analytic Jacobian from directional derivatives, events by root finding")
    interface = MODEL_EXCHANGE
    reads_recorded = True
    options = {"tolerance": 1e-6, "method": "auto", "jacobian": "analytic", "max_step": None}

    def __init__(self, system: System, step: float, **options):
        super().__init__(system, step, **options)
        if getattr(system, "interface", None) != MODEL_EXCHANGE:
            raise MasterFailure(f"master '{self.name}' needs the FMUs instantiated for Model Exchange "
                                "(System(interface=MODEL_EXCHANGE))")
        if not (isinstance(self.tolerance, (int, float)) and 0.0 < self.tolerance < 1.0):
            raise ValueError(f"option 'tolerance' = {self.tolerance!r} is outside its allowed range (0, 1) "
                             "(CVODE's relative tolerance)")
        if self.method not in METHODS:
            raise ValueError(f"option 'method' = {self.method!r}: one of {', '.join(METHODS)}")
        if self.jacobian not in JACOBIANS:
            raise ValueError(f"option 'jacobian' = {self.jacobian!r}: one of {', '.join(JACOBIANS)}")
        if self.max_step is not None and not (isinstance(self.max_step, (int, float)) and self.max_step > 0):
            raise ValueError(f"option 'max_step' = {self.max_step!r}: a time in seconds > 0")
        self.n_rhs = self.n_jacobians = self.n_events = self.n_time_events = 0
        # CVODE's own Jacobian count (its statistics restart with it at every event)
        self._cvode_jacobians = self._cvode_jacobians_now = 0
        components = [system.components[n] for n in system.scene.components]
        self._all = components
        self._with_states = [c for c in components if c.nx]
        live = {c.name: c.live_indicators() for c in components if c.nz}
        self._with_indicators = [c for c in components if live.get(c.name)]
        self._slices, first = [], 0
        for c in self._with_states:
            self._slices.append((c, first, first + c.nx, np.ctypeslib.as_array(c.x)[:c.nx]))
            first += c.nx
        self.nx = first
        self._compile_point()
        self._zslices, first = [], 0
        for c in self._with_indicators:
            n = live[c.name]
            self._zslices.append((c, first, first + n, np.ctypeslib.as_array(c.z)[:n]))
            first += n
        self.nz = first
        #: event indicators the FMUs declare but say cannot change sign, left out of the search
        self.n_dead_indicators = sum(c.nz for c in components) - first
        # a right-hand side reads of each FMU only what the connections carry; the recorded
        # outputs are read at the output points alone
        self._plan, self._recorded_reads = system.connection_plan()
        self._point_t = None
        self._point_bytes = b""
        self._next_time_event = math.inf
        # the FMUs leave initialization in event mode: settle the discrete states there
        self._event_rounds(self.t)
        for c in components:
            c.enter_continuous_time_mode()
        y0 = self._read_states()
        self._build_jacobian_plan()
        self.method_reason = None
        if self.method == "auto":
            self.method, self.method_reason = choose_method(np.linalg.eigvals(self._jacobian(self.t, y0))
                                                            if self.nx else [], f"scene '{system.scene.name}'")
        self._solver = self._make_solver()
        self._restart(self.t, y0)

    # -- the right-hand side -------------------------------------------------------------------
    def _compile_point(self):
        """The calls a point makes, made once: each FMU's fmi2SetTime; its
        fmi2SetContinuousStates from, and fmi2GetDerivatives into, its rows of one buffer
        for the whole system (one copy of CVODE's vector each way, not one per FMU)."""
        n = max(self.nx, 1)
        self._x_all, self._dx_all = (ctypes.c_double * n)(), (ctypes.c_double * n)()
        self._x_view = np.ctypeslib.as_array(self._x_all)[:self.nx]
        self._dx_view = np.ctypeslib.as_array(self._dx_all)[:self.nx]

        def rows(buffer, first):
            return ctypes.cast(ctypes.byref(buffer, first * ctypes.sizeof(ctypes.c_double)),
                               ctypes.POINTER(ctypes.c_double))

        self._time_calls = tuple((c, c.me_counts, c.me_raw.set_time, c.me_raw.handle) for c in self._all)
        self._state_calls = tuple((c, c.me_counts, c.me_raw.set_states, c.me_raw.handle, rows(self._x_all, a),
                                   c.me_raw.nx) for c, a, _, _ in self._slices)
        self._derivative_calls = tuple((c, c.me_counts, c.me_raw.get_derivatives, c.me_raw.handle,
                                        rows(self._dx_all, a), c.me_raw.nx) for c, a, _, _ in self._slices)

    def _set_point(self, t, y):
        """Time and states of every FMU at ``(t, y)``, the values propagated; skipped where
        the system is there already (CVODE asks the Jacobian and the root functions at the
        point of its last right-hand side)."""
        point = y.tobytes()     # a tenth of np.array_equal's cost; equal bytes are equal states
        if t == self._point_t and point == self._point_bytes:
            return
        if t != self._point_t:
            time = ctypes.c_double(t)
            for c, counts, set_time, handle in self._time_calls:
                counts["time"] += 1
                status = set_time(handle, time)
                if status > 1:
                    c.fail(set_time_call(t), status)
                c.time = t
        self._x_view[:] = y
        for c, counts, set_states, handle, rows, n in self._state_calls:
            counts["states"] += 1
            status = set_states(handle, rows, n)
            if status > 1:
                c.fail("fmi2SetContinuousStates", status)
        self.system.propagate_with(self._plan)
        self._point_t = t
        self._point_bytes = point

    def _rhs(self, t, y, yp):
        self.n_rhs += 1
        total = sum(y.tolist())         # finite unless a state is not (or the sum overflows)
        if total - total != 0.0 and not np.isfinite(y).all():
            raise MasterFailure(f"{self.name}: CVODE tried non-finite states at t = {t:.9g} s")
        self._set_point(t, y)
        for c, counts, derivatives, handle, rows, n in self._derivative_calls:
            counts["derivatives"] += 1
            status = derivatives(handle, rows, n)
            if status > 1:
                c.fail("fmi2GetDerivatives", status)
        yp[:] = self._dx_view

    def _roots(self, t, y, events):
        self._set_point(t, y)
        for c, a, b, z in self._zslices:
            c.indicators()
            events[a:b] = z

    def _read_states(self) -> np.ndarray:
        y = np.empty(self.nx)
        for c, a, b, x in self._slices:
            c.get_states()
            y[a:b] = x
        return y

    # -- the Jacobian from directional derivatives ----------------------------------------------
    def _build_jacobian_plan(self):
        """For each FMU, one fmi2GetDirectionalDerivative per known (state or connected
        input), its unknowns the state derivatives and the connected outputs.  Each call
        writes its row of one result buffer; where each value goes in the blocks
        ``[[df/dx, df/du], [dg/dx, dg/du]]`` (one matrix, the rows the derivatives and the
        connections, the columns the states and the connections) is worked out here, so
        that a Jacobian is the calls and one scatter."""
        system = self.system
        connections = list(system.scene.connections)
        nx = self.nx
        self._nk = nk = len(connections)
        state_column = {}
        for c, a, b, _ in self._slices:
            for i, name in enumerate(c.state_names):
                state_column[(c.name, name)] = a + i
        plan = []           # (component, unknowns, n, known, rows of the blocks per unknown, column)
        for c in self._all:
            outputs = []            # distinct connected outputs, each with its connections
            for k, conn in enumerate(connections):
                if conn.source == c.name:
                    for entry in outputs:
                        if entry[0] == conn.output:
                            entry[1].append(k)
                            break
                    else:
                        outputs.append((conn.output, [k]))
            unknowns = [c.vr(n) for n in c.derivative_names] + [c.vr(o) for o, _ in outputs]
            if not unknowns:
                continue
            knowns = [(c.vr(n), state_column[(c.name, n)]) for n in c.state_names]
            knowns += [(c.vr(conn.input), nx + k) for k, conn in enumerate(connections) if conn.target == c.name]
            first = next((a for cc, a, *_ in self._slices if cc is c), 0)
            rows = [[first + i] for i in range(len(c.derivative_names))] + [[nx + k for k in ks] for _, ks in outputs]
            n = len(unknowns)
            vrs = (ctypes.c_uint * n)(*unknowns)
            for vr, column in knowns:
                plan.append((c, vrs, ctypes.c_size_t(n), (ctypes.c_uint * 1)(vr), rows, column))
        width = max([p[2].value for p in plan] + [1])
        self._results = np.zeros((max(len(plan), 1), width))
        row_bytes = width * ctypes.sizeof(ctypes.c_double)
        base = self._results.ctypes.data
        self._calls, targets = [], ([], [], [])
        for i, (c, vrs, n, known, rows, column) in enumerate(plan):
            out = ctypes.cast(ctypes.c_void_p(base + i * row_bytes), ctypes.POINTER(ctypes.c_double))
            self._calls.append((c, c.me_counts, c.me_raw.directional, c.me_raw.handle, vrs, n, known, out))
            for j, block_rows in enumerate(rows):
                for r in block_rows:
                    targets[0].append(r)
                    targets[1].append(column)
                    targets[2].append(i * width + j)
        self._scatter = tuple(np.array(t, dtype=np.intp) for t in targets)
        self._blocks = np.zeros((nx + nk, nx + nk))
        self._seed = (ctypes.c_double * 1)(1.0)
        self._one = ctypes.c_size_t(1)

    def _jacobian(self, t, y) -> np.ndarray:
        self.n_jacobians += 1
        self._set_point(t, y)
        one, seed = self._one, self._seed
        for c, counts, directional, handle, unknowns, n, known, out in self._calls:
            counts["directional"] += 1
            status = directional(handle, unknowns, n, known, one, seed, out)
            if status > 1:
                c.fail("fmi2GetDirectionalDerivative", status)
        rows, columns, values = self._scatter
        blocks = self._blocks
        blocks[rows, columns] = self._results.ravel()[values]
        nx, nk = self.nx, self._nk
        a_xx = blocks[:nx, :nx].copy()      # contiguous, as the products below have always been given
        if not nk:
            return a_xx
        return a_xx + blocks[:nx, nx:].copy() @ np.linalg.solve(np.eye(nk) - blocks[nx:, nx:], blocks[nx:, :nx].copy())

    def _jacobian_callback(self, t, y, yp, matrix):
        matrix[:, :] = self._jacobian(t, y)

    # -- CVODE ------------------------------------------------------------------------------------
    def _make_solver(self):
        from sksundae.cvode import CVODE

        # SUNDIALS prints its warnings (e.g. a root function still zero just after an event,
        # which CVODE then leaves out for a step) to stdout, into what a command prints as
        # its result (``lever fingerprint``): to stderr, unless the user sent them elsewhere.
        # Read when the solver's context is made, below.
        os.environ.setdefault("SUNLOGGER_WARNING_FILENAME", "stderr")

        options = dict(method=self.method, rtol=float(self.tolerance), atol=ATOL_SHARE * float(self.tolerance),
                       max_num_steps=MAX_STEPS, max_step=float(self.max_step or 0.0))
        if self.jacobian == "analytic":
            options["jacfn"] = self._jacobian_callback
        if self.nz:
            def roots(t, y, events):        # a function: scikit-sundae reads attributes off it
                self._roots(t, y, events)
            roots.terminal = [True] * self.nz
            roots.direction = [0] * self.nz
            options.update(eventsfn=roots, num_events=self.nz)
        return CVODE(self._rhs, **options)

    def _restart(self, t, y):
        """CVODE (re)started at ``(t, y)`` (the start, and after every event)."""
        self._tc = t
        self._y = np.array(y, dtype=float)
        self._cvode_jacobians += self._cvode_jacobians_now
        self._cvode_jacobians_now = 0
        if self.nx:
            self._solver.init_step(t, self._y)

    def _step_impl(self, t, h):
        target = t + h
        y = self._y
        while self.nx and self._tc < target:
            tstop = min(self._next_time_event, self.t_end)
            result = self._solver.step(target, method="normal", tstop=tstop)
            if not result.success:
                raise MasterFailure(f"{self.name}: CVODE ({self.method}, tolerance {self.tolerance:g}) stopped at "
                                    f"t = {float(result.t):.9g} s: {result.message}")
            now, y = float(result.t), result.y
            self._cvode_jacobians_now = int(result.njev)
            if result.status == 2:                      # an event indicator's root
                self.n_events += 1
                self._event(now, y)
                y = self._y
            elif result.status == 1 and now == self._next_time_event:
                self.n_time_events += 1
                self._event(now, y)
                y = self._y
            else:
                self._tc = now
                self._y = y = np.array(y)
                if now >= target:
                    break
        if not self.nx:
            while self._next_time_event <= target:     # time events of FMUs without states
                self.n_time_events += 1
                self._event(self._next_time_event, y)
        self._set_point(target, y)
        self.system.propagate_with(self._recorded_reads)
        return None

    # -- events -------------------------------------------------------------------------------------
    def _event(self, t, y):
        """An event at ``t``: the FMUs in event mode, their discrete states settled, back in
        continuous time; CVODE restarted from the states they report."""
        self._set_point(t, y)
        for c in self._all:
            c.enter_event_mode()
        self._event_rounds(t)
        for c in self._all:
            c.enter_continuous_time_mode()
        self._point_t = None            # the FMUs' values changed under the same point
        self._restart(t, self._read_states() if self.nx else y)

    def _event_rounds(self, t):
        """fmi2NewDiscreteStates on every FMU, the values propagated after each round, until
        no FMU needs another; the earliest next time event they announce is kept."""
        for _ in range(MAX_EVENT_ROUNDS):
            needed = False
            upcoming = math.inf
            for c in self._all:
                info = c.new_discrete_states()
                if info.terminateSimulation:
                    raise MasterFailure(f"{self.name}: {c.name} asked to terminate the simulation at t = {t:.9g} s")
                needed = needed or bool(info.newDiscreteStatesNeeded)
                if info.nextEventTimeDefined and info.nextEventTime > t:
                    upcoming = min(upcoming, float(info.nextEventTime))
            self.system.propagate()
            if not needed:
                self._next_time_event = upcoming
                return
        raise MasterFailure(f"{self.name}: the discrete states did not settle at t = {t:.9g} s within "
                            f"{MAX_EVENT_ROUNDS} rounds of fmi2NewDiscreteStates")

    def counters(self) -> dict:
        return {**super().counters(), "method": self.method, "method_reason": self.method_reason,
                "jacobian": self.jacobian, "tolerance": self.tolerance, "rhs": self.n_rhs,
                "jacobians": self._cvode_jacobians + self._cvode_jacobians_now,
                "directional_jacobians": self.n_jacobians, "root_functions": self.nz,
                "dead_indicators": self.n_dead_indicators, "events": self.n_events,
                "time_events": self.n_time_events}
