"""Reference traces and validation (harness.formats.reference_traces, harness.judges.validation, `lever reference`,
`lever validate`)."""
from __future__ import annotations

import csv
import json
import shutil

import numpy as np
import pytest

from harness.formats import reference_traces
from harness.judges import validation, verdict
from harness.description import scene as scenes

LEVER = validation.TOLERANCES["lever"]
CROSS = validation.TOLERANCES["cross-check"]


# -- the band: the cross-check's, as fmpy implements it ----------------------------------------

@pytest.mark.parametrize("kind", ["ripple", "constant", "zero", "steps"])
def test_band_is_fmpys_with_the_cross_check_figures(kind):
    from fmpy.util import validate_signal

    rng = np.random.default_rng(3)
    t_ref = np.linspace(0.0, 2.0, 701)
    y_ref = {"ripple": 3 * np.sin(7 * t_ref) + np.sin(90 * t_ref), "constant": np.full_like(t_ref, 4.2),
             "zero": np.zeros_like(t_ref), "steps": np.floor(3 * t_ref)}[kind]
    t = np.sort(rng.uniform(-0.1, 2.1, 900))
    y = np.interp(t, t_ref, y_ref) + rng.normal(0, 0.3, t.size)
    t_band, y_min, y_max, i_out = validate_signal(t, y, t_ref.copy(), y_ref)
    ours = validation.band(t_ref, y_ref, CROSS.num, CROSS.dx, CROSS.dy)
    np.testing.assert_array_equal(ours.t, t_band)
    np.testing.assert_allclose(ours.low, y_min, rtol=0, atol=1e-12)
    np.testing.assert_allclose(ours.high, y_max, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(validation.outside(t, y, ours), i_out)


def test_cross_check_fraction_is_fmpys_validate_result():
    t_ref = np.linspace(0, 1, 401)
    reference = {"x": np.sin(20 * t_ref), "v": np.cos(3 * t_ref)}
    t = np.linspace(0, 1, 1001)
    traces = {"x": np.sin(20 * t) * 1.3, "v": np.cos(3 * t)}
    findings, _ = validation.compare("x", t, traces, t_ref, reference, CROSS)
    assert max(s.fraction_outside for s in findings.signals) == pytest.approx(
        validation.fmpy_max_outside(t, traces, t_ref, reference), abs=1e-12)
    assert findings.failed_signals == ["x"]


# -- the lever figures --------------------------------------------------------------------------

def _signal(t):
    return 50 * np.sin(74 * t) + 10 * t


def test_lever_tolerance_forgives_one_step_of_lag_not_three():
    h = 1e-3
    t = np.arange(0, 1 + h / 2, h)
    t_ref = t[::10]
    reference = {"y": _signal(t_ref)}
    exact, _ = validation.compare("y", t, {"y": _signal(t)}, t_ref, reference)
    late, _ = validation.compare("y", t, {"y": _signal(t - h)}, t_ref, reference)
    later, _ = validation.compare("y", t, {"y": _signal(t - 3 * h)}, t_ref, reference)
    assert exact.passed and exact.signals[0].max_error < 1e-12
    assert late.passed and late.signals[0].max_error > late.signals[0].band_width   # outside 1 % ...
    assert not later.passed and later.signals[0].fraction_outside > 0.5              # ... but one step


def test_lever_tolerance_allows_one_percent_of_samples_outside():
    t = np.linspace(0, 1, 1001)
    y = 100 * t                  # band +-1, one step 0.1: a sample's neighbours are within the band
    spiky = y.copy()
    spiky[100:700:3] += 30.0     # 200 isolated wrong samples: each is excused by its neighbours
    findings, _ = validation.compare("y", t, {"y": spiky}, t, {"y": y})
    assert findings.passed and findings.signals[0].fraction_outside == 0
    for run, passes in ((12, True), (13, False)):
        wrong = y.copy()
        wrong[200:200 + run] += 30.0      # a run of wrong samples: all but its two ends are outside
        findings, _ = validation.compare("y", t, {"y": wrong}, t, {"y": y})
        assert findings.signals[0].fraction_outside == pytest.approx((run - 2) / 1001)
        assert findings.passed == passes


def test_structural_problems_fail_the_result():
    t = np.linspace(0, 1, 101)
    reference = {"a": np.sin(t), "b": np.cos(t)}
    short, _ = validation.compare("r", t[:50], {"a": np.sin(t[:50]), "b": np.cos(t[:50])}, t, reference)
    assert not short.passed and any("ends at" in p for p in short.problems)
    missing, _ = validation.compare("r", t, {"a": np.sin(t), "c": t}, t, reference)
    assert not missing.passed and any("'b' is missing" in p for p in missing.problems)
    assert any("c" in n for n in missing.notes)
    nan = np.sin(t)
    nan[40:60] = np.nan
    broken, _ = validation.compare("r", t, {"a": nan, "b": np.cos(t)}, t, reference)
    assert broken.failed_signals == ["a"] and broken.signals[0].rms_error == np.inf


def test_columns_match_by_name_or_unique_suffix():
    mapping, missing = validation.match_columns(["tau1", "tau2", "w"], ["coupling.tau1", "tau2", "a.w", "b.w"])
    assert mapping == {"tau1": "coupling.tau1", "tau2": "tau2"} and missing == ["w"]


# -- the committed references -------------------------------------------------------------------

#: how far every reference is checked (``lever reference --until``): its head made as the whole
#: span is made (the same grid and method, cut there), a fifth of the cost of the whole check
HEAD = 0.2
#: checked whole: the FMU cases (exact responses, cheap) and the default scene
WHOLE = (*reference_traces.FMU_CASES, "kavz685")


def test_lever_reference_reports_every_committed_trace_current(lever):
    heads = lever("reference", "--until", f"{HEAD} s")
    assert heads.exit_code == 0, heads.output
    for name in reference_traces.all_names():
        assert f"{name}: current" in heads.output
    whole = lever("reference", *WHOLE)
    assert whole.exit_code == 0, whole.output
    for name in WHOLE:
        assert f"{name}: current" in whole.output


def test_a_references_head_is_the_whole_references_first_rows(monkeypatch):
    """What ``--until`` compares: the rows a solve to ``until`` gives are those of the whole
    span's solve, to the 9 digits the files keep - for a misalignment source's driveline, a
    load that sticks (mode switches) and the rectifier's own solver; and a span stiff enough
    for another solver than DOP853 has its head solved by that solver too."""
    from harness.judges import monolithic

    for name, stop in (("kavz685_misalignment_ramp", 0.3), ("kavz685_stall_resistive", 0.3),
                       ("freewheel_rectifier", 0.1)):
        spec = scenes.load(name).with_overrides([f"experiment.stop={stop}"])
        whole = reference_traces.generate_scene(spec)
        made = reference_traces.generate_scene(spec, until=stop / 2)
        assert made.outputs.times[-1] == pytest.approx(stop / 2) and len(made.outputs.times) < len(whole.outputs.times)
        diff = reference_traces.difference(reference_traces.head(whole, stop / 2), made)
        assert diff.current and not diff.problems, (name, diff)
        assert max(c.relative for c in diff.changes) < 1e-8, (name, diff.changes)
    # a span stiff past 0.1 s: the whole takes CVODE, and so does its head, short as it is
    monkeypatch.setattr(monolithic, "stiff_method",
                        lambda driveline, t0, y0, span, resisting: ("CVODE-BDF", "stiff") if span > 0.1 else None)
    solve, methods = monolithic.solve, []
    monkeypatch.setattr(monolithic, "solve", lambda *a, **k: methods.append(k.get("method")) or solve(*a, **k))
    reference_traces.generate_scene(scenes.load("kavz685").with_overrides(["experiment.stop=0.2"]), until=0.01)
    assert methods == ["CVODE-BDF"]


def test_reference_files_are_in_the_cross_check_layout():
    from fmpy.util import read_csv, read_ref_opt_file

    for name in reference_traces.all_names():
        p = reference_traces.paths(name)
        opt = read_ref_opt_file(str(p["opt"]))
        ref = read_csv(str(p["ref"]))
        assert ref.dtype.names[0] == "time" and ref["time"][0] == opt["StartTime"] and ref["time"][-1] == opt["StopTime"]
        driven = name in reference_traces.FMU_CASES and reference_traces.FMU_CASES[name].inputs is not None
        assert p["in"].exists() == driven
        assert p["ref"].stat().st_size < 2_000_000      # small enough to commit, dense enough to judge against
        if driven:
            assert set(read_csv(str(p["in"])).dtype.names) > {"time"}


def test_every_fmu_has_a_stand_alone_reference_or_says_why_not():
    """Each FMU of the registry: a case and its committed traces, or the reason it has none;
    no case of an FMU the registry does not have."""
    from lever.fmus import registry

    for model in registry.MODELS:
        if not model.no_reference:
            assert reference_traces.read(model.name).kind == "fmu", model.name
    # a case written for a name the registry does not have, or says has none, is never run
    assert set(reference_traces._CASES) == set(reference_traces.FMU_CASES)


def test_validating_an_fmu_without_a_stand_alone_reference_says_why_and_what_instead(lever):
    result = lever("validate", "FreewheelRectifier")
    assert result.exit_code == 2
    assert "FreewheelRectifier has no stand-alone reference" in result.output
    assert "lever validate freewheel_rectifier" in result.output


def test_stale_reference_is_reported_and_update_shows_the_change(lever, tmp_path, monkeypatch):
    for name in ("LeverCoupling", "EngineShaft"):
        shutil.copytree(reference_traces.paths(name)["ref"].parent, tmp_path / name)
    monkeypatch.setattr(reference_traces, "REFERENCE_DIR", tmp_path)
    ref = reference_traces.read("LeverCoupling")
    ref.outputs.signals["tau1"][500] += 2.5
    reference_traces.write(ref)
    checked = lever("reference", "LeverCoupling", "EngineShaft")
    assert checked.exit_code == 1
    assert "LeverCoupling: NOT current" in checked.output and "EngineShaft: current" in checked.output
    line = next(l for l in checked.output.splitlines() if l.strip().startswith("tau1"))
    assert line.split()[1:4] == ["max", "change", "2.5"] and line.endswith("t = 0.5 s")
    # checked up to a time: the change is seen from its time on, not before
    assert lever("reference", "--until", "0.4 s", "LeverCoupling").exit_code == 0
    assert "LeverCoupling: NOT current" in lever("reference", "--until", "500 ms", "LeverCoupling").output
    for refused, words in ((["--update"], "a reference is updated whole"), ([], "before the second sample")):
        result = lever("reference", "--until", "0.4" if refused else "0.1 ms", *refused, "LeverCoupling")
        assert result.exit_code == 2 and words in result.output and "Traceback" not in result.output, result.output
    assert lever("reference", "--update", "LeverCoupling").exit_code == 0
    assert "LeverCoupling: current" in lever("reference", "LeverCoupling").output


# -- every FMU and scene validates; perturbed parameters fail where they should -----------------

def _validate(name, assignments=()):
    ref = reference_traces.read(name)
    if ref.kind == "fmu":
        from harness.api import fmu_start_values
        result = reference_traces.run_fmu(name, ref, fmu_start_values(name, assignments))
    else:
        result = reference_traces.run_scene(scenes.load(name).with_overrides(list(assignments)))
    assert result.failure is None, result.failure
    # the default verdict of lever validate NAME, with the reference's own settings (its
    # scene's [validation] table); the power is left out: it judges no result
    settings = verdict.settings_of(ref)
    findings = verdict.judge(result.times, result.traces, ref.outputs.times, ref.outputs.signals,
                             transient=settings.transient, rtol=verdict.Tolerances([settings.rules]),
                             kinds=settings.kinds, rotation_signal=settings.rotation_signal, with_power=False)
    return findings, result


@pytest.mark.parametrize("name", reference_traces.all_names())
def test_every_fmu_and_scene_validates_against_its_reference(fmu_dir, name):
    findings, _ = _validate(name)
    assert findings.passed, (findings.problems, findings.failed_signals)
    assert [s.name for s in findings.signals] == list(reference_traces.read(name).outputs.signals)


def test_stiffer_coupling_fails_the_torques_and_energy_not_the_kinematics(fmu_dir):
    findings, _ = _validate("LeverCoupling", ["stiffness=750"])
    assert set(findings.failed_signals) == {"tau1", "tau2", "elastic_energy"}


def test_heavier_load_shaft_fails_its_motion_not_its_load_torque(fmu_dir):
    findings, _ = _validate("LoadShaft", ["inertia=0.165"])
    failed = set(findings.failed_signals)
    assert "w" in failed and failed <= {"phi", "w", "a", "load_work"}


# -- lever validate FILE.fmu: an FMU file stand-alone, FMI 2.0 or 3.0 ---------------------------

def _figures(out):
    summary = json.loads((out / "validation.json").read_text())
    return summary["passed"], summary["signals"]


@pytest.mark.parametrize("model, assignments", [("LoadShaft", ()), ("LeverCoupling", ("--set", "stiffness=750"))])
def test_an_fmu_file_validates_stand_alone_as_its_models_name_does(lever, fmu_dir, tmp_path, model, assignments):
    """``lever validate build/fmus3/Model.fmu`` runs that file (here the FMI 3.0 edition) as
    ``lever validate Model`` runs the built FMI 2.0 one, judged by the model's reference: the
    same verdict and figures (the editions' outputs are bit-identical), passing or failing;
    the FMI 2.0 file likewise.  A plot per failing signal, none with ``--no-plots``."""
    from harness.paths import fmi3_dir

    by_name = lever("validate", model, *assignments, "--out", tmp_path / "name")
    expected = _figures(tmp_path / "name")
    failed = [name for name, figures in expected[1].items() if not figures["passed"]]
    assert bool(failed) == bool(assignments)
    assert sorted(p.name for p in (tmp_path / "name").glob("*.png")) == sorted(f"{name}.png" for name in failed)
    for edition, folder in (("fmi2", fmu_dir), ("fmi3", fmi3_dir(fmu_dir))):
        path = folder / f"{model}.fmu"
        done = lever("validate", path, *assignments, "--no-plots", "--out", tmp_path / edition)
        assert done.exit_code == by_name.exit_code == (1 if assignments else 0), done.output
        assert f"{path} (FMI {edition[-1]}.0)" in done.output
        assert f"{path}: {'FAIL' if assignments else 'PASS'}" in done.output
        assert _figures(tmp_path / edition) == expected
        assert (tmp_path / edition / f"{model}_out.csv").exists()
        assert not list((tmp_path / edition).glob("*.png"))


def test_an_fmu_file_that_cannot_be_validated_stand_alone_is_bad_input(lever, fmu_dir, tmp_path):
    from harness.paths import fmi3_dir

    not_fmu = tmp_path / "notes.fmu"
    not_fmu.write_text("not a zip")
    for path, words in ((tmp_path / "missing.fmu", "no such FMU file"), (tmp_path / "MISSING.FMU", "no such FMU file"),
                        (not_fmu, "model description can be read"),
                        (fmi3_dir(fmu_dir) / "FreewheelRectifier.fmu", "experiment.fmi=3")):
        done = lever("validate", path)
        assert done.exit_code == 2 and words in done.output, done.output
    done = lever("validate", fmi3_dir(fmu_dir) / "EngineShaft.fmu", "--step", "0.01")
    assert done.exit_code == 2 and "stand-alone" in done.output


def _damaged_copy(source, target, drop=None, description=None):
    """``source`` rewritten to ``target``: members under ``drop`` left out, the model
    description passed through ``description`` (bytes -> bytes)."""
    import zipfile

    with zipfile.ZipFile(source) as zin, zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as zout:
        for item in zin.infolist():
            if drop and item.filename.startswith(drop):
                continue
            data = zin.read(item.filename)
            if description and item.filename == "modelDescription.xml":
                data = description(data)
            zout.writestr(item, data)
    return target


def test_a_damaged_fmu_file_is_bad_input_with_the_fmus_own_message(lever, fmu_dir, tmp_path):
    """Without its binary for this platform, or with a model description of another build
    (FMI 2.0 guid, FMI 3.0 instantiationToken), an FMU file is refused with exit code 2: what
    is missing, or the FMU's own message - never a traceback."""
    import re

    from harness.paths import fmi3_dir

    stranger = b"{00000000-0000-0000-0000-000000000000}"
    cases = (
        (fmu_dir, "nobin2.fmu", dict(drop="binaries/"), "no binary for this platform (binaries/linux64/EngineShaft"),
        (fmi3_dir(fmu_dir), "nobin3.fmu", dict(drop="binaries/"),
         "no binary for this platform (binaries/x86_64-linux/EngineShaft"),
        (fmu_dir, "guid2.fmu", dict(description=lambda d: re.sub(rb'guid="[^"]*"', b'guid="' + stranger + b'"', d,
                                                                  count=1)),
         "refused to instantiate (fmi2Instantiate returned NULL); FMU said: [error] fmi2Instantiate: fmuGUID"),
        (fmi3_dir(fmu_dir), "token3.fmu",
         dict(description=lambda d: re.sub(rb'instantiationToken="[^"]*"', b'instantiationToken="' + stranger + b'"',
                                           d, count=1)),
         "refused to instantiate (fmi3InstantiateCoSimulation returned NULL); FMU said: [error] fmi3Instantiate"),
    )
    for folder, name, damage, words in cases:
        path = _damaged_copy(folder / "EngineShaft.fmu", tmp_path / name, **damage)
        done = lever("validate", path, "--out", tmp_path / name)
        assert done.exit_code == 2, done.output
        assert words in done.output and "Traceback" not in done.output, done.output


def test_a_scene_with_a_damaged_fmu_file_is_bad_input_for_lever_run(lever, fmu_dir, tmp_path):
    """The same refusal where a scene names the file: exit code 2 with the FMU's message, no
    traceback, no results folder left."""
    import re

    from harness.paths import SCENES

    damaged = _damaged_copy(fmu_dir / "EngineShaft.fmu", tmp_path / "guid2.fmu", description=lambda d: re.sub(
        rb'guid="[^"]*"', b'guid="{00000000-0000-0000-0000-000000000000}"', d, count=1))
    scene = tmp_path / "damaged.toml"
    scene.write_text((SCENES / "kavz685.toml").read_text().replace('fmu = "EngineShaft"', f'fmu = "{damaged}"'))
    done = lever("run", scene, "--stop", "0.01", "--no-reference", "--no-plots", "--out", tmp_path / "out")
    assert done.exit_code == 2, done.output
    assert "refused to instantiate (fmi2Instantiate returned NULL); FMU said: [error] fmi2Instantiate" in done.output
    assert not (tmp_path / "out").exists()


@pytest.fixture(scope="module")
def kavz685_run(fmu_dir):
    return reference_traces.run_scene(scenes.load("kavz685"))


def test_stiffer_coupling_in_the_scene_fails_the_deflection_and_the_ripple_not_the_mean_torque(lever, fmu_dir,
                                                                                               tmp_path):
    result = lever("validate", "kavz685", "--set", "coupling.stiffness=800", "--out", str(tmp_path))
    assert result.exit_code == 1
    findings = __import__("json").loads((tmp_path / "validation.json").read_text())
    failed = {n: {c["quantity"] for c in s["checks"] if not c["passed"]} for n, s in findings["signals"].items()}
    # the deflection theta = T/c is what a stiffness sets, mean and all; the torques' mean
    # follows the load, their ripple's second order changes with the coupling's mode
    assert {"mean", "amplitude", "tube"} <= failed["coupling.theta"]
    assert "order 2" in failed["coupling.tau2"] and "mean" not in failed["coupling.tau2"]
    assert not failed["load.load_torque"]
    assert "coupling.stiffness = 800 N.m/rad (--set; the reference: 715.4 N.m/rad)" in result.output
    assert (tmp_path / "coupling.theta.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with open(tmp_path / "kavz685_out.csv", newline="") as exported:
        assert next(csv.reader(exported))[0] == "time"


# -- results produced elsewhere -------------------------------------------------------------------

def test_external_csv_of_a_scene_passes_and_a_lagging_one_fails(lever, kavz685_run, tmp_path):
    good = tmp_path / "other_tool.csv"
    reference_traces.write_csv(good, reference_traces.Traces(kavz685_run.times, kavz685_run.traces))
    result = lever("validate", "--result", str(good), "kavz685", "--out", str(tmp_path / "good"))
    assert result.exit_code == 0, result.output
    # a tool whose coupling torque lags 10 ms behind (as a 10 ms zero-order hold would)
    traces = dict(kavz685_run.traces)
    for name in ("coupling.tau1", "coupling.tau2"):
        traces[name] = np.concatenate([np.full(10, traces[name][0]), traces[name][:-10]])
    bad = tmp_path / "lagging_tool.csv"
    reference_traces.write_csv(bad, reference_traces.Traces(kavz685_run.times, traces))
    result = lever("validate", "--result", str(bad), "kavz685", "--no-plots", "--out", str(tmp_path / "bad"))
    assert result.exit_code == 1
    assert "FAIL (coupling.tau1: " in result.output and "; coupling.tau2: " in result.output


def test_external_csv_of_an_fmu_with_prefixed_columns(lever, fmu_dir, tmp_path):
    ref = reference_traces.read("EngineShaft")
    run = reference_traces.run_fmu("EngineShaft", ref)
    path = tmp_path / "engine.csv"
    reference_traces.write_csv(path, reference_traces.Traces(run.times, {f"engine.{k}": v for k, v in run.traces.items()}))
    assert lever("validate", "--result", str(path), "EngineShaft", "--out", str(tmp_path / "a")).exit_code == 0
    # missing a signal: judged on the others, the missing one listed
    reference_traces.write_csv(path, reference_traces.Traces(run.times, {k: v for k, v in run.traces.items()
                                                                         if k != "engine_work"}))
    result = lever("validate", "--result", str(path), "EngineShaft", "--out", str(tmp_path / "b"))
    assert result.exit_code == 0 and "not judged (not in the result): engine_work" in result.output
    # ending early fails
    reference_traces.write_csv(path, reference_traces.Traces(run.times[:500], {k: v[:500] for k, v in run.traces.items()}))
    result = lever("validate", "--result", str(path), "EngineShaft", "--out", str(tmp_path / "c"))
    assert result.exit_code == 1 and "ends at t = 0.499" in result.output
    # none of the reference's signals: bad input, said
    reference_traces.write_csv(path, reference_traces.Traces(run.times, {"speed": run.traces["w"]}))
    result = lever("validate", "--result", str(path), "EngineShaft", "--out", str(tmp_path / "d"))
    assert result.exit_code == 2 and "none of the reference's signals" in result.output


@pytest.mark.parametrize("shift", [20.0, -20.0, 100.0, 0.4, -0.4])
def test_a_result_shifted_in_time_gets_a_verdict_not_a_traceback(lever, tmp_path, shift):
    """A result whose times miss the reference's span (a shifted time column) fails,
    saying that the spans do not overlap, or how much of the span it covers (no signal is
    judged on a span the result does not cover); validation.json is standard JSON."""
    import json

    ref = reference_traces.read("EngineShaft")      # 0 ... 1 s
    path = tmp_path / "shifted.csv"
    reference_traces.write_csv(path, reference_traces.Traces(ref.outputs.times + shift, ref.outputs.signals))
    out = tmp_path / "out"
    result = lever("validate", "--result", str(path), "EngineShaft", "--out", str(out))
    assert result.exit_code == 1, result.output
    assert result.exception is None or isinstance(result.exception, SystemExit), result.exception
    assert "EngineShaft: FAIL" in result.output and "Traceback" not in result.output
    if abs(shift) > 1:
        assert f"do not overlap the span 0 ... 1 s" in result.output
    else:
        assert "it covers 60.0% of 0 ... 1 s" in result.output
    summary = json.loads((out / "validation.json").read_text(),
                         parse_constant=lambda c: pytest.fail(f"validation.json holds {c}"))
    assert summary["passed"] is False and summary["problems"]


def test_validate_refuses_bad_input(lever, tmp_path):
    assert lever("validate", "nope").exit_code == 2
    assert lever("validate", "--result", __file__, "kavz685").exit_code == 2      # not a CSV of numbers
    result = lever("validate", "LeverCoupling", "--set", "stiffness=-3")
    assert result.exit_code == 2 and "allowed range" in result.output
    result = lever("validate", "LeverCoupling", "--set", "stiffnes=3")
    assert result.exit_code == 2 and "no parameter 'stiffnes'" in result.output


# -- lever validate --measured: the model-vs-measurement check on given files ----------------

def test_measured_option_checks_a_grade(lever, tmp_path):
    from harness.paths import DATA
    grade = [str(DATA / "monograph" / f"torque_{shaft}_7IRP13-48.csv") for shaft in ("drive", "driven")]
    result = lever("validate", "--measured", *grade, "--out", str(tmp_path))
    assert result.exit_code == 0, result.output
    assert "7IRP" in result.output and (tmp_path / "measured.md").exists()
    # a table without its pair is bad input (exit 2), not a grade that misses its target (exit 1)
    result = lever("validate", "--measured", grade[0], "--out", str(tmp_path / "lonely"))
    assert result.exit_code == 2 and "no driven-shaft table to pair with" in result.output


def test_the_cross_check_verdict_says_what_its_band_cannot_see():
    """A ripple faster than the cross-check's window, at the wrong phase, passes its band; the
    verdict says so with the window and the margins, and the lever figures fail it."""
    t = np.linspace(0.0, 10.0, 10001)
    ref = {"tau2": 107.5 + 6.0 * np.sin(420.0 * t)}
    wrong = {"tau2": 107.5 + 6.0 * np.sin(420.0 * t + 2.0)}
    cross_check, _ = validation.compare("x", t, wrong, t, ref, validation.TOLERANCES["cross-check"])
    assert cross_check.passed
    (note,) = [n for n in cross_check.notes if n.startswith("what the cross-check band can see")]
    assert "window of 0.2 s" in note and "tau2 +-1.2" in note
    lever, _ = validation.compare("x", t, wrong, t, ref, validation.TOLERANCES["lever"])
    assert not lever.passed and not any(n.startswith("what the") for n in lever.notes)


def test_a_window_judges_a_shorter_result_and_the_verdict_names_the_span(lever, fmu_dir, tmp_path):
    """A 1 s run of kavz685 fails against the 10 s reference (it ends early) and passes over
    the window 0 ... 1 s, by the same band; the verdict says which span it judged."""
    run = tmp_path / "run"
    assert lever("run", "kavz685", "--stop", "1", "--no-reference", "--no-plots", "--out", str(run)).exit_code == 0
    whole = lever("validate", "--result", str(run / "traces.csv"), "kavz685", "--out", str(tmp_path / "whole"))
    assert whole.exit_code == 1 and "before the stop time" in whole.output
    assert "FAIL over the reference's whole span, t = 0 ... 10 s" in whole.output
    part = lever("validate", "--result", str(run / "traces.csv"), "kavz685", "--window", "0:1",
                   "--out", str(tmp_path / "part"))
    assert part.exit_code == 0, part.output
    assert "PASS over t = 0 ... 1 s of the reference's 0 ... 10 s" in part.output
    # all of it start-up (the scene's transient ends at 2 s): its tube alone judges it, and says so
    assert "ends before the start-up transient does (t = 2 s): judged by the start-up's tube only" in part.output
    verdict = json.loads((tmp_path / "part" / "validation.json").read_text())
    assert verdict["span_s"] == [0.0, 1.0] and verdict["reference_span_s"] == [0.0, 10.0]
    # a window the result does not cover fails, naming the end; a window outside the reference is bad input
    late = lever("validate", "--result", str(run / "traces.csv"), "kavz685", "--window", "0:2",
                   "--out", str(tmp_path / "late"))
    assert late.exit_code == 1 and "before the stop time (2 s" in late.output
    for bad in ("0:11", "1:1", "x:1", "5"):
        result = lever("validate", "--result", str(run / "traces.csv"), "kavz685", "--window", bad)
        assert result.exit_code == 2, (bad, result.output)


def test_a_window_with_too_few_reference_samples_fails_with_a_sentence():
    t = np.linspace(0, 1, 11)
    findings, _ = validation.compare_span("x", t, {"y": t}, t, {"y": t}, LEVER, 0.01, 0.02)
    assert not findings.passed and "holds 0 of the reference's samples" in findings.problems[0]
