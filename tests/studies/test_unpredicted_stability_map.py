"""The stability map of a scene whose shaft FMU refuses the probe runs its linear model
needs: the map still runs, of observed runs only, says first why nothing was predicted
(naming the FMU and what it refused), writes "not predicted" where a prediction would be,
and advises from the runs alone.

The FMU is the example's user shaft (examples/user_fmu/driven_shaft.py) with one parameter
more: ``refuses = 1`` makes it refuse a step (fmi2Discard) while its input torque is one of
the probe torques, ``refuses = 2`` gives a non-finite speed there.  No coupling torque of a
run is exactly +-1 or +-10 N*m, so its runs are the example shaft's: the observed classes are
checked against the same cases run on the example shaft itself, and against the linear
prediction made from that shaft (which the probes can measure)."""
from __future__ import annotations

import csv
from pathlib import Path

import pytest

from harness import api
from harness.description import scene as scenes
from harness.judges import port_probe, stability
from harness.studies import stabilitymap
from harness.studies.cases import FAILED

MASTERS = ["jacobi", "jacobi-linear"]
STIFFNESS = 1e5


def _refusing_source(example: Path) -> str:
    source = (example / "driven_shaft.py").read_text()
    edits = [("class DrivenShaft(Fmi2Slave):", "class RefusingShaft(Fmi2Slave):"),
             ("from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real",
              "from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real"),
             ('        self.register_variable(Real("tau", causality=Fmi2Causality.input))',
              '        self.refuses = 0\n'
              '        self.register_variable(Integer("refuses", causality=Fmi2Causality.parameter,\n'
              '                                       variability=Fmi2Variability.fixed))\n'
              '        self.register_variable(Real("tau", causality=Fmi2Causality.input))'),
             ("    def do_step(self, current_time, step_size):\n",
              "    def do_step(self, current_time, step_size):\n"
              "        if self.refuses and abs(self.tau) in (1.0, 10.0):\n"
              "            if self.refuses == 1:\n"
              "                return False\n"
              "            self.w = float('nan')\n"
              "            return True\n")]
    for old, new in edits:
        assert source.count(old) == 1, old
        source = source.replace(old, new)
    return source


@pytest.fixture(scope="module")
def scenes_dir(tmp_path_factory, user_example, fmu_dir) -> Path:
    """The example scene (0.1 s), and the same with RefusingShaft.fmu: refusing1.toml and
    refusing2.toml."""
    from pythonfmu.builder import FmuBuilder

    folder = tmp_path_factory.mktemp("refusing")
    scene = user_example(folder, 0.1, 0.02)
    (folder / "refusing_shaft.py").write_text(_refusing_source(Path(__file__).resolve().parents[2] / "examples"
                                                               / "user_fmu"))
    FmuBuilder.build_FMU(folder / "refusing_shaft.py", dest=folder / "RefusingShaft.fmu")
    text = scene.read_text()
    for mode in (1, 2):
        edited = text.replace('fmu = "DrivenShaft.fmu"', 'fmu = "RefusingShaft.fmu"').replace(
            'name = "user_driveline"', f'name = "refusing{mode}"').replace(
            "speed_coefficient = 1.25\n", f"speed_coefficient = 1.25\nrefuses = {mode}\n")
        assert edited.count("RefusingShaft.fmu") == 1 and f"refuses = {mode}" in edited
        (folder / f"refusing{mode}.toml").write_text(edited)
    return folder


@pytest.fixture(scope="module")
def refused_map(scenes_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("refused_map")
    heard = []
    done = api.stability_map(scenes_dir / "refusing1.toml", stiffnesses=[STIFFNESS], dampings=[0.0], masters=MASTERS,
                             min_steps=16, out=out, progress=heard.append)
    return done, out, heard


WHY = ("load (FMU RefusingShaft.fmu) refused the probe runs (FmuCallError: load-probe: fmi2DoStep(t = 0, h = 0.0001) "
       "returned discard")


def test_the_map_runs_every_case_and_says_first_why_nothing_was_predicted(refused_map):
    done, out, heard = refused_map
    result, agreed = done["result"], done["agreement"]
    assert result.model is None and result.edges == {}
    assert agreed["no_prediction"].startswith("No prediction was made: ") and WHY in agreed["no_prediction"]
    assert heard[0] == agreed["no_prediction"]               # said before the cases run
    # 7 steps a master, each run and classified (none failed to run)
    assert len(result.results) == 2 * 7
    assert {r["class"] for r in result.results.values()} <= set(stabilitymap.STATUSES)
    assert all(r.get("status") != FAILED for r in result.results.values())
    # nothing claimed as predicted: no prediction counted, no edge
    assert agreed["by_master"] == {} and agreed["edge_rows"] == [] and agreed["explicit_rows"] == 0
    # the steps: the scene's 1 ms times 0.1 ... 100, scaled by sqrt(715.4 / 1e5)
    steps = sorted(c.step for c in result.results if c.master == "jacobi")
    assert steps == pytest.approx([r * 1e-3 * (715.4 / STIFFNESS) ** 0.5 for r in (0.1, 0.3, 1, 3, 10, 30, 100)],
                                  rel=1e-3)
    assert "No prediction was made" in repr(done)


def test_the_observed_classes_are_those_of_the_same_shaft_run_and_predicted(refused_map, scenes_dir):
    """Independent accounts: each case run on the example shaft (the same equations, no
    refusal), and the linear prediction from that shaft's measured model."""
    done, _, _ = refused_map
    result = done["result"]
    example = scenes.load(scenes_dir / "user_driveline.toml")
    model = stability.model_of(example).with_coupling(STIFFNESS, 0.0)
    agree = 0
    for case, r in result.results.items():
        twin = stabilitymap.run_case(example, case, result.plan)
        assert twin["class"] == r["class"], case
        predicted = stabilitymap.predicted_growth(stability.spectral_radius(model, case.master, case.step),
                                                  case.steps) > stabilitymap.GROWTH_DRIFT
        agree += predicted == stabilitymap.unstable(r)
    assert agree >= 0.9 * len(result.results)
    # both classes are in the map: the test sees a stable and an unstable side
    assert {stabilitymap.unstable(r) for r in result.results.values()} == {True, False}


def test_the_files_say_not_predicted_and_the_advice_is_the_runs(refused_map):
    done, out, _ = refused_map
    result, agreed = done["result"], done["agreement"]
    rows = list(csv.DictReader((out / "stability.csv").open()))
    assert len(rows) == len(result.results)
    for row in rows:
        assert (row["predicted_rho"], row["predicted_growth"], row["predicted_edge"]) == ("not predicted",) * 3
        assert (row["omega_n"], row["zeta"], row["h_omega"]) == ("unknown",) * 3
        assert row["class"] in stabilitymap.STATUSES and float(row["step_s"]) > 0
    md = (out / "stability.md").read_text().splitlines()
    assert md[0] == "# Stability map: refusing1 (observed runs only)"
    assert md[2] == f"**{agreed['no_prediction']}**"
    assert "## Advice from the observed runs only" in md and "| jacobi | 1e+05 | 0 | not predicted |" in "\n".join(md)
    assert (out / "stability_map.png").stat().st_size > 10_000
    # the advice, by hand from the csv: per master the largest step stable below its first unstable one
    lines = []
    for master in MASTERS:
        mine = sorted((float(r["step_s"]), r) for r in rows if r["master"] == master)
        first = next(h for h, r in mine if r["class"] == "divergent" or float(r["growth"]) > 1.25)
        lines.append(f"{max(h for h, _ in mine if h < first):.3g} s with {master}")
    (advice,) = agreed["advice"]
    assert advice.startswith("c = 1e+05 N*m/rad, b = 0 N*m*s/rad: observed stable up to h = ")
    assert sorted(advice.split(" up to h = ")[1].split(", ")) == sorted(lines)
    assert f"- {advice}" in md


def test_lever_stability_exits_0_and_says_it_first(refused_map, scenes_dir, lever):
    _, out, _ = refused_map
    done = lever("stability", scenes_dir / "refusing1.toml", "--stiffness", STIFFNESS, "--damping", 0, "--master",
                 "jacobi", "--master", "jacobi-linear", "--min-steps", 16, "--jobs", 1, "--out", out, "--no-progress")
    assert done.exit_code == 0, done.output
    said = done.output.splitlines()
    assert said[0].startswith("No prediction was made: ") and WHY in said[0]
    assert said[1] == "From the observed runs only:" and "observed stable up to h = " in said[2]
    assert "prediction agrees" not in done.output and said[-1].startswith("written: ")
    # with progress lines, said once, before anything else (the cases resumed from their log)
    done = lever("stability", scenes_dir / "refusing1.toml", "--stiffness", STIFFNESS, "--damping", 0, "--master",
                 "jacobi", "--master", "jacobi-linear", "--min-steps", 16, "--jobs", 1, "--out", out, "--progress")
    assert done.exit_code == 0, done.output
    said = done.output.splitlines()
    assert said[0].startswith("No prediction was made: ") and done.output.count("No prediction was made: ") == 1


def test_a_step_as_h_omega_is_refused_with_why(scenes_dir):
    with pytest.raises(api.InputError, match=r"--h-omega: this map has no h\*omega_n .*refused the probe runs"):
        api.stability_map(scenes_dir / "refusing1.toml", h_omegas=[0.5], masters=["jacobi"])


def test_a_non_finite_speed_is_named_and_the_refusal_probed_once(scenes_dir, monkeypatch):
    monkeypatch.setattr(port_probe, "_PROBED", {})
    calls = []
    speeds = port_probe._speeds
    monkeypatch.setattr(port_probe, "_speeds", lambda *args: calls.append(args) or speeds(*args))
    spec = scenes.load(scenes_dir / "refusing2.toml")
    for _ in range(2):
        model, why = stabilitymap.linear_model(spec)
        assert model is None
        assert "load (FMU RefusingShaft.fmu) cannot be probed: its speed w went non-finite under a torque of 1" in why
    assert len(calls) == 2                  # the first probe pair of one plan, not again for the second ask


def test_a_master_the_fmus_cannot_serve_is_a_failed_case_not_a_divergent_one(refused_map, scenes_dir):
    """RefusingShaft.fmu keeps no FMU state (built without canGetAndSetFMUstate): a master that
    rolls steps back cannot start on it - nothing observed of its stability."""
    done, _, _ = refused_map
    case = stabilitymap.Case("implicit-newton", STIFFNESS, 0.0, None, 16, step=1e-4)
    r = stabilitymap.run_case(scenes.load(scenes_dir / "refusing1.toml"), case, done["result"].plan)
    assert r["status"] == FAILED and r["where"] == "the run could not start"
    assert "declares canGetAndSetFMUstate = false" in r["error"]
    plan = done["result"].plan
    result = stabilitymap.StabilityMap(done["result"].scene, stabilitymap.Plan(
        [STIFFNESS], [0.0], [], ["implicit-newton"], step_ratios=[1.0], scene_step=plan.scene_step,
        scene_stiffness=plan.scene_stiffness, scene_steps=plan.scene_steps), None, {}, {case: r}, no_prediction="x")
    assert stabilitymap.observed_advice(result) == [
        "c = 1e+05 N*m/rad, b = 0 N*m*s/rad: no master observed stable at any swept step; no run could start "
        "(stability.md lists why): implicit-newton"]
