"""The work-precision benchmark: error against run time for every way the harness can
step a scene, next to other co-simulation engines on the same FMUs, the monolithic
solution and the FMU-call floor (``lever bench [SCENE]``); and what the FMUs' FMI 3.0
editions cost beside their FMI 2.0 ones (floor, call prices, a run, side by side).

Each case runs ``repeats`` times; the run time quoted is the median [min-max] of the
stepping loops (instantiation left out, for every engine alike).  What is divided by what
(a master and its baseline, a master and DOP853, a step and the do-nothing floor) is measured
side by side: the cases a headline ratio divides run again in turn, round after round
(``measure_rounds``), and the ratio is the median of the rounds' ratios with their range.  A
master's FMU-call floor is timed just before each of its runs and its call prices just before
and after them; a fixed-step co-simulation master's run is also divided by the floor of its
own calls (``replay``: the calls of the run, recorded once, replayed alone just before each
run).  A figure that cannot be (a share below zero, a floor above the step it bounds,
a figure from fewer runs than asked) is flagged with the machine's load and the spread, not
shown (``harness.studies.trust``).  Errors are measured once
(runs are deterministic) against the tight monolithic reference on the run's own
communication grid: time-averaged RMS and max of the torques and speeds (``coupling.tau1``,
``coupling.tau2``, ``engine.w``, ``load.w``; a case's ``tau_rms`` the larger of the torques')
relative to the mean torque and speed, over the whole run and after the scene's start-up transient, and
the energy residual.

The plan comes from the scene's ``[bench]`` table (steps per master, tolerances for
adaptive ones and the Model Exchange master, the output grid of a tolerance run where the
master records on a grid (``output_steps``), peers, the monolithic tolerances - scipy's
DOP853 (``monolithic_rtol``) and CVODE (``monolithic_cvode_rtol``) on the unsplit equations -,
the target error); masters it does not name are left out.

The package, one module a job: ``schedule`` (the plan, the Case, the case log), ``timing``
(running and timing the cases, the side-by-side rounds), ``floors`` (the FMU-call floor and
call prices, the time split), ``replay`` (a run's own calls recorded and replayed: the
floor of that run), ``master_time`` (the master's own time, measured in runs with every call timed), ``do_nothing_twins`` (the FMUs' do-nothing twins the floor and
the split are also timed on), ``editions`` (the FMUs' FMI 2.0 and FMI 3.0 editions side by
side: floor, call prices, a run), ``headlines`` (the claims and what is no result),
``report`` (tables, bench.md/bench.json/bench.csv, the plot) and ``study`` (the whole
benchmark in order).  What other modules use is named here.
"""
from harness.studies.bench.editions import compare as compare_editions
from harness.studies.bench.floors import CALL_KINDS, call_floor, call_prices, time_split
from harness.studies.bench.headlines import (bracket, case_noise, case_problems, claims, eigenfrequency,
                                             headline_cases, interpolate, overhead_above_floor,
                                             overhead_above_own_calls, split_case, time_at_error)
from harness.studies.bench.report import (COLUMNS, default_out, faster_text, machine_text, markdown, plot,
                                          summary_lines, table_row, write)
from harness.studies.bench.schedule import Case, check as check_plan, fingerprint, plan
from harness.studies.bench.study import bench
from harness.studies.bench.timing import measure_rounds, run_master, run_monolithic, run_peer
from harness.studies.cases import case_key

__all__ = ["CALL_KINDS", "COLUMNS", "Case", "bench", "bracket", "call_floor", "call_prices", "case_key", "check_plan",
           "case_noise", "case_problems", "claims", "compare_editions", "default_out", "eigenfrequency",
           "faster_text", "fingerprint",
           "headline_cases", "interpolate", "machine_text", "markdown", "measure_rounds", "overhead_above_floor",
           "overhead_above_own_calls",
           "plan", "plot", "run_master", "run_monolithic", "run_peer", "split_case", "summary_lines", "table_row",
           "time_at_error", "time_split", "write"]
