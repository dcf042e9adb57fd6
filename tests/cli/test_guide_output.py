"""The output getting started shows is the output `lever run kavz685` prints: its lines, its
signal names and its figures (each to the digits printed), so that the page cannot drift
from the program.  Only the wall time is the machine's, and the results folder the run's."""
from __future__ import annotations

import re
from pathlib import Path

GETTING_STARTED = Path(__file__).resolve().parents[2] / "docs" / "guide" / "getting-started.md"
NUMBER = re.compile(r"[-+]?\d+(?:\.\d+)?(?:e[-+]?\d+)?")


def shown_output(page: str) -> list[str]:
    """The lines of the first fenced block that follows "It prints" on the page."""
    after = page[page.index("It prints"):]
    block = re.search(r"```\n(.*?)```", after, re.S)
    return block.group(1).rstrip("\n").splitlines()


def differences(shown: list[str], printed: list[str]) -> list[str]:
    """Each line where the page and the program differ: in words, or in a figure by more than
    one unit of its last printed digit (the last bit of a sum may round a digit either way on
    another CPU).  The wall time is not compared."""
    found = [f"the page shows {len(shown)} lines, the program prints {len(printed)}"] if len(shown) != len(printed) else []
    for number, (a, b) in enumerate(zip(shown, printed), 1):
        a, b = re.sub(r"wall time \S+ s", "wall time T s", a), re.sub(r"wall time \S+ s", "wall time T s", b)
        if NUMBER.sub("#", a) != NUMBER.sub("#", b):
            found.append(f"line {number}: page {a!r}, program {b!r}")
            continue
        for x, y in zip(NUMBER.findall(a), NUMBER.findall(b)):
            digits = len(x.split("e")[0].partition(".")[2])
            unit = 10.0 ** (-digits) * (10.0 ** int(x.split("e")[1]) if "e" in x else 1.0)
            if abs(float(x) - float(y)) > 1.01 * unit:
                found.append(f"line {number}: page {x}, program {y}")
    return found


def test_a_changed_word_or_figure_is_named_and_the_wall_time_is_not():
    shown = ["kavz685: master m, step 0.001 s, wall time 1.10 s", "  engine.w  mean 36.6626", "  error 2e-06 %"]
    assert differences(shown, ["kavz685: master m, step 0.001 s, wall time 21.27 s", "  engine.w  mean 36.6627",
                               "  error 3e-06 %"]) == []
    assert differences(shown, [shown[0], "  w1  mean 36.6626", "  error 2e-06 %"]) == [
        "line 2: page '  engine.w  mean 36.6626', program '  w1  mean 36.6626'"]
    assert differences(shown, [shown[0], "  engine.w  mean 36.6629", "  error 2e-06 %"]) == [
        "line 2: page 36.6626, program 36.6629"]
    assert differences(shown[:2], shown) == ["the page shows 2 lines, the program prints 3"]


def test_getting_started_shows_what_the_run_prints(lever, tmp_path, fmu_dir):
    out = tmp_path / "kavz685"
    done = lever("run", "kavz685", "--out", out)
    assert done.exit_code == 0, done.output
    printed = done.stdout.replace(f"{out}/", "results/kavz685/").rstrip("\n").splitlines()
    assert differences(shown_output(GETTING_STARTED.read_text(encoding="utf-8")), printed) == []
