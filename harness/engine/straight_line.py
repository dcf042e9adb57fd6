"""Compiled plans as straight-line Python: one function a plan, made once per run.

A step of a co-simulation on a driveline is a dozen FMI calls and a few dozen copies
of floats; interpreting a plan (``System.step_with``, ``System.propagate_with``: loops
over records, attribute reads) costs more Python than the calls themselves.  As
``dataclasses`` and ``namedtuple`` do, the engine writes the plan's work as the source
of one function, every call, handle, buffer and index bound once, and compiles it; it
does what the interpreting loops do, in their order, call for call.

Values are read and written in the body through memoryviews of the ctypes buffers
(``Source.elements``), the buffers themselves passed to the calls: an item of a
memoryview is a double read or written in C, an item of a ctypes array goes through its
type's conversion functions, about a third more and more code touched on every step.

The source is registered with ``linecache`` under the function's file name
(``<harness TITLE DIGEST>``), so a traceback or a debugger shows the line that failed; a
function's ``source`` attribute holds it too.

A function counts its FMI calls once a run, not call by call (``CallTally``): after its
last call it adds one run, and its components add its runs times its calls of each kind to
their counts (``harness.engine.interface.CallCounts``).  Its calls sit in one ``try``
block; a run that stops there (a call's failing status, any exception) counts the calls
made before the line it stopped on and the one on it.
"""
from __future__ import annotations

import bisect
import ctypes
import hashlib
import linecache
from collections import Counter
from typing import Callable

from harness.engine.component import step_call

#: the function maker compiled from each distinct source
_makers: dict[str, Callable] = {}


def elements_of(values):
    """A memoryview of the ctypes array of doubles ``values``, item for item (a view
    sharing its memory, which it keeps alive); any other sequence (a stand-in's list) as
    it is."""
    if not isinstance(values, ctypes.Array):
        return values
    if values._type_ is not ctypes.c_double:
        raise TypeError(f"{type(values).__name__}: an array of doubles expected")
    return memoryview(values).cast("B").cast("d")


class CallTally:
    """The FMI calls of one compiled function: ``calls`` (``(component, kind)`` in the order
    made, ``lines`` their line numbers in its source) and ``runs`` (whole runs: every call
    made)."""
    __slots__ = ("runs", "calls", "lines")

    def __init__(self, calls, lines):
        self.runs = 0
        self.calls, self.lines = tuple(calls), tuple(lines)
        made: dict[object, Counter] = {}
        for component, kind in self.calls:
            made.setdefault(component, Counter())[kind] += 1
        for component, kinds in made.items():
            component.tallies.append((self, kinds))

    def stopped(self, traceback):
        """Count the calls of a run that stopped at ``traceback``'s line of the function: those
        on the lines up to it."""
        for component, kind in self.calls[:bisect.bisect_right(self.lines, traceback.tb_lineno)]:
            component.count(kind)


class Source:
    """The text of one generated function and the objects it names: ``name(obj, kind)``
    gives each object one name (the same object always the same), ``line`` adds a line of
    the body, ``function`` compiles it."""

    def __init__(self, title: str, arguments: str = ""):
        self.title = title
        self.arguments = arguments
        self.lines: list[str] = []
        self.bound: dict[str, object] = {}
        self._names: dict[int, str] = {}
        self._views: dict[int, str] = {}
        self._counts: dict[str, int] = {}
        # the FMI calls (``call``): (component, kind) and the index of each one's line;
        # the index after the last one's checks
        self._calls: list[tuple[object, str]] = []
        self._call_lines: list[int] = []
        self._after_calls = 0

    def name(self, obj, kind: str) -> str:
        """The name ``obj`` goes by in the body (``kind`` and a number)."""
        known = self._names.get(id(obj))
        if known is not None:
            return known
        number = self._counts.get(kind, 0)
        self._counts[kind] = number + 1
        name = self._names[id(obj)] = f"{kind}{number}"
        self.bound[name] = obj
        return name

    def elements(self, values, kind: str) -> str:
        """The name in the body of a memoryview of the ctypes array ``values`` (doubles):
        its items are the array's, read and written in C.  One view each array, kept with
        the function, the array kept alive by it."""
        known = self._views.get(id(values))
        if known is None:
            known = self._views[id(values)] = self.name(elements_of(values), kind)
        return known

    def line(self, text: str, note: str | None = None):
        """Add ``text`` to the body; ``note`` after it as a comment (a scene's names go here:
        escaped, so that no name can end the comment and become code)."""
        if note is not None:
            text += "    # " + note.encode("unicode_escape").decode("ascii")
        self.lines.append("    " + text)

    def call(self, component, kind: str, text: str, note: str):
        """Add the line ``text`` of an FMI call of ``kind`` to ``component`` (counted by the
        function's ``CallTally``; ``note`` its comment)."""
        self._calls.append((component, kind))
        self._call_lines.append(len(self.lines))
        self.line(text, note)

    def calls_checked(self):
        """The last call's checks are in the body: the calls' ``try`` block may end here."""
        self._after_calls = len(self.lines)

    def _counted_body(self) -> tuple[list[str], list[int]]:
        """The body with its calls in a ``try`` block that counts a stopped run, and the run
        counted after it; and the calls' line numbers in the source."""
        lines = self.lines
        if not self._calls:
            return lines or ["    pass"], []
        first, end = self._call_lines[0], self._after_calls
        inside = lines[first:end]

        def top_level(line):
            return line.startswith("    ") and not line.startswith("     ")
        if not all(map(top_level, (lines[first], *lines[end:end + 1]))) \
                or any(line.strip().startswith("return") for line in inside):
            raise ValueError(f"{self.title}: the calls must make one block of the body's top level")
        body = [*lines[:first], "    try:", *("    " + line for line in inside),
                "    except BaseException as error:",
                "        tally.stopped(error.__traceback__)",
                "        raise",
                "    tally.runs += 1", *lines[end:]]
        # "def make", "def <name>", then the body; a call inside the try block one line later
        return body, [index + 3 + (index >= first) for index in self._call_lines]

    def function(self) -> Callable:
        """Compile the body into a function of ``arguments``, the bound objects closed over."""
        name = "".join(c if c.isalnum() else "_" for c in self.title)
        body, call_lines = self._counted_body()
        tally = CallTally(self._calls, call_lines) if self._calls else None
        if tally is not None:
            self.bound["tally"] = tally
        bound = sorted(self.bound)
        source = "\n".join([f"def make({', '.join(bound)}):",
                            f"    def {name}({self.arguments}):",
                            *("    " + line for line in body),
                            f"    return {name}", ""])
        make = _makers.get(source)
        if make is None:
            # one compilation and one ``linecache`` entry for each distinct source: a run of
            # the same scene writes the same text (bounded however many runs a process makes)
            filename = f"<harness {self.title} {hashlib.sha256(source.encode()).hexdigest()[:12]}>"
            linecache.cache[filename] = (len(source), None, source.splitlines(True), filename)
            namespace: dict = {}
            exec(compile(source, filename, "exec"), namespace)      # noqa: S102 - our own plan's source
            make = _makers[source] = namespace["make"]
        function = make(**{key: self.bound[key] for key in bound})
        function.source = source
        function.tally = tally
        return function


def add_steps(source: Source, calls) -> None:
    """``System.step_with`` over the ``StepCall`` records ``calls``, in the body (``t``, ``h``
    are the function's arguments)."""
    for call in calls:
        c = source.name(call.component, "component")
        do_step = source.name(call.do_step, "do_step")
        handle = source.name(call.handle, "handle")
        source.call(call.component, "step", f"status = {do_step}({handle}, t, h, 1)",
                    f"fmi2DoStep of {call.component.name}")
        source.line("if status > 1:")
        source.line(f"    {c}.fail(step_call(t, h), status)")
        source.line(f"{c}.time = t + h")
        source.calls_checked()
    if calls:
        source.bound["step_call"] = step_call


def add_visits(source: Source, visits) -> None:
    """``System.propagate_with`` over the ``Visit`` records ``visits``, in the body."""
    for visit in visits:
        if visit.get_real is not None:
            c = source.name(visit.component, "component")
            get_real = source.name(visit.get_real, "get_real")
            args = ", ".join([source.name(visit.handle, "handle"), source.name(visit.vrs, "vrs"),
                              source.name(visit.n, "count"), source.name(visit.values, "outputs")])
            source.call(visit.component, "get", f"status = {get_real}({args})",
                        f"fmi2GetReal of {visit.component.name}: {len(visit.vrs)} outputs")
            source.line("if status > 1:")
            source.line(f"    {c}.fail('fmi2GetReal', status)")
            source.calls_checked()
        values = source.elements(visit.values, "output_items") if visit.copies else None
        for copy in visit.copies:
            target = source.elements(copy.values, "input_items")
            for k, i in copy.pairs:
                source.line(f"{target}[{k}] = {values}[{i}]")
        for send in visit.sends:
            c = source.name(send.component, "component")
            set_real = source.name(send.set_real, "set_real")
            args = ", ".join([source.name(send.handle, "handle"), source.name(send.vrs, "vrs"),
                              source.name(send.n, "count"), source.name(send.values, "inputs")])
            source.call(send.component, "set", f"status = {set_real}({args})",
                        f"fmi2SetReal of {send.component.name}: {len(send.vrs)} inputs")
            source.line("if status > 1:")
            source.line(f"    {c}.fail('fmi2SetReal', status)")
            source.calls_checked()


def straight_line(title: str, visits=(), steps=None, before=()) -> Callable:
    """One function that runs the visits ``before``, makes the ``steps`` (``StepCall``
    records: each component's fmi2DoStep, as ``System.step_with``), then runs the ``visits``
    (each a compiled propagation, as ``System.interpret`` walks it).  It takes ``(t, h)``
    where ``steps`` are given (also none: a scene without feedthrough components has no
    steps of them), nothing otherwise."""
    source = Source(title, "" if steps is None else "t, h")
    add_visits(source, before)
    add_steps(source, steps or ())
    add_visits(source, visits)
    return source.function()
