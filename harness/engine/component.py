"""One FMU instance in a co-simulation, loaded with fmpy.

The stepping loop calls ``read``, ``write`` and ``do_step`` millions of times, so they go
straight to the FMU's C functions with preallocated ctypes buffers (fmpy's ``getReal``
allocates two arrays per call).  Every call's status is checked; a failing call raises
``FmuCallError`` carrying the messages the FMU logged, so a failed run can say which
FMU refused what, and why.
"""
from __future__ import annotations

import atexit
import ctypes
import itertools
import shutil
import sys
import tempfile
from collections import deque
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterable, Sequence

from fmpy import extract
from fmpy.fmi2 import FMU2Slave, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, fmi2CallbackAllocateMemoryTYPE, \
    fmi2CallbackFreeMemoryTYPE
from fmpy.fmi1 import FMICallException
from fmpy.logging import addLoggerProxy

from harness.description import typed_values
from harness.description.fmu_description import read_description
from harness.engine.interface import CallCounts, RawCalls

_STATUS = ("ok", "warning", "discard", "error", "fatal", "pending")

# FMU log messages are printf-style with variadic arguments, which ctypes cannot read:
# fmpy's native proxy formats them and calls one Python function for the whole process.
# So every component shares one callback struct, and messages are routed by instance name.
# The proxy keeps a single pointer to the last Python logger anyone gave it (fmpy's
# ``simulate_fmu(logger=...)`` gives it a temporary one, freed when it returns: the next
# message calls freed memory).  So the harness never hands fmpy a logger of its own
# making; it points the proxy back at this module's callback, which lives as long as the
# process, before each instance it makes (``_pin_logger``).
_routes: dict[str, deque] = {}
_listeners: list = []
_instances = itertools.count(1)


def _dispatch(env, instance, status, category, message):
    name = instance.decode("utf-8", "replace") if instance else ""
    text = message.decode("utf-8", "replace") if message else ""
    label = _STATUS[status] if 0 <= status < 6 else str(status)
    for listener in _listeners:
        listener(name, status, category.decode("utf-8", "replace") if category else "", text)
    route = _routes.get(name)
    if route is not None:
        route.append(f"[{label}] {text}")
    elif not _listeners:
        print(f"[{label}] {name}: {text}", file=sys.stderr)


def route_messages(instance_name: str, messages: deque):
    """Append the log messages of the FMU instance ``instance_name`` to ``messages`` (for
    code that instantiates FMUs itself, with ``log_callbacks()``), until ``unroute``."""
    _routes[instance_name] = messages


def unroute(instance_name: str):
    _routes.pop(instance_name, None)


def add_log_listener(listener):
    """Also send every FMU log message, as ``listener(instance, status, category,
    text)``, to ``listener`` (for tools and tests that instantiate FMUs themselves with
    ``log_callbacks()``)."""
    _listeners.append(listener)


def log_callbacks() -> fmi2CallbackFunctions:
    """The one callback struct of this process (see above); pass it to
    ``FMU2Slave.instantiate(callbacks=...)``."""
    _pin_logger()
    return _callbacks


def _pin_logger():
    """Point fmpy's native logger proxy at ``_dispatch`` again (code outside the harness
    may have pointed it at a logger of its own since).  ``addLoggerProxy`` re-points it
    only for a struct whose logger is not the proxy yet, hence the struct of its own."""
    _pin.logger = _logger
    addLoggerProxy(ctypes.byref(_pin))


_libc = ctypes.CDLL(None)
# Module globals: alive until the process ends, as the FMUs' pointers to them must be.
_logger = fmi2CallbackLoggerTYPE(_dispatch)
_callbacks = fmi2CallbackFunctions()
_callbacks.logger = _logger
_callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(("calloc", _libc))
_callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(("free", _libc))
addLoggerProxy(ctypes.byref(_callbacks))
_pin = fmi2CallbackFunctions()


# One extraction per FMU file and process.  Every instance of an FMU then loads the same
# library file, which the dynamic loader maps once; a fresh directory per instance maps a
# fresh copy of pythonfmu's library, which is never unmapped (about 0.3 MB per instance,
# so sweeps of thousands of runs grew without bound).
_extracted: dict[tuple, str] = {}


def unzipped(fmu_path: Path | str) -> str:
    """The directory this process extracted ``fmu_path`` to (extracted again when the
    file changes: a rebuilt FMU is a new library)."""
    path = Path(fmu_path).resolve()
    stat = path.stat()
    key = (str(path), stat.st_mtime_ns, stat.st_size)
    folder = _extracted.get(key)
    if folder is None or not Path(folder).is_dir():
        folder = _extracted[key] = extract(str(path))
    return folder


#: temporary folders of this process (``scratch_folder``), removed with the extractions
_scratch: list[str] = []


def scratch_folder(prefix: str) -> Path:
    """A new temporary folder, removed when the process ends (``remove_extractions``) -
    e.g. an SSP archive's unpacked FMUs."""
    folder = tempfile.mkdtemp(prefix=prefix)
    _scratch.append(folder)
    return Path(folder)


def remove_extractions():
    """Delete the extracted FMUs and the scratch folders (at exit; entry points that leave
    by ``os._exit`` call it themselves).  Libraries already loaded stay usable: their
    files are mapped."""
    for folder in [*_extracted.values(), *_scratch]:
        shutil.rmtree(folder, ignore_errors=True)
    _extracted.clear()
    _scratch.clear()


atexit.register(remove_extractions)


#: counts as the unconverted calls take them, made once
_COUNTS = tuple(ctypes.c_size_t(n) for n in range(33))


def _count(n: int):
    return _COUNTS[n] if n < 33 else ctypes.c_size_t(n)


def unconverted(function):
    """``function`` (a ctypes function with ``argtypes``) as a function pointer without
    them: its arguments must be ctypes objects of the right types, passed as they are.
    ctypes' conversion through ``argtypes`` cost about a third of an fmi2GetReal into a
    pythonfmu FMU on this machine (measured: 10.6 against 7.8 us a call, interleaved)."""
    return ctypes.CFUNCTYPE(function.restype)(ctypes.cast(function, ctypes.c_void_p).value)


#: the kinds ``Component.wrap_calls`` gives the state calls: fmi2GetFMUstate,
#: fmi2SetFMUstate and fmi2FreeFMUstate (counted together as ``state``)
STATE_CALLS = ("get_state", "set_state", "free_state")


def step_call(t: float, h: float) -> str:
    """How a refused fmi2DoStep is named in its error: the step's time and size."""
    return f"fmi2DoStep(t = {t:.9g}, h = {h:.3g})"


class FmuCallError(RuntimeError):
    """An FMI call returned error/fatal (or discard): which component, which call,
    at what time, and what the FMU said."""

    def __init__(self, component: str, call: str, status: int, time: float, messages: Sequence[str]):
        self.component, self.call, self.status, self.time = component, call, status, time
        self.messages = list(messages)
        said = ("; FMU said: " + " | ".join(self.messages)) if self.messages else ""
        super().__init__(f"{component}: {call} returned {_STATUS[status] if 0 <= status < 6 else status} "
                         f"at t = {time:.6g} s{said}")


class FmuUnusable(FmuCallError):
    """The FMU file cannot be used here: its binary for this platform is missing or does not
    load, or it refused to instantiate (its own message says why: a model description of
    another build, a missing resource).  Bad input, not a run that failed: a command ends
    with exit code 2 and this message."""

    def __init__(self, component: str, what: str, messages: Sequence[str], call: str = "fmi2Instantiate"):
        self.component, self.call, self.status, self.time = component, call, 3, 0.0
        self.messages = [m for m in messages if not m.startswith("[ok]")][-5:]
        said = ("; FMU said: " + " | ".join(self.messages)) if self.messages else ""
        RuntimeError.__init__(self, f"{component}: {what}{said}")


def library_problem(name: str, fmu_path: Path, error: Exception) -> FmuUnusable:
    """``FmuUnusable`` for an FMU whose binary fmpy could not load (``error``)."""
    text = str(error)
    if "Cannot find shared library" in text:
        library = text.split("Cannot find shared library ")[-1].rstrip(".")
        inside = library[library.find("binaries/"):] if "binaries/" in library else library
        text = (f"it has no binary for this platform ({inside} is missing): an FMU built for another platform, "
                "or its binaries/ folder lost")
    return FmuUnusable(name, f"cannot load {fmu_path.name}: {text}", [], call="loading its binary")


# Where an instance stands in FMI 2.0's co-simulation state machine, as far as ``free``
# needs it: fmi2Terminate is allowed only once initialised (step complete or step failed),
# fmi2FreeInstance in every state but after fmi2Fatal, after which no call at all is.
INSTANTIATED, INITIALIZATION, STEPPING, ERROR, FATAL, TERMINATED, UNKNOWN = (
    "instantiated", "initialization mode", "stepping", "error", "fatal", "terminated", "unknown")


class FMU2SlaveOnce(FMU2Slave):
    """fmpy's FMU2Slave, its C functions' prototypes worked out once a process: fmpy
    reads them from its own methods' signatures for every instance it loads (about 4 ms an
    instance, most of a short run's set-up), and they are the same for every FMI 2.0 library.
    (fmpy takes the FMI version from the class's name: it starts with FMU2.)"""

    _prototypes: dict[str, tuple] | None = None

    def _loadFunctions(self) -> None:
        known = FMU2SlaveOnce._prototypes
        if known is None:
            super()._loadFunctions()
            FMU2SlaveOnce._prototypes = {name: (f.argnames, f.argtypes, f.restype) for name, f in self._functions.items()}
            return
        for name, (argnames, argtypes, restype) in known.items():
            function = getattr(self.dll, name)      # a library without it fails as fmpy's own loading does
            function.argnames, function.argtypes, function.restype = argnames, argtypes, restype
            self._functions[name] = function


class Component(CallCounts):
    """An instantiated FMU: named variables, parameters applied, fast value access."""

    def __init__(self, name: str, fmu_path: Path | str, logging_on: bool = False):
        self._open(name, fmu_path)
        _routes[self.instance_name] = self.messages
        _pin_logger()
        try:
            self.fmu = self._instantiate(logging_on)
        except FmuUnusable:
            _routes.pop(self.instance_name, None)
            raise
        except Exception as error:  # noqa: BLE001 - fmpy raises plain Exceptions for both failures
            _routes.pop(self.instance_name, None)
            if "Failed to instantiate" not in str(error):
                raise library_problem(name, self.fmu_path, error) from None
            raise FmuUnusable(name, f"{self.fmu_path.name} refused to instantiate (fmi2Instantiate returned "
                                    "NULL)", list(self.messages)) from None
        self.state = INSTANTIATED
        functions = self.fmu._functions
        self.raw = RawCalls(ctypes.c_void_p(self.fmu.component), unconverted(functions["fmi2GetReal"]),
                            unconverted(functions["fmi2SetReal"]), self._do_step_function(), ctypes.c_size_t)
        self._get_state = self.fmu._functions["fmi2GetFMUstate"]
        self._set_state = self.fmu._functions["fmi2SetFMUstate"]
        self._free_state = self.fmu._functions["fmi2FreeFMUstate"]
        self._freed = False

    def _open(self, name: str, fmu_path: Path | str, description=None):
        """What a component holds before its FMU is instantiated (every FMI version)."""
        self.name = name
        self.fmu_path = Path(fmu_path)
        self.description = description or read_description(self.fmu_path)
        self.variables = {v.name: v for v in self.description.modelVariables}
        self._unzipped = unzipped(self.fmu_path)
        self.messages: deque[str] = deque(maxlen=50)
        # FMI calls made on the hot path, by kind (the benchmark prices each kind)
        self._start_counts()
        self.time = 0.0
        # A process-unique instance name routes this instance's log messages here.
        self.instance_name = f"{name}#{next(_instances)}"

    def _instantiate(self, logging_on: bool):
        """The FMU instance, its co-simulation interface (see ``harness.engine.me_component``
        for Model Exchange)."""
        fmu = FMU2SlaveOnce(guid=self.description.guid, unzipDirectory=self._unzipped,
                            modelIdentifier=self.description.coSimulation.modelIdentifier,
                            instanceName=self.instance_name)
        fmu.__class__ = FMU2Slave     # loaded: fmpy's own class again (simulate_fmu tells the interface by it)
        fmu.instantiate(callbacks=_callbacks, loggingOn=logging_on)
        return fmu

    def _do_step_function(self):
        return self.fmu._functions["fmi2DoStep"]

    @property
    def unzipped_dir(self) -> str:
        """The folder this process extracted the FMU to (shared by its instances)."""
        return self._unzipped

    # -- helpers ---------------------------------------------------------------------------
    def variable(self, name: str):
        try:
            return self.variables[name]
        except KeyError:
            raise KeyError(f"{self.name} ({self.fmu_path.name}) has no variable '{name}'; it has: "
                           + ", ".join(self.variables)) from None

    def vr(self, name: str) -> int:
        return self.variable(name).valueReference

    def fail(self, call: str, status: int):
        """Raise ``FmuCallError`` for ``call`` that returned ``status``, with the last messages logged."""
        messages = [m for m in self.messages if not m.startswith("[ok]")][-5:]
        self.messages.clear()
        self.note_status(status)
        raise FmuCallError(self.name, call, status, self.time, messages)

    def note_status(self, status: int):
        """The instance returned ``status`` (above warning) to a call: fmi2Error and
        fmi2Fatal change its state (fmi2Discard leaves it where it was, a discarded step
        in "step failed", from which fmi2Terminate is allowed)."""
        if status >= 4:
            self.state = FATAL
        elif status == 3 and self.state != FATAL:
            self.state = ERROR

    @contextmanager
    def lent(self):
        """``self.fmu`` lent to code that drives it itself (fmpy's ``simulate_fmu`` with
        ``fmu_instance``, from set-up to its last step, not terminating it); how that ends
        tells ``free`` the instance's state: stepping when it returns, the status of the
        call that failed when one did, unknown (only fmi2FreeInstance) otherwise."""
        try:
            yield self.fmu
        except FMICallException as error:
            self.state = UNKNOWN
            self.note_status(error.status)
            raise
        except BaseException:
            self.state = UNKNOWN
            raise
        self.state = STEPPING

    def _checked(self, call: str, function, *args):
        try:
            return function(*args)
        except FMICallException as error:
            self.fail(call, error.status)

    # -- set-up ------------------------------------------------------------------------------
    def set_parameters(self, values: dict):
        """Apply parameter values by name (numbers, integers, strings, booleans)."""
        for name, value in values.items():
            var = self.variable(name)
            self._checked(typed_values.call_text(var, name, value), typed_values.set_on, self.fmu, var, value,
                          f"{self.name}.{name}")

    def initialize(self, start: float, stop: float | None):
        self.time = start
        self._checked("fmi2SetupExperiment", self.fmu.setupExperiment, None, start, stop)
        self._checked("fmi2EnterInitializationMode", self.fmu.enterInitializationMode)
        self.state = INITIALIZATION

    def exit_initialization(self):
        self._checked("fmi2ExitInitializationMode", self.fmu.exitInitializationMode)
        self.state = STEPPING

    # -- hot path ----------------------------------------------------------------------------
    def real_buffer(self, names: Iterable[str]):
        """A (value references, values) pair of ctypes arrays for ``read``/``write``."""
        names = list(names)
        vrs = (ctypes.c_uint * len(names))(*[self.vr(n) for n in names])
        return vrs, (ctypes.c_double * len(names))()

    def read(self, vrs, values):
        self.count("get")
        status = self.raw.get_real(self.raw.handle, vrs, _count(len(vrs)), values)
        if status > 1:
            self.fail("fmi2GetReal", status)

    def write(self, vrs, values):
        self.count("set")
        status = self.raw.set_real(self.raw.handle, vrs, _count(len(vrs)), values)
        if status > 1:
            self.fail("fmi2SetReal", status)

    def do_step(self, t: float, h: float):
        self.count("step")
        status = self.raw.do_step(self.raw.handle, t, h, 1)
        if status > 1:
            self.fail(step_call(t, h), status)
        self.time = t + h

    def get(self, names: Sequence[str]) -> list[float]:
        vrs, values = self.real_buffer(names)
        self.read(vrs, values)
        return list(values)

    def wrap_calls(self, wrap: Callable):
        """Replace the hot path's C functions and the state calls by ``wrap(kind, function)``
        (kind: get, set, step, and ``STATE_CALLS``, the three calls the ``state`` count holds),
        e.g. to time every call or record it; before any plan holds them
        (``System(wrap_calls=...)``)."""
        raw = self.raw
        self.raw = raw._replace(get_real=wrap("get", raw.get_real), set_real=wrap("set", raw.set_real),
                                do_step=wrap("step", raw.do_step))
        self._get_state = wrap("get_state", self._get_state)
        self._set_state = wrap("set_state", self._set_state)
        self._free_state = wrap("free_state", self._free_state)

    @property
    def raw_state_calls(self) -> tuple:
        """fmi2GetFMUstate, fmi2SetFMUstate and fmi2FreeFMUstate (FMI 3.0's in a ``Component3``)
        as the raw calls ``save_state``, ``restore_state`` and ``free_state`` make, without
        their counts and checks: for a caller that replays recorded calls."""
        return self._get_state, self._set_state, self._free_state

    # -- state (for masters that roll back) --------------------------------------------------
    # Raw calls like the hot path: an iterating master saves, restores and frees a state
    # on every communication step.
    def save_state(self) -> ctypes.c_void_p:
        self.state_calls += 1
        state = ctypes.c_void_p()
        status = self._get_state(self.raw.handle, ctypes.byref(state))
        if status > 1:
            self.fail("fmi2GetFMUstate", status)
        return state

    def restore_state(self, state, time: float):
        self.state_calls += 1
        status = self._set_state(self.raw.handle, state)
        if status > 1:
            self.fail("fmi2SetFMUstate", status)
        if self.state == ERROR:      # a state saved while stepping, restored after an error
            self.state = STEPPING
        self.time = time

    def free_state(self, state):
        self.state_calls += 1
        status = self._free_state(self.raw.handle, ctypes.byref(state))
        if status > 1:
            self.fail("fmi2FreeFMUstate", status)

    # -- tear-down ---------------------------------------------------------------------------
    def free(self):
        """End the instance with the calls FMI 2.0 allows in its state: fmi2Terminate only
        once initialised and not failed, then fmi2FreeInstance; after fmi2Fatal none (the
        standard allows no further call; the instance and its library stay in memory)."""
        if self._freed:
            return
        self._freed = True
        try:
            if self.state == FATAL:
                return
            if self.state == STEPPING:
                try:
                    self.fmu.terminate()
                    self.state = TERMINATED
                except Exception:  # noqa: BLE001 - freeing must go on after a refused terminate
                    pass
            self.fmu.freeInstance()
        finally:
            _routes.pop(self.instance_name, None)


# -- shared with the FMI 3.0 component (harness.engine.fmi3_component) --------------------------

def dispatch_message(instance_name: str, status: int, category: bytes, message: bytes):
    """Route a log message of the instance ``instance_name`` as this module routes FMI 2.0's."""
    _dispatch(None, instance_name.encode("utf-8"), status, category, message)

