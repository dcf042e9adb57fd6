"""The axes of a parameter sweep (``harness.studies.sweep``): each of the monograph's studies
(Figs. 3.15-3.18, 4.8, 4.12) as one quantity of the base scene over the range the monograph
studies, at the conditions of the figure it mirrors, with the values it reports."""
from __future__ import annotations

from dataclasses import dataclass, field, replace


@dataclass
class Axis:
    """One study: ``quantity`` takes ``values``; ``overrides(value)`` are the scene
    assignments of a case, on top of ``base`` (the figure's conditions)."""
    name: str
    figure: str
    quantity: str                      # label with unit
    values: list
    base: list[str]
    assign: str                        # "component.parameter" the value goes to ("load" pairs: mean, bound)
    #: what the monograph reports: quantity key -> [(x, value or (low, high)), ...]
    reported: dict = field(default_factory=dict)
    note: str = ""

    def overrides(self, value) -> list[str]:
        if self.assign == "load":
            mean, bound = value
            return self.base + [f"load.mean_torque={mean}", f"load.random_amplitude={bound}"]
        if self.assign == "coupling.misalignment":
            return self.base + [f"coupling.misalignment={value} deg"]
        return self.base + [f"{self.assign}={value}"]

    def x(self, value) -> float:
        return float(value[0]) if self.assign == "load" else float(value)


FIG_317 = ["load.mean_torque=150", "load.random_amplitude=11"]     # Figs. 3.17-3.18: 150 +- 11 N*m, 15 deg
#: Load points Mm +- dM the monograph names (sections 3.3, 4.2), chosen with dM growing with
#: Mm as along its Fig. 3.15 (100 +- 8.8 ... 500 +- 21.9): the amplitudes follow dM too.
LOADS = [(100.0, 8.8), (150.0, 11.5), (225.4, 18.3), (350.0, 21.0), (500.0, 21.9), (550.0, 24.1)]
LOADS_412 = [(65.4, 5.3), (150.0, 11.5), (320.0, 12.0), (450.0, 21.5)]


def default_axes() -> list[Axis]:
    return [
        Axis("load", "3.15, 3.16", "mean load Mc [N*m]", LOADS, [], "load",
             {"A_w1": [(100, 0.65), (500, 3.94)], "A_w2": [(100, 0.92), (500, 5.18)],
              "A_a1": [(150, 180.0), (500, 380.0)], "A_a2": [(150, 210.0), (500, 510.0)],
              "A_tau1": [(500, 43.2)], "A_tau2": [(500, 49.4)],
              "mean_w": [(100, 37.2), (550, 23.4)], "mean_tau": [(100, 78.0), (550, 484.0)]},
             "alpha = 15 deg, load Mm +- dM as the monograph pairs them (dM growing with Mm)"),
        Axis("inertia", "3.16", "driven inertia I2 [kg*m^2]", [0.08, 0.12, 0.161, 0.22, 0.30], [], "load.inertia",
             {"mean_w": [(0.30, 33.9)], "mean_tau": [(0.30, 281.0)]},
             "alpha = 15 deg, load 107.5 +- 8.8 N*m; the curve's start values are garbled in the source"),
        Axis("stiffness", "3.17", "stiffness c [N*m/rad]", [200.0, 450.0, 715.4, 820.0, 1000.0, 1250.0], FIG_317,
             "coupling.stiffness",
             {"dA_w": [(200, 1.26), (820, 0.78)], "dA_a": [(200, 980.0), (820, 395.0)],
              "dA_tau": [(200, 7.1), (820, 13.2)]},
             "alpha = 15 deg, load 150 +- 11 N*m; the printed dA_M 'decreases from 7.1 to 13.2' is overlaid as printed"),
        Axis("damping", "3.17", "damping b [N*m*s/rad]", [0.5, 2.0, 4.0, 6.35, 8.5, 10.0], FIG_317, "coupling.damping",
             {"dA_w": [(10, 0.38)], "dA_a": [(10, 128.0)], "dA_tau": [(10, 12.8)]},
             "alpha = 15 deg, load 150 +- 11 N*m"),
        Axis("misalignment", "3.18", "misalignment alpha [deg]", [5.0, 10.0, 15.0, 20.0, 25.0, 30.0, 35.0], FIG_317,
             "coupling.misalignment",
             {"dA_w": [(10, 0.28), (35, 1.37)], "dA_a": [(10, 225.0), (35, 98.0)], "dA_tau": [(10, 11.0), (35, 56.0)]},
             "load 150 +- 11 N*m; the printed dA_a '(225 ... 98)' is overlaid as printed"),
        Axis("stiffness_measured", "4.8", "stiffness c [N*m/rad]", [450.0, 650.0, 750.0, 900.0, 1200.0],
             ["load.mean_torque=225.4", "load.random_amplitude=18.3", "coupling.misalignment=16 deg"],
             "coupling.stiffness", {}, "alpha = 16 deg, load 225.4 +- 18.3 N*m; overlaid: the amplitudes of the "
             "measured mean torque curves (Tables 4.2-4.11, about 220 N*m, angle-periodic load)"),
        Axis("load_alpha0", "4.12", "mean load Mc [N*m]", LOADS_412, ["coupling.misalignment=0"], "load",
             {"A_tau1": [(65.4, (6.3, 8.1)), (320, (7.5, 9.1))]}, "alpha = 0 (measured ranges, Fig. 4.11)"),
        Axis("load_alpha5", "4.12", "mean load Mc [N*m]", LOADS_412, ["coupling.misalignment=5 deg"], "load",
             {"A_tau1": [(450, (30.1, 39.3))], "A_tau2": [(320, (32.0, 34.2)), (420, (35.4, 46.1))]},
             "alpha = 5 deg (measured ranges, Figs. 4.10-4.11)"),
    ]


def select(names: list[str] | None) -> list[Axis]:
    axes = default_axes()
    if not names:
        return axes
    known = {a.name: a for a in axes}
    unknown = [n for n in names if n not in known]
    if unknown:
        raise ValueError(f"unknown sweep axis {', '.join(unknown)} (known: {', '.join(known)})")
    return [known[n] for n in names]


def thin(axes: list[Axis], every: int) -> list[Axis]:
    """Every ``every``-th value of each axis, always keeping both ends (quick looks)."""
    if every <= 1:
        return axes
    return [replace(a, values=[v for i, v in enumerate(a.values) if i % every == 0 or i == len(a.values) - 1])
            for a in axes]
