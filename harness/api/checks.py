"""The checks on the FMUs as values: ``compliance`` (fmpy's validation and ours) and
``bad_inputs`` (the bad-input corpus through fmpy)."""
from __future__ import annotations

from pathlib import Path
from typing import Iterable, Iterator

from harness.api.building import build
from harness.api.results import ReturnedTuple


def compliance(fmus: Iterable[Path | str] = ()) -> Iterator[tuple[Path, list[str]]]:
    """``lever compliance``: fmpy's validation and ours on each FMU file, or on the FMU
    files in a folder (none: the built ones, built first: the FMI 2.0 editions, then the
    FMI 3.0 ones); ``(file, findings)`` one file at a time (empty: none)."""
    from harness.compliance import check_fmu
    from harness.paths import fmi3_dir

    fmus = [Path(f) for f in fmus]
    if not fmus:
        built = build()
        fmus = sorted(built.glob("*.fmu")) + sorted(fmi3_dir(built).glob("*.fmu"))
    for path in fmus:
        if path.is_dir():
            inside = sorted(path.glob("*.fmu"))
            if not inside:
                yield path, [f"{path}: a folder without FMU files (*.fmu)"]
            for fmu in inside:
                yield fmu, check_fmu(fmu)
        else:
            yield path, check_fmu(path)


def bad_inputs() -> tuple[list, str]:
    """``lever badinputs``: the bad-input corpus through fmpy's FMU2Slave on the built FMUs;
    the outcomes (``passed``, ``case.name``, ``messages``) and their summary."""
    from harness.formats import badinputs

    build()
    outcomes = badinputs.run()
    return ReturnedTuple((outcomes, badinputs.summary(outcomes)))
