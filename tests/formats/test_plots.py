"""The plots show what the reports state, at a scale where it can be read: the judged
window zoomed to its own values beside the whole run, legends beside the data, a
stability map as wide as its masters and with the classes it holds."""
from __future__ import annotations

import numpy as np

from harness.formats import plotting
from harness.studies import stabilitymap


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
    overview, drive, driven, difference = fig.axes[:4]
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
    assert stabilitymap.legend_classes({"stable", "divergent"}) == ["stable", "divergent"]
    assert "failed" in stabilitymap.legend_classes({"stable", "failed"})
