"""The plots show what the reports state, at a scale where it can be read: the judged
window zoomed to its own values beside the whole run, legends beside the data, a
stability map as wide as its masters and with the classes it holds."""
from __future__ import annotations

import numpy as np

from types import SimpleNamespace

from harness.formats import plotting, report
from harness.studies import stability_report
from harness.studies import sweep as sweeps
from harness.studies import sweep_report
from harness.studies.bench import Case
from harness.studies.bench import report as bench_report


def _start_up_and_ripple():
    """A start-up from 0 to 107.5 with an overshoot to 120, then a +-6 ripple: the shape of
    KAVZ-685's driven torque."""
    t = np.linspace(0.0, 10.0, 10001)
    y = 107.5 * (1 - np.exp(-t / 0.05)) + 12.5 * np.exp(-((t - 0.2) / 0.1) ** 2) + 6.0 * np.sin(37.0 * t)
    return t, y


def test_a_time_view_zooms_the_judged_window_to_its_values():
    plt = plotting.pyplot()
    t, y = _start_up_and_ripple()
    fig = plotting.time_view(t, [("-tau1 (drive)", y), ("tau2 (driven)", y + 0.5)], "torque", "N*m", 2.0, "x",
                             ("tau2 - (-tau1)", np.full_like(y, 0.5)))
    # the whole run of each series in its own panel, then each judged panel with its detail beside it
    whole_drive, whole_driven, drive, _, driven, _, difference = fig.axes[:7]
    for overview in (whole_drive, whole_driven):
        assert overview.get_ylim()[0] < 1.0 and overview.get_ylim()[1] > 119.0     # the whole run, start-up and all
    for ax, shift in ((drive, 0.0), (driven, 0.5)):
        low, high = ax.get_ylim()
        # the ripple fills the panel: its +-6 N*m is most of the axis, not a twentieth of 0-120
        assert 101.5 + shift - 1.2 < low < 101.5 + shift and 113.5 + shift < high < 113.5 + shift + 1.2
        assert ax.get_xlim()[0] == 2.0
        labels = ax.get_legend_handles_labels()[1]
        (mean,) = [float(label.split()[1]) for label in labels if label.startswith("mean ")]
        assert abs(mean - (107.5 + shift)) < 0.2 and any("A = 6" in label for label in labels)
    assert difference.get_ylim()[0] <= 0.0 <= difference.get_ylim()[1]
    plt.close(fig)


def test_legends_are_beside_the_data_not_on_it():
    plt = plotting.pyplot()
    fig, ax = plt.subplots(layout="constrained")
    ax.plot([0, 1], [0, 1], label="data")
    plotting.legend_outside(ax)
    fig.canvas.draw()
    legend = ax.get_legend().get_window_extent()
    assert legend.x0 >= ax.get_window_extent().x1
    plt.close(fig)


def test_a_stability_maps_legend_names_only_the_classes_it_holds():
    assert stability_report.legend_classes({"stable", "divergent"}) == ["stable", "divergent"]
    assert "failed" in stability_report.legend_classes({"stable", "failed"})


def _accelerations():
    """KAVZ-685's accelerations in shape: a +-600 rad/s^2 impulse at the start, then a
    +-22 wave at the shaft's 5.8 Hz with, on the driven side, a 120 Hz ripple that turns
    ~2,000 times in the judged window (a solid band drawn as a line)."""
    t = np.linspace(0.0, 10.0, 10001)
    impulse = 600.0 * np.exp(-t / 0.01) * np.cos(2 * np.pi * 20 * t)
    a1 = impulse + 22.0 * np.sin(2 * np.pi * 5.8 * t)
    a2 = -impulse + 22.0 * np.sin(2 * np.pi * 5.8 * t) + 15.0 * np.sin(2 * np.pi * 120.0 * t)
    return t, a1, a2


def test_an_impulse_at_the_start_is_left_off_the_overviews_scale_and_its_peaks_named():
    plt = plotting.pyplot()
    t, a1, a2 = _accelerations()
    fig = plotting.time_view(t, [("a1 (drive)", a1), ("a2 (driven)", a2)], "acceleration", "rad/s^2", 2.0, "x",
                             ("a2 - a1", a2 - a1))
    overviews = fig.axes[:2]
    low, high = overviews[0].get_ylim()
    # the running wave (+-37) is a readable part of the axis, not a twentieth of +-600
    assert -300 < low < -37 and 37 < high < 300
    (note,) = [text.get_text() for ax in overviews for text in ax.texts]
    assert "off the scale" in note and "600" in note
    plt.close(fig)


def test_a_start_from_rest_stays_on_the_overviews_scale():
    t, y = _start_up_and_ripple()
    assert plotting.impulse_limits(y, y[t >= 2.0]) is None          # 0 -> 120 on one side only


def test_a_dense_curve_is_drawn_as_its_envelope_and_its_wave_in_a_detail_beside_it():
    plt = plotting.pyplot()
    t, a1, a2 = _accelerations()
    fig = plotting.time_view(t, [("a1 (drive)", a1), ("a2 (driven)", a2)], "acceleration", "rad/s^2", 2.0, "x")
    _, _, drive, drive_detail, driven, driven_detail = fig.axes
    assert not drive.collections and any(len(line.get_xdata()) > 7000 for line in drive.lines)   # a line
    assert driven.collections                                                    # an envelope (filled band)
    assert all(len(line.get_xdata()) <= plotting.ENVELOPE_SLICES for line in driven.lines)
    # the detail: a few periods of the strongest wave (5.8 Hz), at the judged panel's scale
    shown = driven_detail.get_xlim()[1] - driven_detail.get_xlim()[0]
    assert 0.3 < shown < 0.8 and driven_detail.get_ylim() == driven.get_ylim()
    plt.close(fig)


def test_an_envelope_keeps_the_extremes_of_each_slice():
    t = np.linspace(0.0, 1.0, 1001)
    y = np.sin(2 * np.pi * 200 * t)
    tm, low, high = plotting.envelope(t, y, slices=10)
    assert len(tm) == 10 and np.allclose(high, y.reshape(-1)[:1000].reshape(10, 100).max(axis=1), atol=0.02)
    assert low.min() == y.min() and high.max() == y.max()


def _reference_and_run():
    t = np.linspace(0.0, 2.0, 2001)
    names = {"w1": "e.w", "w2": "l.w", "tau1": "c.tau1", "tau2": "c.tau2"}
    ref = {"e.w": 36 + np.sin(t), "l.w": 36 + np.cos(t), "c.tau1": -107 + np.sin(t), "c.tau2": 107 + np.sin(t)}
    run = {k: v + 1e-4 * np.sin(2 * np.pi * 300 * t) for k, v in ref.items()}
    return t, names, SimpleNamespace(times=t, traces=ref), run


def test_the_reference_plot_shows_the_torques_error_beside_the_speeds_in_two_colours():
    plt = plotting.pyplot()
    t, names, reference, run = _reference_and_run()
    fig = report.reference_figure(t, run, reference, names, "jacobi", "x")
    speeds, torques = fig.axes[3], fig.axes[4]
    assert "rad/s" in speeds.get_ylabel() and "N*m" in torques.get_ylabel()
    for ax, pair in ((speeds, ("w1", "w2")), (torques, ("tau1", "tau2"))):
        labels = ax.get_legend_handles_labels()[1]
        assert [any(f"error {names[k]}" in label for label in labels) for k in pair] == [True, True]   # as the traces
        colours = {tuple(line.get_color()) if not isinstance(line.get_color(), str) else line.get_color()
                   for line in ax.lines if line.get_label().startswith("error")}
        assert len(colours) == 2
    plt.close(fig)


def test_the_u12_plots_legend_leaves_the_curve_the_figures_width():
    plt = plotting.pyplot()
    angle = np.linspace(0.0, 720.0, 400)
    view = {"angle": angle, "t": np.linspace(9.6, 9.94, 400), "count": 2, "U12": 1 + 0.007 * np.sin(np.radians(2 * angle))}
    fig = report.angle_figure(view, "u12", [("U12 [1]", [("U12", "U12, the coupling's transfer function")])], "x")
    fig.canvas.draw()
    (ax,) = fig.axes
    assert ax.get_window_extent().width > 0.85 * fig.bbox.width
    assert ax.get_legend().get_window_extent().y0 >= ax.get_window_extent().y1 - 1
    plt.close(fig)


def test_log_ticks_are_plain_numbers_that_do_not_run_into_each_other():
    plt = plotting.pyplot()
    fig, ax = plt.subplots(figsize=(11, 6), layout="constrained")
    ax.loglog([0.13, 0.9], [1.0, 0.01])
    plotting.log_ticks(ax.xaxis)
    fig.canvas.draw()
    shown = [label for label in ax.get_xticklabels() if label.get_text()
             and ax.get_xlim()[0] <= label.get_position()[0] <= ax.get_xlim()[1]]
    assert {label.get_text() for label in shown} >= {"0.2", "0.5"}
    boxes = sorted((label.get_window_extent() for label in shown), key=lambda b: b.x0)
    assert all(a.x1 < b.x0 for a, b in zip(boxes, boxes[1:]))
    plt.close(fig)


def test_a_work_precision_line_joins_its_points_in_the_order_of_their_setting(tmp_path, monkeypatch):
    """Run times within the machine's noise of each other do not reorder the line: CVODE's
    points at tolerances 1e-3 ... 1e-6 go down in error however their times fall."""
    cases = [Case("monolithic-cvode", "monolithic", None, tol, wall_times=[wall], errors={"tau_rms": error})
             for tol, wall, error in ((1e-3, 0.045, 8e-3), (1e-4, 0.075, 2.7e-4), (1e-5, 0.070, 2e-5),
                                      (1e-6, 0.10, 2.6e-6))]
    drawn = {}
    plt = plotting.pyplot()
    monkeypatch.setattr(plt.Figure, "savefig", lambda fig, path, **options: drawn.setdefault("ax", fig.axes[0]))
    bench_report.plot(tmp_path / "wp.png", {"cases": cases, "claims": {"target_error": 1e-3}, "scene": "x"})
    (line,) = [line for line in drawn["ax"].lines if line.get_label() == "monolithic (CVODE)"]
    assert list(line.get_ydata()) == sorted(line.get_ydata(), reverse=True)


def _sweep_rows():
    return [{"axis": "misalignment", "x": x, "result": {"status": "ok", "A_w1": 0.4, "A_w2": 0.5, "A_a1": 20.0,
                                                       "A_a2": 30.0, "A_tau1": 6.6, "A_tau2": 6.5, "dA_w": 0.1,
                                                       "dA_a": da, "dA_tau": dt}}
            for x, da, dt in ((5.0, 12.9, -0.14), (15.0, 9.9, -0.72), (25.0, 4.8, -1.34), (35.0, -7.4, -2.1))]


REPORTED_318 = {"dA_w": [(10, 0.28), (35, 1.37)], "dA_a": [(10, 225.0), (35, 98.0)],
                "dA_tau": [(10, 11.0), (35, 56.0)]}


def test_the_sweep_says_how_far_and_which_way_the_model_is_from_the_monograph():
    compared = {c["key"]: c for c in sweep_report.against_monograph(_sweep_rows(), REPORTED_318)}
    tau = compared["dA_tau"]
    assert tau["model"] == [-0.43, -2.1] and tau["opposite_sign_at"] == [10, 35]
    assert 25 < tau["ratio"][0] <= tau["ratio"][1] < 27
    assert compared["dA_a"]["opposite_sign_at"] == [35]
    sentence = sweep_report.comparison_sentence(tau)
    assert "+11 -> +56" in sentence and "-0.43 -> -2.1" in sentence and sentence.endswith("of opposite sign")
    assert sweep_report.comparison_sentence(compared["dA_a"]).endswith("of opposite sign at 35")
    assert "opposite" not in sweep_report.comparison_sentence(compared["dA_w"])


def test_the_sweeps_plot_puts_the_monographs_points_on_the_models_axes_and_says_the_gap(tmp_path, monkeypatch):
    drawn = {}
    monkeypatch.setattr(plotting, "save_png", lambda fig, path, **options: drawn.setdefault("fig", fig))
    axis = sweeps.select(["misalignment"])[0]
    sweep_report._plot(tmp_path / "s.png", axis, _sweep_rows(), REPORTED_318)
    fig = drawn["fig"]
    assert len(fig.axes) == 6                                       # two rows: no row of the monograph's own
    torque_dA = fig.axes[5]
    labels = torque_dA.get_legend_handles_labels()[1] + fig.axes[3].get_legend_handles_labels()[1]
    assert torque_dA.get_yscale() == "symlog"                       # -2.1 and +56 both readable
    ys = [y for line in torque_dA.lines for y in np.atleast_1d(line.get_ydata())]
    assert 56.0 in ys and -2.1 in ys
    low, high = torque_dA.get_ylim()
    assert low < -2.1 and high > 56.0
    assert "26-27x the model's, of opposite sign" in torque_dA.get_title(loc="left")
    assert fig.axes[3].get_yscale() == "log" and labels
    fig.canvas.draw()
    for ax in (fig.axes[3], torque_dA):                             # plain numbers, not $10^{1}$
        shown = [label.get_text() for label in ax.get_yticklabels() if label.get_text()]
        assert shown and not any("$" in text for text in shown), shown
    plotting.pyplot().close(fig)


def test_a_run_of_three_samples_gets_a_detail_of_two_without_a_warning():
    import warnings

    plt = plotting.pyplot()
    t, y = np.array([0.0, 0.001, 0.002]), np.array([1.0, 2.0, 1.5])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        fig = plotting.time_view(t, [("a", y), ("b", y)], "x", "u", 0.0, "t", ("d", y - y))
    assert fig.axes[3].get_xlim() == (0.001, 0.002)      # the first judged panel's detail
    plt.close(fig)


def test_the_pair_colours_are_not_neighbours_in_the_colour_cycle():
    """Two errors on one axes are told apart: blue and red, not blue and orange or green."""
    from matplotlib.colors import to_rgb

    a, b = (np.array(to_rgb(c)) for c in plotting.PAIR_COLOURS)
    assert np.abs(a - b).sum() > 1.0


def test_the_reference_plot_says_which_way_its_error_is_taken():
    plt = plotting.pyplot()
    t, names, reference, run = _reference_and_run()
    fig = report.reference_figure(t, run, reference, names, "jacobi", "x")
    for ax in fig.axes[3:]:
        assert "co-simulation - reference" in ax.get_ylabel()
    plt.close(fig)


def test_the_whole_run_draws_each_series_in_its_own_panel_on_one_scale():
    """Drive and driven torque lie within a few N*m of each other: on one axes one hid the
    other; side by side, each is seen, on the same scale."""
    plt = plotting.pyplot()
    t, y = _start_up_and_ripple()
    fig = plotting.time_view(t, [("-tau1 (drive)", y), ("tau2 (driven)", y + 0.5)], "torque", "N*m", 2.0, "x")
    whole = [ax for ax in fig.axes if ax.get_title(loc="left").startswith("whole run")]
    assert [ax.get_title(loc="left") for ax in whole] == ["whole run: -tau1 (drive)", "whole run: tau2 (driven)"]
    assert [len(ax.lines) for ax in whole] == [1, 1]
    assert whole[0].get_ylim() == whole[1].get_ylim()
    plt.close(fig)


def _work_precision_label(tmp_path, monkeypatch, repeats: int) -> str:
    cases = [Case("jacobi", "master", step, None, wall_times=[0.1 * k for k in range(1, repeats + 1)],
                  errors={"tau_rms": error}) for step, error in ((1e-3, 1e-2), (5e-4, 5e-3))]
    drawn = {}
    plt = plotting.pyplot()
    monkeypatch.setattr(plt.Figure, "savefig", lambda fig, path, **options: drawn.setdefault("ax", fig.axes[0]))
    bench_report.plot(tmp_path / "wp.png", {"cases": cases, "claims": {"target_error": 1e-3}, "scene": "x"})
    return drawn["ax"].get_xlabel()


def test_the_work_precision_plot_says_median_only_of_repeated_runs(tmp_path, monkeypatch):
    once = _work_precision_label(tmp_path, monkeypatch, 1)
    assert "median" not in once and "one run each" in once
    assert "(median of up to 3 repeats)" in _work_precision_label(tmp_path, monkeypatch, 3)


def test_the_spectrum_marks_the_bins_the_report_states_and_says_its_resolution(tmp_path, monkeypatch):
    """A shaft-order line at 36.66 rad/s over an 8 s window falls between bins 0.785 rad/s
    apart: the report states the bin's frequency, and the plot marks that bin, not the
    mean speed; the load torque is named as the traces name it."""
    from harness.description import scene as scenes
    from harness.judges import metrics

    scene = scenes.load("kavz685")
    names = metrics.signals(scene)
    t = np.arange(0.0, 10.0 + 5e-4, 1e-3)
    speed = 36.66
    load = 107.5 + 4.8 * np.sin(speed * t) + 0.9 * np.sin(418.0 * t)
    traces = {names["w2"]: np.full_like(t, speed), names["tau2"]: load + 0.1 * np.sin(73.3 * t),
              "load.load_torque": load}
    result = SimpleNamespace(scene=scene, times=t, traces=traces)
    drawn = {}
    plt = plotting.pyplot()
    monkeypatch.setattr(report, "save_figure", lambda fig, path: drawn.setdefault("fig", fig))
    report._plot_spectrum(tmp_path, result, "x", plt)
    stated = metrics.spectral_components(t, traces, [names["tau2"], "load.load_torque"], names["w2"],
                                         scene.experiment.transient)
    torque, load_axes = drawn["fig"].axes
    assert load_axes.get_legend_handles_labels()[1][0].startswith("load.load_torque")
    for ax, name in ((torque, names["tau2"]), (load_axes, "load.load_torque")):
        marks = {line.get_label(): (line.get_xdata()[0], line.get_ydata()[0]) for line in ax.lines
                 if line.get_label().startswith("peak")}
        for key in ("rotation", "band"):
            peak = stated[name][key]
            assert (peak["frequency_rad_s"], peak["amplitude"]) in marks.values()
        rotation_bin = stated[name]["rotation"]["frequency_rad_s"]
        assert abs(rotation_bin - speed) > 0.05            # a bin beside the mean speed, marked as such
        assert f"{rotation_bin:.4g} rad/s" in " ".join(marks)
    window = 10.0 - scene.experiment.transient
    label = load_axes.get_xlabel()
    assert "Hann" in label and f"{2 * np.pi / window:.3g} rad/s" in label
    plt.close(drawn["fig"])
