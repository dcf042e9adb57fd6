"""A refusal names the argument as its caller wrote it: a call of ``harness.api`` is told of
its keyword (``rtol='x'``, ``overrides['coupling.k']``, ``window=``), never of the command
line's ``--option``; the command line, calling the same API, tells its user of the option
typed (``--rtol 'x'``, ``--set coupling.k``).  And a dict override keeps its value's type:
the text "900" is no number, True is no number, a numpy scalar is one.  Part of the
harness's bad-input corpus (with test_says_what_ran.py and test_input_safety.py)."""
from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from harness import api
from test_input_safety import VALUES     # the corpus's generated values (this folder is on sys.path)

SHORT = 0.05        # s: the runs here are about their input, not the motion

TIMES = np.linspace(0.0, 1.0, 2001)
#: a result to judge without a run (kavz685's reference spans 0 ... 10 s)
RESULT = (TIMES, {"coupling.tau2": np.zeros_like(TIMES)})


# -- every public function, every argument that goes through a parser the command line shares ------

API_REFUSALS = [
    # load (and every function that loads a scene with overrides)
    (lambda: api.load("kavz685", ["coupling.stiffness"]), "overrides='coupling.stiffness': expected name=value"),
    (lambda: api.load("kavz685", {"couplin.stiffness": 900}), "overrides['couplin.stiffness']: no component 'couplin'"),
    (lambda: api.load("kavz685", {"stiffnes": 900}), "overrides['stiffnes']: name the component"),
    (lambda: api.load("kavz685", {"experiment.stop": "x"}), "overrides['experiment.stop'] = 'x': expected a time"),
    (lambda: api.load("kavz685", {"experiment.stepp": 1}), "overrides['experiment.stepp']: the experiment has no field"),
    (lambda: api.load("kavz685", {"experiment.strict": "true"}), "overrides['experiment.strict'] = 'true': expected "
                                                                  "true or false"),
    (lambda: api.load("kavz685", {"coupling.stiffness": [900]}), "overrides['coupling.stiffness']=[900]: expected a "
                                                                  "number, True or False, or a string"),
    (lambda: api.load("kavz685", {3: 900}), "overrides: 3 is not a parameter's name"),
    (lambda: api.load("kavz685", ["experiment.stop=5"], stop=0.2), "stop=0.2 s and overrides['experiment.stop']=5 "
                                                                   "disagree"),
    (lambda: api.load("kavz685", {"experiment.strict": False}, strict=True), "strict=True and "
                                                                             "overrides['experiment.strict']=false"),
    # run
    (lambda: api.run("kavz685", {"experiment.master": "nope"}), "overrides['experiment.master']='nope': master 'nope' "
                                                                "is unknown"),
    (lambda: api.run("kavz685", master="nope"), "master='nope': master 'nope' is unknown"),
    (lambda: api.run("kavz685", ["experiment.step=1 ms"], step="2 ms"), "step=0.002 s and "
                                                                        "overrides['experiment.step']=1 ms disagree"),
    (lambda: api.run("kavz685", step=-1), "step = -1.0 must be > 0 s"),
    (lambda: api.run("kavz685", master="jacobi", tolerance=0.1), "tolerance: master 'jacobi' takes no tolerance"),
    (lambda: api.run("kavz685", master="me-cvode", tolerance=2), "tolerance=2.0: must lie in (0, 1)"),
    (lambda: api.run("kavz685", stream=True), "stream: name the output folder (out=...)"),
    (lambda: api.run("kavz685", latency=True), "latency: name the output folder (out=...)"),
    # validate: the verdict's tolerances, signals and window, a stand-alone FMU's settings
    (lambda: api.validate("kavz685", rtol=["amplitude"]), "rtol='amplitude': expected [SIGNAL or KIND:]QUANTITY=VALUE"),
    (lambda: api.validate("kavz685", rtol="ripple=0.1"), "rtol='ripple=0.1': tolerance ripple: no such quantity"),
    (lambda: api.validate("kavz685", rtol=["mean=x"]), "rtol='mean=x': tolerance mean = 'x': expected a number"),
    (lambda: api.validate("kavz685", rtol=["mean=-1"]), "rtol='mean=-1': tolerance mean = '-1': must be a finite"),
    (lambda: api.validate("kavz685", result=RESULT, window=(0, 1), rtol=["coupling.tau3:mean=0.1"]),
     "rtol: tolerance for coupling.tau3: neither a signal of the reference nor a kind"),
    (lambda: api.validate("kavz685", result=RESULT, window=(0, 1), signals=["nope"]),
     "signals=nope: not a signal of the reference"),
    (lambda: api.validate("kavz685", result=RESULT, window=(0, 1), signals=["engine.w"]),
     "signals=engine.w: not in the result (its columns: coupling.tau2)"),
    (lambda: api.validate("kavz685", result=RESULT, window="0:2 kg"), "window='0:2 kg': expected START:STOP"),
    (lambda: api.validate("kavz685", result=RESULT, window=(0, 20)), "window='0.0:20.0': must lie in the reference's span"),
    (lambda: api.validate("kavz685", tolerance="cross-check", rtol=["mean=0.1"]),
     "rtol and signals set the 'lever' verdict; tolerance='cross-check' is fmpy's band"),
    (lambda: api.validate("EngineShaft", master="jacobi"), "master/step: EngineShaft is an FMU run stand-alone"),
    (lambda: api.validate("EngineShaft", overrides={"nope": 1}), "overrides['nope']: EngineShaft has no parameter"),
    (lambda: api.validate("EngineShaft", overrides=["inertia"]), "overrides='inertia': expected name=value"),
    (lambda: list(api.validate_each(["kavz685"], reference="x.csv")), "reference: judges a result"),
    (lambda: list(api.validate_each(["kavz685", "EngineShaft"], result="x.csv")),
     "result: name exactly one reference the CSV is to be compared with (e.g. validate_each(['kavz685'], "
     "result='run.csv'))"),
    # the studies
    (lambda: api.bench(only=["nope"]), "only='nope': master 'nope' is unknown"),
    (lambda: api.stability_map(masters=["jacobi", "adaptive"]), "masters=adaptive: not a fixed-step master"),
    (lambda: api.stability_map(stiffnesses=[-1.0]), "stiffnesses: values must be finite and > 0"),
    (lambda: api.stability_map(h_omegas=[0.0]), "h_omegas: values must be finite and > 0"),
    (lambda: api.stability_map(dampings=[-1.0]), "dampings: values must be finite and >= 0"),
    (lambda: api.sweep(overrides={"couplin.damping": 2}), "overrides['couplin.damping']: no component 'couplin'"),
    (lambda: api.sweep(["stiffness"], stop=0.001), "stop=0.001 s: the scene leaves its first experiment.transient"),
    (lambda: api.study("runup", lags=[200]), "lags=200.0: engine.torque_lag must be in [0, 100] s"),
    (lambda: api.study("transfer-modes", lags=[1]), "lags applies to the runup study only"),
    (lambda: api.measured(stiffness=-1), "stiffness=-1.0: must be > 0 N*m/rad"),
    (lambda: api.engines(engines=["nope"]), "unknown engine nope (known: "),
    (lambda: api.hosts(hosts=["nope"]), "unknown host nope (known: "),
    (lambda: api.hosts(native_env="x"), "native_env='x': bare or set-up"),
    (lambda: list(api.fingerprints(masters=["nope"])), "masters='nope': master 'nope' is unknown"),
    (lambda: list(api.fingerprints(stop=-1)), "stop=-1.0: must be >= 0 s"),
]


@pytest.mark.parametrize("call,said", API_REFUSALS, ids=[said[:40] for _, said in API_REFUSALS])
def test_an_api_refusal_names_the_keyword_the_caller_wrote_not_the_command_lines_option(fmu_dir, call, said):
    with pytest.raises(api.InputError) as refused:
        call()
    message = str(refused.value)
    assert message.startswith(said), message
    assert "--" not in message, message


def test_a_result_or_reference_file_that_cannot_be_read_is_named_as_the_argument(fmu_dir, tmp_path):
    missing, empty = tmp_path / "missing.csv", tmp_path / "empty"
    empty.mkdir()
    for call, said in (
            (lambda: api.validate("kavz685", result=missing), f"result={str(missing)!r}: no such file or folder"),
            (lambda: api.validate("kavz685", result=empty), f"result={str(empty)!r}: a folder without traces.csv"),
            (lambda: api.validate("kavz685", result=RESULT, reference=empty),
             f"reference={str(empty)!r}: a folder without reference.csv"),
            (lambda: api.validate("kavz685", result=RESULT, reference=(TIMES[:1], {"coupling.tau2": TIMES[:1]})),
             "reference='(given)': 1 row(s); a reference needs at least two")):
        with pytest.raises(api.InputError) as refused:
            call()
        assert str(refused.value).startswith(said), str(refused.value)


def test_the_command_line_names_its_result_option_for_a_folder_without_traces(lever, fmu_dir, tmp_path):
    (tmp_path / "empty").mkdir()
    done = lever("validate", "kavz685", "--result", tmp_path / "empty", "--out", tmp_path / "out")
    assert done.exit_code == 2 and f"--result {tmp_path / 'empty'}: a folder without traces.csv" in done.output


def test_the_sweep_names_the_override_that_lowers_its_transient(fmu_dir):
    with pytest.raises(api.InputError) as refused:
        api.sweep(["stiffness"], stop=0.001)
    assert "(allowed: stop > 2 s; or lower the transient with overrides['experiment.transient']=...)" in \
        str(refused.value)


def test_the_engines_and_hosts_name_the_argument_that_chooses_them(fmu_dir):
    for call, said in ((lambda: api.engines(engines=["nope"]), "; engines chooses the engines)"),
                       (lambda: api.hosts(hosts=["nope"]), "; hosts chooses the hosts)")):
        with pytest.raises(api.InputError) as refused:
            call()
        assert str(refused.value).endswith(said), str(refused.value)


# -- the command line, calling the same API, names its options ---------------------------------------

@pytest.fixture
def result_csv(tmp_path):
    path = tmp_path / "result.csv"
    np.savetxt(path, np.column_stack([TIMES, np.zeros_like(TIMES)]), delimiter=",", header="time,coupling.tau2",
               comments="")
    return path


CLI_REFUSALS = [
    (("run", "kavz685", "--set", "coupling.stiffness"), "--set 'coupling.stiffness': expected name=value"),
    (("run", "kavz685", "--set", "couplin.stiffness=900"), "--set couplin.stiffness: no component 'couplin'"),
    (("run", "kavz685", "--set", "experiment.stop=x"), "--set experiment.stop = 'x': expected a time"),
    (("run", "kavz685", "--master", "jacobi", "--tolerance", "0.1"), "--tolerance: master 'jacobi' takes no tolerance"),
    (("run", "kavz685", "--set", "experiment.step=1 ms", "--step", "2 ms"),
     "--step 0.002 s and --set experiment.step=1 ms disagree"),
    (("validate", "kavz685", "--rtol", "amplitude"), "--rtol 'amplitude': expected [SIGNAL or KIND:]QUANTITY=VALUE"),
    (("validate", "kavz685", "--rtol", "ripple=0.1"), "--rtol 'ripple=0.1': tolerance ripple: no such quantity"),
    (("validate", "kavz685", "--window", "0:2 kg"), "--window 0:2 kg: expected START:STOP"),
    (("validate", "kavz685", "--tolerance", "cross-check", "--rtol", "mean=0.1"),
     "--rtol and --signals set the 'lever' verdict; --tolerance cross-check is fmpy's band"),
    (("validate", "EngineShaft", "--set", "nope=1"), "--set nope: EngineShaft has no parameter"),
    (("validate", "EngineShaft", "--master", "jacobi"), "--master/--step: EngineShaft is an FMU run stand-alone"),
    (("validate", "kavz685", "--result", "{csv}", "--window", "0:1", "--signals", "nope"),
     "--signals nope: not a signal of the reference"),
    (("validate", "kavz685", "--result", "{csv}", "--window", "0:1", "--rtol", "coupling.tau3:mean=0.1"),
     "--rtol: tolerance for coupling.tau3: neither a signal"),
    (("validate", "kavz685", "--result", "{csv}", "--window", "0:20"), "--window 0.0:20.0: must lie in the reference's span"),
    (("validate", "kavz685", "EngineShaft", "--result", "{csv}"),
     "--result: name exactly one reference the CSV is to be compared with (e.g. lever validate --result run.csv"),
    (("stability", "--stiffness", "-1"), "--stiffness: values must be finite and > 0"),
    (("study", "runup", "--scan", "200"), "--scan 200.0: engine.torque_lag must be in [0, 100] s"),
    (("measured", "--stiffness", "-1"), "--stiffness -1.0: must be > 0 N*m/rad"),
    (("sweep", "--axis", "stiffness", "--stop", "0.001"), "--stop 0.001 s: the scene leaves its first"),
    (("engines", "--engine", "nope"), "--engine chooses the engines"),
]


@pytest.mark.parametrize("arguments,said", CLI_REFUSALS, ids=[said[:40] for _, said in CLI_REFUSALS])
def test_the_command_line_names_the_option_its_user_typed(lever, fmu_dir, tmp_path, result_csv, arguments, said):
    done = lever(*[str(result_csv) if a == "{csv}" else a for a in arguments], "--out", tmp_path / "out")
    assert done.exit_code == 2 and said in done.output, done.output
    assert not any(word in done.output for word in ("overrides[", "rtol=", "window=", "signals=", "stiffness=",
                                                    "lags", "engines chooses")), done.output


# -- a dict override keeps its value's type -----------------------------------------------------------

def test_a_dict_override_is_taken_with_its_type():
    def coupling(value):
        return api.load("kavz685", {"coupling.stiffness": value}).components["coupling"].parameters["stiffness"]

    assert coupling("900") == "900"                       # a text, as a scene file's stiffness = "900"
    assert coupling(900) == 900 and type(coupling(np.int64(900))) is int
    assert coupling(np.float32(0.5)) == 0.5 and type(coupling(np.float64(900.5))) is float
    assert coupling("900 N*m/rad") == "900 N*m/rad"       # a quantity with its unit, as --set takes it
    assert coupling(True) is True                         # a boolean stays one: refused by the plan (below)
    assert api.load("kavz685", {"experiment.strict": True}).experiment.strict is True
    assert api.load("kavz685", {"experiment.strict": np.bool_(True)}).experiment.strict is True
    assert api.load("kavz685", {"experiment.master": "jacobi"}).experiment.master == "jacobi"
    assert api.load("kavz685", {"load.load_kind": "true"}).components["load"].parameters["load_kind"] == "true"
    # the command line's texts, in a list, are read as --set reads them
    assert api.load("kavz685", ["coupling.stiffness=900"]).components["coupling"].parameters["stiffness"] == 900
    with pytest.raises(api.InputError, match=r"^overrides\['load.load_kind'\]=\"'x\": a text value cannot begin or "
                                             "end with a quote"):
        api.load("kavz685", {"load.load_kind": "'x"})


@pytest.mark.parametrize("value,said", [
    ("900", "coupling.stiffness = '900': expected a number in N.m/rad or a number with a unit"),
    (" 900 ", "coupling.stiffness = '900': expected a number in N.m/rad"),
    ("9e2", "coupling.stiffness = '9e2': expected a number in N.m/rad"),      # not 9 elementary charges squared
    (True, "coupling.stiffness = the boolean true: expected a number in N.m/rad"),
    (np.bool_(False), "coupling.stiffness = the boolean false: expected a number in N.m/rad"),
    ("900 kg", "coupling.stiffness = '900 kg': a value in kg"),
])
def test_a_text_or_a_boolean_for_a_numeric_parameter_is_refused_before_the_run(fmu_dir, tmp_path, value, said):
    out = tmp_path / "run"
    with pytest.raises(api.InputError) as refused:
        api.run("kavz685", {"coupling.stiffness": value}, stop=SHORT, out=out)
    assert said in str(refused.value), str(refused.value)
    assert not out.exists()


def test_numpy_scalars_and_quantities_with_units_run_as_the_number(fmu_dir):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", api.RunNote)
        runs = [api.run("kavz685", {"coupling.stiffness": value}, stop=SHORT, reference=False, plots=False)
                for value in (900, np.int64(900), np.float64(900.0), "900 N*m/rad")]
    first = runs[0].traces["coupling.tau2"]
    for done in runs[1:]:       # the same number reaches the FMU: the same code path, the same traces
        assert np.array_equal(done.traces["coupling.tau2"], first)
    assert all(str(done.summary["parameters"]["coupling.stiffness"]["value"]).startswith("900") for done in runs)


OVERRIDE_ENTRIES = [
    lambda bad, tmp: api.run("kavz685", bad, stop=SHORT, out=tmp / "o"),
    lambda bad, tmp: api.validate("kavz685", overrides=bad, out=tmp / "o"),
    lambda bad, tmp: list(api.validate_each(["kavz685"], overrides=bad, out=tmp / "o")),
    lambda bad, tmp: api.sweep(["stiffness"], overrides=bad, out=tmp / "o"),
    lambda bad, tmp: api.engines("kavz685", bad, engines=["lever"], out=tmp / "o"),
    lambda bad, tmp: api.hosts("kavz685", bad, hosts=["harness-jacobi"], out=tmp / "o"),
    lambda bad, tmp: api.export("kavz685", "ssp", bad, out=tmp / "o" / "kavz685.ssp"),
]


@pytest.mark.parametrize("entry", OVERRIDE_ENTRIES, ids=["run", "validate", "validate_each", "sweep", "engines",
                                                         "hosts", "export"])
def test_every_entry_that_takes_overrides_refuses_a_text_for_a_number_before_it_works(fmu_dir, tmp_path, entry):
    with pytest.raises(api.InputError) as refused:
        entry({"coupling.damping": "2"}, tmp_path)
    assert "coupling.damping = '2': expected a number in N.m.s/rad" in str(refused.value), str(refused.value)
    assert not (tmp_path / "o").exists()


def test_a_stand_alone_fmus_overrides_keep_their_type_too(fmu_dir):
    with pytest.raises(api.InputError, match=r"EngineShaft.inertia = '0.3': expected a number in kg.m2"):
        api.validate("EngineShaft", overrides={"inertia": "0.3"})
    with pytest.raises(api.InputError, match=r"EngineShaft.inertia = the boolean true"):
        api.validate("EngineShaft", overrides={"inertia": True})


# -- the corpus's generated values as dict overrides ---------------------------------------------------

#: component parameters of kavz685: numbers in a unit (Real), a whole number, texts
REAL = ["coupling.stiffness", "coupling.damping", "coupling.misalignment", "engine.inertia"]
PARAMETERS = REAL + ["load.seed", "load.load_kind", "coupling.transfer_mode"]


@settings(max_examples=80, derandomize=True, deadline=None, database=None,
          suppress_health_check=list(HealthCheck))
@given(st.sampled_from(PARAMETERS + ["nothing.x"]), VALUES)
def test_every_value_given_in_a_dict_override_keeps_its_type_or_is_refused_naming_it(fmu_dir, key, value):
    """The corpus's values (booleans, texts with and without units, dates, lists, numbers):
    the scene holds the value given, of its type (a text stripped as --set strips it), or
    the call is refused naming the override; a numeric parameter the plan accepts holds a
    number or a quantity with its unit, never a text of a number or a boolean."""
    from harness.description import plan as plans
    from harness.description import units

    try:
        spec = api.load("kavz685", {key: value})
    except api.InputError as error:
        assert str(error).startswith(f"overrides['{key}']"), str(error)
        return
    component, parameter = key.split(".", 1)
    taken = spec.components[component].parameters[parameter]
    given_value = value.strip() if isinstance(value, str) else value
    assert type(taken) is type(given_value) and (taken == given_value or taken != taken), (value, taken)
    refusals = plans.check(spec, fmu_dir=fmu_dir).refusals
    if key in REAL and not refusals:
        assert isinstance(taken, (int, float)) and not isinstance(taken, bool) or (
            isinstance(taken, str) and units.split(taken) is not None), (value, taken)
    if refusals:
        assert any(key in refusal for refusal in refusals), refusals
