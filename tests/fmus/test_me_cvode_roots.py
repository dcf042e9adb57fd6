"""Each Model Exchange edition with events (FMI 2.0 and 3.0) through its events in a host as C
hosts with SUNDIALS CVODE write it (harness/studies/cvode_host.py, after Reference-FMUs'
``fmusim --solver cvode``): the event indicators are CVODE's own root functions and CVODE
goes on from its own history after an event that changed no state, so an indicator still
zero where a mode was entered stops the run ("root found at and very near t").

Scenes that switch modes many times: the freewheel scene (discs stick and slip, every gap
edge crossed both ways), the same with a resistance the mesh torque overcomes (the
flywheel sticks and slides), a load with Coulomb friction and stiction under a resistance
that swings across the drive (stops and breakaways), and an engine on its table.  Each run
reaches its final time and is judged: the freewheel against its monolithic reference
(``lever validate`` for the scene, ``validation.compare`` for the variant), the load and
the engine against their co-simulation editions in fmpy.  The flywheel's stick and slide
is also run through the co-simulation edition (the other interface), against the same
reference."""
from __future__ import annotations

import numpy as np
import pytest

from harness.judges import rectifier, validation
from harness.studies import cvode_host, me_hosts
from lever.physics import component_parameters

EDITIONS = (2, 3)


@pytest.fixture(scope="module")
def freewheel_case():
    return me_hosts.alone_case("FreewheelRectifier")


@pytest.mark.parametrize("fmi", EDITIONS)
def test_the_freewheel_scene_runs_through_cvode_root_finding_and_passes_lever_validate(fmi, freewheel_case, fmu_dir,
                                                                                       lever, tmp_path):
    times, traces, run = me_hosts.run_cvode_roots(freewheel_case, fmu_dir, fmi=fmi)
    assert run.t_end == pytest.approx(freewheel_case.opt.stop, abs=1e-12)
    assert run.events > 150          # disc stick/slip and every gap edge, both ways
    assert not run.zero_after_event
    slips = traces["rectifier.disc_slip"]
    assert np.count_nonzero(np.diff(slips)) > 40
    csv_path = me_hosts.write_result(tmp_path / "FreewheelRectifier_me.csv", times, traces)
    outcome = lever("validate", "--result", str(csv_path), "freewheel_rectifier", "--out", str(tmp_path / "v"))
    assert outcome.exit_code == 0 and "freewheel_rectifier: PASS" in outcome.output, outcome.output


#: the scene's resistance lowered below the largest mesh torque: the flywheel slides at each
#: stroke and sticks again between strokes (an event update that switched only
#: the discs left the flywheel sliding for good)
SLIDING = {"resistance_torque": 200.0}


@pytest.mark.parametrize("fmi", EDITIONS)
def test_the_flywheel_sticks_and_slides_through_cvode_root_finding_as_the_reference_does(fmi, freewheel_case,
                                                                                        fmu_dir):
    stop, step = 0.45, 1e-3           # three strokes
    names = list(dict.fromkeys(freewheel_case.columns.values()))
    fmu = (fmu_dir if fmi == 2 else me_hosts.fmi3_dir(fmu_dir)) / "FreewheelRectifier.fmu"
    run = cvode_host.run(fmu, fmi, {**freewheel_case.start_values, **SLIDING}, names, stop, step,
                         rtol=me_hosts.FMPY_RTOL, atol=me_hosts.FMPY_RTOL * 1e-2)
    assert run.t_end == pytest.approx(stop, abs=1e-12)
    assert not run.zero_after_event
    stuck, w = run.outputs["flywheel_stuck"], run.outputs["w"]
    assert np.count_nonzero(np.diff(stuck)) >= 6          # at each stroke: slides, then sticks again
    assert np.all(w[stuck == 1.0] == 0.0)                 # held exactly at rest where stuck (the update's w = 0)
    assert w.max() > 0.3
    model = component_parameters.freewheel_from({**{k: v for k, v in freewheel_case.start_values.items()
                                                    if k != "tau"}, **SLIDING})
    rows, _, events = rectifier.integrate(model, run.times)
    assert sum(1 for _, name in events if name == "flywheel") >= 6
    reference = {name: np.array([r[name] for r in rows]) for name in names if name != "events"}
    findings, _ = validation.compare("freewheel sliding", run.times, run.outputs, run.times, reference)
    failing = [(s.name, s.problem) for s in findings.signals if not s.passed]
    assert not findings.problems and not failing, (findings.problems, failing)


#: a load whose time-table resistance swings across a held drive of 30 N*m: Coulomb friction
#: 10 N*m and stiction 15 N*m hold it at each reversal until the net torque breaks it away
LOAD = {"load_kind": "table", "table": "0:0; 0.1:60; 0.2:0; 0.3:60; 0.4:0; 0.5:60; 0.6:0", "friction_torque": 10.0,
        "breakaway_torque": 15.0, "w_start": 0.0, "tau": 30.0}
#: an engine on its table from rest against a held load: its speed crosses the table's points
ENGINE = {"characteristic": "kavz685", "w_start": 0.0, "tau": -100.0}


def _co_simulation(path, start_values, outputs, stop, step):
    from fmpy import simulate_fmu

    from harness.engine.component import unzipped

    result = simulate_fmu(unzipped(path), fmi_type="CoSimulation", stop_time=stop, output_interval=step,
                          start_values=start_values, output=outputs)
    return np.asarray(result["time"]), {name: np.asarray(result[name]) for name in outputs}


@pytest.mark.parametrize("fmi", EDITIONS)
@pytest.mark.parametrize("fmu,start,stop,events", [("LoadShaft", LOAD, 0.6, 6), ("EngineShaft", ENGINE, 2.0, 4)])
def test_a_load_with_stiction_and_an_engine_on_its_table_run_through_cvode_root_finding(fmi, fmu, start, stop, events,
                                                                                        fmu_dir):
    path = (fmu_dir if fmi == 2 else me_hosts.fmi3_dir(fmu_dir)) / f"{fmu}.fmu"
    run = cvode_host.run(path, fmi, start, ["phi", "w"], stop, 1e-3)
    assert run.t_end == pytest.approx(stop, abs=1e-12)
    assert run.events >= events and not run.zero_after_event
    times, cs = _co_simulation(fmu_dir / f"{fmu}.fmu", start, ["phi", "w"], stop, 1e-3)
    assert np.allclose(times, run.times, rtol=0.0, atol=1e-12)
    w = run.outputs["w"]
    assert np.max(np.abs(w - cs["w"])) <= 1e-3 * np.ptp(cs["w"])
    if fmu == "LoadShaft":
        held = cs["w"] == 0.0
        assert held.sum() >= 5 and np.all(w[held] == 0.0)     # held at rest exactly, as the co-simulation edition


def test_the_co_simulation_edition_sticks_and_slides_the_flywheel_as_the_reference_does(fmu_dir):
    """The other interface on the same scene: the co-simulation edition (its own RK4 with
    located events) through the flywheel's stick and slide, against the monolithic reference."""
    from harness import api

    scene = api.load("freewheel_rectifier", [f"rectifier.{k}={v}" for k, v in SLIDING.items()], stop=0.45)
    done = api.run(scene, reference=False, plots=False)
    assert done.ok, done.failure
    stuck, w = done.traces["rectifier.flywheel_stuck"], done.traces["rectifier.w"]
    assert np.count_nonzero(np.diff(stuck)) >= 6
    assert np.all(w[stuck == 1.0] == 0.0)
    from harness.judges import monolithic

    model = monolithic.planned(scene).rectifier.model.get()       # the scene's values, checked
    assert model.mc == SLIDING["resistance_torque"]
    rows, _, _ = rectifier.integrate(model, done.times)
    reference = {f"rectifier.{n}": np.array([r[n] for r in rows]) for n in rows[0] if n != "events"}
    findings, _ = validation.compare("freewheel sliding, co-simulation", done.times,
                                     {k: v for k, v in done.traces.items() if k in reference}, done.times, reference)
    failing = [(s.name, s.problem) for s in findings.signals if not s.passed]
    assert not findings.problems and not failing, (findings.problems, failing)
