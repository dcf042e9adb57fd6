"""Mutation testing of the physics, the masters and the judges with mutmut (``make mutants``).

Outside CI's budget: it takes tens of minutes.  mutmut 3 imports the mutated code from
``mutants/`` by the module name of each file's path, so the project is staged first into
``results/mutation/<label>/`` in the layout mutmut expects - the ``lever`` and ``harness``
packages at the top - with the FMUs already built (their physics is not mutated: the tests
selected here run the mutated physics and masters in the test process).  Then

    mutmut run            over each of GROUPS (below) with its tests
    mutmut results        the survivors

and the score table (killed / survived / no tests / timeout, per file) is printed and
written to ``results/mutation/<label>/<group>/score.md``.

    .venv/bin/python tests/mutation/run_mutants.py [--label NAME] [--group physics masters] [--tests-from DIR]

``--tests-from`` takes the tests from another checkout (the "before" score: the tests of
the main branch against the same code).
"""
from __future__ import annotations

import argparse
import fnmatch
import json
import os
import shutil
import subprocess
import sys
from collections import Counter
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]

#: The scope, in two groups run apart so that each mutant runs only the tests that belong
#: to it: (files to mutate, mutant-name globs or [] for all, tests).  Chosen to keep a run
#: under about 20 minutes on two shared cores: the coupling, its elastic laws and
#: kinematics, the engine and the shaft integrator (the driveline's physics; the loads,
#: the freewheel, parameters and signals are left out), and the masters' extrapolation
#: (the weights every extrapolating and adaptive master steps with).
GROUPS = {
    "physics": (["lever/physics/coupling.py", "lever/physics/elastic.py", "lever/physics/kinematics.py",
                 "lever/physics/engine.py", "lever/physics/shaft.py"], [],
                ["tests/physics/test_coupling_physics.py", "tests/physics/test_kinematics.py",
                 "tests/physics/test_loads_and_shafts.py", "tests/oracle/test_oracle_monograph.py",
                 "tests/oracle/test_oracle_physics.py", "tests/oracle/test_oracle_stability_models.py",
                 "tests/oracle/test_oracle_states.py"]),
    "masters": (["harness/engine/masters/explicit.py"], ["harness.engine.masters.explicit.x_extrapolation_weights*",
                                                         "harness.engine.masters.explicit.x_lagrange_weights*"],
                ["tests/engine/test_masters.py", "tests/oracle/test_oracle_physics.py"]),
    # The linear model the stability analysis and the advisor build from a scene (the
    # one-step maps are checked against the real masters by test_stability.py).
    "stability": (["harness/judges/stability.py"], ["harness.judges.stability.x_model_of*",
                                                    "harness.judges.stability.xǁTwoInertiaǁ*"],
                  ["tests/judges/test_stability.py", "tests/oracle/test_oracle_closed_forms.py",
                   "tests/oracle/test_oracle_stability_models.py"]),
    # The shaft FMUs' adapter (saved states among it): reached only by tests that run the
    # slave classes in the test process (the built FMUs carry their own copy of the code).
    "fmus": (["lever/fmus/shafts.py"], [], ["tests/oracle/test_oracle_states.py"]),
    # The Model Exchange master's event path: the event mode, the discrete states settled,
    # CVODE restarted from the states the FMUs report, the stepping loop around them.
    "me-master": (["harness/engine/masters/model_exchange.py"],
                  [f"harness.engine.masters.model_exchange.xǁModelExchangeCvodeMasterǁ{f}__mutmut_*"
                   for f in ("_event", "_event_rounds", "_restart", "_read_states", "_step_impl")],
                  ["tests/engine/test_me_events.py", "tests/engine/test_model_exchange_master.py"]),
    # The shafts' Model Exchange editions (modes, event indicators and updates, partials),
    # run in the test process (the freewheel's is left out, as in the physics group).
    "me-physics": (["lever/physics/me_engine.py", "lever/physics/me_load.py"], [],
                   ["tests/physics/test_me_physics.py"]),
    # The figures a benchmark case and a run report are judged by.
    "metrics": (["harness/judges/metrics.py", "harness/studies/bench/timing.py"],
                ["harness.judges.metrics.x_*", "harness.studies.bench.timing.x__judge__mutmut_*"],
                ["tests/judges/test_metrics_by_hand.py", "tests/studies/test_bench.py"]),
    # The verdict's checks, their allowances and its stated power (the orders by magnitude
    # and phase among them).  Of test_verdict.py all but the runs of changed couplings
    # (12 s of simulation a surviving mutant would pay; the closed forms judge what they do),
    # so that the group's 498 mutants run in about 35 minutes on one shared core.
    "verdict": (["harness/judges/verdict.py"],
                [f"harness.judges.verdict.x_{f}__mutmut_*" for f in
                 ("_checks", "_frame", "power", "_allowed_scale")],
                ["tests/judges/test_verdict_closed_forms.py"]
                + [f"tests/judges/test_verdict.py::test_{t}" for t in (
                    "a_change_just_beyond_the_stated_power_fails_and_just_within_passes",
                    "a_four_percent_larger_ripple_fails_naming_the_amplitude_and_two_percent_less_passes",
                    "the_start_up_spike_does_not_set_the_steady_windows_tube",
                    "a_result_with_some_signals_is_judged_on_those_and_lists_the_rest",
                    "tolerances_by_signal_kind_and_source_in_that_order",
                    "the_api_refuses_a_result_with_nothing_to_judge_and_an_unknown_tolerance_target",
                    "a_window_shorter_than_two_revolutions_judges_no_orders_and_says_so",
                    "the_blind_spots_name_the_sampling_and_the_start_up",
                    "verdict_json_is_standard_and_carries_the_power",
                    "a_stalled_signals_solver_noise_is_not_held_to_a_relative_tolerance",
                    "tolerances_of_the_verdict_are_refused_with_the_cross_check_band",
                    "a_scenes_validation_table_sets_its_tolerances_and_a_bad_one_is_refused")]),
    # The reference made from the FMUs: its own error estimate (the check beside it), read
    # at a run's times, and said in words.
    "fmu-reference": (["harness/judges/fmu_reference.py"],
                      [f"harness.judges.fmu_reference.x_{f}__mutmut_*" for f in
                       ("_model_exchange", "_extrapolated", "own_error", "quality")],
                      ["tests/judges/test_fmu_reference_own_error.py",
                       "tests/judges/test_fmu_reference.py::test_errors_against_the_made_references_agree_with_the_"
                       "monolithic_ones",
                       "tests/judges/test_fmu_reference.py::test_a_run_off_the_reference_grid_is_read_by_spline_with_"
                       "its_error_added"]),
    # The CVODE host's stepping loop: its output grid and event handling.
    "cvode-host": (["harness/studies/cvode_host.py"],
                   ["harness.studies.cvode_host.x__integrate__mutmut_*"],
                   ["tests/studies/test_cvode_host_grid.py",
                    "tests/fmus/test_me_cvode_roots.py::test_a_load_with_stiction_and_an_engine_on_its_table_run_through"
                    "_cvode_root_finding"]),
    # The plan's start state and the run's record of where each value came from.
    "plan": (["harness/description/plan.py"],
             [f"harness.description.plan.x_{f}__mutmut_*" for f in
              ("_driveline", "parameter_record", "overridden")],
             ["tests/description/test_plan_start_and_record.py", "tests/description/test_plan.py",
              "tests/formats/test_run_identity.py"]),
    # The SSP export's configured FMUs: the values and the GUID a copy carries.
    "ssp-configured": (["harness/formats/configured_fmu.py"],
                       [f"harness.formats.configured_fmu.x_{f}__mutmut_*" for f in
                        ("configure", "configured_guid", "_set_starts")],
                       ["tests/formats/test_ssp_export_twice.py", "tests/formats/test_ssp_export.py"]),
    # The API's readers of numbers, counts and times.
    "api-inputs": (["harness/api/inputs.py"],
                   [f"harness.api.inputs.x_{f}__mutmut_*" for f in
                    ("number", "count", "seconds", "step")],
                   # of test_api those that hand it times and numbers (its warnings' test counts the
                   # frames inside the harness, and mutmut's trampoline adds one)
                   ["tests/cli/test_api_time_inputs.py", "tests/cli/test_api.py::test_times_take_units_as_overrides_do",
                    "tests/cli/test_api.py::test_numpy_scalars_are_numbers"]),
    # The monolithic reference's choice of a stiff method.
    "stiff-switch": (["harness/judges/monolithic.py"],
                     [f"harness.judges.monolithic.x_{f}__mutmut_*" for f in ("stiff_method", "reference_method")],
                     ["tests/judges/test_stiff_switch.py", "tests/judges/test_cvode.py"]),
}


def stage(target: Path, tests_from: Path, mutate: list[str], tests: list[str]) -> None:
    """The staged tree: packages at the top, the build inputs where harness.paths finds
    them (ROOT = the staged tree), the FMUs copied from build/fmus."""
    if target.exists():
        shutil.rmtree(target)
    target.mkdir(parents=True)
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    shutil.copytree(REPO / "fmu_src" / "lever", target / "lever", ignore=ignore)
    shutil.copytree(REPO / "fmu_src", target / "fmu_src", ignore=ignore)     # what the FMU build hashes
    shutil.copytree(REPO / "harness", target / "harness", ignore=ignore)
    shutil.copytree(tests_from / "tests", target / "tests", ignore=shutil.ignore_patterns("__pycache__", "mutation"))
    # this checkout's conftest: it knows to stay inside mutmut's process (older ones do not)
    shutil.copy2(REPO / "tests" / "conftest.py", target / "tests" / "conftest.py")
    (target / "build").mkdir()
    for script in ("fmus.py", "fmi3.py"):      # both go into the FMUs' source hash
        shutil.copy2(REPO / "build" / script, target / "build" / script)
    shutil.copytree(REPO / "build" / "shim", target / "build" / "shim", ignore=ignore)
    shutil.copytree(REPO / "build" / "fmus", target / "build" / "fmus")
    shutil.copytree(REPO / "build" / "fmus3", target / "build" / "fmus3")    # the FMI 3.0 editions
    shutil.copytree(REPO / "resources", target / "resources")
    shutil.copytree(REPO / "docs", target / "docs")      # tests that hold the docs' tables to the code
    shutil.copytree(REPO / "examples", target / "examples", ignore=ignore)     # tests that run the examples
    shutil.copy2(REPO / "constraints.txt", target / "constraints.txt")
    selected = [found for t in tests for found in _located(target, t)]
    if not selected:    # an empty selection would make mutmut run the whole suite per mutant
        raise SystemExit(f"none of the group's tests {tests} exists in {tests_from / 'tests'}")
    also_copy = ["fmu_src", "build", "resources", "docs", "examples", "constraints.txt", "tests", "lever", "harness"]
    (target / "pyproject.toml").write_text(
        "[tool.mutmut]\n"
        f"source_paths = {json.dumps(['lever', 'harness'])}\n"
        f"only_mutate = {json.dumps(mutate)}\n"
        f"also_copy = {json.dumps(also_copy)}\n"
        f"pytest_add_cli_args_test_selection = {json.dumps(selected)}\n"
        'pytest_add_cli_args = ["-p", "no:cacheprovider", "-x", "-q"]\n'
        "\n[tool.pytest.ini_options]\n"
        'testpaths = ["tests"]\n')


def _located(target: Path, test: str) -> list[str]:
    """``test`` (tests/<folder>/test_x.py, or one test of it: ``...py::test_name``) in the staged
    tests: at its path, or by its file name when the tests come from a checkout whose files sit
    elsewhere (``--tests-from`` an older one)."""
    test, sep, node = test.partition("::")
    if (target / test).exists():
        return [test + sep + node]
    return [str(path.relative_to(target)) + sep + node
            for path in sorted((target / "tests").rglob(Path(test).name))]


def score(target: Path, names: list[str]) -> str:
    """mutmut's results as a table per file: killed, survived, no tests, not (yet) checked,
    timeout, score = killed / (killed + survived), of the mutants matching ``names``' globs
    (all when empty)."""
    out = subprocess.run([sys.executable, "-m", "mutmut", "results", "--all", "true"], cwd=target,
                         capture_output=True, text=True)
    counts: dict[str, Counter] = {}
    survivors = []
    for line in out.stdout.splitlines():
        name, _, status = line.strip().rpartition(": ")
        if not name or (names and not any(fnmatch.fnmatch(name, n) for n in names)):
            continue
        module = name.split(".x")[0].split(".xǁ")[0]
        counts.setdefault(module, Counter())[status] += 1
        if status == "survived":
            survivors.append(name)
    rows = ["| module | mutants | killed | survived | no tests | not checked | timeout/other | score |",
            "|---|---|---|---|---|---|---|---|"]
    total = Counter()
    for module, c in sorted(counts.items()):
        total.update(c)
        rows.append(_row(module, c))
    rows.append(_row("**all**", total))
    text = "\n".join(rows) + "\n\nSurvivors:\n" + "\n".join(f"- {s}" for s in survivors) + "\n"
    return text


def _row(module: str, c: Counter) -> str:
    n = sum(c.values())
    other = n - c["killed"] - c["survived"] - c["no tests"] - c["not checked"]
    tested = c["killed"] + c["survived"]
    return (f"| {module} | {n} | {c['killed']} | {c['survived']} | {c['no tests']} | {c['not checked']} | {other} | "
            f"{100.0 * c['killed'] / tested if tested else float('nan'):.1f} % |")


def sampled(target: Path, mutate: list[str], names: list[str], n: int, seed: int) -> list[str]:
    """``n`` of the mutants of ``mutate``'s files that match ``names``' globs (all when empty),
    drawn by ``random.Random(seed).sample`` from their names in sorted order: the names mutmut
    gives them, made here by its own mutation of each file (in ``target``, whose
    pyproject.toml it reads)."""
    import random

    listing = ("import json, sys\n"
               "from mutmut.mutation.file_mutation import mutate_file_contents\n"
               "out = []\n"
               "for path in sys.argv[1:]:\n"
               "    module = path[:-3].replace('/', '.')\n"
               "    made = mutate_file_contents(path, open(path).read(), None, None)\n"
               "    out += [n if n.startswith(module) else module + '.' + n for n in made.mutant_names]\n"
               "print(json.dumps(out))\n")
    listed = subprocess.run([sys.executable, "-c", listing, *mutate], cwd=target, capture_output=True, text=True,
                            check=True)
    every = sorted(m for m in json.loads(listed.stdout) if not names or any(fnmatch.fnmatch(m, g) for g in names))
    drawn = sorted(random.Random(seed).sample(every, min(n, len(every))))
    print(f"{len(drawn)} of {len(every)} mutants, drawn with seed {seed}")
    return drawn


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--label", default="current")
    parser.add_argument("--tests-from", type=Path, default=REPO)
    parser.add_argument("--group", choices=list(GROUPS), nargs="+", default=list(GROUPS))
    parser.add_argument("--max-children", type=int, default=2)
    parser.add_argument("--keep", action="store_true", help="reuse a staged tree and mutmut's cached results")
    parser.add_argument("--mutants", nargs="+", default=None, metavar="GLOB",
                        help="only the mutants whose names match these globs (a bounded subset of a group, "
                             "e.g. 'lever.physics.engine.*'; the same subset before and after)")
    parser.add_argument("--sample", type=int, default=None, metavar="N",
                        help="a random N of the group's mutants (of those --mutants selects), drawn with --seed: "
                             "the same N before and after")
    parser.add_argument("--seed", type=int, default=0, help="the seed of --sample's draw")
    args = parser.parse_args()
    subprocess.run([sys.executable, "-c", "from harness.cli import ensure_fmus; ensure_fmus(quiet=True)"],
                   cwd=REPO, check=True)
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)
    status = 0
    for group in args.group:
        mutate, names, tests = GROUPS[group]
        names = args.mutants or names
        target = REPO / "results" / "mutation" / args.label / group
        if not (args.keep and target.exists()):
            stage(target, args.tests_from.resolve(), mutate, tests)
        if args.sample:
            names = sampled(target, mutate, names, args.sample, args.seed)
        run = subprocess.run([sys.executable, "-m", "mutmut", "run", "--max-children", str(args.max_children), *names],
                             cwd=target, env=env)
        table = score(target, names)
        (target / "score.md").write_text(table)
        print(f"## {group} ({args.label})\n\n{table}")
        status = status or run.returncode
    return status


if __name__ == "__main__":
    sys.exit(main())
