"""What a run's record and the Python API say is what ran, or the input is refused: a
``--set experiment.X`` and a ``--X`` that disagree are refused (the record named the --set
value, not the one that ran); a run the command line calls NOT TO BE TRUSTED is not ``ok``
in the API either; a result made with other values is noted by the API's validate as by
the command line, the values compared as quantities ("15.0 deg" is "15 deg"); a refusal
names the argument the caller gave; the tables a user writes in a scene file are typed
strictly; what the API returns has a short ``repr``; a made reference's wait is said before
it is made.  Each case here is part of the harness's bad-input corpus (test_input_safety.py
has the rest)."""
from __future__ import annotations

import json
import warnings
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from harness import api
from harness.api import results
from harness.description import scene as scenes
from harness.description import units
from harness.formats.run_files import run_title
from test_input_safety import VALUES, _toml_value     # the corpus's generated values (this folder is on sys.path)

SHORT = 0.05        # s: the runs here are about the record, not the motion


# -- a --set experiment.X and a --X that disagree -----------------------------------------------

@pytest.mark.parametrize("overrides,arguments,named", [
    (["experiment.master=jacobi"], {"master": "jacobi-linear"},
     ("master='jacobi-linear' and overrides['experiment.master']=jacobi disagree",)),
    (["experiment.step=0.0005"], {"step": 0.001}, ("step=0.001 s and overrides['experiment.step']=0.0005 disagree",)),
    (["experiment.step=0.5 ms"], {"step": "1 ms"}, ("step=0.001 s and overrides['experiment.step']=0.5 ms",)),
    ({"experiment.step": "0.5 ms"}, {"step": "1 ms"}, ("step=0.001 s and overrides['experiment.step']=0.5 ms",)),
])
def test_a_set_value_and_an_option_that_disagree_are_refused_before_anything_runs(fmu_dir, tmp_path, overrides,
                                                                                  arguments, named):
    out = tmp_path / "run"
    with pytest.raises(api.InputError) as refused:
        api.run("kavz685", overrides, stop=SHORT, out=out, **arguments)
    assert all(word in str(refused.value) for word in named), str(refused.value)
    assert "--" not in str(refused.value) and not out.exists()


def test_a_stop_given_twice_differently_is_refused_and_the_same_one_is_taken():
    with pytest.raises(api.InputError, match=r"^stop=0\.2 s and overrides\['experiment\.stop'\]=5 disagree"):
        api.load("kavz685", ["experiment.stop=5"], stop=0.2)
    assert api.load("kavz685", ["experiment.stop=200 ms"], stop=0.2).experiment.stop == 0.2
    assert api.load("kavz685", {"experiment.stop": "200 ms"}, stop=0.2).experiment.stop == 0.2


def test_a_set_value_and_an_option_that_agree_run_and_the_record_states_them(fmu_dir, tmp_path):
    done = api.run("kavz685", ["experiment.step=1 ms", "experiment.master=jacobi"], master="jacobi", step=0.001,
                   stop=SHORT, out=tmp_path / "run", plots=False, notify=lambda *_: None)
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["master"] == "jacobi" and summary["step_s"] == 0.001 and done.result.master == "jacobi"
    assert summary["overrides"]["experiment.master"] == "jacobi"


def test_the_command_line_refuses_the_conflict_with_exit_2_and_writes_nothing(lever, fmu_dir, tmp_path):
    done = lever("run", "kavz685", "--set", "experiment.master=jacobi", "--master", "jacobi-linear", "--stop", SHORT,
                 "--out", tmp_path / "run")
    assert done.exit_code == 2 and "--master 'jacobi-linear' and --set experiment.master=jacobi disagree" in done.output
    assert "overrides" not in done.output and not (tmp_path / "run").exists()


def test_a_plot_title_names_an_adaptive_masters_tolerance_and_first_step():
    title = run_title({"scene": "kavz685", "master": "adaptive", "step_s": 1e-3, "tolerance": 1e-4})
    assert title == "kavz685 - adaptive, first h = 0.001 s, tolerance 0.0001"
    assert run_title({"scene": "kavz685", "master": "jacobi", "step_s": 1e-3, "tolerance": None}) == \
        "kavz685 - jacobi, h = 0.001 s"


# -- provenance as quantities -------------------------------------------------------------------

@pytest.mark.parametrize("given,reference,same", [
    ("15.0 deg", "15 deg", True),
    ("6.35 N*m*s/rad", "6.35 N.m.s/rad", True),
    ("0.2617993877991494 rad", "15 deg", True),       # 15 * pi / 180, to the last digit printed
    ("1 kN.m/rad", "1000 N.m/rad", True),
    ("900", "900.0", True),
    ("16 deg", "15 deg", False),
    ("15 rad", "15 deg", False),
    ("900", "900 N.m/rad", False),                   # a bare number's unit is not said: not the same
    ("15 deg", "15 N.m", False),                     # another dimension
    ("kinematic", "kinematic", True),
    ("kinematic", "dynamic", False),
])
def test_values_are_compared_as_quantities_in_the_references_unit(given, reference, same):
    assert units.same_value(given, reference) is same


def test_a_result_made_with_the_same_values_written_otherwise_is_not_said_to_differ(lever, fmu_dir, tmp_path):
    done = lever("run", "kavz685", "--set", "coupling.misalignment=15.0 deg", "--set",
                 "coupling.damping=6.35 N*m*s/rad", "--stop", SHORT, "--no-plots", "--no-reference",
                 "--out", tmp_path / "run")
    assert done.exit_code == 0, done.output
    # without a reference.csv beside them the traces are judged against the committed
    # reference, and what they were made with is compared with what it was made with
    judged = lever("validate", "kavz685", "--result", tmp_path / "run" / "traces.csv", "--window", f"0:{SHORT}",
                   "--out", tmp_path / "validate")
    assert "made with its reference's parameter values" in judged.output, judged.output
    assert "other values" not in judged.output


# -- the API says what the command line says ------------------------------------------------------

def test_a_run_not_to_be_trusted_is_not_ok_and_says_so(fmu_dir):
    with pytest.warns(api.RunNote, match="NOT TO BE TRUSTED: the energy residual is"):
        done = api.run("kavz685", master="me-cvode", tolerance=0.999, stop=0.2, plots=False)
    assert not done.ok and done.outcome == "untrusted" and done.untrusted.startswith("the energy residual is")
    assert done.failure is None and "UNTRUSTED" in repr(done) and "NOT TO BE TRUSTED" in repr(done)
    assert any("NOT TO BE TRUSTED" in note for note in done.notes)


def test_the_command_line_says_not_to_be_trusted_once_and_exits_3(lever, fmu_dir, tmp_path):
    done = lever("run", "kavz685", "--master", "me-cvode", "--tolerance", 0.999, "--stop", 0.2, "--no-plots",
                 "--out", tmp_path / "run")
    assert done.exit_code == 3 and done.output.count("NOT TO BE TRUSTED") == 1, done.output


def test_validate_notes_a_run_made_with_other_values_as_the_command_line_does(fmu_dir):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", api.RunNote)
        made = api.run("kavz685", {"coupling.stiffness": 716}, stop=SHORT, plots=False)
        same = api.run("kavz685", {"coupling.stiffness": "715.4 N*m/rad"}, stop=SHORT, plots=False)
    notes = api.validate("kavz685", result=made, window=(0, SHORT)).findings.notes
    (said,) = [n for n in notes if "made with" in n]
    assert said.startswith("the result was made with other values than its reference (the Run given")
    assert "coupling.stiffness = 716 N.m/rad" in said and "the reference: 715.4 N.m/rad" in said
    notes = api.validate("kavz685", result=same, window=(0, SHORT)).findings.notes
    assert any("made with its reference's parameter values" in n for n in notes), notes


@pytest.mark.parametrize("arguments,said", [
    ({"rtol": 0.05}, "rtol=0.05: expected 'QUANTITY=VALUE' texts"),
    ({"rtol": {"amplitude": True}}, "rtol['amplitude']=True: expected a number"),
    ({"rtol": {"amplitude": "0.05"}}, "rtol['amplitude']='0.05': expected a number"),
    ({"signals": [None]}, "signals: None is not a name"),
    ({"signals": 3}, "signals=3: expected a name or a list of names"),
])
def test_a_refusal_names_the_argument_the_caller_gave(arguments, said):
    with pytest.raises(api.InputError) as refused:
        api.validate("kavz685", **arguments)
    assert str(refused.value).startswith(said), str(refused.value)
    assert "overrides" not in str(refused.value)


def test_strict_is_a_boolean():
    with pytest.raises(api.InputError, match=r"strict='no': expected True or False"):
        api.load("kavz685", strict="no")


# -- strict types in the tables a user writes ------------------------------------------------------

@pytest.mark.parametrize("table,said", [
    ("[validation]\namplitude = true\n", "validation.amplitude = the boolean true: expected a relative tolerance"),
    ("[validation]\namplitude = \"0.05\"\n", "validation.amplitude = '0.05': expected a relative tolerance"),
    ("[validation.torque]\nmean = false\n", "validation.torque.mean = the boolean false"),
    ("[bench]\ntarget_error = \"1e-3\"\n", "bench.target_error = '1e-3': expected a number"),
    ("[bench]\nrepeats_limit_s = true\n", "bench.repeats_limit_s = the boolean true"),
    ("[bench]\nmonolithic_rtol = [1e-6, \"1e-8\"]\n", "bench.monolithic_rtol = a list (item 1: '1e-8')"),
    ("[bench.steps]\njacobi = [true, 1e-3]\n", "bench.steps.jacobi = a list (item 0: the boolean true): expected a "
                                             "list of steps [s]"),
    ("[bench.steps]\njacobi = 1e-3\n", "bench.steps.jacobi = 0.001: expected a list of steps [s]"),
    ("[bench]\nsteps = [1e-3]\n", "bench.steps = a list: expected a table of a list of steps [s] per master"),
    ("[bench.output_steps]\nadaptive = \"1 ms\"\n", "bench.output_steps.adaptive = '1 ms': expected a step [s]"),
    ("[bench]\ntarget_eror = 1e-3\n", "bench.target_eror: no such key (did you mean 'target_error'?)"),
    ("[experiment]\nfmi = 2.0\n", "experiment.fmi = 2.0: expected 2 or 3"),
])
def test_a_scene_files_tables_take_numbers_not_booleans_or_strings(tmp_path, table, said):
    path = tmp_path / "mine.toml"
    path.write_text(f'extends = "kavz685"\n{table}')
    with pytest.raises(scenes.SceneError) as refused:
        scenes.load(path)
    assert said in str(refused.value), str(refused.value)


def test_the_command_line_refuses_such_a_table_with_exit_2(lever, tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text('extends = "kavz685"\n[validation]\namplitude = true\nmean = "0.05"\n')
    done = lever("run", path, "--stop", SHORT, "--out", tmp_path / "run")
    assert done.exit_code == 2 and "validation.amplitude = the boolean true" in done.output
    assert "validation.mean = '0.05'" in done.output and not (tmp_path / "run").exists()


TABLE_KEYS = {"validation": ["amplitude", "mean", "order", "tube"], "validation.torque": ["mean", "amplitude"],
              "bench": ["target_error", "repeats_limit_s", "monolithic_rtol", "baseline"],
              "bench.steps": ["jacobi"], "bench.output_steps": ["adaptive"]}


@settings(max_examples=100, derandomize=True, deadline=None, database=None,
          suppress_health_check=list(HealthCheck))
@given(st.sampled_from(sorted(TABLE_KEYS)), st.data(), VALUES)
def test_every_value_a_user_writes_in_these_tables_is_taken_as_a_number_or_refused_naming_it(tmp_path_factory,
                                                                                          table, data, value):
    """The corpus's generated values (booleans, strings with and without units, dates, lists,
    numbers) in each table: what loads holds numbers where numbers belong; the rest is
    refused naming the table's key."""
    key = data.draw(st.sampled_from(TABLE_KEYS[table]))
    path = tmp_path_factory.mktemp("table") / "mine.toml"
    path.write_text(f'extends = "kavz685"\n[{table}]\n{key} = {_toml_value(value)}\n', encoding="utf-8",
                    errors="surrogatepass")
    try:
        scene = scenes.load(path)
    except scenes.SceneError as refused:
        said = str(refused)
        assert f"{table}.{key}" in said or "not a valid TOML file" in said, said      # a control character
        return
    top, _, inner = table.partition(".")
    written = getattr(scene, top)[inner][key] if inner else getattr(scene, top)[key]
    if key == "baseline":
        assert isinstance(written, str)
    elif key == "monolithic_rtol" or table == "bench.steps":
        assert isinstance(written, list) and all(units.is_number(x) for x in written)
    else:
        assert units.is_number(written), written


def test_sound_tables_are_taken(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text('extends = "kavz685"\n[validation]\namplitude = 0.05\n[validation.torque]\nmean = 0.002\n'
                    '[bench]\ntarget_error = 1e-3\nbaseline = "jacobi"\nmonolithic_rtol = [1e-6]\n'
                    '[bench.steps]\njacobi = [1e-3, 5e-4]\n[bench.output_steps]\nadaptive = 1e-3\n')
    scene = scenes.load(path)
    assert scene.validation == {"amplitude": 0.05, "torque": {"mean": 0.002}}
    assert scene.bench["steps"] == {"jacobi": [1e-3, 5e-4]}


# -- short reprs ------------------------------------------------------------------------------------

def test_the_stability_maps_result_has_a_short_repr_and_keeps_its_data(monkeypatch, tmp_path):
    from harness.api import studies
    from harness.studies import stability_report, stabilitymap

    class Many:
        """A map of 2,000 cases: its own repr is long, as a real one's is."""
        scene = scenes.load("kavz685")
        results = {("jacobi", k): {"class": "stable", "growth": 1.0 + k} for k in range(2000)}
        reused = 7

        def __repr__(self):
            return f"Many({self.results!r})"

    agreement = {"by_master": {"jacobi": {"cases": 2000, "agree": 1990}}, "mismatches": [{"case": k} for k in range(10)],
                 "edge_rows": [], "explicit_rows": 0}
    monkeypatch.setattr(studies, "build", lambda: None)
    monkeypatch.setattr(stabilitymap, "sweep", lambda *a, **k: Many())
    monkeypatch.setattr(stabilitymap, "agreement", lambda result: agreement)
    monkeypatch.setattr(stability_report, "write", lambda out, result: [Path(out) / "stability.md"])
    done = api.stability_map("kavz685", out=tmp_path / "map")
    shown = repr(done)
    assert len(repr(dict(done))) > 50_000 and len(shown) < results.REPR_LIMIT, len(shown)
    assert "2000 cases, 7 of them from the case log" in shown and "agrees in 1990/2000" in shown
    assert "10 cases disagree" in shown and done["agreement"] is agreement and done["result"].reused == 7


def test_a_returned_dict_or_tuple_says_each_item_in_brief():
    big = results.Returned(grades={f"g{k}": list(range(100)) for k in range(50)}, report=Path("/x/measured.md"))
    pair = results.ReturnedTuple(("\n".join(["| a |"] * 400), Path("/x/runup.md")))
    assert len(repr(big)) < 300 and "'grades': 50 entries (g0, g1, g2, g3, ...)" in repr(big)
    assert repr(pair) == "ReturnedTuple(a text of 400 lines, /x/runup.md)"
    text, path = pair
    assert path == Path("/x/runup.md") and text.count("\n") == 399


def test_the_values_the_api_returns_for_a_scene_have_short_reprs(fmu_dir):
    assert len(repr(api.load("kavz685", {"coupling.stiffness": 900}))) < results.REPR_LIMIT
    assert "--set coupling.stiffness = 900" in repr(api.load("kavz685", {"coupling.stiffness": 900}))
    for value in (api.scenes(), api.masters()):
        assert len(repr(value)) < results.REPR_LIMIT


# -- a long wait said first ----------------------------------------------------------------------------

def test_the_made_references_wait_is_said_before_it_is_made(fmu_dir, monkeypatch, tmp_path):
    from harness.description import plan as plans
    from harness.engine.run import simulate
    from harness.judges import fmu_reference

    monkeypatch.setenv("LEVER_CACHE_DIR", str(tmp_path / "cache"))
    plan = plans.check(scenes.load("kavz685").with_overrides(["experiment.stop=0.04"]))
    run = simulate(plan, "jacobi", 1e-3)
    said = fmu_reference.expected_wait(plan, run)
    pace = run.wall_time / (len(run.times) - 1)
    # Model Exchange: two CVODE runs on the grid of a quarter step: 2 x 4 x 40 points at the run's pace
    assert f"{2 * 4 * 40:,} communication points, 8 times this run's" in said, said
    assert f"{1e3 * pace:.3g} ms a point" in said
    monkeypatch.setattr(fmu_reference, "offers_model_exchange", lambda plan: False)
    said = fmu_reference.expected_wait(plan, run)
    # extrapolated: the grid's quarter step, then halved twice: (4 + 8 + 16) x 40 points
    assert f"{28 * 40:,} communication points, 28 times this run's" in said and said.startswith("about ")
    fmu_reference.reference(plan, run.times, source="extrapolated")
    assert fmu_reference.expected_wait(plan, run) is None           # cached: nothing to wait for


def test_a_run_says_the_made_references_wait_before_the_wait(fmu_dir, monkeypatch, tmp_path):
    from harness.judges import fmu_reference, monolithic

    def no_monolithic(plan, times, **_):
        raise monolithic.ReferenceUnavailable("no equations for it (as for a user's FMU)")

    heard, heard_when_made = [], []
    making = fmu_reference.reference

    def made(plan, times, **options):
        heard_when_made.extend(heard)
        return making(plan, times, **options)

    monkeypatch.setenv("LEVER_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(monolithic, "solve", no_monolithic)
    monkeypatch.setattr(fmu_reference, "reference", made)
    done = api.run("kavz685", master="jacobi", stop=0.04, notify=lambda kind, message: heard.append(message))
    (note,) = [m for m in heard_when_made if m.startswith("no monolithic reference")]
    assert "making it takes " in note and "communication points" in note, note
    assert done.summary["reference"]["source"] != "monolithic"


def test_a_long_run_says_how_long_from_its_own_pace_once(monkeypatch):
    from harness.engine import observers

    wall = iter([0.0, 0.5, 1.0, 1.5, 2.0])
    monkeypatch.setattr(observers.clock, "perf_counter", lambda: next(wall))
    heard = []
    watch = observers.PaceWatch(10.0, heard.append)
    watch.started(0.0)                    # wall 0
    watch.stepped(31, 0.2)                # not a 32nd step: the clock is not read
    watch.stepped(32, 0.25)               # wall 0.5: too early to say
    watch.stepped(64, 0.5)                # wall 1.0: 5 % in 1 s -> 20 s in all
    watch.stepped(96, 0.75)               # said once only
    assert heard == ["the run takes about 20 s (5 % of t = 0 ... 10 s done in 1 s; about 19 s to go)"]
    quick = observers.PaceWatch(10.0, heard.append)
    wall = iter([0.0, 1.0])
    quick.started(0.0)
    quick.stepped(32, 5.0)                # half done in 1 s: 2 s in all, nothing to say
    assert len(heard) == 1 and quick.said


def test_validate_says_how_long_the_scene_it_runs_takes_before_the_wait(fmu_dir, monkeypatch, tmp_path):
    # as `lever run`: a run of the scene that will take long says so from its own pace; the
    # pace watch is set to speak at once here, the rule itself is tested with `lever run`
    from harness.api import validating
    from harness.engine.observers import PaceWatch

    heard = []
    monkeypatch.setattr(validating, "PaceWatch",
                        lambda stop, say: PaceWatch(stop, say, after=0.0, longer_than=0.0))
    api.validate("kavz685", overrides=["experiment.stop=0.2"], window=(0, 0.2), out=tmp_path / "v",
                 notify=lambda kind, message: heard.append((kind, message)))
    assert heard and heard[0][0] == "note" and heard[0][1].startswith("the run takes about"), heard
