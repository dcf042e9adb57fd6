"""The example notebook (examples/api_notebook.ipynb) runs from top to bottom in a fresh
Jupyter kernel, as a user's notebook server would run it, and shows what its text says:
a run, a plot, a changed parameter, a validation passed and one failed, masters compared,
the FMU in fmpy."""
from __future__ import annotations

from pathlib import Path

NOTEBOOK = Path(__file__).resolve().parents[2] / "examples" / "api_notebook.ipynb"


def texts(cells) -> list[str]:
    """Every output of ``cells`` as text: streams, results, displays."""
    return [o.get("text") or o.get("data", {}).get("text/plain", "") for c in cells for o in c.get("outputs", [])]


def test_the_notebook_is_committed_without_outputs():
    import nbformat

    nb = nbformat.read(NOTEBOOK, as_version=4)
    nbformat.validate(nb)
    assert [c.outputs for c in nb.cells if c.cell_type == "code" and c.outputs] == []


def test_the_example_notebook_runs_and_shows_what_it_says(fmu_dir, tmp_path):
    import nbformat
    from nbclient import NotebookClient

    nb = nbformat.read(NOTEBOOK, as_version=4)
    # the kernel starts in tmp_path: a file the notebook wrote would land there, not in examples/;
    # generous limits: a loaded shared machine starts a kernel slowly; nothing here waits on them when idle
    NotebookClient(nb, timeout=300, startup_timeout=180, kernel_name="python3",
                   resources={"metadata": {"path": str(tmp_path)}}).execute()
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert not [o for c in code for o in c.outputs if o.output_type == "error"]
    shown = texts(code)
    said = "\n---\n".join(shown)            # what the notebook showed, when an assertion fails
    assert any(s.startswith("Run(kavz685: ok, master jacobi-quadratic") for s in shown), said
    assert any(o.get("data", {}).get("image/png") for c in code for o in c.outputs), said      # the plot
    assert any(s.startswith("Validation(kavz685: PASS, judged t = 0 ... 1 s") for s in shown), said
    assert any(s.startswith("Validation(kavz685: FAIL, judged t = 0 ... 1 s") for s in shown), said
    # (a kernel may send two quick prints as one stream output: compared line by line)
    lines = "".join(o.get("text", "") for c in code for o in c.outputs if o.output_type == "stream").splitlines()
    compared = [line for line in lines if " coupling.tau2 error " in line and "% RMS, wall time" in line]
    assert [s.split()[0] for s in compared] == ["jacobi", "jacobi-linear", "jacobi-quadratic"], said
    assert "'engine_torque'" in shown[-1], said        # fmpy's own structured array of the FMU
