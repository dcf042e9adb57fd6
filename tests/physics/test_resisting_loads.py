"""Loads that resist the motion and the load spectrum from the source
(lever.physics.friction, lever.physics.load.SpectrumLoad): closed forms of a braked shaft,
stick and breakaway, the resistive stall scene against the monolithic reference, and the
spectrum's components at their frequencies."""
from __future__ import annotations

import math

import numpy as np
import pytest

from harness.description import scene
from harness.engine import run
from harness.judges import metrics
from harness.judges import monolithic
from lever.physics import component_parameters
from lever.physics.friction import ResistingLoad
from lever.physics.load import ConstantLoad, RandomLoad, Spectrum, SpectrumLoad
from lever.physics.parameters import ParameterError
from lever.physics.shaft import Shaft


def braked(brake=20.0, coulomb=0.0, breakaway=0.0, viscous=0.0, inertia=0.05, direction="resistive"):
    return Shaft(inertia, ResistingLoad(ConstantLoad(brake), direction, coulomb, breakaway, viscous))


# --------------------------------------------------------------------------------------
# One shaft: closed forms
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("viscous", [0.0, 0.4])
def test_a_braked_shaft_stops_where_the_closed_form_says_and_stays(viscous):
    """I w' = -R - b w from w0: w = (w0 + R/b) e^{-bt/I} - R/b, at rest from
    t* = (I/b) ln(1 + b w0/R) (t* = I w0/R without b), and held there (no drive)."""
    inertia, brake, w0 = 0.05, 20.0, 3.0
    shaft = braked(brake, viscous=viscous, inertia=inertia)
    stop = inertia * w0 / brake if not viscous else inertia / viscous * math.log(1 + viscous * w0 / brake)
    h = 1e-3
    phi, w, t, work = 0.0, w0, 0.0, 0.0
    while w != 0.0:
        phi, w, step_work = shaft.advance(t, phi, w, 0.0, h)
        t, work = t + h, work + step_work
    # the stop lies in the step that ended first at rest, and the angle is the closed form's
    assert t - h < stop <= t
    if viscous:
        k = viscous / inertia
        angle = (w0 + brake / viscous) * (1 - math.exp(-k * stop)) / k - brake / viscous * stop
    else:
        angle = w0 * stop / 2
    assert phi == pytest.approx(angle, rel=1e-10)
    # all the kinetic energy went into the brake and the viscous friction
    assert work == pytest.approx(-0.5 * inertia * w0 ** 2, rel=1e-12)
    for k in range(100):    # held: not driven backwards
        assert shaft.advance(t + k * h, phi, 0.0, 0.0, h) == (phi, 0.0, 0.0)


def test_static_friction_holds_up_to_the_breakaway_then_slips_towards_the_drive():
    shaft = braked(brake=0.0, coulomb=5.0, breakaway=8.0, direction="active")
    assert shaft.rates(0.0, 1.0, 0.0, 7.9) == (0.0, -7.9)          # held: friction balances the drive
    assert shaft.rates(0.0, 1.0, 0.0, -7.9) == (0.0, 7.9)
    a, external = shaft.rates(0.0, 1.0, 0.0, 8.1)                   # broken away: sliding friction
    assert external == -5.0 and a == pytest.approx(3.1 / 0.05)
    a, external = shaft.rates(0.0, 1.0, 0.0, -8.1)
    assert external == 5.0 and a == pytest.approx(-3.1 / 0.05)
    # a ramp from 0 breaks away inside the step where tau passes 8 N.m: at s = 8/rate
    rate, h = 1000.0, 0.02
    phi, w, _ = shaft.advance(0.0, 0.0, 0.0, 0.0, h, rate)
    s0 = 8.0 / rate          # after it: I w' = rate*s - 5, so w(h) = (rate (h^2 - s0^2)/2 - 5 (h - s0)) / I
    assert w == pytest.approx((rate * (h * h - s0 * s0) / 2 - 5.0 * (h - s0)) / 0.05, rel=1e-9)


def test_an_active_load_reverses_a_stalled_shaft_a_brake_does_not():
    """At rest an active 700 N.m turns the shaft backwards against 600 N.m;
    the same 700 N.m as a brake holds it."""
    for direction, moves in (("active", True), ("resistive", False)):
        shaft = braked(brake=700.0, inertia=0.161, direction=direction)
        phi, w, _ = shaft.advance(0.0, 0.0, 0.0, 600.0, 0.01)
        assert (w < 0.0) is moves and (w == 0.0) is not moves


def test_a_brake_never_drives_and_friction_parameters_are_judged_together():
    negative = braked(brake=-50.0)          # max(Mc, 0): a negative brake torque brakes with 0
    assert negative.rates(0.0, 0.0, 2.0, 0.0) == (0.0, 0.0)
    with pytest.raises(ParameterError) as info:
        component_parameters.load_from({"friction_torque": 5.0, "breakaway_torque": 4.0})
    assert info.value.name == "breakaway_torque" and "Fs >= Fc" in str(info.value)
    assert not component_parameters.load_from({}).resisting           # the defaults: the old active load
    assert component_parameters.load_from({"friction_torque": 0.1, "breakaway_torque": 0.1}).resisting
    smooth = component_parameters.load_from({"load_kind": "constant", "mean_torque": 107.5,
                                  "viscous_damping": 0.1})                          # viscous only: no sticking
    assert not smooth.resisting and smooth.rates(0.0, 0.0, 2.0, 0.0)[1] == -107.5 - 0.2


# --------------------------------------------------------------------------------------
# The resistive stall scene, co-simulated and against the reference
# --------------------------------------------------------------------------------------


def test_the_resistive_stall_scene_stops_holds_and_closes_its_energy_balance(fmu_dir):
    spec = scene.load("kavz685_stall_resistive").with_overrides(["experiment.stop=1", "experiment.transient=0.5"])
    result = run.simulate(spec)
    assert result.ok, result.failure
    t, w2, w1 = result.times, result.traces["load.w"], result.traces["engine.w"]
    moving = np.flatnonzero(w2 != 0.0)
    # stops within 14 ms (lever run kavz685_stall_resistive: first row at rest 0.013 s) and
    # never moves again; the drive shaft comes to rest behind it (no reversal anywhere)
    assert 0.005 < t[moving[-1] + 1] < 0.02 and np.all(w2[moving[-1] + 1:] == 0.0)
    assert np.all(w2 >= 0.0) and np.all(w1 > -1e-6) and abs(w1[-1]) < 1e-6
    # the holding torque is the coupling's 619.6 N.m (< 708 N.m held)
    assert result.traces["load.load_torque"][-1] == pytest.approx(result.traces["coupling.tau2"][-1], rel=1e-12)
    balance = metrics.energy_balance(spec, t, result.traces)
    # measured 1.0e-5 of the work in (lever run kavz685_stall_resistive, 3 s: 0.003 J of 298 J)
    assert balance["residual_relative"] < 3e-5, balance
    ref = monolithic.solve(spec, t, use_cache=False)
    assert np.all(ref.traces["load.w"][moving[-1] + 2:] == 0.0)
    ref_balance = metrics.energy_balance(spec, ref.times, ref.traces, ref.traces["coupling.dissipated_energy"])
    assert ref_balance["residual_relative"] < 1e-8, ref_balance
    errors = metrics.driveline_errors(spec, t, result.traces, ref.times, ref.traces)
    # measured RMS 0.00079 % of the mean torque for tau2 (same run)
    assert errors["coupling.tau2"]["rms_relative"] < 3e-5, errors


def test_the_reference_switches_stick_and_slip_at_the_physics_events():
    """Breakaway and stop again in the reference: a driveline whose driven shaft is held by
    stiction until the engine winds the coupling past the breakaway, then slips."""
    spec = scene.load("kavz685").with_overrides([
        "experiment.stop=0.6", "load.load_kind=constant", "load.mean_torque=0", "load.w_start=0",
        "engine.w_start=0", "load.friction_torque=150", "load.breakaway_torque=300", "load.viscous_damping=0.2"])
    times = np.linspace(0.0, 0.6, 601)
    ref = monolithic.solve(spec, times, use_cache=False)
    w2, tau2 = ref.traces["load.w"], ref.traces["coupling.tau2"]
    held = w2 == 0.0
    assert held[0] and not held[-1]
    first_slip = np.argmax(~held)
    # held while the coupling torque stays below the breakaway, moving beyond it
    assert np.all(np.abs(tau2[:first_slip - 1]) <= 300.0 + 1e-6) and tau2[first_slip] > 290.0
    balance = metrics.energy_balance(spec, ref.times, ref.traces, ref.traces["coupling.dissipated_energy"])
    assert balance["residual_relative"] < 1e-8, balance


# --------------------------------------------------------------------------------------
# The spectrum of docs/physics.md#the-oscillograms-spectrum
# --------------------------------------------------------------------------------------


def test_the_spectrum_load_splits_the_bound_into_an_order_a_narrow_band_and_the_rest():
    spectrum = Spectrum(order=1, order_share=0.6, order_phase=0.3, narrowband_share=0.3)
    load = SpectrumLoad(107.5, 10.0, 1, 6, 2.0, 450.0, spectrum)
    again = SpectrumLoad(107.5, 10.0, 1, 6, 2.0, 450.0, spectrum)
    samples = [load.resistance(0.0137 * k, 0.7 * k, 0.0) for k in range(2000)]
    assert samples == [again.resistance(0.0137 * k, 0.7 * k, 0.0) for k in range(2000)]
    assert max(abs(m - 107.5) for m in samples) <= 10.0 + 1e-12          # |Mc - Mm| <= dM
    assert all(415.0 <= f <= 425.0 for _, f, _ in load.narrowband) and len(load.narrowband) == 5
    assert sum(a for a, _, _ in load.narrowband) == pytest.approx(3.0, rel=1e-12)
    assert load.order_amplitude == 6.0 and sum(load.weights) == pytest.approx(1.0, rel=1e-12)
    # angle-locked: at a fixed time only the order part moves with phi
    rest = load.resistance(0.2, 0.0, 0.0) - 6.0 * math.sin(0.3)
    for phi in (0.5, 2.0, 4.0):
        assert load.resistance(0.2, phi, 0.0) == pytest.approx(rest + 6.0 * math.sin(phi + 0.3), abs=1e-12)
    # the broad multisine is RandomLoad's own for the seed, scaled to the rest of dM
    plain = RandomLoad(107.5, 1.0, 1, 6, 2.0, 450.0)
    assert load.frequencies == plain.frequencies and load.phases == plain.phases
    with pytest.raises(ParameterError) as info:
        SpectrumLoad(107.5, 10.0, 1, 6, 2.0, 450.0, Spectrum(order_share=0.7, narrowband_share=0.4))
    assert info.value.name == "narrowband_share"


def test_without_an_order_part_the_spectrum_shaft_steps_in_closed_form():
    load = SpectrumLoad(107.5, 8.8, 2, 6, 2.0, 450.0, Spectrum(narrowband_share=0.5))
    exact = Shaft(0.161, load)
    assert load.advance(0.161, 0.0, 0.0, 39.0, 100.0, 1e-3) is not None
    stepped = Shaft(0.161, load, max_substep=1e-6)
    phi, w, _ = exact.advance(0.3, 1.0, 39.0, 100.0, 2e-3)
    phi_rk, w_rk = stepped._rk4(0.3, 1.0, 39.0, 100.0, 2e-3)
    assert phi == pytest.approx(phi_rk, abs=1e-12) and w == pytest.approx(w_rk, abs=1e-10)


# --------------------------------------------------------------------------------------
# The spectrum shaft's split step: exact in time, RK4 on the order term only
# --------------------------------------------------------------------------------------

KAVZ_SPECTRUM = Spectrum(order=1, order_share=0.55, order_phase=-2.12, narrowband_share=0.45)


def _spectrum_load(spectrum=KAVZ_SPECTRUM, seed=1, tones=6):
    return SpectrumLoad(107.5, 8.8, seed, tones, 2.0, 450.0, spectrum)


def _plain_rk4(load, max_substep):
    shaft = Shaft(0.161, load, max_substep)
    shaft.split = False            # the generic RK4 on the whole torque, the split step's yardstick
    return shaft


@pytest.mark.parametrize("h, tau_rate", [(1e-3, 0.0), (1e-3, 800.0), (6e-3, -300.0), (2e-2, 50.0)])
def test_the_split_step_agrees_with_fine_rk4_on_the_whole_load(h, tau_rate):
    # One substep per communication step (the KAVZ-685 scene's setting) against RK4 on the
    # whole torque with 1 us substeps: the narrow band at 415-425 rad/s is exact in the split
    # step, the order term (37 rad/s at this speed) is what its RK4 resolves.
    split = Shaft(0.161, _spectrum_load(), max_substep=1.0)
    fine = _plain_rk4(_spectrum_load(), 1e-6)
    got = split.advance(0.37, 2.0, 36.6, 107.0, h, tau_rate)
    want = fine.advance(0.37, 2.0, 36.6, 107.0, h, tau_rate)
    # RK4's local error on the order term, O(h^5): measured 1.9e-8 rad, 9e-8 rad/s, 2.5e-6 J
    # at 6 ms (the fine RK4's own rounding is about 1e-12)
    scale = (h / 6e-3) ** 5
    assert got[0] == pytest.approx(want[0], abs=4e-8 * scale + 1e-11)
    assert got[1] == pytest.approx(want[1], abs=2e-7 * scale + 1e-11)
    assert got[2] == pytest.approx(want[2], abs=5e-6 * scale + 1e-9)
    # and it converges at fourth order: ten times the substeps, 1e-4 of the error (to rounding)
    n = split._substeps(h, 36.6)
    finer = Shaft(0.161, _spectrum_load(), max_substep=h / (10 * n)).advance(0.37, 2.0, 36.6, 107.0, h, tau_rate)
    assert abs(finer[1] - want[1]) <= max(3e-4 * abs(got[1] - want[1]), 1e-11)


@pytest.mark.parametrize("substeps", [1, 3, 8])
def test_without_an_order_term_the_split_step_is_the_closed_form(substeps):
    # the kernels of the tones' time integrals, checked against RandomLoad's closed form
    for spectrum in (Spectrum(narrowband_share=0.45), Spectrum(narrowband_share=0.3)):
        load = _spectrum_load(spectrum, seed=3, tones=12)
        for h, tau_rate in ((1e-3, 0.0), (5e-3, 400.0), (0.05, -30.0)):
            split = load.advance_split(0.161, 0.37, 2.0, 36.6, 107.0, h, tau_rate, substeps)
            exact = load.advance(0.161, 0.37, 2.0, 36.6, 107.0, h, tau_rate)
            assert split == pytest.approx(exact, rel=1e-14, abs=1e-13)


def test_the_split_step_follows_the_order_terms_phase_and_refuses_a_runaway():
    load = _spectrum_load()
    shaft = Shaft(0.161, load, max_substep=1.0)
    assert shaft.split and load.advance(0.161, 0.0, 0.0, 36.6, 107.0, 1e-3) is None
    # at most PHASE_STEP = 0.25 rad of k*phi per substep: 1 at 37 rad/s and 6 ms, 24 at 1000 rad/s
    assert shaft._substeps(6e-3, 36.6) == 1
    assert shaft._substeps(6e-3, -1000.0) == 24
    assert Shaft(0.161, load)._substeps(1e-3, 36.6) == 4          # max_substep's default still bounds it
    with pytest.raises(ParameterError, match="order term at w = 1e\\+09 rad/s") as info:
        shaft.advance(0.0, 0.0, 1e9, 0.0, 1.0)
    assert info.value.name == "max_substep"



def test_a_shaft_spinning_up_within_a_step_takes_the_substeps_of_its_end_speed():
    # From rest under 2000 N.m the driven shaft reaches about 590 rad/s in 50 ms: the order
    # term's phase then turns by some 15 rad, which one substep from the start speed (0)
    # would not follow.  The step counts the speed it ends at, and agrees with fine RK4.
    load = _spectrum_load()
    shaft = Shaft(0.161, load, max_substep=1.0)
    counted = []
    original = load.advance_split

    def counting(*args):
        counted.append(args[-1])
        return original(*args)

    load.advance_split = counting
    got = shaft.advance(0.0, 0.0, 0.0, 2000.0, 0.05)
    want = _plain_rk4(_spectrum_load(), 1e-6).advance(0.0, 0.0, 0.0, 2000.0, 0.05)
    assert counted[0] >= 0.05 * 580.0 / SpectrumLoad.PHASE_STEP
    assert got[1] == pytest.approx(want[1], abs=1e-6) and got[0] == pytest.approx(want[0], abs=1e-7)
