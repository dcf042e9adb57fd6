"""Run every host recipe of this folder whose host is named, judge each result CSV with
`lever validate --result CSV kavz685` at the default verdict, and print the table
host x recipe -> verdict (`make hosts`; docs/hosts.md).

    OMSIMULATOR=...  PYFMI_PYTHON=...  OMSIMULATOR_PYTHONPATH=...  python examples/hosts/run_recipes.py

The hosts are named by environment variables:

* PYFMI_PYTHON: a Python with PyFMI (the pyfmi_*.py recipes);
* OMSIMULATOR: OMSimulator's command-line program (the omsimulator_*.sh recipes);
* OMSIMULATOR_PYTHONPATH: the folder holding OMSimulator's Python package, with
  OMSIMULATOR_PYTHON the Python to run it (default: PYFMI_PYTHON, else this Python).

A recipe whose host is not named is listed as not run, with the variable it needs.  `lever` is
the one next to this Python unless LEVER names another.  Exit status 0 when every recipe that
ran passed, 1 otherwise.
"""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

HERE = Path(__file__).resolve().parent
#: the scene every recipe runs and is judged against
SCENE = "kavz685"
#: what a recipe may take (the slowest, PyFMI's Master at 0.1 ms, takes minutes on a busy
#: two-core machine)
TIMEOUT = 1800


@dataclass(frozen=True)
class Recipe:
    host: str
    file: str
    #: the environment variable naming the host
    needs: str


RECIPES = (
    Recipe("PyFMI", "pyfmi_master.py", "PYFMI_PYTHON"),
    Recipe("PyFMI", "pyfmi_coupled_me.py", "PYFMI_PYTHON"),
    Recipe("OMSimulator", "omsimulator_weak.sh", "OMSIMULATOR"),
    Recipe("OMSimulator", "omsimulator_strong.sh", "OMSIMULATOR"),
    Recipe("OMSimulator", "omsimulator_fmi3.sh", "OMSIMULATOR"),
    Recipe("OMSimulatorPython", "omsimulator_python.py", "OMSIMULATOR_PYTHONPATH"),
)


@dataclass
class Outcome:
    recipe: Recipe
    #: PASS, FAIL (the verdict's), ERROR (the recipe failed) or NOT RUN
    verdict: str
    #: why: the variable missing, the recipe's error, the failing signals
    detail: str = ""
    seconds: float = 0.0


def lever() -> str:
    return os.environ.get("LEVER") or str(Path(sys.executable).with_name("lever"))


def command(recipe: Recipe, result: Path, env: dict) -> list[str] | None:
    """How the recipe is run, as its first lines say; None when its host is not named."""
    if not env.get(recipe.needs):
        return None
    if recipe.file.endswith(".sh"):
        return ["sh", str(HERE / recipe.file), str(result)]
    if recipe.needs == "OMSIMULATOR_PYTHONPATH":
        python = env.get("OMSIMULATOR_PYTHON") or env.get("PYFMI_PYTHON") or sys.executable
        env["PYTHONPATH"] = env["OMSIMULATOR_PYTHONPATH"]
    else:
        python = env[recipe.needs]
    return [python, str(HERE / recipe.file), str(result)]


def run(recipe: Recipe, folder: Path) -> Outcome:
    env = dict(os.environ, LEVER=lever())
    result = folder / f"{Path(recipe.file).stem}.csv"
    argv = command(recipe, result, env)
    if argv is None:
        return Outcome(recipe, "NOT RUN", f"{recipe.needs} not set")
    start = time.monotonic()
    try:
        done = subprocess.run(argv, env=env, cwd=folder, capture_output=True, text=True, timeout=TIMEOUT)
    except subprocess.TimeoutExpired:
        return Outcome(recipe, "ERROR", f"no result within {TIMEOUT} s", time.monotonic() - start)
    seconds = time.monotonic() - start
    if done.returncode != 0 or not result.exists():
        said = (done.stderr.strip() or done.stdout.strip()).splitlines()
        return Outcome(recipe, "ERROR", f"exit {done.returncode}: {said[-1] if said else 'no output'}", seconds)
    judged = subprocess.run([lever(), "validate", "--result", str(result), SCENE], cwd=folder,
                            capture_output=True, text=True)
    if judged.returncode == 0:
        return Outcome(recipe, "PASS", "", seconds)
    # the verdict's last line names each failing signal and what failed
    summary = [line.strip() for line in judged.stdout.splitlines() if line.strip().startswith(f"{SCENE}: FAIL")]
    verdict = "FAIL" if judged.returncode == 1 else "ERROR"
    return Outcome(recipe, verdict, summary[-1][len(f"{SCENE}: FAIL "):].split(" over ")[0] if summary
                   else (judged.stderr.strip() or judged.stdout.strip())[-300:], seconds)


def table(outcomes: list[Outcome]) -> str:
    rows = ["| host | recipe | verdict (`lever validate --result CSV kavz685`, default) | run time |",
            "|---|---|---|---|"]
    for o in outcomes:
        verdict = o.verdict + (f": {o.detail}" if o.detail else "")
        rows.append(f"| {o.recipe.host} | `examples/hosts/{o.recipe.file}` | {verdict} | "
                    f"{f'{o.seconds:.0f} s' if o.seconds else ''} |")
    return "\n".join(rows)


def main() -> int:
    with tempfile.TemporaryDirectory() as tmp:
        outcomes = []
        for recipe in RECIPES:
            outcomes.append(run(recipe, Path(tmp)))
            print(f"{recipe.file}: {outcomes[-1].verdict}", file=sys.stderr, flush=True)
    print(table(outcomes))
    return 0 if all(o.verdict in ("PASS", "NOT RUN") for o in outcomes) else 1


if __name__ == "__main__":
    sys.exit(main())
