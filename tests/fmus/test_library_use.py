"""The harness used as a library, in one Python process: validating an FMU stand-alone
(fmpy's ``simulate_fmu``), running scenes whose FMUs log, and fmpy used directly with a
logger of the caller's, in any order - no crash, no message lost - and the FMI 2.0 calls
the harness makes to end an instance are those the standard allows in its state."""
from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

from harness.description import scene as scenes
from harness.engine import component as components
from harness.engine.run import simulate

# A refused misalignment: the coupling FMU logs why and refuses fmi2ExitInitializationMode.
REFUSED = ["coupling.misalignment=43.3 deg", "experiment.stop=0.01", "experiment.transient=0"]
REFUSAL_TEXT = "reaches 45 deg, where the half-coupling function is undefined"

_SCRIPT = textwrap.dedent("""
    import sys
    import harness.engine.component        # the harness's logger first, as any run imports it
    from fmpy import simulate_fmu
    from harness.description import scene as scenes
    from harness.formats import reference_traces
    from harness.paths import FMUS

    REFUSED, TEXT = {refused!r}, {text!r}

    def validate():
        reference = reference_traces.read("EngineShaft")
        result = reference_traces.run_fmu("EngineShaft", reference)
        assert result.failure is None and len(result.times) == 1001, result.failure

    def run():
        spec = scenes.load("kavz685").with_overrides(REFUSED)
        result = reference_traces.run_scene(spec)
        assert result.failure and TEXT in result.failure, result.failure

    def fmpy_with_a_logger_of_its_own():
        said = []
        simulate_fmu(str(FMUS / "LeverCoupling.fmu"), stop_time=0.01, start_values={{"misalignment": 0.7557}},
                     logger=lambda *args: said.append(args[-1]))

    validate(); run(); validate(); run()
    try:
        fmpy_with_a_logger_of_its_own()      # refused: fmpy raises, its logger is gone after
    except Exception:
        pass
    run(); validate(); run()
    print("done", flush=True)
""").format(refused=REFUSED, text=REFUSAL_TEXT)


def test_validate_then_run_in_one_process_keeps_the_fmus_messages(fmu_dir):
    done = subprocess.run([sys.executable, "-X", "faulthandler", "-c", _SCRIPT], capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0 and done.stdout.strip().endswith("done"), \
        f"exit {done.returncode}\n{done.stdout[-2000:]}\n{done.stderr[-4000:]}"
    assert "Fatal Python error" not in done.stderr, done.stderr[-4000:]


class _Recording:
    """The FMU2Slave of a component, each FMI call it is asked for noted by name."""

    def __init__(self, fmu, calls: list):
        self._fmu, self._calls = fmu, calls

    def __getattr__(self, name):
        attribute = getattr(self._fmu, name)
        if callable(attribute):
            def call(*args, **kwargs):
                self._calls.append(name)
                return attribute(*args, **kwargs)
            return call
        return attribute


def _recorded_run(monkeypatch, overrides) -> tuple[object, dict[str, list[str]], list[str]]:
    """A run of kavz685 with ``overrides``: its result, each component's FMI calls made
    through fmpy (set-up and tear-down), and every message the FMUs logged."""
    calls: dict[str, list[str]] = {}
    logged: list[str] = []
    original = components.Component.__init__

    def recorded(self, name, *args, **kwargs):
        original(self, name, *args, **kwargs)
        calls[name] = []
        self.fmu = _Recording(self.fmu, calls[name])

    monkeypatch.setattr(components.Component, "__init__", recorded)
    listener = lambda instance, status, category, text: logged.append(text)
    components.add_log_listener(listener)
    try:
        result = simulate(scenes.load("kavz685").with_overrides(overrides))
    finally:
        components._listeners.remove(listener)
    return result, calls, logged


def test_a_refused_initialisation_ends_without_fmi2terminate(monkeypatch, fmu_dir):
    """FMI 2.0 (co-simulation state machine): fmi2Terminate only from 'step complete' or
    'step failed'; after an fmi2Error, fmi2FreeInstance (or fmi2Reset).  The shim refuses
    a call in a state the standard does not allow, and logs it."""
    result, calls, logged = _recorded_run(monkeypatch, REFUSED)
    assert result.failure_stage == "initialisation" and REFUSAL_TEXT in result.failure
    assert calls["coupling"][-2:] == ["exitInitializationMode", "freeInstance"], calls["coupling"]
    # the components initialised before the coupling refused may be terminated, as allowed
    for name, made in calls.items():
        assert made[-1] == "freeInstance", (name, made)
    assert not [m for m in logged if "not allowed in state" in m], logged


def test_a_whole_run_terminates_each_instance_before_freeing_it(monkeypatch, fmu_dir):
    result, calls, logged = _recorded_run(monkeypatch, ["experiment.stop=0.01", "experiment.transient=0"])
    assert result.ok, result.failure
    for name, made in calls.items():
        assert made[-2:] == ["terminate", "freeInstance"], (name, made)
    assert not [m for m in logged if "not allowed in state" in m], logged


@pytest.mark.parametrize("status, calls", [(3, ["freeInstance"]), (4, [])])
def test_after_an_error_only_free_after_fatal_nothing(fmu_dir, status, calls):
    """A component whose call returned fmi2Error is freed without fmi2Terminate; after
    fmi2Fatal the standard allows no call at all."""
    component = components.Component("engine", fmu_dir / "EngineShaft.fmu")
    made: list[str] = []
    real = component.fmu
    component.initialize(0.0, 1.0)
    component.exit_initialization()
    component.fmu = _Recording(real, made)
    with pytest.raises(components.FmuCallError):
        component.fail("fmi2DoStep(t = 0, h = 0.001)", status)
    component.free()
    assert made == calls
    if status == 4:      # the test's own instance: not fatal really, so freed here
        real.freeInstance()


def test_the_fmpy_peer_ends_a_refused_initialisation_without_fmi2terminate(fmu_dir):
    from harness.peers import simulate_peer

    logged: list[str] = []
    listener = lambda instance, status, category, text: logged.append(text)
    components.add_log_listener(listener)
    try:
        result = simulate_peer("fmpy-jacobi", scenes.load("kavz685").with_overrides(REFUSED), 1e-3, fmu_dir)
    finally:
        components._listeners.remove(listener)
    assert result.failure and REFUSAL_TEXT in result.failure, result.failure
    assert not [m for m in logged if "not allowed in state" in m], logged
