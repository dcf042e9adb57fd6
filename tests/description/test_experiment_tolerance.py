"""A scene's ``experiment.tolerance``: the relative tolerance of the scene's own master.

What it promises: the scene's master runs at it exactly as if ``--tolerance`` had given it
(the same traces, bit for bit: the same code path); another master keeps its own default and
is told so; ``--tolerance`` overrides it and a disagreeing ``--set experiment.tolerance`` is
refused; a tolerance out of (0, 1), of another type or for a master that takes none is
refused naming ``experiment.tolerance``; an SSP archive carries it."""
import numpy as np
import pytest

from harness import api
from harness.api import InputError
from harness.description import scene as scenes
from harness.engine import masters, run
from harness.formats import ssp

SHORT = ["experiment.stop=0.005", "experiment.transient=0"]


def _scene(*changes):
    return scenes.load("kavz685_stiff_1e6").with_overrides(SHORT + list(changes))


def test_the_scenes_master_runs_at_the_stated_tolerance_as_if_it_were_given(fmu_dir):
    spec = _scene()
    assert (spec.experiment.master, spec.experiment.tolerance) == ("adaptive-trapezoidal", 1e-4)
    stated = run.simulate(spec)
    given = run.simulate(_scene("experiment.tolerance=0.5"), options={"tolerance": 1e-4})
    default = run.simulate(_scene("experiment.tolerance=1e-3"))
    assert stated.options["tolerance"] == 1e-4 and default.options["tolerance"] == 1e-3
    assert np.array_equal(stated.times, given.times)
    assert all(np.array_equal(stated.traces[k], given.traces[k]) for k in stated.traces)
    # a tenth of the tolerance takes more steps: the option reaches the master
    assert len(stated.times) > len(default.times)


def test_another_master_keeps_its_own_default_and_is_told(fmu_dir):
    notes = []
    done = api.run(_scene(), master="me-cvode", reference=False, plots=False,
                   notify=lambda kind, text: notes.append(text))
    assert done.result.options["tolerance"] == masters.MASTERS["me-cvode"].options["tolerance"]
    assert any("experiment.tolerance = 0.0001 is the scene's master's (adaptive-trapezoidal); me-cvode runs at its "
               "own default 1e-06" in note for note in notes), notes
    # the scene's master chosen by --set: the scene's tolerance was its master's, and goes with it
    assert _scene("experiment.master=jacobi").experiment.tolerance is None
    assert _scene("experiment.master=me-cvode", "experiment.tolerance=1e-5").experiment.tolerance == 1e-5


def test_the_argument_overrides_it_and_a_disagreeing_set_is_refused(fmu_dir):
    done = api.run(_scene(), tolerance=1e-3, reference=False, plots=False)
    assert done.result.options["tolerance"] == 1e-3
    with pytest.raises(InputError, match=r"tolerance=0\.001 and overrides\['experiment.tolerance'\]=1e-4 disagree"):
        api.run("kavz685_stiff_1e6", SHORT + ["experiment.tolerance=1e-4"], tolerance=1e-3, reference=False)
    same = api.run("kavz685_stiff_1e6", SHORT + ["experiment.tolerance=1e-4"], tolerance=1e-4, reference=False,
                   plots=False)
    assert same.result.options["tolerance"] == 1e-4


@pytest.mark.parametrize("value, words", [("2", "experiment.tolerance = 2.0 must be in (0, 1)"),
                                          ("0", "experiment.tolerance = 0.0 must be in (0, 1)"),
                                          ("-1e-3", "experiment.tolerance = -0.001 must be in (0, 1)"),
                                          ("inf", "experiment.tolerance = inf must be in (0, 1)"),
                                          ("true", "expected a relative tolerance in (0, 1)")])
def test_a_tolerance_out_of_range_or_not_a_number_is_refused_naming_it(value, words):
    with pytest.raises((InputError, scenes.SceneError)) as refused:
        api.run("kavz685_stiff_1e6", SHORT + [f"experiment.tolerance={value}"], reference=False)
    assert words in str(refused.value) and "experiment.tolerance" in str(refused.value)


def test_a_scene_stating_a_tolerance_for_a_master_that_takes_none_is_refused(tmp_path, fmu_dir):
    path = tmp_path / "fixed.toml"
    path.write_text('extends = "kavz685"\nname = "fixed"\n[experiment]\nstop = 0.01\nmaster = "jacobi"\n'
                    'transient = 0\ntolerance = 1e-4\n')
    with pytest.raises(InputError) as refused:
        api.run(str(path), reference=False)
    text = str(refused.value)
    assert "experiment.tolerance = 0.0001: master 'jacobi' takes no tolerance" in text
    assert ", ".join(masters.takes_tolerance()) in text and "jacobi," not in text
    assert str(path) in text
    # the same scene with another master named is run: the tolerance is not that master's
    assert api.run(str(path), master="gauss-seidel", reference=False, plots=False, notify=lambda *_: None).failure is None


def test_an_ssp_archive_carries_the_tolerance(tmp_path, fmu_dir):
    archive = ssp.export(_scene(), tmp_path / "stiff.ssp", fmu_dir)
    read = ssp.read_scene(archive)
    assert (read.experiment.master, read.experiment.tolerance) == ("adaptive-trapezoidal", 1e-4)
    plain = ssp.read_scene(ssp.export(scenes.load("kavz685").with_overrides(SHORT), tmp_path / "k.ssp", fmu_dir))
    assert plain.experiment.tolerance is None
