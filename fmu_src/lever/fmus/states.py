"""FMU states (``fmi2GetFMUstate``/``fmi2SetFMUstate`` and their serialized form): everything
an instance needs to continue exactly, judged completely before it is applied."""
from __future__ import annotations

import json
import math
import re
import struct
from pathlib import Path

from ..physics.parameters import Parameter, ParameterError
from .guard import guarded
from .recompute import ALL

#: A serialized state: ``STATE_MAGIC``, a space, a JSON header (format, model, GUID,
#: length of the payload), a newline, the payload (JSON of the state).
STATE_MAGIC = b"lever-fmu-state"
#: The native entry (build/shim) keeps the state machine's state and the time in its own
#: header and passes them in front of the bytes as ``SHIM_FRAME <state bit> <the time's 64
#: bits in hex>``: the state is refused unless they agree with its phase and time.
SHIM_FRAME = b"lever-shim-frame"
_SHIM_PHASES = {1: ("instantiated",), 2: ("initialization",), 4: ("stepping",), 8: ("stepping",),
                16: ("terminated",)}
STATE_FORMAT = 1
_HEADER_LIMIT = 1024     # bytes the header line may take
_NESTING_LIMIT = 4       # a state is {"variables": {...}, "internal": {"y": [...]}}


class _OwnState(dict):
    """A state an instance took itself (``fmi2GetFMUstate``), with the model and GUID
    its serialized form carries in its header."""
    __slots__ = ("owner", "model", "guid")


class _SerializedState:
    """Bytes given to ``fmi2DeSerializeFMUstate``, kept as they are: pythonfmu calls the
    deserializer on the class, where nothing can be logged and an exception is fatal, so
    they are judged (header, then content) by ``fmi2SetFMUstate`` on the instance."""
    __slots__ = ("data",)

    def __init__(self, data: bytes):
        self.data = data


def _nesting(data: bytes) -> int:
    """The deepest nesting of JSON arrays and objects in ``data`` (strings skipped):
    judged before parsing, so deeply nested bytes never reach the recursive parser."""
    depth = deepest = 0
    in_string = escaped = False
    for byte in data:
        if in_string:
            if escaped:
                escaped = False
            elif byte == 0x5C:          # backslash
                escaped = True
            elif byte == 0x22:          # quote
                in_string = False
        elif byte == 0x22:
            in_string = True
        elif byte in (0x5B, 0x7B):      # [ {
            depth += 1
            deepest = max(deepest, depth)
        elif byte in (0x5D, 0x7D):
            depth -= 1
    return deepest


_GUIDS: dict[str, str] = {}


def _guid_of(resources) -> str:
    """The GUID in the model description of the unpacked FMU whose resources folder is
    ``resources`` (FMI 3.0 calls it the instantiation token; "" where there is none to read:
    the model run outside an FMU)."""
    key = str(resources or "")
    if key not in _GUIDS:
        guid = ""
        if key:
            try:
                text = (Path(key).parent / "modelDescription.xml").read_text(encoding="utf-8", errors="replace")
                found = re.search(r'\b(?:guid|instantiationToken)\s*=\s*"([^"]*)"', text)
                guid = found.group(1) if found else ""
            except (OSError, ValueError):
                pass
        _GUIDS[key] = guid
    return _GUIDS[key]


class StateSaving:
    """The FMU-state entry points of a ``LeverSlave``; a model with internal state (beyond
    its declared variables) overrides ``_internal_state``, ``_internal_problem`` and
    ``_restore_internal_state``."""

    # -- the model's internal state ------------------------------------------------------
    def _internal_state(self) -> dict:
        return {}

    def _internal_problem(self, internal) -> str | None:
        """Why ``internal`` (from a serialized state) is not this model's internal state."""
        return None if internal == {} else f"internal state {internal!r} where this model keeps none"

    def _restore_internal_state(self, state: dict):
        pass

    def _guid(self) -> str:
        return _guid_of(self.resources)

    @guarded(default=dict)
    def _get_fmu_state(self):
        state = _OwnState(
            time=self._time,
            phase=self._phase,
            variables={name: getattr(self, name) for name in self._declared},
            internal=self._internal_state(),
        )
        state.owner, state.model, state.guid = self, type(self).__name__, self._guid()
        return state

    # -- restoring a state: judged whole unless the instance took it itself ----------------
    def _parse_serialized(self, data: bytes) -> tuple[dict | None, str | None]:
        """(state, None) from serialized bytes, or (None, why they are no state of this FMU);
        behind the native entry, the state must agree with the entry's header."""
        if not data.startswith(SHIM_FRAME + b" "):
            return self._parse_model_state(data)
        end = data.find(b"\n", 0, 128)
        if end < 0:
            return None, "the native entry's frame is not terminated (truncated or malformed)"
        try:
            bit, bits = data[len(SHIM_FRAME) + 1:end].decode("ascii").split(" ")
            bit, time = int(bit), struct.unpack("<d", struct.pack("<Q", int(bits, 16)))[0]
        except (UnicodeDecodeError, ValueError, struct.error):
            return None, "the native entry's frame does not decode"
        state, problem = self._parse_model_state(data[end + 1:])
        if problem is None:
            problem = self._state_problem(state)
        if problem is None and (state["phase"] not in _SHIM_PHASES.get(bit, ()) or state["time"] != time):
            problem = (f"its parts disagree: the native entry's header says state {bit} ("
                       f"{'/'.join(_SHIM_PHASES.get(bit, ('unknown',)))}) at t = {time!r} s, the model's part "
                       f"phase {state['phase']!r} at t = {state['time']!r} s (damaged or edited bytes)")
        return (None, problem) if problem else (state, None)

    def _parse_model_state(self, data: bytes) -> tuple[dict | None, str | None]:
        if not data.startswith(STATE_MAGIC + b" "):
            return None, f"the bytes do not start with {STATE_MAGIC.decode()!r} (not a serialized state of a lever FMU)"
        end = data.find(b"\n", 0, _HEADER_LIMIT)
        if end < 0:
            return None, f"the state's header is not terminated within {_HEADER_LIMIT} bytes (truncated or malformed)"
        try:
            header = json.loads(data[len(STATE_MAGIC) + 1:end].decode("utf-8"))
        except (UnicodeDecodeError, ValueError) as error:
            return None, f"the state's header does not decode ({type(error).__name__}: {error})"
        if not (isinstance(header, dict) and set(header) == {"format", "model", "guid", "length"}):
            return None, f"the state's header {header!r} lacks format, model, guid or length"
        if header["format"] != STATE_FORMAT:
            return None, f"state format {header['format']!r}; this FMU reads format {STATE_FORMAT}"
        if header["model"] != type(self).__name__:
            return None, f"not a state of {type(self).__name__}: it is a state of {header['model']!r}"
        guid = self._guid()
        if header["guid"] and guid and header["guid"] != guid:
            return None, (f"not a state of this build of {type(self).__name__}: GUID {header['guid']!r}, "
                          f"this FMU's is {guid!r}")
        payload = data[end + 1:]
        if header["length"] != len(payload):
            return None, (f"the state's header announces {header['length']!r} bytes of content, "
                          f"{len(payload)} follow (truncated or padded)")
        if _nesting(payload) > _NESTING_LIMIT:
            return None, f"the state's content is nested deeper than {_NESTING_LIMIT} levels"
        try:
            return json.loads(payload.decode("utf-8")), None
        except (UnicodeDecodeError, ValueError, RecursionError) as error:
            return None, f"the state's content does not decode ({type(error).__name__}: {error})"

    def _state_problem(self, state) -> str | None:
        """Why ``state`` is not a complete, valid state of this FMU (None when it is one):
        every part is judged before anything is applied."""
        if not isinstance(state, dict) or set(state) != {"time", "phase", "variables", "internal"}:
            return "not a state of this FMU (it needs time, phase, variables and internal)"
        variables = state["variables"]
        if not isinstance(variables, dict) or set(variables) != set(self._declared):
            names = set(variables) if isinstance(variables, dict) else set()
            return (f"not a state of {type(self).__name__}: its variables differ (unknown: "
                    f"{', '.join(sorted(map(str, names - set(self._declared)))) or '-'}; missing: "
                    f"{', '.join(sorted(set(self._declared) - names)) or '-'})")
        if state["phase"] not in ("instantiated", "initialization", "stepping", "terminated"):
            return f"not a state of this FMU: unknown phase {state['phase']!r}"
        if not (type(state["time"]) is float and math.isfinite(state["time"])):
            return f"not a state of this FMU: time {state['time']!r} is not a finite number"
        for name, spec in self._declared.items():
            value = variables[name]
            kind = getattr(spec, "kind", "real")
            if type(value) not in {"real": (float, int), "integer": (int,), "string": (str,)}[kind]:
                return f"not a state of this FMU: '{name}' = {value!r} is not a{'n' if kind == 'integer' else ''} {kind}"
            message = spec.problem(value) if isinstance(spec, Parameter) else (
                None if math.isfinite(value) else f"output '{name}' = {value!r} is not finite")
            if message:
                return f"not a state of this FMU: {message}"
        return self._internal_problem(state["internal"])

    @guarded()
    def _set_fmu_state(self, state):
        # A state this instance took is one; anything else (another instance's, or
        # deserialized bytes) is judged completely first.  An iterating master restores
        # its own state on every step: the check would cost a fifth of the restore.
        own = type(state) is _OwnState and state.owner is self
        if not own:
            problem = None
            if isinstance(state, _SerializedState):
                state, problem = self._parse_serialized(state.data)
            elif type(state) is _OwnState and state.model != type(self).__name__:
                problem = f"not a state of {type(self).__name__}: it is a state of {state.model!r}"
            problem = problem or self._state_problem(state)
            if problem:
                self._error(f"fmi2SetFMUstate: {problem}; the FMU's state is unchanged")
                return
        elif state["phase"] == self._phase == "stepping" and not self._model_stale and self._build_error is None:
            # Its own state while stepping: the parameters are fixed since, the model was
            # built for them and nothing can fail (an iterating master's every step).
            for name, value in state["variables"].items():
                setattr(self, name, value)
            self._time = state["time"]
            self._restore_internal_state(state["internal"])
            self._dirty = ALL
            return
        # Applied as one transaction: should the model not build from the state's
        # parameters, the instance is put back as it was.
        before = dict(self.__dict__)
        try:
            for name, value in state["variables"].items():
                if type(value) is int and getattr(self._declared[name], "kind", "real") == "real":
                    value = float(value)    # a real written as an integer: reals are kept as floats
                setattr(self, name, value)
            self._time = state["time"]
            self._phase = state["phase"]
            if self._phase != "instantiated" and (self._model_stale or self._build_error is not None
                                                   or self._built_with != self._values()):
                self._try_build(report=False, reset=False)
                if self._build_error is not None:
                    raise ParameterError("state", self._build_error)
            self._restore_internal_state(state["internal"])
        except Exception as error:
            self.__dict__.clear()
            self.__dict__.update(before)
            why = str(error) if isinstance(error, ParameterError) else f"{type(error).__name__}: {error}"
            self._error(f"fmi2SetFMUstate: the model does not build from the state ({why}); the FMU's state "
                        "is unchanged")
            return
        self._dirty = ALL

    @staticmethod
    def _fmu_state_to_bytes(state) -> bytes:
        if isinstance(state, _SerializedState):
            # A deserialized state serialized again: its own bytes, without the frame the
            # native entry put in front of them (the entry writes its header anew), so the
            # same bytes come out that went in.  (As JSON it would raise, which pythonfmu
            # makes fatal.)
            data = state.data
            if data.startswith(SHIM_FRAME + b" ") and b"\n" in data[:128]:
                data = data[data.index(b"\n") + 1:]
            return data
        # repr-exact floats: a restored state continues bit-identically.
        payload = json.dumps(state, allow_nan=True).encode("utf-8")     # judged when restored
        header = json.dumps({"format": STATE_FORMAT, "model": getattr(state, "model", ""),
                             "guid": getattr(state, "guid", ""), "length": len(payload)})
        return STATE_MAGIC + b" " + header.encode("utf-8") + b"\n" + payload

    @staticmethod
    def _fmu_state_from_bytes(data: bytes):
        return _SerializedState(bytes(data))

