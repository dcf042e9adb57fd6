"""What a timing on a busy machine may claim: ratios from runs made side by side, their
spread, and the checks that keep impossible figures out of `lever bench` and `lever hosts`
- all on synthetic timings (no test here times anything)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from harness.description import scene
from harness.engine.run import RunResult
from harness import peers
from harness.studies import bench, hosts, trust
from harness.studies.bench import Case


def test_the_pairwise_ratio_is_the_median_of_the_ratios_of_each_pair_with_their_range():
    # A and B measured in turn; the third pair ran during a load spike that slowed both
    a = [2.0, 2.2, 6.0, 2.1]
    b = [1.0, 1.0, 4.0, 1.0]
    r = trust.paired_ratio(a, b)
    assert r["ratios"] == pytest.approx([2.0, 2.2, 1.5, 2.1])
    assert r["median"] == pytest.approx(2.05) and (r["min"], r["max"], r["n"]) == (1.5, 2.2, 4)
    # the ratio of the medians would mix the spike into one side only
    assert r["median"] != pytest.approx(np.median(a) / np.median(b))
    assert not r["single_run"] and trust.ratio_text(r) == "2.05x [1.50-2.20x, 4 pairs]"
    one = trust.paired_ratio([3.0], [2.0])
    assert one["single_run"] and "a single run" in trust.ratio_text(one)
    with pytest.raises(ValueError, match="2 numerators against 1"):
        trust.paired_ratio([1.0, 2.0], [1.0])


def test_two_measurements_of_a_ratio_agree_when_their_ranges_overlap():
    quiet, busy = trust.paired_ratio([2.0, 2.1], [1.0, 1.0]), trust.paired_ratio([2.6, 2.0], [1.3, 1.05])
    assert trust.overlap(quiet, busy)
    assert not trust.overlap(quiet, trust.paired_ratio([3.0, 3.1], [1.0, 1.0]))


def test_a_split_with_a_share_below_zero_or_more_than_the_run_is_flagged():
    assert trust.split_problems({"crossing": 0.2, "slave": 0.3, "master": 0.5}, 1.0) == []
    negative = trust.split_problems({"crossing": 0.4, "slave": 0.9, "master": -0.3}, 1.0)
    assert negative[0] == "master share below zero (-30 %)"
    assert "exceed the run time" in negative[1]
    assert trust.split_problems({"crossing": 0.5, "slave": -0.15, "master": 0.65}, 1.0) == \
        ["slave share below zero (-15 %)"]


def test_a_case_whose_prices_were_taken_at_a_busier_moment_has_no_split_but_a_reason():
    prices = {"c": {"step": 60e-6, "get": 10e-6}}
    twins = {"c": {"step": 20e-6, "get": 5e-6}}
    # 1000 steps priced at 70 us each, in a run of 51 ms: the run cannot have cost less than its calls
    case = Case("jacobi", "master", 1e-3, wall_times=[0.05, 0.052], steps=1000, asked=2, load=[3.4, 3.6],
                calls_by_kind={"c": {"step": 1000, "get": 1000}},
                prices={"ours": [prices, prices], "hollow": [twins, twins]}, errors={"tau_rms": 1e-3})
    bench.split_case(case)
    assert case.split_unreliable.startswith("master share below zero (-37 %)")
    assert "machine too noisy (load average 3.40-3.60 on" in case.split_unreliable
    row = bench.table_row(case)
    assert row["crossing_s"] is row["slave_s"] is row["master_s"] is None
    text = bench.markdown({"claims": {"target_error": 1e-3, "time_at_target_s": {}}, "scene": "s", "repeats": 2,
                           "floor_per_step_s": 5e-5}, [row])
    assert "unreliable: master share below zero" in text and "-37 %" not in text.split("unreliable:")[0]


def test_a_floor_above_the_step_it_bounds_is_flagged_and_no_overhead_is_shown():
    assert trust.floor_problem(105e-6, 55e-6) == "the call floor (105.0 us) is above the step it bounds (55.0 us)"
    assert trust.floor_problem(40e-6, 55e-6) is None
    case = Case("jacobi", "master", 5e-5, wall_times=[0.55, 0.56], steps=10000, asked=2, floor_times=[105e-6, 90e-6],
                load=[2.9, 3.1], errors={"tau_rms": 1e-2})
    case.floor_time = 97.5e-6 * case.steps
    row = bench.table_row(case)
    assert "call floor" in row["unreliable"] and row["overhead_above_call_floor"] is None
    assert "machine too noisy" in row["unreliable"]


def test_a_figure_from_fewer_runs_than_asked_is_flagged_and_a_failed_case_is_not():
    long = Case("jacobi", "master", 7e-5, wall_times=[10.9], steps=142858, asked=3, load=[1.7, 2.0],
                errors={"tau_rms": 4e-2})
    row = bench.table_row(long)
    assert row["unreliable"].startswith("from 1 of 3 runs")
    text = bench.markdown({"claims": {"target_error": 1e-2, "time_at_target_s": {}}, "scene": "s", "repeats": 3,
                           "floor_per_step_s": 5e-5}, [row])
    assert "| unreliable | 1 of 3 |" in text and "10.900 s" not in text
    failed = Case("jacobi", "master", 1e-4, wall_times=[0.8], asked=3, failure="diverged")
    assert bench.table_row(failed)["unreliable"] is None


def _stiff_claims(rounds, repeats=3):
    spec = scene.load("kavz685_stiff")
    largest = Case("jacobi", "master", 7e-5, wall_times=[10.9], errors={"tau_rms": 4e-2}, asked=repeats,
                   energy_residual=1e-6)
    master = Case("trapezoidal-newton", "master", 2e-3, wall_times=[0.5], errors={"tau_rms": 5e-3}, asked=repeats,
                  energy_residual=1e-6)
    walls = {bench.case_key("master", "jacobi", 7e-5, None): rounds[0],
             bench.case_key("master", "trapezoidal-newton", 2e-3, None): rounds[1]}
    return bench.claims(spec, [largest, master], {"target_error": 1e-2, "baseline": "jacobi"},
                        rounds={"walls": walls, "hollow_floor": []})


def test_a_headline_ratio_comes_from_the_rounds_and_a_single_round_says_so():
    claims = _stiff_claims(([8.0, 11.0, 8.4], [0.5, 0.8, 0.6]))
    faster = claims["largest_stable_baseline_step"]["faster"]["trapezoidal-newton"]
    assert faster["ratios"] == pytest.approx([16.0, 13.75, 14.0]) and faster["median"] == pytest.approx(14.0)
    text = bench.markdown({"claims": claims, "scene": "kavz685_stiff", "repeats": 3, "floor_per_step_s": 5e-5}, [])
    assert "(14.0x [13.8-16.0x, 3 pairs] faster)" in text
    single = _stiff_claims(([8.0], [0.5]), repeats=1)
    text = bench.markdown({"claims": single, "scene": "kavz685_stiff", "repeats": 1, "floor_per_step_s": 5e-5}, [])
    assert "16.0x (a single run: no spread) faster" in text


def test_a_master_slower_than_the_baseline_is_said_to_be_slower():
    r = trust.paired_ratio([1.0, 1.0], [1.6, 1.8])      # 0.625x, 0.556x "faster"
    assert bench.faster_text(r) == "1.7x [1.6-1.8x, 2 pairs] slower"
    assert bench.faster_text(trust.paired_ratio([2.0], [1.0])) == "2.0x (a single run: no spread) faster"


def test_a_bound_above_the_ratio_it_bounds_is_flagged():
    assert "above the measured ratio" in trust.bound_problem(2.27, {"median": 1.54, "max": 2.9})
    assert trust.bound_problem(1.5, {"median": 1.54, "max": 1.6}) is None
    verdict = trust.judged(1.54, [trust.bound_problem(2.27, {"median": 1.54})], "machine too noisy (x)")
    assert verdict["value"] is None and verdict["measured"] == 1.54 and not verdict["reliable"]
    assert verdict["reason"].endswith(": machine too noisy (x)")


def _result(times, failure=None):
    spec = scene.load("kavz685")
    return RunResult(spec, "ecos", 5e-4, np.asarray(times), {}, 1.0, {}, failure)


def test_a_peer_that_made_another_number_of_steps_is_refused():
    spec = scene.load("kavz685")          # 0 to 10 s
    h = 5e-4
    # ecos's t += h: 19,999 steps, the last one dropped
    short = np.cumsum(np.r_[0.0, np.full(19999, h)])
    refused = peers.refuse_other_experiment(_result(short), "ecos", spec, h)
    assert not refused.ok and refused.failure == \
        "refused: peer ecos made 19999 steps of 0.0005 s, not the 20000 from 0 to 10 s; stopped at t = 9.9995 s, not 10 s"
    whole = np.arange(20001) * h
    assert peers.refuse_other_experiment(_result(whole), "ecos", spec, h).ok
    # an adaptive peer chooses its steps, but must reach the stop time
    assert peers.experiment_problem(np.array([0.0, 3.0, 7.5, 10.0]), spec, h, fixed_step=False) is None
    assert "stopped at t = 7.5 s" in peers.experiment_problem(np.array([0.0, 3.0, 7.5]), spec, h, fixed_step=False)
    # fmpy.ssp records no row at the start: its first row is after the first step
    assert peers.refuse_other_experiment(_result(whole[1:]), "fmpy-ssp", spec, h).ok
    assert not peers.refuse_other_experiment(_result(whole), "fmpy-ssp", spec, h).ok
    assert not peers.refuse_other_experiment(_result(whole[1:-1]), "fmpy-ssp", spec, h).ok
    # a failed run keeps its own diagnosis
    assert peers.refuse_other_experiment(_result(short[:10], "diverged"), "ecos", spec, h).failure == "diverged"


def test_lever_hosts_reports_the_ratio_round_by_round_with_the_load(monkeypatch):
    spec = scene.load("kavz685")
    walls = iter([1.0, 1.5, 2.0, 2.8, 1.0, 1.6])      # harness, libcosim; round after round

    class Result:
        ok, failure = True, None

        def __init__(self):
            self.wall_time = next(walls)

    monkeypatch.setattr(hosts.peers, "simulate_peer", lambda *a, **k: Result())
    report = hosts.time_hosts(spec, 1e-3, 3, hosts=("harness-jacobi", "libcosim-fixed"), log=lambda text: None)
    row = report["hosts"]["libcosim-fixed"]
    assert row["ratio_spread"]["ratios"] == pytest.approx([1.5, 1.4, 1.6]) and row["ratio"] == pytest.approx(1.5)
    assert (row["min_s"], row["max_s"]) == (1.5, 2.8)
    assert report["machine"]["cpus"] >= 1
    text = hosts.table(report)
    assert "1.50x [1.40-1.60x, 3 pairs]" in text and ("load average" in text or "load not known" in text)
    assert math.isfinite(report["hosts"]["harness-jacobi"]["ratio"])


def test_a_step_said_to_cost_less_than_a_master_that_cost_nothing_is_flagged():
    spec = scene.load("kavz685")                     # scene step 1 ms
    case = Case("jacobi", "master", 1e-3, wall_times=[1.0, 1.0, 1.0], asked=3, steps=1000, load=[2.0, 2.1],
                errors={"tau_rms": 1e-3}, split={"crossing": 0.2, "slave": 0.4, "master": 0.4})
    # the step against the do-nothing floor, round by round: 2.0x, 2.2x, 5.0x
    rounds = {"walls": {bench.case_key("master", "jacobi", 1e-3, None): [1.0, 1.0, 1.0]},
              "hollow_floor": [0.5e-3, 0.45e-3, 0.2e-3]}
    claims = bench.claims(spec, [case], {"target_error": 1e-3, "baseline": "jacobi"}, rounds=rounds,
                          machine={"cpus": 2, "load_min": 2.0, "load_max": 2.1, "load_median": 2.05, "samples": 2})
    step = claims["baseline_step"]
    assert step["ratio"]["median"] == pytest.approx(1e-3 / 0.45e-3)
    # the calls priced at our FMUs are 3x those priced at the twins: above the step's 2.2x
    assert step["bound_without_master"] == pytest.approx(3.0)
    assert "the bound without a master (3.00x) is above the measured ratio (2.22x)" in step["unreliable"]
    assert "machine too noisy (load average 2.00-2.10 on 2 CPUs" in step["unreliable"]
    text = bench.markdown({"claims": claims, "scene": "kavz685", "repeats": 3, "floor_per_step_s": 5e-5}, [])
    assert "against the do-nothing FMUs' floor: unreliable (" in text and "would take 3.00x" not in text
    case.split = {"crossing": 0.5, "slave": 0.4, "master": 0.1}          # 1.8x: below every round's ratio
    assert "unreliable" not in bench.claims(spec, [case], {"target_error": 1e-3, "baseline": "jacobi"},
                                            rounds=rounds)["baseline_step"]


def test_a_long_case_run_once_says_why_and_does_not_blame_the_machine():
    case = Case("ecos", "peer", 2.5e-4, wall_times=[7.36], steps=40000, asked=3, load=[1.21, 1.25],
                errors={"tau_rms": 1e-3})
    row = bench.table_row(case)
    assert row["unreliable"].startswith("from 1 of 3 runs (one took 7.36 s: a long case is not repeated): "
                                        "the machine (load average 1.21-1.25 on"), row["unreliable"]
    assert "too noisy" not in row["unreliable"]


def test_an_idle_machine_whose_repeats_agree_is_not_blamed():
    """A figure left aside on a machine below one process a CPU, its repeats within a quarter
    of each other, says what the machine was and does not call it noisy; busier, or with
    repeats spread wider, it does."""
    idle = {"cpus": 2, "load_min": 1.49, "load_max": 1.53}
    steady = trust.spread([1.93, 2.0, 2.06])
    assert trust.noise(idle, steady) == ("not the machine's noise (load average 1.49-1.53 on 2 CPUs; repeats "
                                         "spread 1.930 s-2.060 s over 3 runs)")
    assert trust.noise(idle, trust.spread([0.6, 0.7, 0.96])).startswith("machine too noisy")
    assert trust.noise({"cpus": 2, "load_min": 1.9, "load_max": 2.1}, steady).startswith("machine too noisy")
    assert trust.noise(None, steady).startswith("machine too noisy")
