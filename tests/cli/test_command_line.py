"""The command line shows its choices: the masters in --help, the user's commands
apart from the developers', descriptions that end where their sentence ends, SCENE as the
positional argument of every scene command, where the FMUs are, the files a run wrote, a
unit to write instead of a wrong one, the scenes aligned, a study's time said before it."""
from __future__ import annotations

import re

import pytest

from harness import api
from harness.cli import DEVELOPER_COMMANDS, main


def test_help_lists_the_users_commands_apart_from_the_developers(lever):
    said = lever("--help").output
    users, developers = said.split("Developer commands")
    listed = re.findall(r"^  ([a-z-]+)\s+(.*)$", users, re.M)
    assert {name for name, _ in listed} == set(main.commands) - set(DEVELOPER_COMMANDS)
    assert all(re.search(rf"^  {name}\s", developers, re.M) for name in DEVELOPER_COMMANDS)
    for name, command in main.commands.items():          # whole sentences, not cut at "Figs."
        short = command.get_short_help_str(200)
        assert short.endswith(".") and not short.endswith("...") and len(short) <= 60, (name, short)


def test_master_options_list_the_masters(lever):
    for command in (["run"], ["validate"], ["bench"], ["fingerprint"]):
        said = " ".join(lever(*command, "--help").output.split())
        assert all(m in said for m in api.masters()), command
    assert "me-cvode" not in " ".join(lever("stability", "--help").output.split())   # fixed-step ones only
    refused = lever("run", "--master", "jacobi-quadratc", "--no-reference")
    assert refused.exit_code == 2 and "'jacobi-quadratc' is not one of" in refused.output


def test_sweep_takes_scene_as_every_scene_command_does(lever, tmp_path):
    for name in ("run", "bench", "stability", "engines", "hosts", "export-ssp", "export-container", "sweep"):
        assert lever(name, "--help").output.startswith(f"Usage: main {name} [OPTIONS] [SCENE]\n"), name
    refused = lever("sweep", "nope", "--axis", "load", "--out", tmp_path / "s")
    assert refused.exit_code == 2 and "no scene 'nope'" in refused.output
    old = lever("sweep", "--scene", "nope", "--axis", "load", "--out", tmp_path / "s")   # the deprecated alias
    assert old.exit_code == 2 and "--scene is deprecated" in old.output and "no scene 'nope'" in old.output
    both = lever("sweep", "kavz685", "--scene", "nope", "--out", tmp_path / "s")
    assert both.exit_code == 2 and "name the scene once" in both.output


def test_build_says_where_the_fmus_are_when_they_are_current(lever, fmu_dir):
    said = lever("build").output
    assert said.strip() == f"FMUs (up to date, nothing to build): {fmu_dir} (FMI 2.0), {fmu_dir.parent / 'fmus3'} " \
                           "(FMI 3.0)"


def test_a_run_without_plots_lists_no_plots(lever, fmu_dir, tmp_path):
    said = lever("run", "--stop", "0.05", "--no-plots", "--no-reference", "--no-progress", "--out", tmp_path).output
    assert said.rstrip().endswith(f"results: {tmp_path}/ (traces.csv, summary.json, report.md)"), said
    assert "coupling.tau2  mean" in said          # named as in traces.csv


def test_a_unit_of_another_dimension_says_what_to_write(lever, fmu_dir, tmp_path):
    said = lever("run", "--set", "coupling.stiffness=900Nm", "--out", tmp_path)
    assert said.exit_code == 2 and "write it in N.m/rad, e.g. '900 N*m/rad'" in said.output
    assert api.run("kavz685", {"coupling.stiffness": "900 N*m/rad"}, stop=0.01, reference=False,
                   notify=lambda *_: None).ok             # ... and what it suggests is taken


def test_scenes_are_listed_in_two_aligned_columns(lever):
    lines = lever("scenes").output.splitlines()
    starts = {len(re.match(r"^\S+\s+", line).group()) for line in lines}
    assert len(lines) == len(api.scenes()) and len(starts) == 1


def test_a_study_says_how_long_it_will_take_before_it_runs(lever, fmu_dir, tmp_path):
    from harness.studies.cases import duration_text

    said = lever("stability", "--master", "jacobi", "--stiffness", "1e4", "--damping", "0", "--h-omega", "0.5",
                 "--no-refine", "--min-steps", "16", "--jobs", "1", "--out", tmp_path).output
    first = said.splitlines()[0]
    assert re.fullmatch(r"1 cases \(0 already done\), 1 process\(es\); about \d+ s \(estimated\)", first), first
    assert duration_text(30, "narrow it") == "about 30 s (estimated)"
    assert duration_text(600, "narrow it") == ("about 10 min (estimated from runs timed just now; Ctrl-C stops it "
                                               "and the same command resumes; narrow it)")


def test_a_sweep_says_how_long_it_will_take_before_it_runs(lever, fmu_dir, tmp_path):
    said = lever("sweep", "kavz685", "--axis", "inertia", "--thin", "100", "--stop", "2.2", "--progress",
                 "--workers", "1", "--out", tmp_path)
    assert said.exit_code in (0, 1), said.output
    assert re.search(r"^sweep: 2 cases to run; about \d+ s \(estimated\)$", said.stderr, re.M), said.stderr


def test_step_and_stop_take_units_as_the_api_does(lever, fmu_dir, tmp_path):
    runs = {}
    for name, step, stop in (("units", "2 ms", "20ms"), ("seconds", "0.002", "0.02")):
        said = lever("run", "--step", step, "--stop", stop, "--no-plots", "--no-reference", "--no-progress",
                     "--out", tmp_path / name)
        assert said.exit_code == 0, said.output
        runs[name] = (tmp_path / name / "traces.csv").read_bytes()
    assert runs["units"] == runs["seconds"] and len(runs["units"].splitlines()) == 12   # header and 11 rows


@pytest.mark.parametrize("command, option, value", [
    (["run", "--no-reference"], "--step", "2 kg"), (["run", "--no-reference"], "--stop", "half a second"),
    (["validate", "kavz685"], "--step", "1 m"), (["sweep", "--axis", "load"], "--stop", "5 N")])
def test_a_time_option_of_a_wrong_unit_is_refused_naming_the_option(lever, tmp_path, command, option, value):
    said = lever(*command, option, value, "--out", tmp_path)
    assert said.exit_code == 2 and f"Invalid value for '{option}': {option}='{value}'" in said.output, said.output
    assert not any(tmp_path.iterdir())                   # refused before anything ran
