"""A run whose energy residual says its traces cannot be trusted says so - in the summary
printed, summary.json, report.md - and ends with exit code 3; a run within
the bound ends with 0 and says nothing of the kind."""
from __future__ import annotations

import json
import math

from harness.judges import metrics


def test_the_trust_bound_is_the_residual_share():
    assert metrics.untrusted(None) is None
    assert metrics.untrusted({"residual_relative": metrics.TRUSTED_RESIDUAL}) is None
    said = metrics.untrusted({"residual_relative": 0.25})
    assert said.startswith("the energy residual is 25 % of the work in (trusted up to 5 %)")
    assert "not finite" in metrics.untrusted({"residual_relative": math.nan})


def test_an_untrusted_run_says_so_and_exits_3(lever, fmu_dir, tmp_path):
    done = lever("run", "kavz685", "--stop", "0.2", "--master", "me-cvode", "--tolerance", "0.999",
                 "--no-reference", "--no-plots", "--out", tmp_path / "loose")
    assert done.exit_code == 3, done.output
    assert "NOT TO BE TRUSTED: the energy residual is 25 % of the work in" in done.output
    summary = json.loads((tmp_path / "loose" / "summary.json").read_text())
    assert summary["untrusted"].startswith("the energy residual is 25 %")
    assert "**Not to be trusted:** the energy residual is 25 %" in (tmp_path / "loose" / "report.md").read_text()
    done = lever("run", "kavz685", "--stop", "0.2", "--master", "me-cvode", "--no-reference", "--no-plots",
                 "--out", tmp_path / "tight")
    assert done.exit_code == 0 and "TRUSTED" not in done.output, done.output
    assert "untrusted" not in json.loads((tmp_path / "tight" / "summary.json").read_text())
