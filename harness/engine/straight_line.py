"""Compiled plans as straight-line Python: one function a plan, made once per run.

A step of a co-simulation on a driveline is a dozen FMI calls and a few dozen copies
of floats; interpreting a plan (``System.step_with``, ``System.propagate_with``: loops
over records, attribute reads) costs more Python than the calls themselves.  As
``dataclasses`` and ``namedtuple`` do, the engine writes the plan's work as the source
of one function, every call, handle, buffer and index bound once, and compiles it; it
does what the interpreting loops do, in their order, call for call.

The source is registered with ``linecache`` under the function's file name
(``<harness TITLE DIGEST>``), so a traceback or a debugger shows the line that failed; a
function's ``source`` attribute holds it too.
"""
from __future__ import annotations

import hashlib
import linecache
from typing import Callable

from harness.engine.component import step_call

#: the function maker compiled from each distinct source
_makers: dict[str, Callable] = {}


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
        self._counts: dict[str, int] = {}

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

    def line(self, text: str, note: str | None = None):
        """Add ``text`` to the body; ``note`` after it as a comment (a scene's names go here:
        escaped, so that no name can end the comment and become code)."""
        if note is not None:
            text += "    # " + note.encode("unicode_escape").decode("ascii")
        self.lines.append("    " + text)

    def function(self) -> Callable:
        """Compile the body into a function of ``arguments``, the bound objects closed over."""
        name = "".join(c if c.isalnum() else "_" for c in self.title)
        body = self.lines or ["    pass"]
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
        return function


def add_steps(source: Source, calls) -> None:
    """``System.step_with`` over the ``StepCall`` records ``calls``, in the body (``t``, ``h``
    are the function's arguments)."""
    for call in calls:
        c = source.name(call.component, "component")
        do_step = source.name(call.do_step, "do_step")
        handle = source.name(call.handle, "handle")
        source.line(f"{c}.steps += 1", f"fmi2DoStep of {call.component.name}")
        source.line(f"status = {do_step}({handle}, t, h, 1)")
        source.line("if status > 1:")
        source.line(f"    {c}.fail(step_call(t, h), status)")
        source.line(f"{c}.time = t + h")
    if calls:
        source.bound["step_call"] = step_call


def add_visits(source: Source, visits) -> None:
    """``System.propagate_with`` over the ``Visit`` records ``visits``, in the body."""
    for visit in visits:
        values = source.name(visit.values, "outputs") if visit.values is not None else None
        if visit.get_real is not None:
            c = source.name(visit.component, "component")
            get_real = source.name(visit.get_real, "get_real")
            args = ", ".join([source.name(visit.handle, "handle"), source.name(visit.vrs, "vrs"),
                              source.name(visit.n, "count"), values])
            source.line(f"{c}.gets += 1", f"fmi2GetReal of {visit.component.name}: {len(visit.vrs)} outputs")
            source.line(f"status = {get_real}({args})")
            source.line("if status > 1:")
            source.line(f"    {c}.fail('fmi2GetReal', status)")
        for copy in visit.copies:
            target = source.name(copy.values, "inputs")
            for k, i in copy.pairs:
                source.line(f"{target}[{k}] = {values}[{i}]")
        for send in visit.sends:
            c = source.name(send.component, "component")
            set_real = source.name(send.set_real, "set_real")
            args = ", ".join([source.name(send.handle, "handle"), source.name(send.vrs, "vrs"),
                              source.name(send.n, "count"), source.name(send.values, "inputs")])
            source.line(f"{c}.sets += 1", f"fmi2SetReal of {send.component.name}: {len(send.vrs)} inputs")
            source.line(f"status = {set_real}({args})")
            source.line("if status > 1:")
            source.line(f"    {c}.fail('fmi2SetReal', status)")


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
