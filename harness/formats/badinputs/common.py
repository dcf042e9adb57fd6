"""What every part of the bad-input corpus shares: a case (``Case``) and its outcome
(``Outcome``), the FMUs' declared parameters and inputs, the log every instance's messages
are collected in, and the FMI status codes."""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

from lever.fmus import registry
from lever.physics.parameters import Parameter

FMI2_OK, FMI2_WARNING, FMI2_DISCARD, FMI2_ERROR, FMI2_FATAL = range(5)
REFUSED = (FMI2_DISCARD, FMI2_ERROR)

#: FMU -> its adapter class, for every FMU of the registry
ADAPTERS = {m.name: m.adapter() for m in registry.MODELS}
#: FMU -> (parameters, names of its inputs), as the adapters declare them
DECLARED = {fmu: (tuple(cls.PARAMETERS), tuple(p.name for p in cls.INPUTS)) for fmu, cls in ADAPTERS.items()}
PHASES = ("instantiated", "initialization", "stepping")
DEG = math.pi / 180.0



@dataclass(frozen=True)
class Case:
    """One bad input.

    ``phase``: where the FMU is when the bad input arrives (``instantiated``,
    ``initialization`` or ``stepping``, the last after one step).  ``setup``: good values
    set first.  ``action``: ``("set", name, value)`` or ``("call", fmi_function, args)``.
    ``refused_by``: the call that must return error/discard: the action itself
    (``"action"``) or ``fmi2ExitInitializationMode`` (``"exit"``: values that are only
    judged together, when the model is built).  ``expect``: fragments the logged error
    message must contain (the variable and its allowed range).  ``start``: the start time.
    """

    fmu: str
    category: str
    label: str
    phase: str
    action: tuple
    expect: tuple[str, ...]
    setup: tuple[tuple[str, object], ...] = ()
    refused_by: str = "action"
    #: the start time given to fmi2SetupExperiment (the first step starts there)
    start: float = 0.0
    #: the interface the instance is instantiated for: ``CoSimulation`` (fmpy's FMU2Slave) or
    #: ``ModelExchange`` (FMU2Model; ``phase`` then one of ``ME_PHASES``)
    interface: str = "CoSimulation"

    @property
    def name(self) -> str:
        return f"{self.fmu}: {self.label}"


def declared(fmu: str, name: str) -> Parameter:
    cls = ADAPTERS[fmu]
    return {p.name: p for p in (*cls.PARAMETERS, *cls.INPUTS)}[name]


# -- running a case ---------------------------------------------------------------------------------------

@dataclass
class Outcome:
    case: Case
    status: int | None = None          # status of the call that had to refuse
    messages: list[str] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)

    @property
    def passed(self) -> bool:
        return not self.problems


instance_numbers = itertools.count(1)
LOG: dict[str, list[tuple[int, str]]] = {}
listening = False


def listen():
    global listening
    if not listening:
        from harness.engine.component import add_log_listener
        add_log_listener(lambda name, status, category, text: LOG.setdefault(name, []).append((status, text)))
        listening = True


def c_array(n: int):
    import ctypes
    return (ctypes.c_double * max(n + 1, 1))()


_DESCRIPTIONS: dict[str, object] = {}


def model_description(path) -> object:
    """The model description of the FMU file ``path``, read once per process."""
    key = str(path)
    if key not in _DESCRIPTIONS:
        import fmpy
        _DESCRIPTIONS[key] = fmpy.read_model_description(key)
    return _DESCRIPTIONS[key]


def status_of(fmu, function: str, *args) -> int:
    """fmpy's method ``function`` of ``fmu`` called: the status it raised, else OK (0 in FMI
    2.0 and 3.0)."""
    from fmpy.fmi1 import FMICallException
    try:
        getattr(fmu, function)(*args)
    except FMICallException as error:
        return error.status
    return FMI2_OK


def settle(update) -> int:
    """The event iteration: ``update()`` (fmi2NewDiscreteStates / fmi3UpdateDiscreteStates,
    whose first result says another round is needed) until no round is needed: OK, the
    status a round raised, or Error after 100 rounds."""
    from fmpy.fmi1 import FMICallException
    for _ in range(100):
        try:
            if not update()[0]:
                return FMI2_OK
        except FMICallException as error:
            return error.status
    return FMI2_ERROR


def judge_log(outcome: Outcome, logged: list, case: Case) -> str:
    """What every refused call is judged by in the messages it logged (``(level, text)``,
    FMI 2.0 and 3.0 levels alike): the refusals kept as ``outcome.messages``, no fatal
    status, each fragment ``case.expect`` names said; the messages' text."""
    outcome.messages = [text for level, text in logged if level >= FMI2_DISCARD]
    if any(level == FMI2_FATAL for level, _ in logged):
        outcome.problems.append("a fatal status was logged")
    text = " ".join(outcome.messages)
    missing = [f for f in case.expect if f.lower() not in text.lower()]
    if missing:
        outcome.problems.append(f"the message does not say {missing}: {text!r}")
    return text


def changed(before: dict, after: dict | None) -> list[str]:
    """The variables whose value differs between two reads (NaN equal to NaN; all of them
    when the second read failed)."""
    return [n for n, x in before.items()
            if after is None or not (after[n] == x or (math.isnan(x) and math.isnan(after[n])))]


def judge_after_refusal(outcome: Outcome, instance, everything: dict | None, states, most: int | None = None):
    """The last checks of a refused call on ``instance`` (a driver's wrapper with ``reals``,
    ``states`` and ``usable``): the values read before it (``everything``) and the states as
    they were, and the instance usable; what is not, is the case's problem (at most ``most``
    moved variables named)."""
    after = instance.reals()
    if everything is not None:
        moved = changed(everything, after)
        if moved:
            outcome.problems.append(f"the refused call changed {', '.join(moved[:most])}")
    if states is not None and instance.states() != states:
        outcome.problems.append(f"the refused call changed the states: {states} -> {instance.states()}")
    why = instance.usable()
    if why:
        outcome.problems.append(why)


def free_instance(fmu, function: str = "fmi2FreeInstance") -> list[str]:
    """Free an fmpy instance; its raising is the case's problem (the list of them)."""
    try:
        fmu.freeInstance()
    except Exception as error:  # noqa: BLE001 - reported as the case's problem
        return [f"{function} raised {error!r}"]
    return []
