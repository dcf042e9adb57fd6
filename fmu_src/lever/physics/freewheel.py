"""The axial freewheel (overrunning clutch) used as a vibration rectifier, with its torsion
shaft, gear mesh and output flywheel (docs/physics.md#freewheel-rectifier; the paper of
Khudorozhkov & Yurkevich, equations (1)-(18) and Table 1).

The chain, from the drive to the output (the paper's Fig. 2):

1. rocker, prescribed: ``phi1 = phi0 (1 - cos(omega t))`` (8);
2. the two half-couplings (lumped: inertia ``2 J2``), tied to the rocker by balls in
   tear-shaped pockets: the relative angle ``e = phi1 - phi2`` pushes the half-couplings
   axially by ``x = (e + z1) r tan(alpha)`` (1).  ``-z1 < e < 0`` is the axial gap
   (the discs are free); for ``e > 0`` the disc packs are clamped with the axial force
   of the MSM stiffness ``C_fi``; for ``e < -z1`` the balls sit at the pocket's end
   and the rocker drags the half-couplings back through the pocket wall;
3. the driven parts of the freewheel (lumped: ``2 J3``), coupled to the half-couplings
   by the friction discs: ``n`` pairs per half with coefficient ``f_s`` under the clamp
   force, plus the drag moment ``M_v + k_v |w2 - w3|`` of the disc pack;
4. the torsion shaft ``C_t, k_t`` with the spline gap ``z2`` to its output end ``J4``;
5. the gear mesh ``C_z, k_z`` with the backlash ``z3`` to the output flywheel ``J5``
   (5 kg*m^2 models the paper's stop mode), with a Coulomb resistance ``Mc`` and a
   torque port ``tau`` for a downstream model.

How the printed equations are used (and where they are not) is in docs/record/decisions.md.
Here, in short: the model is written as torques on the relative coordinates, each
with an exact potential, so power in = d(kinetic + elastic)/dt + output + dissipated
holds identically:

    T12 = T_p + kappa(de) * C_fi * max(e, 0) + C_b * min(e + z1, 0)      rocker -> half-couplings
    T34 = C_t * dz(phi3 - phi4, z2) + k_t * (w3 - w4)                  torsion shaft
    T45 = C_z * dz(phi4 - phi5, z3) + k_z * (w4 - w5)                  gear mesh

with ``dz(d, z) = d for d > 0, d + z for d < -z, 0 in the gap``; ``T_p = 2 P_pr r
tan(alpha)`` the return springs' torque through the ramps; ``kappa`` the ball
rolling friction ``f_k`` on the ramps (sign function regularised linearly over
``|de| < v_k``: it changes the ramp torque by 0.35 %).  The disc friction (the
torque that matters) and the output's resistance use **explicit stick/slip logic**:
in stick the half-couplings and the driven parts move as one body while the torque
they exchange stays within the discs' capacity ``n f_s C_fi max(e, 0) / tan(alpha)
+ M_v``; in slip the friction is that capacity (plus the drag's viscous part) against
the relative motion.  Switching happens at located events, as do the gap edges.

Everything here is plain Python on floats: the FMU integrates it with fixed RK4
substeps and event location (``advance``); the harness's monolithic reference uses
the same right-hand side and switching logic under scipy's DOP853 with its own event
location.
"""
from __future__ import annotations

import math
from typing import NamedTuple

from .parameters import ParameterError

#: disc modes: the half-couplings and the driven parts stuck together, or slipping
#: with w2 > w3 (+1) or w2 < w3 (-1)
STICK = 0
#: flywheel modes: stuck (0), sliding against the resistance (+1/-1), or no resistance at all
FREE = 2

#: names of the event functions, in the order ``event_values`` returns them
EVENTS = ("msm_contact", "msm_pocket_end", "torsion_contact", "torsion_back_contact",
          "mesh_contact", "mesh_back_contact", "disc", "flywheel")
#: the first six are edges of the gaps (crossed both ways); the last two switch modes
N_EDGES = 6

#: the state vector: the motion, then the work accumulated since the start
STATE = ("phi2", "w2", "phi3", "w3", "phi4", "w4", "phi5", "w5", "input_work", "output_work", "dissipated_energy")


class Outputs(NamedTuple):
    rocker_angle: float
    rocker_speed: float
    rocker_acceleration: float
    half_coupling_acceleration: float
    driven_acceleration: float
    torsion_end_acceleration: float
    flywheel_acceleration: float
    msm_deflection: float     # e = phi1 - phi2
    torsion_twist: float      # phi3 - phi4
    mesh_deflection: float    # phi4 - phi5
    rocker_torque: float      # T12 (on the half-couplings; the rocker gets -T12)
    disc_torque: float        # torque the half-couplings pass to the driven parts through the discs
    disc_capacity: float      # what the discs can pass before they slip
    torsion_torque: float     # T34
    mesh_torque: float        # T45
    resistance: float         # torque the output's resistance applies against the flywheel
    kinetic_energy: float
    elastic_energy: float
    dissipated_power: float


def _dead_zone(d: float, gap: float) -> float:
    """Deflection of a spring behind a gap ``[-gap, 0]`` (the paper's convention: the
    drive-side contact is at 0, the back contact at ``-gap``)."""
    if d > 0.0:
        return d
    if d < -gap:
        return d + gap
    return 0.0


def contact_side(d: float, gap: float) -> int:
    """+1 on the drive-side contact, -1 on the back contact, 0 in the gap."""
    return 1 if d > 0.0 else (-1 if d < -gap else 0)


class FreewheelRectifier:
    """The rectifier's equations.  ``p`` holds checked parameter values by the
    declared names (``lever.physics.component_parameters.FREEWHEEL``)."""

    def __init__(self, p: dict):
        self.p = dict(p)
        self.omega = p["input_speed"]
        self.phi0 = p["rocker_amplitude"]
        self.J2 = 2.0 * p["half_coupling_inertia"]     # both half-couplings
        self.J3 = 2.0 * p["driven_parts_inertia"]      # both sets of driven parts
        self.J23 = self.J2 + self.J3
        self.J4 = p["torsion_end_inertia"]
        self.J5 = p["flywheel_inertia"]
        self.tan_a = math.tan(p["ramp_angle"])
        self.fk = p["ball_friction"]
        if self.fk * self.tan_a >= 1.0:
            raise ParameterError("ball_friction", f"parameter 'ball_friction' = {self.fk:g} with ramp_angle = "
                                 f"{p['ramp_angle']:g} rad: f_k tan(alpha) must stay below 1 (the balls would "
                                 f"lock on the ramps); allowed: ball_friction < {1.0 / self.tan_a:.6g}")
        self.vk = p["ball_friction_speed"]
        self.z1, self.z2, self.z3 = p["msm_gap"], p["torsion_gap"], p["mesh_gap"]
        self.c_fi, self.c_b = p["msm_stiffness"], p["pocket_stiffness"]
        self.c_t, self.c_z = p["torsion_stiffness"], p["mesh_stiffness"]
        self.k_t, self.k_z, self.k_v = p["torsion_damping"], p["mesh_damping"], p["drag_damping"]
        self.m_v = p["drag_torque"]
        self.mc = p["resistance_torque"]
        # the return springs (P_pr on each half) act on the rocker-half-coupling angle through the ramps
        self.t_p = 2.0 * p["spring_force"] * p["contact_radius"] * self.tan_a
        # disc capacity per unit of the ramps' elastic torque C_fi*e: 2 n f_s r Q / (2 r tan(alpha) Q)
        self.gain = p["friction_pairs"] * p["disc_friction"] / self.tan_a
        self.max_substep = p["max_substep"]
        self.max_events = int(p["max_events"])

    # -- derived quantities reported to users -----------------------------------------------
    def axial_stiffness(self) -> float:
        """c_x of one half [N/m] implied by the MSM stiffness: C_fi = 2 c_x (r tan(alpha))^2."""
        lever = self.p["contact_radius"] * self.tan_a
        return self.c_fi / (2.0 * lever * lever)

    def self_locking(self) -> tuple[float, float]:
        """(tan(alpha), n f_s): the discs hold whatever the ramps push while tan(alpha) <= n f_s."""
        return self.tan_a, self.p["friction_pairs"] * self.p["disc_friction"]

    def rocker(self, t: float) -> tuple[float, float, float]:
        """(phi1, w1, a1) of the prescribed rocker, (8)."""
        wt = self.omega * t
        c, s = math.cos(wt), math.sin(wt)
        return self.phi0 * (1.0 - c), self.phi0 * self.omega * s, self.phi0 * self.omega * self.omega * c

    # -- the right-hand side ------------------------------------------------------------------
    def _ramp(self, e: float, de: float) -> tuple[float, float, float]:
        """(T12, ball-friction loss power, disc capacity) at MSM deflection ``e``."""
        if e > 0.0:
            elastic = self.c_fi * e
            s = de / self.vk
            s = 1.0 if s > 1.0 else (-1.0 if s < -1.0 else s)
            kappa = (self.tan_a + s * self.fk) / ((1.0 - s * self.fk * self.tan_a) * self.tan_a)
            return self.t_p + kappa * elastic, (kappa - 1.0) * elastic * de, self.gain * elastic + self.m_v
        if e < -self.z1:
            return self.t_p + self.c_b * (e + self.z1), 0.0, self.m_v
        return self.t_p, 0.0, self.m_v

    def forces(self, t: float, y, disc: int, fly: int, ext: float):
        """Everything the right-hand side needs: ``(a2, a3, a4, a5, T12, F, cap, T34, T45,
        brake, loss, w1)``; ``F`` the torque the half-couplings pass to the driven parts,
        ``brake`` the resistance against the flywheel, ``loss`` the dissipated power."""
        p2, w2, p3, w3, p4, w4, p5, w5 = y[0], y[1], y[2], y[3], y[4], y[5], y[6], y[7]
        wt = self.omega * t
        phi1 = self.phi0 * (1.0 - math.cos(wt))
        w1 = self.phi0 * self.omega * math.sin(wt)
        e = phi1 - p2
        de = w1 - w2
        t12, loss, cap = self._ramp(e, de)
        d = p3 - p4
        v34 = w3 - w4
        t34 = self.k_t * v34 + (self.c_t * d if d > 0.0 else (self.c_t * (d + self.z2) if d < -self.z2 else 0.0))
        d = p4 - p5
        v45 = w4 - w5
        t45 = self.k_z * v45 + (self.c_z * d if d > 0.0 else (self.c_z * (d + self.z3) if d < -self.z3 else 0.0))
        loss += self.k_t * v34 * v34 + self.k_z * v45 * v45
        if disc == STICK:
            a2 = a3 = (t12 - t34) / self.J23
            f = t12 - self.J2 * a2
        else:
            slip = w2 - w3
            f = disc * cap + self.k_v * slip
            a2 = (t12 - f) / self.J2
            a3 = (f - t34) / self.J3
            loss += f * slip
        a4 = (t34 - t45) / self.J4
        if fly == STICK:
            brake = t45 + ext
            a5 = 0.0
        else:
            brake = 0.0 if fly == FREE else fly * self.mc
            a5 = (t45 + ext - brake) / self.J5
        return a2, a3, a4, a5, t12, f, cap, t34, t45, brake, loss, w1

    def derivatives(self, t: float, y, disc: int, fly: int, ext: float) -> list:
        """d/dt of the state (``STATE``)."""
        a2, a3, a4, a5, t12, f, cap, t34, t45, brake, loss, w1 = self.forces(t, y, disc, fly, ext)
        w5 = y[7]
        return [y[1], a2, y[3], a3, y[5], a4, w5, a5, t12 * w1, (brake - ext) * w5, loss]

    def jacobian(self, t: float, y, disc: int, fly: int, ext: float) -> list[list[float]]:
        """``d derivatives / d(y, ext)``, analytic, in the modes ``disc``, ``fly``: 11 rows
        (``STATE``), 12 columns (``STATE`` then ``ext``).  Each torque's gradient follows
        the branch ``forces`` takes (a gap edge, ``e = 0`` or the ball friction's
        saturation ``|de| = v_k`` on the side ``forces`` evaluates): the kinks are events or,
        for the saturation, continuous in value."""
        return self._gradients(t, y, disc, fly, ext)["rows"]

    def output_gradients(self, t: float, y, disc: int, fly: int, ext: float) -> dict:
        """``d named_outputs / d(y, ext)``, analytic, in the modes ``disc``, ``fly``: for each
        output of ``named_outputs`` its gradient over ``STATE`` then ``ext`` (12 values), on
        the branch ``forces`` takes (as ``jacobian``).  Mode flags, contact sides, the event
        count and the rocker's motion (a function of time) have none."""
        g = self._gradients(t, y, disc, fly, ext)
        n = len(STATE) + 1

        def unit(*pairs):
            out = [0.0] * n
            for k, v in pairs:
                out[k] += v
            return out
        e = self.rocker(t)[0] - y[0]
        d34, d45 = y[2] - y[4], y[4] - y[6]
        ramp = self.t_p + self.c_fi * max(e, 0.0) + self.c_b * min(e + self.z1, 0.0)
        c34 = self.c_t * _dead_zone(d34, self.z2)
        c45 = self.c_z * _dead_zone(d45, self.z3)
        rows = g["rows"]
        zero = [0.0] * n
        out = {name: zero for name in ("rocker_angle", "rocker_speed", "rocker_acceleration", "msm_contact",
                                       "torsion_contact", "mesh_contact", "disc_slip", "flywheel_stuck", "events")}
        for k, (angle, speed, acceleration) in enumerate((
                ("half_coupling_angle", "half_coupling_speed", "half_coupling_acceleration"),
                ("driven_angle", "driven_speed", "driven_acceleration"),
                ("torsion_end_angle", "torsion_end_speed", "torsion_end_acceleration"), ("phi", "w", "a"))):
            out[angle], out[speed], out[acceleration] = unit((2 * k, 1.0)), unit((2 * k + 1, 1.0)), rows[2 * k + 1]
        out.update({
            "msm_deflection": unit((0, -1.0)), "torsion_twist": unit((2, 1.0), (4, -1.0)),
            "mesh_deflection": unit((4, 1.0), (6, -1.0)),
            "rocker_torque": g["t12"], "disc_torque": g["f"], "disc_capacity": g["cap"],
            "torsion_torque": g["t34"], "mesh_torque": g["t45"], "resistance": g["brake"],
            "input_work": unit((8, 1.0)), "output_work": unit((9, 1.0)), "dissipated_energy": unit((10, 1.0)),
            "kinetic_energy": unit((1, self.J2 * y[1]), (3, self.J3 * y[3]), (5, self.J4 * y[5]), (7, self.J5 * y[7])),
            "elastic_energy": unit((0, -ramp), (2, c34), (4, c45 - c34), (6, -c45)),
        })
        return out

    def _gradients(self, t: float, y, disc: int, fly: int, ext: float) -> dict:
        """The gradients ``jacobian`` and ``output_gradients`` are made of: ``rows`` (the
        Jacobian), and those of the torques ``t12``, ``f`` (the discs'), ``cap``, ``t34``,
        ``t45`` and ``brake``."""
        n = len(STATE) + 1                       # the last column: ext
        def grad(**entries):
            g = [0.0] * n
            for k, v in entries.items():
                g[int(k[1:])] = v
            return g

        def comb(*terms):
            g = [0.0] * n
            for c, v in terms:
                if c:
                    for k in range(n):
                        g[k] += c * v[k]
            return g

        p2, w2, p3, w3, p4, w4, p5, w5 = y[0], y[1], y[2], y[3], y[4], y[5], y[6], y[7]
        _, _, _, _, _, f, _, _, _, brake, _, w1 = self.forces(t, y, disc, fly, ext)
        e, de = self.rocker(t)[0] - p2, w1 - w2
        zero = [0.0] * n
        # T12, its loss and the disc capacity (``_ramp``), through e = phi1 - phi2, de = w1 - w2
        if e > 0.0:
            elastic = self.c_fi * e
            s = de / self.vk
            inside = -1.0 < s < 1.0
            s = 1.0 if s > 1.0 else (-1.0 if s < -1.0 else s)
            q = (1.0 - s * self.fk * self.tan_a) * self.tan_a
            kappa = (self.tan_a + s * self.fk) / q
            dkappa = (self.fk * self.tan_a * (1.0 + self.tan_a * self.tan_a) / (q * q) / self.vk) if inside else 0.0
            d_e, d_de = kappa * self.c_fi, dkappa * elastic                     # of T12
            g12 = grad(x0=-d_e, x1=-d_de)
            g_ramp = grad(x0=-(kappa - 1.0) * self.c_fi * de, x1=-(dkappa * elastic * de + (kappa - 1.0) * elastic))
            g_cap = grad(x0=-self.gain * self.c_fi)
        elif e < -self.z1:
            g12, g_ramp, g_cap = grad(x0=-self.c_b), zero, zero
        else:
            g12, g_ramp, g_cap = zero, zero, zero
        d = p3 - p4
        c34 = self.c_t if (d > 0.0 or d < -self.z2) else 0.0
        v34 = w3 - w4
        g34 = grad(x2=c34, x4=-c34, x3=self.k_t, x5=-self.k_t)
        d = p4 - p5
        c45 = self.c_z if (d > 0.0 or d < -self.z3) else 0.0
        v45 = w4 - w5
        g45 = grad(x4=c45, x6=-c45, x5=self.k_z, x7=-self.k_z)
        g_loss = comb((1.0, g_ramp), (2.0 * self.k_t * v34, grad(x3=1.0, x5=-1.0)),
                      (2.0 * self.k_z * v45, grad(x5=1.0, x7=-1.0)))
        if disc == STICK:
            g2 = g3 = comb((1.0 / self.J23, g12), (-1.0 / self.J23, g34))
            g_f = comb((1.0, g12), (-self.J2, g2))          # f = T12 - J2 a2
        else:
            slip = w2 - w3
            g_f = comb((disc, g_cap), (self.k_v, grad(x1=1.0, x3=-1.0)))
            g2 = comb((1.0 / self.J2, g12), (-1.0 / self.J2, g_f))
            g3 = comb((1.0 / self.J3, g_f), (-1.0 / self.J3, g34))
            g_loss = comb((1.0, g_loss), (slip, g_f), (f, grad(x1=1.0, x3=-1.0)))
        g4 = comb((1.0 / self.J4, g34), (-1.0 / self.J4, g45))
        if fly == STICK:
            g_brake = comb((1.0, g45), (1.0, grad(x11=1.0)))
            g5 = zero
        else:
            g_brake = zero
            g5 = comb((1.0 / self.J5, g45), (1.0 / self.J5, grad(x11=1.0)))
        g_out = comb((w5, g_brake), (-w5, grad(x11=1.0)), (brake - ext, grad(x7=1.0)))
        rows = [grad(x1=1.0), g2, grad(x3=1.0), g3, grad(x5=1.0), g4, grad(x7=1.0), g5,
                comb((w1, g12)), g_out, g_loss]
        return {"rows": rows, "t12": g12, "f": g_f, "cap": g_cap, "t34": g34, "t45": g45, "brake": g_brake}

    # -- events and modes ------------------------------------------------------------------------
    def event_values(self, t: float, y, disc: int, fly: int, ext: float) -> list:
        """The functions whose zeros are events (``EVENTS``).  Gap edges change sign both
        ways; the mode functions are positive while the mode holds."""
        phi1 = self.phi0 * (1.0 - math.cos(self.omega * t))
        e = phi1 - y[0]
        d34 = y[2] - y[4]
        d45 = y[4] - y[6]
        out = [e, e + self.z1, d34, d34 + self.z2, d45, d45 + self.z3]
        if disc == STICK or fly == STICK:
            f = self.forces(t, y, disc, fly, ext)
        if disc == STICK:
            out.append(f[6] - abs(f[5]))
        else:
            out.append(disc * (y[1] - y[3]))
        if fly == STICK:
            out.append(self.mc - abs(f[9]))
        elif fly == FREE:
            out.append(1.0)
        else:
            out.append(fly * y[7])
        return out

    def deflection_rates(self, t: float, y, disc: int, fly: int, ext: float) -> tuple[tuple, tuple]:
        """Speeds and accelerations of the three gapped deflections ``(e, phi3 - phi4,
        phi4 - phi5)``: the derivatives of the gap-edge functions (``EVENTS``, two edges
        a deflection)."""
        a2, a3, a4, a5, *_ = self.forces(t, y, disc, fly, ext)
        _, w1, a1 = self.rocker(t)
        return (w1 - y[1], y[3] - y[5], y[5] - y[7]), (a1 - a2, a3 - a4, a4 - a5)

    def disc_mode_at(self, t: float, y, fly: int, ext: float) -> int:
        """The disc mode for a state where the half-couplings and the driven parts turn at
        the same speed: stick if the discs can pass the torque that takes, else slip the
        way that torque pushes."""
        f = self.forces(t, y, STICK, fly, ext)
        return STICK if abs(f[5]) <= f[6] else (1 if f[5] > 0.0 else -1)

    def flywheel_mode_at(self, t: float, y, disc: int, ext: float) -> int:
        if self.mc == 0.0:
            return FREE
        if y[7] != 0.0:
            return 1 if y[7] > 0.0 else -1
        f = self.forces(t, y, disc, STICK, ext)
        return STICK if abs(f[9]) <= self.mc else (1 if f[9] > 0.0 else -1)

    def switch(self, t: float, y, disc: int, fly: int, which: int, ext: float) -> tuple[list, int, int]:
        """The state and modes after mode event ``which`` (``EVENTS`` index) at ``t``.
        Where a slip ends the two speeds are set equal, keeping the momentum; the
        (round-off sized) kinetic energy that takes is booked as dissipated."""
        y = list(y)
        if which == N_EDGES:           # the discs
            if disc != STICK:
                w = (self.J2 * y[1] + self.J3 * y[3]) / self.J23
                y[10] += 0.5 * (self.J2 * y[1] ** 2 + self.J3 * y[3] ** 2) - 0.5 * self.J23 * w * w
                y[1] = y[3] = w
                disc = self.disc_mode_at(t, y, fly, ext)
            else:
                f = self.forces(t, y, STICK, fly, ext)
                disc = 1 if f[5] > 0.0 else -1
        elif which == N_EDGES + 1:     # the flywheel
            if fly not in (STICK, FREE):
                y[10] += 0.5 * self.J5 * y[7] ** 2
                y[7] = 0.0
                fly = self.flywheel_mode_at(t, y, disc, ext)
            else:
                f = self.forces(t, y, disc, STICK, ext)
                fly = 1 if f[9] > 0.0 else -1
        return y, disc, fly

    # -- start ---------------------------------------------------------------------------------
    def start(self) -> tuple[list, int, int]:
        """At rest, every gap open ahead of the drive: the rocker must travel z1 + z2 + z3
        before the flywheel feels a torque (the paper's "torque appears only after the
        gaps are taken up")."""
        phi5 = 0.0
        phi4 = phi5 - self.z3
        phi3 = phi4 - self.z2
        phi2 = self.rocker(0.0)[0] + self.z1
        y = [phi2, 0.0, phi3, 0.0, phi4, 0.0, phi5, 0.0, 0.0, 0.0, 0.0]
        fly = FREE if self.mc == 0.0 else STICK
        disc = self.disc_mode_at(0.0, y, fly, 0.0)
        fly = self.flywheel_mode_at(0.0, y, disc, 0.0)
        return y, disc, fly

    # -- what is reported -----------------------------------------------------------------------
    def outputs(self, t: float, y, disc: int, fly: int, ext: float) -> Outputs:
        a2, a3, a4, a5, t12, f, cap, t34, t45, brake, loss, w1 = self.forces(t, y, disc, fly, ext)
        phi1, _, a1 = self.rocker(t)
        e = phi1 - y[0]
        d34 = y[2] - y[4]
        d45 = y[4] - y[6]
        kinetic = 0.5 * (self.J2 * y[1] ** 2 + self.J3 * y[3] ** 2 + self.J4 * y[5] ** 2 + self.J5 * y[7] ** 2)
        return Outputs(phi1, w1, a1, a2, a3, a4, a5, e, d34, d45, t12, f, cap, t34, t45, brake,
                       kinetic, self.elastic_energy(e, d34, d45), loss)

    def named_outputs(self, t: float, y, disc: int, fly: int, ext: float, events: int = 0) -> dict:
        """The FMU's outputs by name (the FMU and the monolithic reference both report
        through this, so their traces carry the same quantities)."""
        o = self.outputs(t, y, disc, fly, ext)
        return {
            "phi": y[6], "w": y[7], "a": o.flywheel_acceleration,
            "rocker_angle": o.rocker_angle, "rocker_speed": o.rocker_speed,
            "rocker_acceleration": o.rocker_acceleration,
            "half_coupling_angle": y[0], "half_coupling_speed": y[1],
            "half_coupling_acceleration": o.half_coupling_acceleration,
            "driven_angle": y[2], "driven_speed": y[3], "driven_acceleration": o.driven_acceleration,
            "torsion_end_angle": y[4], "torsion_end_speed": y[5],
            "torsion_end_acceleration": o.torsion_end_acceleration,
            "msm_deflection": o.msm_deflection, "torsion_twist": o.torsion_twist,
            "mesh_deflection": o.mesh_deflection,
            "msm_contact": float(contact_side(o.msm_deflection, self.z1)),
            "torsion_contact": float(contact_side(o.torsion_twist, self.z2)),
            "mesh_contact": float(contact_side(o.mesh_deflection, self.z3)),
            "disc_slip": float(disc), "flywheel_stuck": 1.0 if fly == STICK else 0.0,
            "rocker_torque": o.rocker_torque, "disc_torque": o.disc_torque, "disc_capacity": o.disc_capacity,
            "torsion_torque": o.torsion_torque, "mesh_torque": o.mesh_torque, "resistance": o.resistance,
            "input_work": y[8], "output_work": y[9], "kinetic_energy": o.kinetic_energy,
            "elastic_energy": o.elastic_energy, "dissipated_energy": y[10], "events": float(events),
        }

    def elastic_energy(self, e: float, d34: float, d45: float) -> float:
        """Potential of the three elastic joints (the return springs' part ``T_p e`` is
        counted from ``e = 0``)."""
        ramp = self.t_p * e + 0.5 * self.c_fi * max(e, 0.0) ** 2 + 0.5 * self.c_b * min(e + self.z1, 0.0) ** 2
        return (ramp + 0.5 * self.c_t * _dead_zone(d34, self.z2) ** 2
                + 0.5 * self.c_z * _dead_zone(d45, self.z3) ** 2)

    # -- the FMU's integrator --------------------------------------------------------------------
    def _rk4(self, t, y, h, disc, fly, ext0, ext_rate, t_ext):
        f = self.derivatives
        k1 = f(t, y, disc, fly, ext0 + ext_rate * (t - t_ext))
        half = 0.5 * h
        k2 = f(t + half, [a + half * b for a, b in zip(y, k1)], disc, fly, ext0 + ext_rate * (t + half - t_ext))
        k3 = f(t + half, [a + half * b for a, b in zip(y, k2)], disc, fly, ext0 + ext_rate * (t + half - t_ext))
        k4 = f(t + h, [a + h * b for a, b in zip(y, k3)], disc, fly, ext0 + ext_rate * (t + h - t_ext))
        sixth = h / 6.0
        return [a + sixth * (b + 2.0 * (c + d) + e) for a, b, c, d, e in zip(y, k1, k2, k3, k4)]

    #: RK4 substeps one step may take (about 30 us each in CPython): beyond it the step is
    #: refused at once, not ground through for minutes while the importer waits
    MAX_SUBSTEPS = 200_000
    #: RK4 integrations one step may take in all, event location included (a chattering
    #: contact with a large 'max_events' would otherwise keep the importer waiting)
    MAX_INTEGRATIONS = 400_000

    def advance(self, t: float, h: float, y, disc: int, fly: int, ext: float = 0.0, ext_rate: float = 0.0,
                log=None) -> tuple[list, int, int, int]:
        """Integrate from ``t`` over ``h`` with the port torque ``ext + ext_rate * s``:
        classical RK4 over substeps of at most ``max_substep``, every event located by
        regula falsi (Illinois) on the substep and handled where it happens.  Returns
        ``(y, disc, fly, number of events)``; ``log(time, event name, disc, fly)`` is
        called at each event.  Raises ``RuntimeError`` when more than ``max_events``
        events pile up in one call (a chattering contact)."""
        t_end = t + h
        needed = h / self.max_substep
        if not needed <= self.MAX_SUBSTEPS:
            raise ParameterError("max_substep", f"a step of h = {h:.6g} s needs {needed:.3g} RK4 substeps of "
                                 f"max_substep = {self.max_substep:.6g} s, more than the {self.MAX_SUBSTEPS} "
                                 "allowed per step: take smaller communication steps or a larger 'max_substep'")
        n = max(1, math.ceil(needed - 1e-9))
        dt_nominal = h / n
        if not dt_nominal >= math.ulp(max(abs(t), abs(t_end))):
            # t + dt would round back to t: the substeps could never reach the step's end
            raise ParameterError("max_substep", f"at t = {t:.9g} s a substep of {dt_nominal:.3g} s (max_substep = "
                                 f"{self.max_substep:.6g} s) is below the time's resolution "
                                 f"{math.ulp(abs(t_end)):.3g} s: take a larger 'max_substep' or start nearer t = 0")
        events = 0
        budget = self.MAX_INTEGRATIONS       # substeps and event location alike
        y = list(y)
        while t < t_end - 1e-15 * max(1.0, abs(t_end)):
            budget -= 1
            if budget < 0:
                raise RuntimeError(f"the step from t = {t_end - h:.9g} s of h = {h:.6g} s took more than "
                                   f"{self.MAX_INTEGRATIONS} RK4 integrations ({events} events located): a contact "
                                   "or the discs chatter; take smaller steps or a lower 'max_events'")
            dt = min(dt_nominal, t_end - t)
            ext_t = ext + ext_rate * (t - (t_end - h))
            g0 = self.event_values(t, y, disc, fly, ext_t)
            y1 = self._rk4(t, y, dt, disc, fly, ext, ext_rate, t_end - h)
            g1 = self.event_values(t + dt, y1, disc, fly, ext + ext_rate * (t + dt - (t_end - h)))
            hit = self._first_crossing(g0, g1)
            if hit is None:
                t, y = t + dt, y1
                continue
            k, theta = hit
            lo, hi, g_lo, g_hi = 0.0, dt, g0[k], g1[k]
            y_hi = y1
            side = -1 if k >= N_EDGES or g_lo > 0.0 else 1
            # Illinois: keep the bracket [lo, hi] around the sign change of g_k
            stale = 0
            for _ in range(60):
                if hi - lo <= 1e-13 * max(1.0, abs(t)) + 1e-15:
                    break
                s = hi - g_hi * (hi - lo) / (g_hi - g_lo) if g_hi != g_lo else 0.5 * (lo + hi)
                if not lo < s < hi:
                    s = 0.5 * (lo + hi)
                budget -= 1
                ys = self._rk4(t, y, s, disc, fly, ext, ext_rate, t_end - h)
                gs = self.event_values(t + s, ys, disc, fly, ext + ext_rate * (t + s - (t_end - h)))
                # an earlier event inside the bracket takes over
                early = self._first_crossing(g0, gs)
                if early is not None and early[0] != k:
                    k, hi, g_hi, y_hi = early[0], s, gs[early[0]], ys
                    lo, g_lo = 0.0, g0[k]
                    side = -1 if k >= N_EDGES or g_lo > 0.0 else 1
                    stale = 0
                    continue
                if (gs[k] > 0.0) == (side < 0) and gs[k] != 0.0:
                    lo, g_lo = s, gs[k]
                    if stale == -1:
                        g_hi *= 0.5
                    stale = -1
                else:
                    hi, g_hi, y_hi = s, gs[k], ys
                    if stale == 1:
                        g_lo *= 0.5
                    stale = 1
            t, y = t + hi, y_hi
            events += 1
            if events > self.max_events:
                raise RuntimeError(f"more than {self.max_events} events in one step (t = {t:.9g} s, last: "
                                   f"{EVENTS[k]}): a contact or the discs chatter")
            if k >= N_EDGES:
                ext_t = ext + ext_rate * (t - (t_end - h))
                y, disc, fly = self.switch(t, y, disc, fly, k, ext_t)
            if log is not None:
                log(t, EVENTS[k], disc, fly)
        return y, disc, fly, events

    @staticmethod
    def _first_crossing(g0, g1):
        """``(index, fraction)`` of the earliest sign change between ``g0`` and ``g1`` by
        linear interpolation, or None.  Gap edges count both ways (an edge function at
        exactly zero at the start is just leaving its edge); a mode function counts when it
        turns negative, also from exactly zero (a slip starts with equal speeds)."""
        best = None
        for k in range(len(g0)):
            a, b = g0[k], g1[k]
            if k < N_EDGES:
                crossed = (a > 0.0 and b <= 0.0) or (a < 0.0 and b >= 0.0)
            else:      # a mode ends when its function turns negative (it may start at 0)
                crossed = a >= 0.0 and b < 0.0
            if crossed:
                theta = a / (a - b)
                if best is None or theta < best[1]:
                    best = (k, theta)
        return best
