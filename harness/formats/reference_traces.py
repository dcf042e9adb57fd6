"""Reference traces in the FMI cross-check layout (``resources/reference/<NAME>/``):

* ``<NAME>_in.csv``  the inputs that drive an FMU stand-alone (FMUs with inputs only),
* ``<NAME>_ref.csv`` the outputs it must produce,
* ``<NAME>_ref.opt`` ``StepSize, StartTime, StopTime, RelTol`` (one ``key,value`` per line).

CSV: a header of quoted names, the first column ``time`` [s], one row per sample, numbers
with 9 significant digits.  A row repeated at the same time is a discontinuity of an input
(left value first), as fmpy's ``Input`` reads it.

Every trace is computed by the project from the physics (``lever.physics``) and the
monolithic reference solver (``harness.judges.monolithic``), never by running the FMU under test:

* an FMU case (``FMU_CASES``: each FMU of ``lever.fmus.registry`` that has one) runs the
  FMU alone, with its defaults, driven by analytic input signals; its reference is the exact
  response: a shaft's motion integrated by scipy (DOP853, rtol = atol = 1e-10) under the
  continuous torque, the coupling's algebraic outputs, the misalignment source's time table.
  An output that depends directly on an input (the coupling's, a shaft's acceleration ``a``;
  the model descriptions declare it) is taken with the input the FMU holds when the output
  is read.  That is the cross-check's sampling, as fmpy's ``simulate_fmu`` does it: set the
  inputs at ``t_k``, step to ``t_k+1``, read the outputs - so the reference at ``t_k+1``
  sees the inputs of ``t_k`` (an importer that sets the next inputs before it reads gets the
  coupling's outputs one step early: within the ``lever`` tolerance's horizontal step, see
  ``harness.judges.validation``);
* a scene's reference is ``harness.judges.monolithic.solve`` of the scene (its recorded signals),
  kept every ``k``-th communication step so that a scene keeps about ``SCENE_ROWS`` rows:
  dense enough to judge a result at its own sample times (``harness.judges.verdict``).

The traces are regenerated only on purpose (``lever reference --update``);
``lever reference`` checks that the committed ones are what the project computes now.
"""
from __future__ import annotations

import csv
import functools
import hashlib
import io
import math
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from lever.fmus import registry

from harness.description import scene as scenes
from harness.paths import FMUS, RESOURCES, SCENES

REFERENCE_DIR = RESOURCES / "reference"
DIGITS = 9
#: relative change (to the signal's largest magnitude) below which a regenerated trace is
#: the committed one. Regenerating on another x86-64 CPU moves the traces by up to 6e-7
#: (numpy's and libm's SIMD paths round differently, events amplify it; measured on an AMD
#: EPYC against traces made elsewhere), so 1e-5: a margin over that spread, still far below a
#: physical change (a parameter moved by 1e-4 moves the torques by about that much)
CURRENT_TOLERANCE = 1e-5
#: a scene reference keeps about this many rows: a 10 s scene every 1 ms, 15 samples a period
#: of KAVZ-685's 415-425 rad/s load band (the verdict's interpolant then errs by about 1 % of
#: that band's amplitude, and says so), under 2 MB a file
SCENE_ROWS = 10000
RTOL = 1e-10
#: two sample times closer than this many communication steps are the same time
_SAME_TIME = 1e-9


# -- files ------------------------------------------------------------------------------------

@dataclass
class Traces:
    times: np.ndarray
    signals: dict[str, np.ndarray]


@dataclass
class Options:
    """The ``_ref.opt`` file: the communication step the result is to be computed with,
    the span, and the relative tolerance the reference was computed with."""
    step: float
    start: float
    stop: float
    rel_tol: float = RTOL


def _number(x: float) -> str:
    return f"{float(x):.{DIGITS}g}"


def write_csv(path: Path, traces: Traces):
    path.parent.mkdir(parents=True, exist_ok=True)
    names = list(traces.signals)
    columns = [np.asarray(traces.signals[n], dtype=float) for n in names]
    with open(path, "w", newline="") as f:
        f.write(",".join(f'"{n}"' for n in ["time"] + names) + "\n")
        for i, t in enumerate(traces.times):
            f.write(",".join([_number(t)] + [_number(c[i]) for c in columns]) + "\n")


class TraceFileError(ValueError):
    pass


class SpanError(ValueError):
    """A span asked of a reference that it cannot be made over."""


def read_csv(path: Path) -> Traces:
    """A CSV result or reference: a header row, the first column the time (named ``time``,
    any case), every other column a signal.  Quoted names and blank lines are allowed.
    The same bytes at the same path are parsed once a process (a committed reference is
    read by every validation; its parse is most of a short one): each call gets arrays of
    its own."""
    path = Path(path)
    try:
        content = path.read_bytes()
    except OSError as error:
        raise TraceFileError(f"{path}: {error.strerror}") from None
    key = (path, hashlib.blake2b(content, digest_size=16).digest())
    with _parsed_lock:
        parsed = _parsed.pop(key, None)
    if parsed is None:
        parsed = _parse_csv(path, content)
    if len(content) <= _PARSED_LARGEST:
        with _parsed_lock:
            _parsed[key] = parsed                   # the most recent last
            while len(_parsed) > _PARSED_KEPT:
                _parsed.pop(next(iter(_parsed)))
    return Traces(parsed.times.copy(), {n: v.copy() for n, v in parsed.signals.items()})


#: the CSV files parsed last, by path and digest of their bytes: at most ``_PARSED_KEPT``, each
#: of at most ``_PARSED_LARGEST`` bytes (a committed reference is a few MB)
_parsed: dict[tuple[Path, bytes], Traces] = {}
_parsed_lock = threading.Lock()
_PARSED_KEPT = 6
_PARSED_LARGEST = 16 << 20


def _parse_csv(path: Path, content: bytes) -> Traces:
    try:
        # utf-8-sig: a byte-order mark (as spreadsheets write one) is not part of the first name
        text = content.decode("utf-8-sig")
        rows = [row for row in csv.reader(io.StringIO(text, newline="")) if "".join(row).strip()]  # blank rows out
    except UnicodeDecodeError as error:
        raise TraceFileError(f"{path}: not a text file in UTF-8 (byte {error.start}: {error.reason}); expected a "
                             "CSV table") from None
    except csv.Error as error:
        raise TraceFileError(f"{path}: not a CSV table ({error})") from None
    if len(rows) < 2:
        raise TraceFileError(f"{path}: expected a header row and at least one data row")
    names = [cell.strip().strip('"').strip() for cell in rows[0]]
    if names[0].lower() != "time":
        raise TraceFileError(f"{path}: the first column must be 'time', not '{names[0]}'")
    duplicates = sorted({n for n in names if names.count(n) > 1})
    if duplicates:
        raise TraceFileError(f"{path}: duplicate column(s) {', '.join(duplicates)}")
    widths = sorted({len(row) for row in rows[1:]})
    if widths != [len(names)]:
        raise TraceFileError(f"{path}: rows have {widths} columns, the header {len(names)}")
    try:
        data = np.array(rows[1:], dtype=float)      # numpy parses the cells (as float() does)
    except ValueError:
        try:
            data = np.array([[float(cell) for cell in row] for row in rows[1:]], dtype=float)
        except ValueError as error:         # the cell float() refuses, named
            raise TraceFileError(f"{path}: not a number ({error})") from None
    return Traces(data[:, 0].copy(), {n: data[:, i].copy() for i, n in enumerate(names) if i})


def write_opt(path: Path, opt: Options):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(f"StepSize,{opt.step!r}\nStartTime,{opt.start!r}\nStopTime,{opt.stop!r}\n"
                    f"RelTol,{opt.rel_tol!r}\n")


def read_opt(path: Path) -> Options:
    values = {}
    for line in Path(path).read_text().splitlines():
        parts = line.split(",")
        if len(parts) == 2:
            values[parts[0].strip()] = float(parts[1])
    missing = [k for k in ("StepSize", "StartTime", "StopTime", "RelTol") if k not in values]
    if missing:
        raise TraceFileError(f"{path}: missing {', '.join(missing)}")
    return Options(values["StepSize"], values["StartTime"], values["StopTime"], values["RelTol"])


@dataclass
class ReferenceTraces:
    """One name's reference: its outputs, options and (FMUs) inputs."""
    name: str
    kind: str                       # "fmu" or "scene"
    outputs: Traces
    opt: Options
    inputs: Traces | None = None
    description: str = ""


def paths(name: str, root: Path | None = None) -> dict[str, Path]:
    folder = (root or REFERENCE_DIR) / name
    return {"in": folder / f"{name}_in.csv", "ref": folder / f"{name}_ref.csv", "opt": folder / f"{name}_ref.opt"}


def write(reference: ReferenceTraces, root: Path | None = None) -> list[Path]:
    p = paths(reference.name, root)
    written = []
    if reference.inputs is not None:
        write_csv(p["in"], reference.inputs)
        written.append(p["in"])
    write_csv(p["ref"], reference.outputs)
    write_opt(p["opt"], reference.opt)
    return written + [p["ref"], p["opt"]]


def why_no_reference(name: str) -> str | None:
    """Why the FMU ``name`` has no stand-alone reference, as the registry says (None: any
    other name)."""
    if name in registry.NAMES and registry.model(name).no_reference:
        return f"{name} has no stand-alone reference: {registry.model(name).no_reference}"
    return None


def read(name: str, root: Path | None = None) -> ReferenceTraces:
    p = paths(name, root)
    if why_no_reference(name):
        raise TraceFileError(why_no_reference(name))
    if not p["ref"].exists():
        raise TraceFileError(f"no committed reference for '{name}' ({p['ref']} is missing; "
                             f"`lever reference --update {name}` makes it)")
    inputs = read_csv(p["in"]) if p["in"].exists() else None
    return ReferenceTraces(name, "fmu" if name in FMU_CASES else "scene", read_csv(p["ref"]), read_opt(p["opt"]), inputs)


def rounded(traces: Traces) -> Traces:
    """The traces as the CSV stores them (9 significant digits)."""
    r = lambda a: np.array([float(_number(x)) for x in np.asarray(a, dtype=float)])
    return Traces(r(traces.times), {n: r(v) for n, v in traces.signals.items()})


# -- FMU cases: analytic inputs and their exact responses --------------------------------------

def _sines(t, terms):
    """``sum a sin(w t + p)`` and its derivative for terms ``(a, w, p)``."""
    t = np.asarray(t, dtype=float)
    value = sum(a * np.sin(w * t + p) for a, w, p in terms)
    rate = sum(a * w * np.cos(w * t + p) for a, w, p in terms)
    return value, rate


@dataclass(frozen=True)
class FmuCase:
    model: str
    description: str
    stop: float
    step: float
    outputs: tuple[str, ...]
    #: (t, left=False) -> input columns; at ``events`` they jump (``left``: the value before);
    #: None: the FMU has no inputs
    inputs: Callable | None
    #: times -> exact outputs
    exact: Callable
    events: tuple[float, ...] = ()
    start: float = 0.0

    def grid(self) -> np.ndarray:
        n = int(round((self.stop - self.start) / self.step))
        return self.start + self.step * np.arange(n + 1)

    def input_traces(self) -> Traces | None:
        """The inputs at every communication point; at an event two rows at the same
        time, the left value first (fmpy's ``Input`` applies the right one from there on).
        None for an FMU without inputs (no ``_in.csv``)."""
        if self.inputs is None:
            return None
        t = self.grid()
        values = self.inputs(t)
        for e in sorted(self.events, reverse=True):
            i = int(np.searchsorted(t, e - 1e-9 * self.step))
            if not math.isclose(t[i], e, rel_tol=0, abs_tol=1e-9 * self.step):
                raise ValueError(f"{self.model}: input event at {e} s is not a communication point")
            before = self.inputs(np.array([e]), left=True)
            t = np.insert(t, i, e)
            values = {k: np.insert(v, i, before[k][0]) for k, v in values.items()}
        return Traces(t, values)


# LeverCoupling: both flanges turning at about 38 rad/s (six revolutions of the transfer
# function in 1 s), a deflection oscillating at 2 Hz and at the 74 rad/s ripple frequency,
# the misalignment stepping from 15 to 20 deg at 0.5 s (the input may vary in time).
_W0 = 38.0
_DRIVE = ((0.12, 2 * math.pi * 2.0, 0.0), (0.03, 74.0, 0.0))
_DRIVEN = ((-0.04, 2 * math.pi * 3.0, 0.5),)
_ALPHA = (math.radians(15.0), math.radians(20.0))
_STEP_AT = 0.5


def _coupling_inputs(t, left=False):
    p1, v1 = _sines(t, _DRIVE)
    p2, v2 = _sines(t, _DRIVEN)
    after = t > _STEP_AT if left else t >= _STEP_AT
    return {"phi1": _W0 * t + p1, "w1": _W0 + v1, "phi2": _W0 * t + p2, "w2": _W0 + v2,
            "misalignment": np.where(after, _ALPHA[1], _ALPHA[0])}


def _held(t):
    """When the importer last set the inputs, for outputs read at ``t``: the communication
    point before (the cross-check's sampling: outputs are read after a step, before the
    next inputs are set), the start itself at the start."""
    t = np.asarray(t, dtype=float)
    return np.concatenate([t[:1], t[:-1]])


def _coupling_exact(t):
    """The coupling has no state: its outputs are its algebraic function of the inputs it
    holds when they are read (``_held``)."""
    from lever.physics import component_parameters

    u = _coupling_inputs(_held(t))
    out = {k: np.empty(len(t)) for k in ("tau1", "tau2", "U12", "theta", "elastic_energy", "dissipated_power")}
    for alpha in _ALPHA:
        rows = u["misalignment"] == alpha
        coupling = component_parameters.coupling_from({}, misalignment=alpha)
        # the physics takes scalars: evaluated row by row
        results = [coupling.evaluate(*row) for row in zip(u["phi1"][rows], u["w1"][rows], u["phi2"][rows],
                                                           u["w2"][rows])]
        for key, field in zip(out, ("tau1", "tau2", "ratio", "deflection", "energy", "dissipation")):
            out[key][rows] = [getattr(r, field) for r in results]
    return out


# Shafts: a coupling torque with a slow swing, the 74 rad/s ripple and a 420 rad/s
# component (the oscillograms' high-frequency line); tau_rate is its exact derivative.
_ENGINE_TAU = (-110.0, ((-25.0, 2 * math.pi * 2.0, 0.0), (-6.0, 74.0, 0.0), (-3.0, 420.0, 0.0)))
# about zero: the LoadShaft's default load is none, so the shaft swings about its start speed
_LOAD_TAU = (0.0, ((20.0, 2 * math.pi * 1.5, 0.3), (6.0, 74.0, 0.0), (3.0, 420.0, 0.0)))


def _torque_inputs(spec):
    mean, terms = spec

    def inputs(t, left=False):
        value, rate = _sines(t, terms)
        return {"tau": mean + value, "tau_rate": rate}
    return inputs


def _shaft_exact(kind: str, spec):
    """The shaft's exact response to the continuous torque, with its defaults."""
    def exact(t):
        from scipy.integrate import solve_ivp
        from lever.physics import component_parameters

        declared = component_parameters.ENGINE if kind == "engine" else component_parameters.LOAD
        shaft = (component_parameters.engine_from if kind == "engine" else component_parameters.load_from)({})
        phi0, w0 = component_parameters.start_state({}, declared)
        torque = _torque_inputs(spec)
        mean, terms = spec

        def rhs(time, y):
            tau = mean + sum(a * math.sin(w * time + p) for a, w, p in terms)
            a, external = shaft.rates(time, y[0], y[1], tau)
            return [y[1], a, external * y[1]]

        sol = solve_ivp(rhs, (t[0], t[-1]), [phi0, w0, 0.0], method="DOP853", t_eval=t, rtol=RTOL, atol=RTOL)
        if not sol.success:
            raise RuntimeError(f"{kind} reference: {sol.message}")
        phi, w, work = sol.y
        tau = torque(_held(t))["tau"]     # the acceleration depends on the input: as read (``_held``)
        a, external = zip(*(shaft.rates(ti, p, v, q) for ti, p, v, q in zip(t, phi, w, tau)))
        external = np.array(external)
        if kind == "engine":
            return {"phi": phi, "w": w, "a": np.array(a), "engine_torque": external, "engine_work": work}
        return {"phi": phi, "w": w, "a": np.array(a), "load_torque": -external, "load_work": -work}
    return exact


# MisalignmentSource: its default table (15 deg held); it has no inputs.
def _source_exact(t):
    """A time table's value and rate at ``t`` (the table the source is built with)."""
    from lever.physics import component_parameters

    table = component_parameters.misalignment_source_from({})
    return {"misalignment": np.array([table.value(x) for x in t]),
            "misalignment_rate": np.array([table.rate(x) for x in t])}


_CASES = {
    "LeverCoupling": FmuCase(
        "LeverCoupling", "defaults (KAVZ-685); flanges at about 38 rad/s with a 2 Hz and a 74 rad/s deflection, "
        "misalignment 15 deg stepping to 20 deg at 0.5 s", 1.0, 1e-3,
        ("tau1", "tau2", "U12", "theta", "elastic_energy", "dissipated_power"),
        _coupling_inputs, _coupling_exact, events=(_STEP_AT,)),
    "EngineShaft": FmuCase(
        "EngineShaft", "defaults (KAVZ-685, linear characteristic); coupling torque -110 N*m with a 2 Hz swing, "
        "74 and 420 rad/s components", 1.0, 1e-3,
        ("phi", "w", "a", "engine_torque", "engine_work"),
        _torque_inputs(_ENGINE_TAU), _shaft_exact("engine", _ENGINE_TAU)),
    "LoadShaft": FmuCase(
        "LoadShaft", "defaults (no load); coupling torque with a 20 N*m swing at 1.5 Hz, 74 and 420 rad/s "
        "components", 1.0, 1e-3,
        ("phi", "w", "a", "load_torque", "load_work"),
        _torque_inputs(_LOAD_TAU), _shaft_exact("load", _LOAD_TAU)),
    "MisalignmentSource": FmuCase(
        "MisalignmentSource", "defaults (15 deg held); no inputs: the output is a function of time", 1.0, 1e-3,
        ("misalignment", "misalignment_rate"), None, _source_exact),
}
#: model identifier -> its stand-alone case, for each FMU of the registry that has one
FMU_CASES = {m.name: _CASES[m.name] for m in registry.MODELS if not m.no_reference}


def generate_fmu(name: str) -> ReferenceTraces:
    case = FMU_CASES[name]
    t = case.grid()
    return ReferenceTraces(name, "fmu", Traces(t, case.exact(t)), Options(case.step, case.start, case.stop, RTOL),
                     case.input_traces(), case.description)


# -- scenes ----------------------------------------------------------------------------------

def scene_grid(scene: scenes.Scene) -> np.ndarray:
    """Every k-th communication point, k the smallest that keeps about ``SCENE_ROWS`` rows."""
    e = scene.experiment
    n_steps = int(round((e.stop - e.start) / e.step))
    k = max(1, math.ceil(n_steps / SCENE_ROWS))
    points = np.arange(0, n_steps + 1, k)
    if points[-1] != n_steps:
        points = np.append(points, n_steps)
    return np.minimum(e.start + points * e.step, e.stop)


def generate_scene(scene: scenes.Scene, until: float | None = None) -> ReferenceTraces:
    """The scene's reference; ``until``: its rows up to that time only, solved as the whole
    span is (the same grid, the method the whole span takes) and cut there (``head``)."""
    from harness.judges import monolithic

    if "reference" not in scene.features:
        raise monolithic.ReferenceUnavailable(f"scene '{scene.name}' does not declare the 'reference' feature")
    t = scene_grid(scene)
    plan = monolithic.planned(scene)
    method = "DOP853"
    if until is not None:
        if monolithic.SOLVERS.get(plan.kind, monolithic.solve_driveline) is monolithic.solve_driveline:
            method = monolithic.reference_method(plan, t)[0]     # a stiff span's solver even on its head
        if until < t[1]:
            raise SpanError(f"{until:g} s is before the second sample of '{scene.name}' (at {t[1]:g} s)")
        t = t[t <= until + _SAME_TIME * scene.experiment.step]
    solved = monolithic.solve(plan, t, method=method)
    signals = {n: solved.traces[n] for n in scene.record if n in solved.traces}
    # a reference may name recorded outputs that are a solver's own bookkeeping (an event
    # count): nothing to compare, so no trace
    bookkeeping = set(solved.info.get("bookkeeping", ()))
    left_out = [n for n in scene.record if n not in solved.traces and n not in bookkeeping]
    if left_out:
        raise monolithic.ReferenceUnavailable(f"scene '{scene.name}': the reference does not compute "
                                              + ", ".join(left_out))
    e = scene.experiment
    made = ReferenceTraces(scene.name, "scene", Traces(solved.times, signals), Options(e.step, e.start, e.stop, RTOL),
                           None, scene.description)
    return made if until is None else head(made, until)


def scene_names() -> list[str]:
    """The scenes that have a reference: those declaring the ``reference`` feature (worked
    out once for the same scene files: every validation asks)."""
    files = sorted(SCENES.glob("*.toml"))
    digest = hashlib.blake2b(digest_size=16)
    for path in files:
        content = path.read_bytes()
        digest.update(f"\0{path.name}\0{len(content)}\0".encode())
        digest.update(content)
    return list(_scene_names(tuple(files), digest.digest()))


@functools.lru_cache(maxsize=2)
def _scene_names(files: tuple[Path, ...], digest: bytes) -> tuple[str, ...]:
    names = []
    for path in files:
        try:
            spec = scenes.load(path)
        except scenes.SceneError:
            continue
        if "reference" in spec.features:
            names.append(path.stem)
    return tuple(names)


def all_names() -> list[str]:
    return list(FMU_CASES) + scene_names()


def generate(name: str, until: float | None = None) -> ReferenceTraces:
    """``name``'s reference as the project computes it now; ``until``: up to that time only
    (``head``; a scene is solved that far only, an FMU case is cheap and made whole)."""
    if name in FMU_CASES:
        made = generate_fmu(name)
        if until is not None and until < made.outputs.times[1]:
            raise SpanError(f"{until:g} s is before the second sample of '{name}' (at {made.outputs.times[1]:g} s)")
        return made if until is None else head(made, until)
    return generate_scene(scenes.load(name), until)


def head(reference: ReferenceTraces, until: float) -> ReferenceTraces:
    """``reference``'s rows at or before time ``until`` (its options as they are: the whole
    span's, still compared): what a reference made to ``until`` only is compared with."""
    margin = _SAME_TIME * reference.opt.step

    def cut(traces: Traces | None) -> Traces | None:
        if traces is None:
            return None
        kept = traces.times <= until + margin
        return Traces(traces.times[kept], {n: v[kept] for n, v in traces.signals.items()})
    return ReferenceTraces(reference.name, reference.kind, cut(reference.outputs), reference.opt,
                           cut(reference.inputs), reference.description)


# -- is the committed reference current? --------------------------------------------------------

@dataclass
class Change:
    signal: str
    max_change: float
    #: relative to the signal's largest magnitude
    relative: float
    at_time: float


@dataclass
class Difference:
    """What regenerating a reference would change (empty: it is current)."""
    name: str
    changes: list[Change] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)     # structural: grid, names, options

    @property
    def current(self) -> bool:
        return not self.problems and all(c.relative <= CURRENT_TOLERANCE for c in self.changes)


def _diff_traces(label: str, old: Traces, new: Traces, diff: Difference):
    added = [n for n in new.signals if n not in old.signals]
    removed = [n for n in old.signals if n not in new.signals]
    if added:
        diff.problems.append(f"{label}: new signal(s) {', '.join(added)}")
    if removed:
        diff.problems.append(f"{label}: signal(s) no longer computed: {', '.join(removed)}")
    same_grid = len(old.times) == len(new.times) and np.allclose(old.times, new.times, rtol=0, atol=1e-9)
    if not same_grid:
        diff.problems.append(f"{label}: time grid {len(old.times)} rows {old.times[0]:g}...{old.times[-1]:g} s -> "
                             f"{len(new.times)} rows {new.times[0]:g}...{new.times[-1]:g} s")
    for name in new.signals:
        if name not in old.signals:
            continue
        y_new = new.signals[name]
        y_old = old.signals[name] if same_grid else np.interp(new.times, old.times, old.signals[name])
        delta = np.abs(y_new - y_old)
        i = int(np.argmax(delta))
        scale = max(float(np.max(np.abs(y_new))), 1e-12)
        prefix = f"{label}:" if label != "outputs" else ""
        diff.changes.append(Change(prefix + name, float(delta[i]), float(delta[i]) / scale, float(new.times[i])))


def difference(committed: ReferenceTraces | None, fresh: ReferenceTraces) -> Difference:
    """What changes from the committed reference to the freshly generated one (compared as
    the files store it, 9 significant digits)."""
    diff = Difference(fresh.name)
    if committed is None:
        diff.problems.append("no committed reference")
        return diff
    o, n = committed.opt, fresh.opt
    if (o.step, o.start, o.stop, o.rel_tol) != (n.step, n.start, n.stop, n.rel_tol):
        diff.problems.append(f"options: StepSize {o.step:g} -> {n.step:g}, StartTime {o.start:g} -> {n.start:g}, "
                             f"StopTime {o.stop:g} -> {n.stop:g}, RelTol {o.rel_tol:g} -> {n.rel_tol:g}")
    _diff_traces("outputs", committed.outputs, rounded(fresh.outputs), diff)
    if (committed.inputs is None) != (fresh.inputs is None):
        diff.problems.append("inputs file " + ("added" if committed.inputs is None else "removed"))
    elif fresh.inputs is not None:
        _diff_traces("inputs", committed.inputs, rounded(fresh.inputs), diff)
    return diff


# -- running what a reference describes ---------------------------------------------------------

@dataclass
class Result:
    """What a run under validation produced, named like its reference's signals."""
    times: np.ndarray
    traces: dict[str, np.ndarray]
    #: how it was produced, in words
    how: str
    failure: str | None = None


def run_fmu(name: str, reference: ReferenceTraces, start_values: dict | None = None,
            fmu_path: Path | None = None) -> Result:
    """The FMU stand-alone under fmpy's ``simulate_fmu``, driven by the reference's inputs,
    at the ``_ref.opt`` step, recording at every communication point: the FMU file
    ``fmu_path`` (default ``name``'s in build/fmus) (FMI 2.0 or 3.0, as its description says; the
    harness's ``UnsupportedFmu`` for another).  The instance is the harness's own (its
    messages come through the process's one logger, see ``harness.engine.component``), lent
    to ``simulate_fmu`` and freed as its state allows."""
    from fmpy import simulate_fmu
    from harness.engine.fmi3_component import open_component

    opt = reference.opt
    inputs = reference.inputs
    signal = None if inputs is None else np.rec.fromarrays([inputs.times] + list(inputs.signals.values()),
                                                           names=["time"] + list(inputs.signals))
    outputs = list(reference.outputs.signals)
    how = f"fmpy.simulate_fmu, step {opt.step:g} s, {opt.start:g}...{opt.stop:g} s"
    component = open_component(name, FMUS / f"{name}.fmu" if fmu_path is None else fmu_path)
    if fmu_path is not None:
        how += f", {fmu_path} (FMI {component.description.fmiVersion})"
    try:
        with component.lent() as fmu:
            # the extracted folder, not the file: simulate_fmu would extract it again
            result = simulate_fmu(component.unzipped_dir, start_time=opt.start, stop_time=opt.stop,
                                  step_size=opt.step, output_interval=opt.step, input=signal, output=outputs,
                                  start_values=dict(start_values or {}), relative_tolerance=opt.rel_tol,
                                  model_description=component.description, fmu_instance=fmu, terminate=False,
                                  debug_logging=False)
    except Exception as error:   # fmpy raises plain Exceptions for refused calls
        said = [m for m in component.messages if not m.startswith("[ok]")]
        said = f" (FMU said: {' | '.join(said)})" if said else ""
        return Result(np.empty(0), {n: np.empty(0) for n in outputs}, how, f"{name}: {error}{said}")
    finally:
        component.free()
    return Result(np.asarray(result["time"], dtype=float), {n: np.asarray(result[n], dtype=float) for n in outputs},
                  how)


def run_scene(scene: scenes.Scene, master: str | None = None, step: float | None = None,
              fmu_dir: Path = FMUS, observer=None) -> Result:
    from harness.engine.run import simulate

    run = simulate(scene, master, step, fmu_dir, observer=observer)
    how = f"master {run.master}, step {run.step:g} s, {scene.experiment.start:g}...{scene.experiment.stop:g} s"
    # what the scene records (not what its features add, e.g. the energy balance's variables)
    return Result(run.times, {n: run.traces[n] for n in scene.record}, how, run.failure)
