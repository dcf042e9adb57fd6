"""The bad-input corpus (harness/formats/badinputs/) through fmpy's FMU2Slave on the built FMUs:
every case is refused with fmi2Error/fmi2Discard and a message naming the variable and
what is allowed, nothing is fatal, and every instance is freed cleanly."""
from __future__ import annotations

import pytest

from harness.formats import badinputs
from lever.fmus.registry import NAMES as FMU_NAMES

CORPUS = badinputs.corpus()


@pytest.mark.parametrize("case", CORPUS, ids=[c.name for c in CORPUS])
def test_bad_input_is_refused_with_a_message(fmu_dir, case):
    outcome = badinputs.run_case(case, fmu_dir)
    assert outcome.passed, "; ".join(outcome.problems)
    assert outcome.status in badinputs.REFUSED and outcome.messages


def test_the_corpus_covers_every_kind_of_bad_input_for_every_fmu():
    categories = {(c.fmu, c.category) for c in CORPUS}
    assert set(badinputs.DECLARED) == set(FMU_NAMES)
    for fmu, (parameters, inputs) in badinputs.DECLARED.items():
        expected = {"set after initialisation", "out-of-order call", "bad step", "bad state", "set on an output",
                    "wrong type or reference"}
        if any(p.kind == "real" for p in parameters):
            expected.add("non-finite parameter")
        if any(p.kind == "string" and not p.choices for p in parameters):     # a table
            expected.add("malformed table")
        if inputs:
            expected |= {"non-finite input", "set in a wrong state"}
        for category in expected:
            assert (fmu, category) in categories, (fmu, category)
    for fmu in ("EngineShaft", "LoadShaft"):
        assert (fmu, "non-positive inertia") in categories
    for category in ("non-positive stiffness", "negative damping", "misalignment out of range"):
        assert ("LeverCoupling", category) in categories
    assert ("LeverCoupling", "unknown mode") in categories and ("LoadShaft", "unknown mode") in categories
    # every kind of damage to a serialized state, for every FMU
    for fmu in badinputs.DECLARED:
        edits = {c.action[2][0] for c in CORPUS if c.fmu == fmu and c.action[:2] == ("call", "edited-state")}
        # every generic edit its state has something for, and for the engine the lagged torque's own
        assert edits - set(badinputs.co_simulation.STATE_EDITS) == ({"internal-empty"} if fmu == "EngineShaft" else set()), fmu
        assert set(badinputs.co_simulation.state_edits(fmu)) <= edits, fmu
    assert len(badinputs.co_simulation.state_edits("MisalignmentSource")) == len(badinputs.co_simulation.STATE_EDITS) - 3   # no input or real
    assert len({c.name for c in CORPUS}) == len(CORPUS) > 800


def test_the_corpus_covers_every_model_exchange_call_and_state_for_every_fmu():
    me = [c for c in CORPUS if c.action[:2] == ("call", "me")]
    for fmu in FMU_NAMES:
        nx, _ = badinputs.model_exchange.ME_SIZES[fmu]
        cases = [c for c in me if c.fmu == fmu]
        on_me = [c for c in cases if c.interface == "ModelExchange"]
        # every ME function refused in a state the table does not allow, and on a Co-Simulation instance
        wrong_state = {c.action[2][0] for c in on_me if c.category == "out-of-order ME call"}
        assert set(badinputs.model_exchange.ME_FUNCTIONS) | {"fmi2GetDirectionalDerivative"} <= wrong_state, fmu
        assert {c.phase for c in on_me} == set(badinputs.model_exchange.ME_PHASES), fmu
        on_cs = {c.action[2][0] for c in cases if c.interface == "CoSimulation"}
        assert on_cs == set(badinputs.model_exchange.ME_FUNCTIONS), fmu
        assert {"fmi2DoStep", "fmi2GetFMUstate"} <= wrong_state, fmu
        # every array of the wrong size (and NULL where the model has states), NaN/inf states
        sized = {(c.action[2][0], c.action[2][2]) for c in on_me if c.action[2][1:2] == ("size",)}
        for function, size in badinputs.model_exchange.ME_ARRAYS.items():
            n = nx if size == "nx" else badinputs.model_exchange.ME_SIZES[fmu][1]
            assert (function, n + 1) in sized and (not n or (function, n - 1) in sized), (fmu, function)
        assert sum(c.category == "non-finite ME state" for c in on_me) == (3 if nx else 0) + 3, fmu
        assert sum(c.category == "bad directional derivative" for c in on_me) >= 6, fmu


def test_the_summary_counts_cases_and_names_failures(fmu_dir):
    cases = [c for c in CORPUS if c.category == "bad step"][:2]
    broken = badinputs.Case("EngineShaft", "not refused", "a good inertia", "instantiated",
                            ("set", "inertia", 0.2), ("'inertia'",))
    outcomes = badinputs.run(fmu_dir, cases + [broken])
    text = badinputs.summary(outcomes)
    assert text.splitlines()[0].endswith("3 cases through fmpy's FMU2Slave, 2 pass, 1 fail")
    assert "FAIL EngineShaft: a good inertia: status 0, expected fmi2Error or fmi2Discard" in text


def test_the_corpus_covers_the_fmi3_state_machine_sizes_nan_and_states_for_every_fmu():
    fmi3 = [c for c in CORPUS if c.action[:2] == ("call", "fmi3")]
    assert {c.interface for c in fmi3} == {"CoSimulation3", "ModelExchange3"}
    for fmu in FMU_NAMES:
        nx, nz = badinputs.model_exchange.ME_SIZES[fmu]
        cases = [c for c in fmi3 if c.fmu == fmu]
        me = [c for c in cases if c.interface == "ModelExchange3"]
        # every Model Exchange function in every state the FMI 3.0 table does not allow
        refused = {(c.action[2][0], c.phase) for c in me if c.category == "FMI 3 out-of-order call"}
        for function, allowed in badinputs.fmi3.ME3_ALLOWED.items():
            assert {(function, p) for p in badinputs.fmi3.ME3_PHASES if p not in allowed} <= refused, (fmu, function)
        on_cs = {c.action[2][0] for c in cases if c.interface == "CoSimulation3" and "Co-Simulation instance" in c.label}
        assert {"fmi3SetTime", "fmi3SetContinuousStates", "fmi3GetContinuousStateDerivatives"} <= on_cs, fmu
        assert {"fmi3DoStep", "fmi3GetFMUState"} <= {c.action[2][0] for c in me if "Model Exchange instance" in c.label}
        # nValues for every type's getter and setter in both interfaces, the arrays of another size
        counted = {(c.interface, c.action[2][0]) for c in cases if c.action[2][1:2] == ("count",)}
        assert len(counted) == 2 * 2 * len(badinputs.fmi3.FMI3_TYPES), fmu
        sized = {(c.action[2][0], c.action[2][2]) for c in me if c.action[2][1:2] == ("size",)}
        for function, size in badinputs.fmi3.ME3_ARRAYS.items():
            n = nx if size == "nx" else nz
            assert (function, n + 1) in sized and (not n or (function, n - 1) in sized), (fmu, function)
        categories = {c.category for c in cases}
        assert {"FMI 3 out-of-order call", "FMI 3 wrong size or reference", "FMI 3 non-finite value",
                "FMI 3 bad state"} <= categories, fmu
        edits = {c.action[2][1] for c in cases if c.action[2][0] == "state3"}
        assert edits == set(badinputs.fmi3.STATE3_EDITS), fmu
        assert {c.action[2][1] for c in cases if c.action[2][0] == "state3-inner"} == set(badinputs.co_simulation.state_edits(fmu))
    assert len(fmi3) > 800 and len(CORPUS) - len(fmi3) > 800


def test_an_accepted_fmi3_call_fails_its_case(fmu_dir):
    """The FMI 3 runner fails a case whose call is not refused (a legal fmi3SetTime) and says so."""
    legal = badinputs.Case("EngineShaft", "FMI 3 out-of-order call", "fmi3SetTime in continuous (legal)",
                           "continuous", ("call", "fmi3", ("fmi3SetTime",)), ("fmi3SetTime",),
                           interface="ModelExchange3")
    outcome = badinputs.run_case(legal, fmu_dir)
    assert not outcome.passed and "status 0, expected fmi3Error" in outcome.problems[0]
    text = badinputs.summary([outcome])
    assert "FMU3Slave (0) and FMU3Model (1)" in text and "FMI 3.0 cases: 1 (the corpus 0 -> 1 cases with them)" in text
