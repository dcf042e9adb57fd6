"""What a shaft FMU looks like from our lever coupling, measured: its inertia and its
damping (the slope of its torque in its speed), from its Model Exchange derivatives where
it offers them (``linearised``), else from short probe runs of fresh co-simulation
instances.

A co-simulation-only FMU (every pythonfmu FMU) offers neither its equations nor its
Jacobian, and no state to roll back to; what it offers is a run.  Seen from the coupling,
a port takes a torque ``tau`` and gives back an angle and a speed; about a motion its
linear part is ``J dw/dt = tau - k w + (what does not depend on tau or w)``.  Each probe
starts a fresh instance from the scene's start values and holds the torque at ``+A`` and
``-A`` over ``PROBE_STEPS`` steps of a tenth of the scene's step; half the difference of
the speeds, ``dw``, is the response to a torque step of ``A`` with what does not depend on
the torque cancelled (and a quadratic nonlinearity with it).  Over a step with the torque
held, the exact solution of the linear port is ``dw[n+1] = a dw[n] + beta`` with
``a = exp(-k h / J)`` and ``beta = A (1 - a) / k``: a least-squares fit of ``a`` and
``beta`` gives ``k = A (1 - a) / beta`` and ``J = A h (1 - a) / (beta (-ln a))``.

The model's uncertainty is stated, not assumed away: the probes run at two amplitudes
(``AMPLITUDES``, in the port's torque unit), and the spread of ``J`` and ``k`` between
them measures how far the port is from linear; the fit's residual measures dynamics a
first-order port does not have (a lag, a second inertia behind a spring).
"""
from __future__ import annotations

import math
import time as clock
from dataclasses import dataclass
from pathlib import Path

import numpy as np

#: the probe torques [the port's torque unit, N*m when it is wired to our coupling]
AMPLITUDES = (1.0, 10.0)
#: steps of a probe run, each a tenth of the scene's communication step
PROBE_STEPS = 200
#: a probe estimated to take longer than this [s] says so before it runs
LONG_PROBE = 10.0


class ProbeRefused(RuntimeError):
    """A port's FMU could not be probed (it refused an instantiation, a value, a step)."""


@dataclass(frozen=True)
class PortModel:
    """A port measured from outside: ``inertia`` J and ``damping`` k (the port's torque
    unit per rad/s), with their relative spreads over the probe amplitudes and the fit's
    residual relative to the response."""
    component: str
    fmu: str
    inertia: float
    damping: float
    inertia_spread: float
    damping_spread: float       # absolute, in the damping's unit
    residual: float
    probe_step: float
    probe_steps: int
    #: "probe runs", or "Model Exchange derivatives" (``linearised``)
    method: str = "probe runs"

    def text(self) -> str:
        how = (f"from its Model Exchange derivatives at the start, torques +-{' and +-'.join(f'{a:g}' for a in AMPLITUDES)}"
               f" N*m" if self.method != "probe runs" else
               f"from probe runs: torque steps of {' and '.join(f'{a:g}' for a in AMPLITUDES)} N*m, "
               f"{self.probe_steps} steps of {self.probe_step:.3g} s; fit residual {100 * self.residual:.2g} %")
        return (f"{self.component} ({Path(self.fmu).name}): inertia {self.inertia:.4g} +- "
                f"{100 * self.inertia_spread:.2g} %, damping {self.damping:.4g} +- {self.damping_spread:.2g} ({how})")


def fit_first_order(dw: np.ndarray, amplitude: float, h: float) -> tuple[float, float, float]:
    """``(J, k, residual)`` of ``J dw/dt = amplitude - k dw`` from the response ``dw``
    (``dw[0] = 0``) sampled every ``h`` (module docstring)."""
    x, y = dw[:-1], dw[1:]
    design = np.column_stack([x, np.ones_like(x)])
    (a, beta), *_ = np.linalg.lstsq(design, y, rcond=None)
    if not (np.isfinite(a) and np.isfinite(beta)) or beta == 0.0 or a <= 0.0:
        raise ProbeRefused(f"the speed does not answer a torque step as a shaft does (fit a = {a:.3g}, "
                           f"beta = {beta:.3g})")
    ratio = 1.0 if abs(1.0 - a) < 1e-12 else (1.0 - a) / (-math.log(a))
    inertia = amplitude * h * ratio / beta
    damping = amplitude * (1.0 - a) / beta
    scale = float(np.max(np.abs(dw))) or 1.0
    residual = float(np.sqrt(np.mean((y - design @ np.array([a, beta])) ** 2))) / scale
    return inertia, damping, residual


def _speeds(component: str, path: Path, start_values: dict, tau: str, w: str, torque: float, h: float,
            steps: int) -> np.ndarray:
    """The speed of a fresh instance of ``path`` with its torque held at ``torque``."""
    from harness.engine.fmi3_component import open_component

    fmu = open_component(f"{component}-probe", path)
    try:
        fmu.set_parameters(dict(start_values))
        fmu.initialize(0.0, None)
        fmu.exit_initialization()
        vrs_in, values_in = fmu.real_buffer([tau])
        vrs_out, values_out = fmu.real_buffer([w])
        values_in[0] = torque
        speeds = np.empty(steps + 1)
        fmu.write(vrs_in, values_in)
        fmu.read(vrs_out, values_out)
        speeds[0] = values_out[0]
        for n in range(steps):
            fmu.write(vrs_in, values_in)
            fmu.do_step(n * h, h)
            fmu.read(vrs_out, values_out)
            speeds[n + 1] = values_out[0]
        return speeds
    finally:
        fmu.free()


def probe(component: str, path: Path, start_values: dict, tau: str, w: str, step: float, say=None) -> PortModel:
    """The ``PortModel`` of ``component`` (FMU ``path``, started from ``start_values``,
    torque input ``tau``, speed output ``w``) at a probe step of ``step / 10``; ``say``
    hears the estimate first when the probes would take longer than ``LONG_PROBE``.
    ``ProbeRefused`` names the FMU and why."""
    path = Path(path)
    key = (str(path), path.stat().st_mtime if path.exists() else 0.0, tuple(sorted(
        (k, repr(v)) for k, v in start_values.items())), tau, w, float(step))
    if key not in _PROBED:
        try:
            _PROBED[key] = (linearised(component, path, start_values, tau, w)
                            or _probe(component, path, start_values, tau, w, step, say))
        except ProbeRefused as refusal:
            # kept too: the map asks once for its plan and once for its sweep, and a
            # refusal that does not settle costs all its probe steps each time
            _PROBED[key] = refusal
    if isinstance(_PROBED[key], ProbeRefused):
        raise ProbeRefused(str(_PROBED[key]))
    return _PROBED[key]


#: the speed change [rad/s] the damping's difference quotient in the Model Exchange derivatives uses
SPEED_DELTA = 1e-3


def linearised(component: str, path: Path, start_values: dict, tau: str, w: str) -> PortModel | None:
    """The ``PortModel`` of an FMI 2.0 FMU offering Model Exchange whose speed ``w`` is a
    continuous state, from its derivatives at the start: ``1/J = d(dw/dt)/d tau`` (central
    differences at each of ``AMPLITUDES``: their spread measures the nonlinearity) and
    ``-k/J = d(dw/dt)/dw``; None where it offers no such thing (then it is probed), and
    where it refuses a call (the probe runs then say so, if they fail too)."""
    from harness.description.fmu_description import read_description
    from harness.engine.me_component import ModelExchangeComponent

    description = read_description(path)
    if description.modelExchange is None or description.fmiVersion != "2.0":
        return None
    try:
        fmu = ModelExchangeComponent(f"{component}-linearised", path)
    except Exception:  # noqa: BLE001 - the probe runs are the fallback
        return None
    try:
        if w not in fmu.state_names:
            return None
        fmu.set_parameters(dict(start_values))
        fmu.initialize(0.0, None)
        fmu.exit_initialization()
        for _ in range(100):
            if not fmu.new_discrete_states().newDiscreteStatesNeeded:
                break
        fmu.enter_continuous_time_mode()
        fmu.get_states()
        i = fmu.state_names.index(w)
        vrs, values = fmu.real_buffer([tau])

        def rate(torque: float, dw: float = 0.0) -> float:
            values[0] = torque
            fmu.write(vrs, values)
            fmu.get_states()
            fmu.x[i] += dw
            fmu.set_states()
            fmu.derivatives()
            fmu.x[i] -= dw
            fmu.set_states()
            return fmu.dx[i]

        inertias = [2.0 * a / (rate(a) - rate(-a)) for a in AMPLITUDES]
        slopes = [(rate(0.0, SPEED_DELTA) - rate(0.0, -SPEED_DELTA)) / (2.0 * SPEED_DELTA)]
    except Exception:  # noqa: BLE001 - the probe runs are the fallback
        return None
    finally:
        fmu.free()
    inertia = inertias[0]
    if not (math.isfinite(inertia) and inertia > 0.0 and math.isfinite(slopes[0])):
        return None
    return PortModel(component, str(path), float(inertia), float(-slopes[0] * inertia),
                     float(abs(max(inertias) - min(inertias)) / inertia), 0.0, 0.0, 0.0, 0,
                     "Model Exchange derivatives")


#: the ports probed in this process (their PortModel, or the ProbeRefused they raised), by FMU file,
#: its time, start values, port names and step
_PROBED: dict = {}


def _probe(component, path, start_values, tau, w, step, say) -> PortModel:
    h, n = step / 10.0, PROBE_STEPS
    fits = []
    try:
        started = clock.perf_counter()
        first = _speeds(component, Path(path), start_values, tau, w, AMPLITUDES[0], h, n)
        took = clock.perf_counter() - started
        estimate = took * (2 * len(AMPLITUDES) - 1)
        if say is not None and estimate > LONG_PROBE:
            say(f"probing {component} ({Path(path).name}): about {estimate:.0f} s more "
                f"({2 * len(AMPLITUDES)} runs of {n} steps, {took:.1f} s each)")
        for amplitude in AMPLITUDES:
            up = first if amplitude == AMPLITUDES[0] else _speeds(component, Path(path), start_values, tau, w,
                                                                  amplitude, h, n)
            down = _speeds(component, Path(path), start_values, tau, w, -amplitude, h, n)
            dw = 0.5 * (up - down)
            dw = dw - dw[0]
            if not np.all(np.isfinite(dw)):
                raise ProbeRefused(f"its speed {w} went non-finite under a torque of {amplitude:g}")
            fits.append(fit_first_order(dw, amplitude, h))
    except ProbeRefused as error:
        raise ProbeRefused(f"{component} (FMU {Path(path).name}) cannot be probed: {error}") from None
    except Exception as error:  # noqa: BLE001 - any refusal of the FMU is said with its name
        raise ProbeRefused(f"{component} (FMU {Path(path).name}) refused the probe runs "
                           f"({type(error).__name__}: {error})") from None
    inertias = [f[0] for f in fits]
    dampings = [f[1] for f in fits]
    inertia = inertias[0]
    if not (math.isfinite(inertia) and inertia > 0.0):
        raise ProbeRefused(f"{component} (FMU {Path(path).name}) cannot be probed: it shows no positive inertia "
                           f"({inertia:.3g})")
    return PortModel(component, str(path), float(inertia), float(dampings[0]),
                     float(abs(max(inertias) - min(inertias)) / inertia), float(abs(max(dampings) - min(dampings))),
                     float(max(f[2] for f in fits)), h, n)

