"""The FMI 2.0 boundary as the FMUs' native entry (build/shim) enforces it: the Co-Simulation
state machine, the status getters, FMU states and their serialized bytes, strings that are
not UTF-8, the GUID.  Each case drives a built FMU through its raw C functions (fmpy's
ctypes prototypes, without fmpy's exception on a non-OK status) and checks that a refusal
is fmi2Error with a message, reaches nothing, and leaves the instance usable.

The variable-level rules (which variable may be set when, the contents of a state) are the
Python side's (tests/fmus/test_fmus.py, tests/fmus/test_badinputs.py)."""
from __future__ import annotations

import ctypes
import struct
from ctypes import byref, c_double, c_int, c_size_t, create_string_buffer

import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave, fmi2FMUstate

from harness.engine.component import add_log_listener, log_callbacks

OK, WARNING, DISCARD, ERROR, FATAL = range(5)
DO_STEP_STATUS, PENDING_STATUS, LAST_SUCCESSFUL_TIME, TERMINATED = range(4)
H = 1e-3

LOG: list[tuple[str, int, str]] = []
add_log_listener(lambda name, status, category, message: LOG.append((name, status, message)))


@pytest.fixture(scope="module")
def unzipped(fmu_dir, tmp_path_factory):
    """{model identifier: (model description, extracted directory)}"""
    root = tmp_path_factory.mktemp("boundary")
    return {m: (read_model_description(str(fmu_dir / f"{m}.fmu")), extract(str(fmu_dir / f"{m}.fmu"), str(root / m)))
            for m in ("EngineShaft", "LoadShaft", "LeverCoupling", "MisalignmentSource")}


class Native:
    """One instance, called through the FMU's C functions as a C host would."""

    count = 0

    def __init__(self, unzipped, model: str = "EngineShaft"):
        md, directory = unzipped[model]
        Native.count += 1
        self.name = f"{model}-{Native.count}"
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        self.fmu = FMU2Slave(guid=md.guid, unzipDirectory=directory, modelIdentifier=model, instanceName=self.name)
        self.fmu.instantiate(callbacks=log_callbacks(), loggingOn=False)
        self.f = self.fmu._functions

    def call(self, function: str, *args) -> int:
        return self.f[function](self.fmu.component, *args)

    def start(self):
        assert self.call("fmi2SetupExperiment", 0, 0.0, 0.0, 0, 0.0) == OK
        assert self.call("fmi2EnterInitializationMode") == OK
        assert self.call("fmi2ExitInitializationMode") == OK
        return self

    def step(self, t: float, h: float = H) -> int:
        return self.call("fmi2DoStep", t, h, 1)

    def time(self) -> float:
        value = c_double(-1.0)
        assert self.call("fmi2GetRealStatus", LAST_SUCCESSFUL_TIME, byref(value)) == OK
        return value.value

    def get(self, name: str) -> float:
        vr, value = (ctypes.c_uint * 1)(self.vr[name]), (c_double * 1)()
        assert self.call("fmi2GetReal", vr, 1, value) == OK
        return value[0]

    def set_strings(self, name: str, *values) -> int:
        vr = (ctypes.c_uint * len(values))(*[self.vr[name]] * len(values))
        return self.call("fmi2SetString", vr, len(values), (ctypes.c_char_p * len(values))(*values))

    def state(self):
        state = fmi2FMUstate()
        assert self.call("fmi2GetFMUstate", byref(state)) == OK
        return state

    def serialize(self, state) -> bytes:
        size = c_size_t()
        assert self.call("fmi2SerializedFMUstateSize", state, byref(size)) == OK
        buffer = create_string_buffer(size.value)
        assert self.call("fmi2SerializeFMUstate", state, buffer, size) == OK
        return buffer.raw

    def deserialize(self, data: bytes):
        state = fmi2FMUstate()
        status = self.call("fmi2DeSerializeFMUstate", create_string_buffer(data, len(data)), len(data), byref(state))
        return status, state

    def messages(self, min_status: int = ERROR) -> list[str]:
        return [m for n, s, m in LOG if n == self.name and s >= min_status]

    freed = False

    def free(self):
        if not self.freed:
            self.fmu.freeInstance()
            self.freed = True


@pytest.fixture
def native(unzipped):
    made = []

    def make(model="EngineShaft"):
        made.append(Native(unzipped, model))
        return made[-1]

    yield make
    for instance in made:
        instance.free()


# -- the state machine ------------------------------------------------------------------------

def test_setup_experiment_while_stepping_is_refused_and_time_stays(native):
    e = native().start()
    assert e.step(0.0) == OK and e.step(H) == OK
    assert e.time() == 2 * H
    assert e.call("fmi2SetupExperiment", 0, 0.0, 5.0, 0, 0.0) == ERROR
    assert "fmi2SetupExperiment is not allowed in state 'step complete'" in e.messages()[-1]
    assert e.time() == 2 * H
    assert e.step(2 * H) == OK and e.time() == 3 * H


WRONG_STATE = [
    ("instantiated", "fmi2ExitInitializationMode", ()),
    ("instantiated", "fmi2Terminate", ()),
    ("instantiated", "fmi2DoStep", (0.0, H, 1)),
    ("instantiated", "fmi2GetRealStatus", (LAST_SUCCESSFUL_TIME, byref(c_double()))),
    ("initialization", "fmi2SetupExperiment", (0, 0.0, 0.0, 0, 0.0)),
    ("initialization", "fmi2DoStep", (0.0, H, 1)),
    ("stepping", "fmi2EnterInitializationMode", ()),
    ("stepping", "fmi2ExitInitializationMode", ()),
    ("stepping", "fmi2CancelStep", ()),
    ("terminated", "fmi2DoStep", (H, H, 1)),
    ("terminated", "fmi2SetReal", ((ctypes.c_uint * 1)(7), 1, (c_double * 1)(1.0))),
    ("terminated", "fmi2Terminate", ()),
]


@pytest.mark.parametrize("phase, function, args", WRONG_STATE, ids=[f"{p}-{f}" for p, f, _ in WRONG_STATE])
def test_a_call_in_the_wrong_state_is_refused_and_reaches_nothing(native, phase, function, args):
    e = native()
    if phase == "initialization":
        assert e.call("fmi2SetupExperiment", 0, 0.0, 0.0, 0, 0.0) == OK
        assert e.call("fmi2EnterInitializationMode") == OK
    elif phase in ("stepping", "terminated"):
        e.start()
        assert e.step(0.0) == OK
        if phase == "terminated":
            assert e.call("fmi2Terminate") == OK
    assert e.call(function, *args) == ERROR
    assert f"{function} is not allowed in state" in e.messages()[-1]
    # the instance goes on from where it was
    if phase == "instantiated":
        e.start()
    elif phase == "initialization":
        assert e.call("fmi2ExitInitializationMode") == OK
    elif phase == "terminated":
        assert e.call("fmi2Reset") == OK
        e.start()
    t = e.time()
    assert e.step(t) == OK and e.time() == t + H


# -- the status getters -------------------------------------------------------------------------

def test_last_successful_time_after_steps_a_refused_step_and_a_restore(native):
    e = native().start()
    for k in range(2):
        assert e.step(k * H) == OK
    saved = e.state()
    assert e.step(2 * H, -H) == ERROR            # refused by the model: nothing moved
    assert e.time() == 2 * H
    assert e.step(2 * H) == OK and e.step(3 * H) == OK and e.time() == 4 * H
    assert e.call("fmi2SetFMUstate", saved) == OK
    assert e.time() == 2 * H
    assert e.step(2 * H) == OK and e.time() == 3 * H
    assert e.call("fmi2FreeFMUstate", byref(saved)) == OK and not saved


def test_the_other_status_getters_say_what_is_true(native):
    e = native().start()
    assert e.step(0.0) == OK
    status, flag = c_int(-1), c_int(-1)
    assert e.call("fmi2GetStatus", DO_STEP_STATUS, byref(status)) == ERROR
    assert "no step is pending" in e.messages()[-1]
    assert e.call("fmi2GetBooleanStatus", TERMINATED, byref(flag)) == OK and flag.value == 0
    assert e.call("fmi2GetIntegerStatus", DO_STEP_STATUS, byref(status)) == ERROR
    assert e.call("fmi2GetStringStatus", PENDING_STATUS, byref(ctypes.c_char_p())) == ERROR
    assert e.step(H) == OK


# -- FMU states ---------------------------------------------------------------------------------

def test_serializing_into_too_small_a_buffer_is_refused_and_writes_nothing(native):
    e = native().start()
    assert e.step(0.0) == OK
    state = e.state()
    size = c_size_t()
    assert e.call("fmi2SerializedFMUstateSize", state, byref(size)) == OK
    small = create_string_buffer(b"\xaa" * (size.value - 1), size.value - 1)
    assert e.call("fmi2SerializeFMUstate", state, small, size.value - 1) == ERROR
    assert f"the state needs {size.value}" in e.messages()[-1]
    assert small.raw == b"\xaa" * (size.value - 1)
    assert len(e.serialize(state)) == size.value
    e.call("fmi2FreeFMUstate", byref(state))


def _mutations(data: bytes) -> dict[str, bytes]:
    inner = data[32:]
    header = lambda version=1, state=4, time=0.0, length=len(inner), magic=b"LVRSHIM\0": (  # noqa: E731
        magic + struct.pack("<IIdQ", version, state, time, length))
    return {
        "empty": b"",
        "shorter than the header": data[:20],
        "another magic": header(magic=b"NOTLEVER") + inner,
        "another format version": header(version=2) + inner,
        "no state": header(state=0) + inner,
        "two states at once": header(state=6) + inner,
        "a time that is NaN": header(time=float("nan")) + inner,
        "announces more bytes than follow": header(length=len(inner) + 1) + inner,
        "announces fewer bytes than follow": header(length=len(inner) - 1) + inner,
        "truncated": data[:-1],
    }


MUTATIONS = list(_mutations(b"\0" * 40))


@pytest.mark.parametrize("mutation", MUTATIONS)
def test_malformed_serialized_state_is_refused_before_anything_is_applied(native, mutation):
    e = native().start()
    assert e.step(0.0) == OK
    state = e.state()
    data = e.serialize(state)
    assert data[:8] == b"LVRSHIM\0" and struct.unpack("<Q", data[24:32])[0] == len(data) - 32
    w = e.get("w")
    status, restored = e.deserialize(_mutations(data)[mutation])
    assert status == ERROR and not restored
    assert "fmi2DeSerializeFMUstate" in e.messages()[-1]
    # nothing was applied and the instance goes on
    assert e.get("w") == w and e.time() == H
    assert e.step(H) == OK
    e.call("fmi2FreeFMUstate", byref(state))


def test_a_state_that_is_not_ours_is_refused(native):
    e = native().start()
    not_a_state = create_string_buffer(64)
    pointer = ctypes.cast(not_a_state, fmi2FMUstate)
    assert e.call("fmi2SetFMUstate", pointer) == ERROR
    assert "not an FMU state of this FMU" in e.messages()[-1]
    assert e.call("fmi2SerializedFMUstateSize", pointer, byref(c_size_t())) == ERROR
    assert e.step(0.0) == OK


def test_a_serialized_state_carries_its_time_and_state_into_a_fresh_instance(native):
    """Instantiate, DeSerialize, SetFMUstate, DoStep - allowed by FMI 2.0 in a fresh instance:
    the native entry restores the communication time and the 'step complete' state with it.
    (That the model continues exactly is the Python side's, tested in tests/fmus/test_fmus.py.)"""
    a = native("MisalignmentSource").start()
    for k in range(5):
        assert a.step(k * H) == OK
    data = a.serialize(a.state())
    b = native("MisalignmentSource")
    status, state = b.deserialize(data)
    assert status == OK
    assert b.call("fmi2SetFMUstate", state) == OK
    assert b.time() == 5 * H
    assert b.step(5 * H) == OK and a.step(5 * H) == OK
    assert b.get("misalignment") == a.get("misalignment")
    assert b.time() == a.time() == 6 * H


# -- strings and GUID ---------------------------------------------------------------------------

NOT_UTF8 = {"invalid byte": b"\xff\xfe", "lone continuation byte": b"abc\x80",
            "overlong '/'": b"\xc0\xaf", "surrogate": b"\xed\xa0\x80", "above U+10FFFF": b"\xf4\x90\x80\x80",
            "cut-off sequence": b"\xe2\x82", "NULL": None}


@pytest.mark.parametrize("text", list(NOT_UTF8))
def test_a_string_that_is_not_utf8_is_refused_and_the_instance_goes_on(native, text):
    e = native()
    assert e.set_strings("characteristic", "0:100; 50:0".encode(), NOT_UTF8[text]) == ERROR
    assert "fmi2SetString: value[1]" in e.messages()[-1]
    assert e.set_strings("characteristic", "".encode()) == OK
    e.start()
    assert e.step(0.0) == OK


def test_utf8_text_passes(native):
    e = native("MisalignmentSource")
    assert e.set_strings("table", "0:0; 1:0.1 \u2014 ok".encode()) in (OK, ERROR)   # the model judges the text
    assert not any("not UTF-8" in m for m in e.messages())


def test_a_wrong_guid_is_refused_at_instantiate(unzipped):
    md, directory = unzipped["EngineShaft"]
    fmu = FMU2Slave(guid="{00000000-0000-0000-0000-000000000000}", unzipDirectory=directory,
                    modelIdentifier="EngineShaft", instanceName="wrong-guid")
    try:
        with pytest.raises(Exception, match="Failed to instantiate"):
            fmu.instantiate(callbacks=log_callbacks(), loggingOn=False)
    finally:
        fmu.freeLibrary()
    assert any(n == "wrong-guid" and "is not this FMU's GUID" in m for n, s, m in LOG)


def test_fmpy_raises_on_the_native_refusals(native):
    """fmpy's own calls see the refusals as the standard's fmi2Error."""
    e = native().start()
    with pytest.raises(FMICallException) as info:
        e.fmu.enterInitializationMode()
    assert info.value.status == ERROR


# -- a state whose parts disagree -------------------------------------------------------------

def _reframed(data: bytes, state: int | None = None, time: float | None = None) -> bytes:
    """``data`` with the native entry's header saying another state or time."""
    _, old_state, old_time = struct.unpack("<8sId", data[:8] + data[12:24])
    return data[:12] + struct.pack("<Id", old_state if state is None else state,
                                   old_time if time is None else time) + data[24:]


def _refused_whole(e, data: bytes) -> str:
    """Restore ``data`` into ``e``: it must be refused (at DeSerialize or SetFMUstate) and
    leave ``e`` as it was and stepping on; returns the refusal's message."""
    t, w = e.time(), e.get("w")
    status, state = e.deserialize(data)
    if status == OK:
        assert e.call("fmi2SetFMUstate", state) == ERROR, "a state whose parts disagree was restored"
        e.call("fmi2FreeFMUstate", byref(state))
    else:
        assert status == ERROR
    said = e.messages()[-1]
    assert e.time() == t and e.get("w") == w
    assert e.step(t) == OK and e.time() == t + H
    return said


@pytest.mark.parametrize("case", ["header time 5.0 over model time", "header 'terminated' over model 'stepping'",
                                  "header 'instantiated' over model 'stepping'",
                                  "header 'step complete' over model 'terminated'"])
def test_a_state_whose_header_and_model_part_disagree_is_refused_whole(native, case):
    e = native().start()
    for k in range(10):
        assert e.step(k * H) == OK
    source = native().start()
    assert source.step(0.0) == OK
    if case.endswith("'terminated'"):
        assert source.call("fmi2Terminate") == OK
    data = source.serialize(source.state())
    edited = {"header time 5.0 over model time": lambda: _reframed(data, time=5.0),
              "header 'terminated' over model 'stepping'": lambda: _reframed(data, state=16),
              "header 'instantiated' over model 'stepping'": lambda: _reframed(data, state=1),
              "header 'step complete' over model 'terminated'": lambda: _reframed(data, state=4)}[case]()
    said = _refused_whole(e, edited)
    assert "disagree" in said, said
    # the unedited state is restored
    status, state = e.deserialize(data)
    assert status == OK and e.call("fmi2SetFMUstate", state) == OK


def test_every_single_bit_flip_of_the_header_time_is_refused(native):
    e = native().start()
    for k in range(3):
        assert e.step(k * H) == OK
    data = e.serialize(e.state())
    for bit in range(64):
        flipped = bytearray(data)
        flipped[16 + bit // 8] ^= 1 << (bit % 8)
        _refused_whole(e, bytes(flipped))
        e.call("fmi2SetFMUstate", e.deserialize(data)[1])    # back to where the flips start from


# -- instantiate/free cycles ------------------------------------------------------------------

def _rss() -> int:
    with open("/proc/self/status") as status:
        return next(int(line.split()[1]) * 1024 for line in status if line.startswith("VmRSS"))


def test_instantiate_free_cycles_do_not_accumulate_memory(unzipped):
    """pythonfmu 0.7 leaks about 1.4 KB of Python objects at every instantiation (1,403 B a
    cycle measured over 20,000 cycles of EngineShaft); the native entry keeps freed inner
    instances (reset) for the next fmi2Instantiate instead, so the cycles stay flat."""
    md, directory = unzipped["EngineShaft"]
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=directory, modelIdentifier="EngineShaft", instanceName="cycles")
    for _ in range(100):
        fmu.instantiate(loggingOn=False)
        fmu.freeInstance()
    cycles, before = 3000, _rss()
    for _ in range(cycles):
        fmu.instantiate(loggingOn=False)
        fmu.freeInstance()
    per_cycle = (_rss() - before) / cycles
    assert per_cycle < 400, f"{per_cycle:.0f} bytes stay allocated per instantiate/free cycle"


def test_an_instance_taken_from_the_kept_ones_is_a_fresh_one(native):
    """A freed instance's inner instance is reset and reused: nothing of its past shows."""
    fresh = native().start()
    assert fresh.step(0.0) == OK
    w_fresh = fresh.get("w")
    used = native()
    vr, value = (ctypes.c_uint * 1)(used.vr["inertia"]), (c_double * 1)(0.5)
    assert used.call("fmi2SetReal", vr, 1, value) == OK
    used.start()
    for k in range(3):
        assert used.step(k * H) == OK
    used.free()
    again = native()                         # takes the kept inner instance
    assert again.get("inertia") == 0.128 and again.call("fmi2DoStep", 0.0, H, 1) == ERROR   # instantiated
    again.start()
    assert again.step(0.0) == OK and again.get("w") == w_fresh and again.time() == H
