"""Tests for the FMI 2.0 shim in front of pythonfmu (build/shim).

Each test drives a real pythonfmu FMU, wrapped with the shim, through fmpy.

fmpy notes: the high-level FMU2Slave methods (setReal, doStep, ...) return
None and raise ``FMICallException`` (with ``.status``) for any status above
fmi2Warning; the low-level ``fmi2*`` methods return the status as an int.
Log messages reach Python only through fmpy's native ``addLoggerProxy``, which
formats the variadic message in C and then calls *one process-wide* Python
logger, so we install a single module-level collector and keep it alive.
"""

from __future__ import annotations

import ctypes
import importlib.util
import json
import math
import shutil
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path

import pytest

fmpy = pytest.importorskip("fmpy")
from fmpy.fmi1 import FMICallException  # noqa: E402
from fmpy.fmi2 import FMU2Slave, fmi2CallbackFunctions  # noqa: E402
from harness.engine.component import add_log_listener, log_callbacks  # noqa: E402
from pythonfmu.builder import FmuBuilder  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
SHIM_DIR = REPO / "build" / "shim"

FMI2_OK, FMI2_WARNING, FMI2_DISCARD, FMI2_ERROR, FMI2_FATAL = range(5)


def _load_compile_module():
    # build/ is not a package (and "build" would shadow the PyPI project).
    spec = importlib.util.spec_from_file_location("lever_shim_compile", SHIM_DIR / "compile.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


shim = _load_compile_module()

# --------------------------------------------------------------------------
# Slaves under test
# --------------------------------------------------------------------------

GAIN_SLAVE = '''
import math

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real
from pythonfmu.enums import Fmi2Status


class ShimGain(Fmi2Slave):
    """y = gain * u; bad input is reported by logging, never by raising."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._gain = 2.0
        self.u = 0.0
        self.y = 0.0
        self.register_variable(Real("gain", causality=Fmi2Causality.parameter,
                                    variability=Fmi2Variability.tunable,
                                    getter=lambda: self._gain, setter=self._set_gain))
        self.register_variable(Real("u", causality=Fmi2Causality.input))
        self.register_variable(Real("y", causality=Fmi2Causality.output))

    def _set_gain(self, value):
        if value < 0:
            # The '%' checks that messages are not used as printf formats.
            self.log(f"gain must be >= 0 (100% required), got {value}; keeping {self._gain}",
                     Fmi2Status.error)
            return
        self._gain = value

    def exit_initialization_mode(self):
        self.log("initialized", Fmi2Status.ok)

    def do_step(self, current_time, step_size):
        if current_time < 0 or not math.isfinite(self.u):
            self.log(f"cannot step at t={current_time} with u={self.u}", Fmi2Status.error)
            return False
        self.y = self._gain * self.u
        return True
'''

BOOM_SLAVE = '''
from pythonfmu import Fmi2Causality, Fmi2Slave, Real


class ShimBoom(Fmi2Slave):
    """Violates our convention: raises in do_step (pythonfmu -> fmi2Fatal)."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.y = 1.0
        self.register_variable(Real("y", causality=Fmi2Causality.output))

    def do_step(self, current_time, step_size):
        raise RuntimeError("boom")
'''

# --------------------------------------------------------------------------
# Log capture
# --------------------------------------------------------------------------

LOG: list[tuple[str, int, str, str]] = []


def _collect(instance_name, status, category, message):
    LOG.append((instance_name, status, category, message))


# fmpy's logger proxy serves one Python function per process, which the harness owns:
# use its callback struct and listen to every message.
add_log_listener(_collect)


def _callbacks() -> fmi2CallbackFunctions:
    return log_callbacks()


def messages(name: str | None = None, min_status: int = FMI2_OK) -> list[tuple[str, int, str, str]]:
    return [m for m in LOG if (name is None or m[0] == name) and m[1] >= min_status]


@pytest.fixture(autouse=True)
def _clear_log():
    LOG.clear()
    yield
    LOG.clear()


# --------------------------------------------------------------------------
# Fixtures
# --------------------------------------------------------------------------


def _build(tmp: Path, module: str, source: str) -> Path:
    script = tmp / f"{module}.py"
    script.write_text(textwrap.dedent(source))
    return Path(FmuBuilder.build_FMU(script, dest=tmp))


@pytest.fixture(scope="module")
def shim_so(tmp_path_factory) -> Path:
    return shim.compile_shim(tmp_path_factory.mktemp("shim") / "lever_fmi2_shim.so")


@pytest.fixture(scope="module")
def gain_fmus(tmp_path_factory, shim_so) -> tuple[Path, Path]:
    """(unwrapped original, wrapped copy) of the gain FMU."""
    tmp = tmp_path_factory.mktemp("gain")
    original = _build(tmp, "shim_gain_slave", GAIN_SLAVE)
    wrapped = tmp / "wrapped" / original.name
    wrapped.parent.mkdir()
    shutil.copy2(original, wrapped)
    shim.wrap_fmu(wrapped, shim_so)
    return original, wrapped


@pytest.fixture(scope="module")
def gain_fmu(gain_fmus, tmp_path_factory):
    """(model description, extracted directory) of the wrapped gain FMU."""
    wrapped = gain_fmus[1]
    md = fmpy.read_model_description(str(wrapped))
    unzipdir = fmpy.extract(str(wrapped), unzipdir=str(tmp_path_factory.mktemp("gain_x")))
    return md, unzipdir


def vrs(md) -> dict[str, int]:
    return {v.name: v.valueReference for v in md.modelVariables}


def open_slave(md, unzipdir, name: str, logging_on: bool = False) -> FMU2Slave:
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir,
                    modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
    fmu.instantiate(callbacks=_callbacks(), loggingOn=logging_on)
    return fmu


def initialize(fmu: FMU2Slave) -> None:
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()


# --------------------------------------------------------------------------
# Build / packaging
# --------------------------------------------------------------------------

FMI2_CS_FUNCTIONS = """
    fmi2GetTypesPlatform fmi2GetVersion fmi2SetDebugLogging fmi2Instantiate fmi2FreeInstance
    fmi2SetupExperiment fmi2EnterInitializationMode fmi2ExitInitializationMode fmi2Terminate
    fmi2Reset fmi2GetReal fmi2GetInteger fmi2GetBoolean fmi2GetString fmi2SetReal
    fmi2SetInteger fmi2SetBoolean fmi2SetString fmi2GetFMUstate fmi2SetFMUstate
    fmi2FreeFMUstate fmi2SerializedFMUstateSize fmi2SerializeFMUstate fmi2DeSerializeFMUstate
    fmi2GetDirectionalDerivative fmi2SetRealInputDerivatives fmi2GetRealOutputDerivatives
    fmi2DoStep fmi2CancelStep fmi2GetStatus fmi2GetRealStatus fmi2GetIntegerStatus
    fmi2GetBooleanStatus fmi2GetStringStatus
""".split()


def test_shim_exports_the_cs_api_only(shim_so):
    lib = ctypes.CDLL(str(shim_so))
    for name in FMI2_CS_FUNCTIONS:
        assert hasattr(lib, name), name
    for internal in ("shim_logger", "shim_record", "inner_api", "g_api"):
        assert not hasattr(lib, internal), internal

    lib.fmi2GetVersion.restype = ctypes.c_char_p
    lib.fmi2GetTypesPlatform.restype = ctypes.c_char_p
    assert lib.fmi2GetVersion() == b"2.0"
    assert lib.fmi2GetTypesPlatform() == b"default"

    # NULL components are rejected, not dereferenced.
    lib.fmi2DoStep.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_int]
    assert lib.fmi2DoStep(None, 0.0, 0.1, 1) == FMI2_ERROR
    vr = (ctypes.c_uint * 1)(0)
    val = (ctypes.c_double * 1)(1.0)
    assert lib.fmi2SetReal(None, vr, ctypes.c_size_t(1), val) == FMI2_ERROR
    assert lib.fmi2GetReal(None, vr, ctypes.c_size_t(1), val) == FMI2_ERROR
    assert lib.fmi2SetDebugLogging(None, 1, ctypes.c_size_t(0), None) == FMI2_ERROR
    assert lib.fmi2Terminate(None) == FMI2_ERROR
    # the one function that is not FMI 2.0's: the FMI 3.0 entry's path to the event indicators
    assert lib.leverGetEventIndicatorValues(None, val, ctypes.c_size_t(1)) == FMI2_ERROR
    lib.fmi2FreeInstance(None)


def test_compile_failure_raises_with_compiler_output(tmp_path, monkeypatch):
    monkeypatch.setenv("CC", "cc -include /nonexistent/lever_missing.h")
    with pytest.raises(RuntimeError, match="lever_missing.h"):
        shim.compile_shim(tmp_path / "broken.so")


def test_wrap_fmu_moves_pythonfmu_library_and_keeps_the_rest(gain_fmus, shim_so):
    original, wrapped = gain_fmus
    with zipfile.ZipFile(original) as a, zipfile.ZipFile(wrapped) as b:
        ident = "ShimGain"
        lib = f"binaries/linux64/{ident}.so"
        inner = "binaries/linux64/pythonfmu-export.so"
        assert sorted(b.namelist()) == sorted(a.namelist() + [inner, shim.CONFIG_NAME])
        config = b.read(shim.CONFIG_NAME).decode()
        guid = fmpy.read_model_description(str(original)).guid
        assert f"guid={guid}\n" in config
        python = shim.build_python()
        if python["library"]:
            assert f"python_library={python['library']}\n" in config
        assert b.read(lib) == shim_so.read_bytes()
        assert b.read(inner) == a.read(lib)
        for name in a.namelist():
            if name != lib:  # other platforms' binaries included
                assert b.read(name) == a.read(name), name
        assert f"binaries/win64/{ident}.dll" in b.namelist()
        # The shim keeps the original entry's permission bits.
        assert b.getinfo(lib).external_attr == a.getinfo(lib).external_attr
    assert wrapped.stat().st_mode == original.stat().st_mode
    with pytest.raises(ValueError, match="already contains"):
        shim.wrap_fmu(wrapped, shim_so)
    assert not list(wrapped.parent.glob("*.tmp"))


def test_missing_inner_library_fails_instantiate_with_message(gain_fmus, tmp_path):
    wrapped = gain_fmus[1]
    md = fmpy.read_model_description(str(wrapped))
    unzipdir = fmpy.extract(str(wrapped), unzipdir=str(tmp_path / "x"))
    (Path(unzipdir) / "binaries" / "linux64" / "pythonfmu-export.so").unlink()
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir,
                    modelIdentifier=md.coSimulation.modelIdentifier, instanceName="orphan")
    try:
        with pytest.raises(Exception, match="Failed to instantiate"):
            fmu.instantiate(callbacks=_callbacks(), loggingOn=False)
    finally:
        fmu.freeLibrary()
    [(name, status, _, text)] = messages("orphan")
    assert status == FMI2_ERROR
    assert "pythonfmu-export.so" in text


# --------------------------------------------------------------------------
# Runtime behaviour
# --------------------------------------------------------------------------


def test_normal_operation(gain_fmu):
    md, unzipdir = gain_fmu
    vr = vrs(md)
    fmu = open_slave(md, unzipdir, "plain")
    try:
        initialize(fmu)
        assert fmu.getReal([vr["gain"]]) == [2.0]
        fmu.setReal([vr["u"]], [3.0])
        assert fmu.fmi2DoStep(fmu.component, 0.0, 0.1, 1) == FMI2_OK
        assert fmu.getReal([vr["y"]]) == [6.0]
        fmu.setReal([vr["gain"]], [0.5])
        fmu.doStep(0.1, 0.1)
        assert fmu.getReal([vr["y"]]) == [1.5]
        assert fmu.terminate() == FMI2_OK
    finally:
        fmu.freeInstance()
    assert messages(min_status=FMI2_WARNING) == []


def test_rejected_parameter_is_an_error_and_logged_with_logging_off(gain_fmu):
    md, unzipdir = gain_fmu
    vr = vrs(md)
    fmu = open_slave(md, unzipdir, "strict", logging_on=False)
    try:
        initialize(fmu)
        fmu.setReal([vr["u"]], [1.0])
        with pytest.raises(FMICallException) as info:
            fmu.setReal([vr["gain"]], [-1.0])
        assert info.value.status == FMI2_ERROR
        assert info.value.function == "fmi2SetReal"

        [(name, status, category, text)] = messages()
        assert (name, status, category) == ("strict", FMI2_ERROR, "logStatusError")
        assert text == "gain must be >= 0 (100% required), got -1.0; keeping 2.0"

        # The instance survives: old value kept, the next calls are OK again.
        assert fmu.getReal([vr["gain"]]) == [2.0]
        assert fmu.fmi2DoStep(fmu.component, 0.0, 0.1, 1) == FMI2_OK
        assert fmu.getReal([vr["y"]]) == [2.0]
    finally:
        fmu.freeInstance()


def test_failed_step_is_an_error_not_a_discard(gain_fmu):
    md, unzipdir = gain_fmu
    vr = vrs(md)
    fmu = open_slave(md, unzipdir, "stepper")
    try:
        initialize(fmu)
        fmu.setReal([vr["u"]], [math.nan])
        with pytest.raises(FMICallException) as info:
            fmu.doStep(0.0, 0.1)
        assert info.value.status == FMI2_ERROR
        assert "u=nan" in messages("stepper", FMI2_ERROR)[-1][3]

        fmu.setReal([vr["u"]], [1.0])
        with pytest.raises(FMICallException) as info:
            fmu.doStep(-1.0, 0.1)
        assert info.value.status == FMI2_ERROR
        assert "t=-1.0" in messages("stepper", FMI2_ERROR)[-1][3]

        assert fmu.fmi2DoStep(fmu.component, 0.0, 0.1, 1) == FMI2_OK
        assert fmu.getReal([vr["y"]]) == [2.0]
    finally:
        fmu.freeInstance()


def test_ok_messages_follow_the_importers_debug_logging(gain_fmu):
    md, unzipdir = gain_fmu

    def initialized(name):
        return [m for m in messages(name) if m[3] == "initialized"]

    on = open_slave(md, unzipdir, "chatty", logging_on=True)
    off = open_slave(md, unzipdir, "quiet", logging_on=False)
    try:
        initialize(on)
        initialize(off)
        assert initialized("chatty") == [("chatty", FMI2_OK, "logAll", "initialized")]
        assert initialized("quiet") == []

        # Categories filter OK messages; fmi2Reset re-creates the Python object.
        off.setDebugLogging(True, ["logStatusError"])
        off.reset()
        initialize(off)
        assert initialized("quiet") == []
        off.setDebugLogging(True, ["logAll"])
        off.reset()
        initialize(off)
        assert initialized("quiet") == [("quiet", FMI2_OK, "logAll", "initialized")]
    finally:
        on.freeInstance()
        off.freeInstance()


def test_two_instances_are_independent(gain_fmu):
    md, unzipdir = gain_fmu
    vr = vrs(md)
    a = open_slave(md, unzipdir, "a")
    b = open_slave(md, unzipdir, "b")
    try:
        initialize(a)
        initialize(b)
        a.setReal([vr["gain"], vr["u"]], [3.0, 1.0])
        b.setReal([vr["gain"], vr["u"]], [5.0, 2.0])

        with pytest.raises(FMICallException):
            a.setReal([vr["gain"]], [-7.0])
        assert [m[0] for m in messages(min_status=FMI2_WARNING)] == ["a"]

        # b's calls are unaffected by a's error status, and vice versa.
        assert b.fmi2DoStep(b.component, 0.0, 0.1, 1) == FMI2_OK
        assert a.fmi2DoStep(a.component, 0.0, 0.1, 1) == FMI2_OK
        assert a.getReal([vr["gain"], vr["y"]]) == [3.0, 3.0]
        assert b.getReal([vr["gain"], vr["y"]]) == [5.0, 10.0]
    finally:
        a.freeInstance()
    try:
        assert b.fmi2DoStep(b.component, 0.1, 0.1, 1) == FMI2_OK
        assert b.getReal([vr["y"]]) == [10.0]
    finally:
        b.freeInstance()


# Runs in a child process: if the shim let pythonfmu touch its freed Python
# object, the crash fails this test instead of killing pytest.
FATAL_DRIVER = r'''
import json, sys
from ctypes import byref
import fmpy
from fmpy import calloc, free
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                       fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)
from fmpy.logging import addLoggerProxy

log = []
def collect(env, name, status, category, message):
    log.append([status, message.decode()])

cb = fmi2CallbackFunctions()
cb.logger = fmi2CallbackLoggerTYPE(collect)
cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
addLoggerProxy(byref(cb))

path, unzipdir = sys.argv[1], sys.argv[2]
md = fmpy.read_model_description(path)
fmpy.extract(path, unzipdir=unzipdir)
fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir,
                modelIdentifier=md.coSimulation.modelIdentifier, instanceName="boom")
fmu.instantiate(callbacks=cb, loggingOn=False)
fmu.setupExperiment(startTime=0.0)
fmu.enterInitializationMode()
fmu.exitInitializationMode()

def status(call):
    try:
        call()
        return 0
    except FMICallException as e:
        return e.status

result = {
    "doStep": status(lambda: fmu.doStep(0.0, 0.1)),
    "getReal": status(lambda: fmu.getReal([0])),
    "doStep2": status(lambda: fmu.doStep(0.0, 0.1)),
    "terminate": status(lambda: fmu.terminate()),
}
fmu.freeInstance()
result["log"] = log
print(json.dumps(result), flush=True)
'''


def test_python_exception_quarantines_the_instance(tmp_path, shim_so):
    fmu = _build(tmp_path, "shim_boom_slave", BOOM_SLAVE)
    shim.wrap_fmu(fmu, shim_so)
    proc = subprocess.run([sys.executable, "-c", FATAL_DRIVER, str(fmu), str(tmp_path / "x")],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    result = json.loads(proc.stdout.strip().splitlines()[-1])

    assert result["doStep"] in (FMI2_ERROR, FMI2_FATAL)
    assert result["getReal"] == FMI2_ERROR
    assert result["doStep2"] == FMI2_ERROR
    assert result["terminate"] == FMI2_ERROR

    log = result["log"]
    assert any(s == FMI2_FATAL and "RuntimeError('boom')" in text for s, text in log), log
    unusable = [text for s, text in log if s == FMI2_ERROR]
    assert unusable == ["instance is unusable after a fatal error in fmi2DoStep"] * 3


def test_without_a_compiler_lever_build_says_how_to_get_one(lever, tmp_path, monkeypatch):
    monkeypatch.setenv("CC", str(tmp_path / "no-such-compiler"))
    result = lever("build", "--force", "--out", str(tmp_path / "fmus"))
    assert result.exit_code == 1 and "Traceback" not in result.output
    assert "cannot run" in result.output and "apt install gcc" in result.output and "CC=" in result.output


def test_a_build_started_while_another_builds_waits_and_finds_its_fmus_current(tmp_path, monkeypatch):
    """Two builds at once (test workers, two shells) would write one staging folder: the
    second waits for the first's lock, then finds the FMUs current and builds nothing."""
    spec = importlib.util.spec_from_file_location("lever_build_fmus_lock", REPO / "build" / "fmus.py")
    fmus = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(fmus)
    monkeypatch.setattr(fmus, "STAGING", tmp_path / "staging")
    built = tmp_path / "built"                     # the first build's FMUs, once it is done
    monkeypatch.setattr(fmus, "is_current", lambda out_dir: built.exists())
    monkeypatch.setattr(fmus, "_build_in", lambda *a: pytest.fail("built again while the first build's FMUs are current"))
    (tmp_path / "staging").mkdir()
    # the first build: another process holding the lock for a second, then done
    first = subprocess.Popen([sys.executable, "-c",
                              "import fcntl, pathlib, sys, time\n"
                              "f = open(sys.argv[1], 'a'); fcntl.flock(f, fcntl.LOCK_EX)\n"
                              "print('locked', flush=True); time.sleep(1.0)\n"
                              "pathlib.Path(sys.argv[2]).touch()\n",
                              str(tmp_path / "staging" / ".build.lock"), str(built)],
                             stdout=subprocess.PIPE, text=True)
    assert first.stdout.readline().strip() == "locked"
    said = []
    fmus.build(tmp_path / "fmus", log=said.append)
    assert first.wait(timeout=60) == 0
    assert said == [f"FMUs in {tmp_path / 'fmus'} are up to date"]
