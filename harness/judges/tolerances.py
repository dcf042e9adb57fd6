"""Tolerances of the engineer's verdict (``harness.judges.verdict``): the quantities they
apply to, their defaults, the rules from a scene's ``[validation]`` table, ``--rtol`` and the
API, and what a reference's scene or FMU tells the verdict (``settings_of``)."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from harness.description.arguments import Argument

#: what a tolerance applies to
QUANTITIES = ("mean", "amplitude", "order", "tube")
#: the defaults (docs/validation.md#the-defaults-and-why):
#: mean - a result at the benchmark's accuracy target (RMS error 0.1 % of the mean) has its
#:   mean within 0.1 % (a mean error is at most the RMS error), so 0.1 % passes every such result;
#: amplitude - 2 %: at 0.1 % RMS torque error the error on KAVZ-685's tau2 is 0.11 N*m against
#:   a 6 N*m ripple amplitude (1.8 %), while a changed coupling moves it by 3.6 % (damping +20 %)
#:   and 4.7 % (misalignment 15 -> 20 deg);
#: order - 5 % of each leading order's magnitude (about 3 deg of phase): the leading orders move
#:   less than the peak-to-peak amplitude under a result's own error, more under a model's change;
#: tube - 5 % of the range in the window (a tenth of the ripple amplitude): a catch-all for a
#:   shape the other quantities miss, wide enough not to flag a sound result's sample-level noise.
DEFAULT_RTOL = {"mean": 1e-3, "amplitude": 0.02, "order": 0.05, "tube": 0.05}
#: the kinds of signals a tolerance may name, by the unit of the variable
UNIT_KINDS = {"rad/s": "speed", "N.m": "torque", "rad/s2": "acceleration", "rad": "angle", "J": "energy",
              "W": "power", "": "ratio"}
KINDS = tuple(dict.fromkeys(UNIT_KINDS.values()))


#: a quantity smaller than this share of the signal's largest magnitude over the reference is
#: judged against that share instead: below it a reference's figures are the solver's noise
#: (a stalled shaft's speed, 1e-11 rad/s, is no ripple to hold a result to 2 % of)
NOISE_FLOOR = 1e-3


def allowed_scale(*values: float, magnitude: float = 0.0) -> float:
    """What a relative tolerance is taken of: the first of ``values`` that is not zero (a
    constant signal's amplitude is judged against its mean), at least ``NOISE_FLOOR`` of the
    signal's largest ``magnitude``; 1 in the signal's unit for a signal zero throughout (as
    the FMI cross-check takes one)."""
    first = next((abs(v) for v in values if v != 0 and math.isfinite(v)), 0.0)
    scale = max(first, NOISE_FLOOR * abs(magnitude))
    return scale if scale > 0 else 1.0


def kind_of_unit(unit: str | None) -> str:
    return UNIT_KINDS.get(unit or "", "other")


@dataclass(frozen=True)
class Rule:
    """One tolerance: ``quantity`` of ``target`` (a signal, a kind, or "" for every signal)
    is ``value`` (relative), set by ``source`` ("default", "scene file", "--rtol", the API's "rtol")."""
    target: str
    quantity: str
    value: float
    source: str


def rule(target: str, quantity: str, value, source: str) -> Rule:
    """A checked ``Rule``: ValueError naming the quantity or value otherwise."""
    if quantity not in QUANTITIES:
        raise ValueError(f"tolerance {target + ':' if target else ''}{quantity}: no such quantity "
                         f"(one of {', '.join(QUANTITIES)})")
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"tolerance {target + ':' if target else ''}{quantity} = {value!r}: expected a number "
                         "(relative, e.g. 0.05 for 5 %)") from None
    if not (math.isfinite(number) and number >= 0):
        raise ValueError(f"tolerance {target + ':' if target else ''}{quantity} = {value!r}: must be a finite "
                         "relative tolerance >= 0 (e.g. 0.05 for 5 %)")
    return Rule(target, quantity, number, source)


def parse_rtol(texts, argument: Argument = Argument("--rtol")) -> list[Rule]:
    """``[TARGET:]QUANTITY=VALUE`` texts (``amplitude=0.05``, ``torque:mean=0.002``,
    ``coupling.tau2:order=0.1``): TARGET a signal or a kind (``KINDS``), none: every signal.
    ``argument``: what a refusal names and the rules' source (``--rtol``, the API's ``rtol``)."""
    rules = []
    for text in texts:
        if "=" not in str(text):
            raise ValueError(f"{argument.given(repr(text))}: expected [SIGNAL or KIND:]QUANTITY=VALUE, e.g. "
                             f"amplitude=0.05 or coupling.tau2:mean=0.002 (quantities: {', '.join(QUANTITIES)})")
        left, value = (s.strip() for s in str(text).split("=", 1))
        target, _, quantity = left.rpartition(":")
        try:
            rules.append(rule(target.strip(), quantity.strip(), value, argument.name))
        except ValueError as error:
            raise ValueError(f"{argument.given(repr(text))}: {error}") from None
    return rules


def rules_from_table(table: dict, source: str = "scene file") -> list[Rule]:
    """A scene's ``[validation]`` table: ``QUANTITY = VALUE`` for every signal, and sub-tables
    named by a kind or a signal (``[validation.torque]``, ``[validation."coupling.tau2"]``)."""
    rules = []
    for key, value in table.items():
        if isinstance(value, dict):
            rules += [rule(key, q, v, source) for q, v in value.items()]
        else:
            rules.append(rule("", key, value, source))
    return rules


@dataclass
class Tolerances:
    """Rules from several sources; a later list overrides an earlier, and within one source a
    signal's rule overrides its kind's, which overrides one for every signal."""
    layers: list[list[Rule]] = field(default_factory=list)

    def of(self, signal: str, kind: str) -> dict[str, tuple[float, str]]:
        out = {q: (v, "default") for q, v in DEFAULT_RTOL.items()}
        for layer in self.layers:
            for target in ("", kind, signal):
                for r in layer:
                    if r.target == target:
                        out[r.quantity] = (r.value, r.source)
        return out

    def unknown_targets(self, signals, kinds=KINDS) -> list[str]:
        """Targets no signal or kind answers to (a misspelt name judges nothing)."""
        known = set(signals) | set(kinds) | {""}
        return sorted({r.target for layer in self.layers for r in layer if r.target not in known})


@dataclass
class ReferenceSettings:
    """What a reference's scene (or FMU) tells the verdict: where its start-up transient
    ends, each signal's kind, the driven shaft's speed, and its ``[validation]`` tolerances."""
    transient: float | None
    kinds: dict
    rotation_signal: str | None
    rules: list
    #: signal -> its unit (None: not known)
    units: dict = field(default_factory=dict)


def settings_of(reference) -> ReferenceSettings:
    """``ReferenceSettings`` of a committed reference (``reference_traces.ReferenceTraces``):
    a scene's from its scene file (the transient from its start, ``scene_kinds.roles`` for the
    driven shaft), an FMU's from its model description (no transient, no shaft)."""
    from fmpy import read_model_description

    from harness.description import plan, scene_kinds
    from harness.description import scene as scenes
    from harness.paths import FMUS

    signals = list(reference.outputs.signals)
    if reference.kind == "fmu":
        path = FMUS / f"{reference.name}.fmu"
        units = {}
        if path.exists():
            units = {v.name: v.unit or (v.declaredType.unit if v.declaredType else None)
                     for v in read_model_description(str(path)).modelVariables}
        return ReferenceSettings(None, {s: kind_of_unit(units.get(s)) for s in signals}, None, [],
                                 {s: units.get(s) for s in signals})
    scene = scenes.load(reference.name)
    descriptions = plan.descriptions_for(scene)
    kinds, units = {}, {}
    for signal in signals:
        component, _, variable = signal.partition(".")
        spec = scene.components.get(component)
        description = descriptions.get(spec.fmu) if spec else None
        var = next((v for v in description.modelVariables if v.name == variable), None) if description else None
        unit = (var.unit or (var.declaredType.unit if var.declaredType else None)) if var else None
        kinds[signal], units[signal] = kind_of_unit(unit), unit
    load = scene_kinds.roles(scene)[2]
    rotation = f"{load}.w" if load and f"{load}.w" in signals else None
    try:
        rules = rules_from_table(scene.validation, f"scene file ({scene.path.name if scene.path else scene.name})")
    except ValueError as error:
        raise ValueError(f"scene {scene.name}: [validation] {error}") from None
    return ReferenceSettings(scene.experiment.start + scene.experiment.transient, kinds, rotation, rules, units)
