"""Shared fixtures of the test suite."""
from __future__ import annotations

import os
import signal
import sys
from pathlib import Path

import pytest

from lever.fmus.registry import NAMES as FMU_NAMES

TESTS = Path(__file__).resolve().parent
REPO = TESTS.parent

#: The suite's cache (harness.cache: the references, the do-nothing twins), never the user's
#: own: one folder that every worker of a run shares and the runs after it keep, as a user's
#: cache is kept (a reference solved once serves every test that judges against it; an edit
#: of the code keys new entries, and a run starts by removing those of older code).  Set here, at import, in the controller and in each
#: worker alike, and inherited by every `lever` a test starts.
TEST_CACHE = REPO / "build" / "tmp" / "test-cache"
os.environ["LEVER_CACHE_DIR"] = str(TEST_CACHE)


#: Tests whose outcome could move with numpy's SIMD dispatch: they compare what went through
#: numpy's vectorised functions, reductions or FFTs with the physics' standard-library results,
#: with scipy or fmpy, or with committed numbers, exactly or close to rounding.  They get the
#: marker ``numerics``; `make test` runs them again with numpy's dispatch limited to each
#: lower level this CPU has (tests/numpy_dispatch.py, docs/testing.md).
NUMERICS = (
    "physics/test_loads_and_shafts.py::test_random_load_draws_are_numpys_default_rng_bit_for_bit",
    "physics/test_loads_and_shafts.py::test_random_load_scalar_resistance_is_the_multisine",
    "physics/test_loads_and_shafts.py::test_random_load_stays_within_its_bound",
    "physics/test_kinematics.py::test_pairwise_sum_is_numpys_sum_bit_for_bit",
    "physics/test_kinematics.py::test_the_standard_library_fft_agrees_with_numpy_to_rounding",
    "physics/test_kinematics.py::test_standard_library_real_ffts_agree_with_numpy",
    "physics/test_kinematics.py::test_position_derivative_is_the_transfer_function",
    "physics/test_kinematics.py::test_kinematic_mode_is_the_renormalised_half_coupling_ratio",
    "physics/test_kinematics.py::test_the_reported_amplitude_fit_agrees_with_scipy",
    "physics/test_coupling_physics.py::test_torques_are_minus_t_and_u12_t",
    "oracle/test_oracle_physics.py::test_monotone_cubic_slopes_are_scipys_pchip_on_uneven_tables",
    "oracle/test_oracle_closed_forms.py::test_stability_edges_table_of_the_docs",
    "judges/test_validate.py::test_band_is_fmpys_with_the_cross_check_figures",
    "judges/test_validate.py::test_cross_check_fraction_is_fmpys_validate_result",
    "judges/test_validate.py::test_lever_reference_reports_every_committed_trace_current",
)

#: Test files whose tests run the built FMUs from where the harness looks for them
#: (harness.paths.FMUS) without asking for ``fmu_dir``: the FMUs are built, or found current,
#: before each of their tests (``_built_fmus``).
RUN_BUILT_FMUS = (
    "engine/test_cosim.py",
    "engine/test_event_scenes.py",
    "engine/test_extreme.py",
    "engine/test_fmi3_scenes.py",
    "formats/test_plots.py::test_a_time_view_zooms_the_judged_window_to_its_values",
    "project/test_docs.py::test_every_command_and_option_the_guide_shows_exists",
    "formats/test_plots.py::test_an_impulse_at_the_start_is_left_off_the_overviews_scale_and_its_peaks_named",
    "formats/test_plots.py::test_log_ticks_are_plain_numbers_that_do_not_run_into_each_other",
    "formats/test_plots.py::test_the_sweeps_plot_puts_the_monographs_points_on_the_models_axes_and_says_the_gap",
    "judges/test_fmu_reference.py::test_errors_against_the_made_references_agree_with_the_monolithic_ones",
    "judges/test_fmu_reference.py::test_a_run_off_the_reference_grid_is_read_by_spline_with_its_error_added",
    "judges/test_fmu_reference.py::test_the_extrapolation_is_refused_when_the_runs_do_not_show_the_masters_order",
    "judges/test_fmu_reference.py::test_the_made_reference_is_cached_by_the_scene",
    "judges/test_fmu_reference.py::test_a_users_fmu_without_units_connects_and_is_judged_against_the_extrapolated_reference",
    "judges/test_fmu_reference.py::test_a_run_with_no_reference_to_be_had_says_so_in_one_line",
    "engine/test_iteration_and_adaptive.py",
    "engine/test_masters.py",
    "engine/test_me_events.py",
    "engine/test_model_exchange_master.py",
    "fmus/test_dropin.py",
    "formats/test_peers.py",
    "judges/test_stability.py",
    "oracle/test_oracle_closed_forms.py",
    "studies/test_bench.py",
)

#: What ``make test-fast`` (``pytest -m "not slow"``) leaves out: a test file, or a test of one,
#: that took 0.5 s or more in total (all its parameters, set-up included) in a whole run with
#: ``--durations=0`` on the shared two-core machine (docs/testing.md).  The rest keeps tests of
#: every folder (tests/project/test_suite_lists.py).
SLOW = (
    "judges/test_verdict_samples.py::test_the_stated_power_is_true_for_every_committed_reference",
    "cli/test_validate_reference.py",
    "project/test_validate_pages.py",
    "judges/test_verdict_closed_forms.py::test_the_stated_power_is_the_smallest_change_that_fails_by_hand",
    "judges/test_verdict_closed_forms.py::test_the_stated_time_shift_is_where_the_highest_order_turns_past_its_tolerance",
    "judges/test_verdict_closed_forms.py::test_a_mean_tolerance_beyond_the_signals_own_size_is_stated_as_it_is",
    "judges/test_stiff_switch.py",
    "judges/test_fmu_reference_own_error.py",
    "studies/test_cvode_host_grid.py",
    "studies/test_replay.py::test_a_run_is_not_faster_than_the_replay_of_its_own_calls",
    "studies/test_replay.py::test_a_slower_harness_shows_in_the_run_side_by_side",
    "description/test_plan_start_and_record.py",
    "formats/test_ssp_export_twice.py",
    "description/test_physics_checked_once.py::test_a_run_checks_each_components_parameters_once",
    "judges/test_verdict.py::test_a_changed_coupling_fails_on_the_five_columns_another_tool_gives",
    "formats/test_run_identity.py",
    "judges/test_verdict.py::test_verdict_json_is_standard_and_carries_the_power",
    "judges/test_verdict.py::test_a_result_with_some_signals_is_judged_on_those_and_lists_the_rest",
    "fmus/test_fmi3.py",
    "engine/test_fmi3_scenes.py",
    "engine/test_event_scenes.py",
    "engine/test_me_events.py",
    "fmus/test_load_events.py",
    "cli/test_api.py::test_a_run_gives_its_traces_as_an_array_and_its_summary_and_writes_nothing",
    "cli/test_api.py::test_the_command_line_goes_through_the_api",
    "cli/test_api.py::test_the_example_script_runs",
    "cli/test_api.py::test_validate_judges_given_traces_over_a_window",
    "cli/test_api.py::test_numpy_scalars_are_numbers",
    "cli/test_notebook.py::test_the_example_notebook_runs_and_shows_what_it_says",
    "cli/test_guide_output.py::test_getting_started_shows_what_the_run_prints",
    "cli/test_every_scene.py::test_the_api_without_out_returns_the_run_with_its_kinds_summary",
    "cli/test_every_scene.py::test_the_api_with_out_writes_the_summary_the_api_returns",
    "cli/test_every_scene.py::test_lever_run_writes_every_scene",
    "cli/test_every_scene.py::test_a_streamed_run_of_each_kind_draws_its_kinds_plots",
    "judges/test_cache.py::test_a_run_and_a_bench_of_a_users_scene_leave_the_checkout_as_it_was",
    "judges/test_cache.py::test_an_edit_of_any_module_a_reference_runs_changes_the_digest",
    "judges/test_cache.py::test_the_digest_reads_every_module_a_reference_runs",
    "judges/test_cache.py::test_the_made_reference_the_twins_and_the_case_logs_are_keyed_on_the_code",
    "judges/test_cache.py::test_the_benchs_twins_go_to_the_cache",
    "cli/test_command_line.py::test_a_study_says_how_long_it_will_take_before_it_runs",
    "cli/test_command_line.py::test_a_run_without_plots_lists_no_plots",
    "cli/test_command_line.py::test_a_sweep_says_how_long_it_will_take_before_it_runs",
    "cli/test_command_line.py::test_step_and_stop_take_units_as_the_api_does",
    "studies/test_signal_names.py::test_the_sweeps_files_name_the_signals_as_the_traces_do",
    "cli/test_input_safety.py::test_a_bad_set_value_is_exit_2_and_a_sentence",
    "cli/test_input_safety.py::test_a_value_of_the_wrong_type_in_a_scene_file_is_refused",
    "cli/test_input_safety.py::test_an_unconnected_input_is_named_in_the_output_and_the_report",
    "cli/test_input_safety.py::test_cli_fuzz_csvs",
    "cli/test_input_safety.py::test_cli_fuzz_scene_files",
    "cli/test_input_safety.py::test_cli_fuzz_set_values",
    "cli/test_input_safety.py::test_ssp_units_are_converted_or_refused_never_ignored",
    "cli/test_input_safety.py::test_validate_result_fails_a_trace_with_nan_inf_or_absurd_samples",
    "engine/test_cosim.py::test_cli_bad_experiment_override_exits_2",
    "engine/test_cosim.py::test_cli_bad_parameter_exits_2_with_a_message",
    "engine/test_cosim.py::test_cli_failing_run_exits_1_and_keeps_the_rows_before_the_failure",
    "engine/test_cosim.py::test_cli_no_reference_run",
    "engine/test_cosim.py::test_cli_short_run_writes_the_results",
    "engine/test_cosim.py::test_cli_user_errors_exit_2_without_traceback",
    "engine/test_cosim.py::test_kavz685_default_scene_meets_its_accuracy_targets",
    "engine/test_cosim.py::test_masters_converge_to_the_reference_at_first_order",
    "engine/test_cosim.py::test_masters_step_the_same_system_differently",
    "engine/test_cosim.py::test_reference_cache_returns_what_was_solved",
    "engine/test_cosim.py::test_reference_energy_balance_is_exact",
    "engine/test_cosim.py::test_reference_handles_a_tabulated_engine_characteristic",
    "engine/test_cosim.py::test_same_seed_same_traces_other_seed_other_traces",
    "engine/test_cosim.py::test_synchronous_steady_state_is_the_analytic_one",
    "engine/test_determinism.py::test_same_scene_seed_and_master_give_identical_traces",
    "engine/test_determinism.py::test_serialised_state_restored_mid_run_continues_bit_identically",
    "engine/test_extreme.py::test_lever_run_exits_nonzero_with_the_diagnosis_and_the_traces",
    "engine/test_extreme.py::test_load_above_stall_torque_reverses_the_drive_without_nan",
    "engine/test_extreme.py::test_misalignment_at_the_edge_runs_and_matches_the_reference",
    "engine/test_extreme.py::test_misalignment_beyond_the_edge_is_refused_by_name",
    "engine/test_extreme.py::test_plateau_law_is_the_papers_and_the_run_crosses_both_plateaus",
    "engine/test_extreme.py::test_step_load_on_a_tiny_inertia",
    "engine/test_extreme.py::test_stiff_undamped_coupling_is_stable_with_the_trapezoidal_master",
    "engine/test_extreme.py::test_time_varying_misalignment_follows_its_source_and_the_reference",
    "engine/test_extreme.py::test_time_varying_misalignment_past_the_edge_stops_with_the_couplings_refusal",
    "engine/test_interrupts.py::test_a_second_ctrl_c_while_writing_stops_and_names_what_is_missing",
    "engine/test_interrupts.py::test_bench_interrupted_logs_the_case_and_resumes",
    "engine/test_interrupts.py::test_ctrl_c_while_plotting_keeps_the_plots_drawn",
    "engine/test_interrupts.py::test_ctrl_c_while_solving_the_reference_writes_the_run_without_it",
    "engine/test_interrupts.py::test_ctrl_c_while_stepping_writes_the_part_computed",
    "engine/test_interrupts.py::test_ctrl_c_while_writing_a_freewheel_run",
    "engine/test_interrupts.py::test_ctrl_c_while_writing_the_summary_finishes_every_file",
    "engine/test_interrupts.py::test_ctrl_c_while_writing_the_traces_finishes_them_and_names_the_plots_not_drawn",
    "engine/test_interrupts.py::test_dask_sweep_interrupted_logs_the_case_under_way",
    "engine/test_interrupts.py::test_run_interrupted_keeps_the_computed_part",
    "engine/test_interrupts.py::test_run_interrupted_while_streaming_keeps_valid_traces",
    "engine/test_interrupts.py::test_stability_interrupted_stops_its_workers_and_resumes",
    "engine/test_interrupts.py::test_sweep_interrupted_keeps_finished_cases",
    "engine/test_iteration_and_adaptive.py::test_adaptive_master_meets_its_tolerance_on_kavz",
    "engine/test_iteration_and_adaptive.py::test_adaptive_trapezoidal_keeps_its_step_where_the_stiff_mode_is_unresolved",
    "engine/test_iteration_and_adaptive.py::test_adaptive_trapezoidal_meets_its_tolerance_on_the_stiff_start",
    "engine/test_iteration_and_adaptive.py::test_adaptive_trapezoidal_steps_grow_back_after_an_event",
    "engine/test_iteration_and_adaptive.py::test_iterative_masters_reach_their_tolerance_every_step",
    "engine/test_iteration_and_adaptive.py::test_trapezoidal_coupling_conserves_the_spring_energy",
    "engine/test_masters.py::test_extrapolating_masters_send_the_polynomial_ahead_in_the_calls_of_jacobi",
    "engine/test_masters.py::test_linear_extrapolation_beats_zero_order_hold_on_kavz",
    "engine/test_masters.py::test_master_converges_at_its_promised_order",
    "engine/test_model_exchange_master.py::test_a_co_simulation_only_fmu_is_refused_before_anything_runs",
    "engine/test_model_exchange_master.py::test_an_algebraic_loop_is_refused_naming_it",
    "engine/test_model_exchange_master.py::test_ctrl_c_stops_it_at_an_output_point",
    "engine/test_model_exchange_master.py::test_fmi_calls_are_counted_by_kind",
    "engine/test_model_exchange_master.py::test_kavz685_agrees_with_cvode_on_the_unsplit_equations",
    "engine/test_model_exchange_master.py::test_lever_run_says_the_method_and_takes_the_tolerance",
    "engine/test_model_exchange_master.py::test_state_events_stick_and_slip_like_the_reference",
    "engine/test_model_exchange_master.py::test_the_stability_analysis_chooses_as_the_master_does_on_the_stiff_scenes",
    "engine/test_model_exchange_master.py::test_the_analytic_jacobian_saves_fmi_calls_on_the_stiff_scene",
    "engine/test_model_exchange_master.py::test_the_divergence_guard_stops_it",
    "engine/test_model_exchange_master.py::test_the_stiff_scenes",
    "engine/test_model_exchange_master.py::test_time_events_of_a_misalignment_table",
    "engine/test_own_fmu.py::test_an_fmu_by_path_relative_or_absolute",
    "engine/test_own_fmu.py::test_lever_run_stop_shortens_the_run_and_the_report_says_what_it_judged",
    "engine/test_own_fmu.py::test_the_archive_runs_in_fmpy_ssp",
    "engine/test_own_fmu.py::test_the_archive_runs_in_lever_run",
    "engine/test_own_fmu.py::test_the_archive_runs_in_libcosim",
    "engine/test_own_fmu.py::test_the_mixed_scene_runs_and_the_driveline_is_untouched",
    "engine/test_traces.py::test_a_run_killed_part_way_leaves_valid_traces",
    "engine/test_traces.py::test_streamed_run_equals_the_ordinary_run",
    "fmus/test_badinputs.py::test_bad_input_is_refused_with_a_message",
    "fmus/test_dropin.py::test_a_c_host_calling_from_several_threads_gets_the_same_numbers",
    "fmus/test_dropin.py::test_a_c_host_in_a_bare_environment_runs_each_fmu",
    "fmus/test_dropin.py::test_a_c_host_on_a_bare_system_cpython",
    "fmus/test_dropin.py::test_a_c_host_on_the_oldest_supported_cpython",
    "fmus/test_dropin.py::test_each_fmu_alone_in_libcosim_matches_our_harness_and_the_physics",
    "fmus/test_dropin.py::test_every_file_uri_form_locates_the_resources",
    "fmus/test_dropin.py::test_kavz_run_in_libcosim_passes_lever_validate_at_its_stated_tolerance",
    "fmus/test_dropin.py::test_fmpy_ssp_runs_a_string_parameter_the_archives_fmus_carry",
    "fmus/test_dropin.py::test_lever_check_finds_nothing_in_a_built_fmu",
    "fmus/test_dropin.py::test_lever_engines_writes_the_table",
    "fmus/test_dropin.py::test_lever_run_and_export_on_the_command_line",
    "fmus/test_dropin.py::test_libcosim_connects_the_osp_ports_as_the_api_connects_the_variables",
    "fmus/test_dropin.py::test_libcosim_from_ssp_is_libcosim_from_the_api",
    "fmus/test_dropin.py::test_ssp_export_loads_back_as_the_same_scene_and_validates_in_fmpy",
    "fmus/test_dropin.py::test_the_container_fmu_is_the_driveline_as_one_block",
    "fmus/test_dropin.py::test_the_exported_scene_runs_in_another_engine_within_tolerance",
    "fmus/test_dropin.py::test_the_host_process_ends_without_touching_freed_memory",
    "fmus/test_dropin.py::test_two_instances_of_each_fmu_in_one_process_do_not_interfere",
    "fmus/test_fmi_boundary_native.py::test_instantiate_free_cycles_do_not_accumulate_memory",
    "fmus/test_fmus.py::test_a_serialized_state_continues_exactly_wherever_it_is_restored",
    "fmus/test_fmus.py::test_every_fmu_validates_without_findings",
    "fmus/test_fmus.py::test_the_model_runs_on_the_standard_library_alone",
    "fmus/test_hosts.py::test_ecos_applies_the_exported_parameter_values",
    "fmus/test_hosts.py::test_ecos_couples_as_libcosim_does_one_step_behind_our_jacobi",
    "fmus/test_hosts.py::test_ecos_logging_every_variable_of_an_fmi3_edition_logs_its_event_indicators",
    "fmus/test_hosts.py::test_ecos_runs_each_fmu_alone_in_a_bare_environment",
    "fmus/test_hosts.py::test_ecos_runs_each_fmi3_edition_alone_as_the_fmi2_edition",
    "fmus/test_hosts.py::test_ecos_runs_the_fmi3_misalignment_source_to_its_reference",
    "fmus/test_hosts.py::test_lever_hosts_writes_the_table",
    "fmus/test_host_recipes.py::test_each_recipes_result_passes_the_default_verdict_in_its_host",
    "fmus/test_host_recipes.py::test_a_host_that_writes_no_result_is_an_error_not_a_verdict",
    "fmus/test_hosts.py::test_lever_hosts_refuses_the_hosts_that_cannot_run_an_fmi3_scene_before_anything_runs",
    "fmus/test_hosts.py::test_the_kavz685_scene_in_ecos_passes_lever_validate_at_its_stated_step",
    "fmus/test_me_hosts.py::test_fmpy_model_exchange_cvode_passes_lever_validate",
    "fmus/test_me_cvode_roots.py",
    "cli/test_untrusted_runs.py::test_an_untrusted_run_says_so_and_exits_3",
    "fmus/test_me_hosts.py::test_the_c_importers_model_exchange_loop_passes_lever_validate",
    "fmus/test_me_hosts.py::test_the_c_importers_fmi3_model_exchange_loop_passes_lever_validate",
    "fmus/test_me_hosts.py::test_the_c_importers_fmi3_co_simulation_passes_lever_validate_as_fmi2",
    "fmus/test_library_use.py::test_validate_then_run_in_one_process_keeps_the_fmus_messages",
    "fmus/test_resources.py",
    "fmus/test_shim.py::test_a_build_started_while_another_builds_waits_and_finds_its_fmus_current",
    "fmus/test_shim.py::test_shim_exports_the_cs_api_only",
    "fmus/test_step_time.py::test_a_million_steps_of_each_hosts_clock_are_accepted",
    "fmus/test_step_watchdog.py",
    "formats/test_outputs.py::test_a_failed_run_leaves_no_reference_of_an_earlier_one",
    "formats/test_outputs.py::test_a_lever_run_of_an_archive_leaves_no_unpacked_copy",
    "formats/test_outputs.py::test_a_rerun_removes_what_it_does_not_write_and_the_report_names_what_exists",
    "formats/test_outputs.py::test_a_second_writer_is_refused_and_the_lock_dies_with_its_holder",
    "formats/test_peers.py::test_all_peers_are_available",
    "formats/test_peers.py::test_ecos_runs_the_scene_as_a_peer",
    "formats/test_peers.py::test_a_peer_refuses_fmus_of_an_fmi_version_it_does_not_run_and_says_why",
    "formats/test_peers.py::test_ecos_runs_the_fmi3_editions_as_the_fmi2_ones",
    "formats/test_peers.py::test_ecos_logging_everything_never_gives_zeros_for_an_fmi3_scene",
    "formats/test_peers.py::test_fmpy_jacobi_runs_the_fmi3_editions_as_the_fmi2_ones",
    "formats/test_peers.py::test_fmpy_jacobi_says_what_an_fmi3_fmu_refused",
    "formats/test_peers.py::test_libcosim_refuses_an_fmi3_fmu_itself_as_its_peers_say",
    "formats/test_peers.py::test_what_stops_a_peer_is_said_before_anything_runs",
    "formats/test_peers.py::test_libcosim_reports_a_refused_parameter_instead_of_crashing",
    "formats/test_peers.py::test_libcosim_runs_our_fmus",
    "formats/test_peers.py::test_every_peer_keeps_the_contract",
    "formats/test_ssp_engines.py",
    "formats/test_ssp_export.py::test_each_fmu_in_the_archive_starts_at_the_scenes_values_with_a_guid_of_its_own",
    "formats/test_ssp_export.py::test_every_ssd_ssv_and_ssm_file_is_valid_against_the_ssp_schemas",
    "formats/test_ssp_export.py::test_the_archive_loads_back_with_its_scene_annotation_where_it_is_now_and_where_it_was",
    "formats/test_ssp_export.py::test_the_ssd_is_what_omsimulator_adds_as_a_weakly_coupled_system",
    "judges/test_revolutions.py::test_the_plot_files_over_the_angle",
    "judges/test_coupling_stability.py::test_the_measured_eigenfrequency_is_the_one_of_the_fmus_equations",
    "judges/test_coupling_stability.py::test_the_advisor_warns_and_the_stiff_run_ends_diverged_with_its_traces",
    "judges/test_coupling_stability.py::test_the_guard_bounds_both_coupling_speeds_from_our_engine_line",
    "judges/test_coupling_stability.py::test_the_map_of_the_user_scene_agrees_with_the_observed_classes",
    "judges/test_coupling_stability.py::test_the_bench_ladder_of_a_scene_without_bench",
    "judges/test_coupling_stability.py::test_a_scene_without_our_coupling_is_told_what_the_analysis_needs",
    "judges/test_coupling_stability.py::test_an_fmu_refusing_its_probes_is_named_with_why",
    "judges/test_coupling_stability.py::test_a_long_probe_says_its_estimate_first",
    "judges/test_coupling_stability.py::test_an_fmu_offering_model_exchange_is_linearised_and_predicts_as_our_own",
    "studies/test_unpredicted_stability_map.py",
    "judges/test_stability.py::test_advisor_warns_and_proposes_stable_choices",
    "judges/test_stability.py::test_lever_run_prints_the_advice",
    "judges/test_stability.py::test_lever_stability_runs_and_resumes",
    "judges/test_stability.py::test_midpoint_edge_with_the_accelerations_of_the_current_torques",
    "judges/test_stability.py::test_predicted_growth_rate_matches_the_real_run",
    "judges/test_stability.py::test_stand_in_steps_like_the_real_fmus",
    "judges/test_stability.py::test_stand_in_with_a_viscous_load_steps_like_the_real_fmus",
    "judges/test_validate.py::test_a_result_shifted_in_time_gets_a_verdict_not_a_traceback",
    "judges/test_validate.py::test_a_window_judges_a_shorter_result_and_the_verdict_names_the_span",
    "judges/test_validate.py::test_an_fmu_file_validates_stand_alone_as_its_models_name_does",
    "judges/test_validate.py::test_every_fmu_and_scene_validates_against_its_reference",
    "judges/test_validate.py::test_external_csv_of_a_scene_passes_and_a_lagging_one_fails",
    "judges/test_validate.py::test_external_csv_of_an_fmu_with_prefixed_columns",
    "judges/test_validate.py::test_lever_reference_reports_every_committed_trace_current",
    "judges/test_validate.py::test_a_references_head_is_the_whole_references_first_rows",
    "judges/test_validate.py::test_measured_option_checks_a_grade",
    "judges/test_validate.py::test_stiffer_coupling_in_the_scene_fails_the_deflection_and_the_ripple_not_the_mean_torque",
    "oracle/test_oracle_accuracy.py::test_each_master_keeps_its_measured_accuracy_on_the_default_scene",
    "oracle/test_oracle_closed_forms.py::test_fmu_cosimulation_grows_at_the_hand_derived_zoh_rate",
    "oracle/test_oracle_closed_forms.py::test_stability_edges_table_of_the_docs",
    "oracle/test_oracle_closed_forms.py::test_steady_speed_is_m1_minus_mm_over_k1",
    "oracle/test_oracle_monograph.py::test_kinematic_amplitudes_of_model_md",
    "oracle/test_oracle_monograph.py::test_scaled_mode_reproduces_the_printed_fig_3_7_amplitudes",
    "oracle/test_oracle_ranges.py::test_each_bound_is_enforced_by_the_fmu",
    "oracle/test_oracle_ranges.py::test_every_declared_bound_is_exactly_what_the_fmu_accepts",
    "oracle/test_oracle_stability_models.py::test_the_advisor_analyses_a_tabulated_engine_with_its_hand_derived_slope",
    "oracle/test_oracle_states.py",
    "oracle/test_oracle_stop_time.py::test_a_fixed_step_run_ends_exactly_at_its_stop_time",
    "oracle/test_oracle_stop_time.py::test_an_adaptive_run_ends_exactly_at_its_stop_time",
    "physics/test_coupling_physics.py::test_deflection_rate_is_the_time_derivative_of_the_deflection",
    "physics/test_coupling_physics.py::test_power_balance_along_a_trajectory",
    "physics/test_coupling_physics.py::test_torques_are_minus_t_and_u12_t",
    "physics/test_engine_lag.py::test_stand_in_with_a_lag_steps_like_the_real_fmus",
    "physics/test_engine_lag.py::test_the_line_with_a_lag_steps_exactly_at_any_lag",
    "physics/test_engine_lag.py::test_the_reference_and_the_fmus_agree_on_a_lagged_run_up",
    "physics/test_freewheel.py::test_energy_balance_with_the_output_free_and_a_slipping_brake",
    "physics/test_freewheel.py::test_fmu_validates_and_declares_units_ranges_and_a_shaft_port",
    "physics/test_freewheel.py::test_scene_reproduces_the_stop_mode_test",
    "physics/test_fuzz.py",
    "physics/test_kinematics.py::test_kinematic_mode_is_the_renormalised_half_coupling_ratio",
    "physics/test_kinematics.py::test_position_derivative_is_the_transfer_function",
    "physics/test_kinematics.py::test_position_function_periodicity_and_origin",
    "physics/test_kinematics.py::test_scaled_amplitude_is_the_reported_amplitude",
    "physics/test_kinematics.py::test_unit_mean_and_periodicity_property",
    "physics/test_kinematics.py::test_unit_mean_over_a_revolution",
    "physics/test_loads_and_shafts.py::test_exact_engine_step_matches_fine_rk4_and_solve_ivp",
    "physics/test_me_physics.py::test_coupling_partials_equal_central_differences",
    "physics/test_me_physics.py::test_driveline_jacobian_equals_central_differences",
    "physics/test_me_physics.py::test_me_derivatives_are_the_reference_right_hand_side_bit_for_bit",
    "physics/test_me_physics.py::test_me_derivatives_with_a_misalignment_source_are_the_reference_right_hand_side",
    "project/test_install.py",
    "project/test_layers.py::test_no_import_circle_among_harness_modules",
    "project/test_layers.py::test_no_private_name_is_used_outside_its_module",
    "studies/test_do_nothing_twins.py",
    "studies/test_bench.py::test_bench_records_failed_cases_goes_on_and_resumes",
    "studies/test_bench.py::test_the_fmi_editions_are_measured_in_turn_round_by_round",
    "studies/test_bench.py::test_small_bench_writes_its_table_plot_and_claims",
    "studies/test_bench.py::test_the_floor_loops_carry_the_values_so_the_models_run_the_scenes_motion",
    "studies/test_latency.py::test_lever_run_latency_writes_the_table",
    "studies/test_measured.py::test_a_new_measurement_is_checked_the_same_way",
    "studies/test_measured.py::test_brake_reading_tends_to_the_transmitted_one_as_the_gauge_nears_the_coupling",
    "studies/test_measured.py::test_lever_measured_reports_every_grade",
    "studies/test_sweep.py::test_a_failed_cases_multi_line_error_stays_in_its_table_cell",
    "studies/test_sweep.py::test_local_sweep_keeps_failures_and_resumes",
    "studies/test_sweep.py::test_sweep_on_a_dask_cluster",
)

#: What runs alone, after the rest of `make test` ran on every core (``pytest -n``, marker
#: ``serial``): tests whose verdict rests on wall-clock time that other tests beside them would
#: stretch.  Everything else is safe side by side: it writes under its own ``tmp_path``, takes no
#: fixed port, and shares the FMUs only once they are built (build/fmus.py locks a build), so
#: a new test needs no entry here (docs/testing.md).
SERIAL = (
    # the time to stop after SIGINT compared with a whole run timed after it (a neighbour's load
    # between the two moves the ratio), or bounded in seconds, or SIGINT sent a fixed time in
    "engine/test_interrupts.py::test_run_interrupted_keeps_the_computed_part",
    "engine/test_interrupts.py::test_stability_interrupted_stops_its_workers_and_resumes",
    "engine/test_interrupts.py::test_sweep_interrupted_keeps_finished_cases",
    # a run's time over its replay's, timed in turns: a neighbour taking a core moves each turn
    "studies/test_replay.py::test_a_run_is_not_faster_than_the_replay_of_its_own_calls",
    "studies/test_replay.py::test_a_slower_harness_shows_in_the_run_side_by_side",
)

#: Work that several tests share through a fixture of their module (``file::fixture``) or of
#: this file (``fixture``): an installed wheel, a run or an archive several tests judge.  The
#: tests that use one run in one worker (marker ``xdist_group``, `make test`'s ``--dist
#: loadgroup``), so that the work is done once rather than once in every worker.
SHARED_WORK = (
    "project/test_install.py::installed",
    "judges/test_coupling_stability.py::user_scene",
    "formats/test_outputs.py::earlier_run",
    "formats/test_ssp_engines.py::archive",
    "engine/test_own_fmu.py::monitor_fmu",
    "physics/test_freewheel.py::short_scene_run",
    "fmus/test_dropin.py::kavz_in",
    "kavz685_in_libcosim_from_ssp",
)


def pytest_configure(config):
    if not hasattr(config, "workerinput"):      # the controller, once a run: what older code cached goes
        from harness import cache
        cache.clear(stale_only=True)
    config.addinivalue_line("markers", "numerics: the outcome could move with numpy's SIMD dispatch "
                                       "(tests/conftest.py NUMERICS)")
    config.addinivalue_line("markers", "serial: run alone, after the tests run side by side "
                                       "(tests/conftest.py SERIAL)")
    # A suite started as a background job of a shell without job control inherits SIGINT
    # ignored, and so would every `lever` the Ctrl-C tests start: they would wait for an
    # interrupt that never comes.  A handled signal is reset to its default across exec.
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


# tryfirst: before pytest-xdist's own hook, which reads the xdist_group markers given here
@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    for item in items:
        file = item.path.relative_to(TESTS).as_posix()
        for name in SHARED_WORK:
            defined_in, _, fixture = name.rpartition("::")
            if fixture in item.fixturenames and defined_in in ("", file):
                item.add_marker(pytest.mark.xdist_group(name))
                break
        if f"{file}::{item.originalname}" in NUMERICS:
            item.add_marker(pytest.mark.numerics)
        if file in SLOW or f"{file}::{item.originalname}" in SLOW:
            item.add_marker(pytest.mark.slow)
        if file in SERIAL or f"{file}::{item.originalname}" in SERIAL:
            item.add_marker(pytest.mark.serial)


def pytest_report_header(config):
    # Which SIMD code numpy runs here, so that a log says at which dispatch level it passed.
    from numpy._core._multiarray_umath import __cpu_baseline__

    from harness.judges.solution import simd_in_use
    return (f"numpy SIMD: baseline {' '.join(__cpu_baseline__) or '-'}, dispatched in use: {simd_in_use() or 'none'}"
            f" (NPY_DISABLE_CPU_FEATURES={os.environ.get('NPY_DISABLE_CPU_FEATURES', '')!r})")


def pytest_addoption(parser):
    parser.addoption("--accuracy-report", action="store_true", default=False,
                     help="print each master's measured errors (tests/oracle/test_oracle_accuracy.py), to re-measure")


@pytest.fixture(scope="session")
def fmu_dir() -> Path:
    """The built FMUs, (re)built first when they are missing or older than their sources."""
    from harness.cli import ensure_fmus
    from harness.paths import FMUS

    ensure_fmus(quiet=True)
    for name in FMU_NAMES:
        assert (FMUS / f"{name}.fmu").exists(), name
    return FMUS


@pytest.fixture(scope="session")
def user_example():
    """``user_example(folder, stop, transient)``: examples/user_fmu built into ``folder`` -
    the user's pythonfmu FMU (no units) and its scene ``user_driveline.toml`` shortened to
    ``stop`` with the start-up ``transient``; returns the scene file."""
    return _user_example


def _user_example(folder: Path, stop: float, transient: float) -> Path:
    import importlib.util

    example = Path(__file__).resolve().parents[1] / "examples" / "user_fmu"
    spec = importlib.util.spec_from_file_location("user_fmu_build", example / "build_fmu.py")
    build = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(build)
    build.build(folder)
    text = (example / "user_driveline.toml").read_text()
    assert "stop = 2.0" in text and "transient = 0.5" in text
    (folder / "user_driveline.toml").write_text(text.replace("stop = 2.0", f"stop = {stop!r}").replace(
        "transient = 0.5", f"transient = {transient!r}"))
    return folder / "user_driveline.toml"


@pytest.fixture(scope="session")
def c_importer(tmp_path_factory) -> Path:
    """The minimal C importer (tests/c_host), compiled once for the tests of every module."""
    from harness.studies import hosts

    return hosts.compile_c_importer(tmp_path_factory.mktemp("c_host") / "minimal_importer")


@pytest.fixture(scope="session")
def kavz685_in_libcosim_from_ssp(fmu_dir):
    """The whole KAVZ-685 scene as libcosim assembles it from our SSP export (a child
    process of some seconds), run once for the tests of every module that judge it."""
    from harness import peers
    from harness.description import scene

    spec = scene.load("kavz685")
    return peers.simulate_peer("libcosim-ssp", spec, spec.experiment.step, fmu_dir)


@pytest.fixture(autouse=True)
def _built_fmus(request):
    if request.path.relative_to(TESTS).as_posix() in RUN_BUILT_FMUS:
        request.getfixturevalue("fmu_dir")


# pythonfmu 0.7's native library can corrupt the heap while the process tears down
# (seen as "corrupted double-linked list" after every test had passed, about one run in
# four with a few hundred FMU instances).  Once pytest has printed its summary, leave
# without running interpreter and library teardown, keeping pytest's exit status.
def pytest_sessionfinish(session, exitstatus):
    session.config._lever_exit_status = int(exitstatus)


@pytest.hookimpl(trylast=True)
def pytest_unconfigure(config):
    status = getattr(config, "_lever_exit_status", None)
    # mutmut runs pytest inside its own process (it sets MUTANT_UNDER_TEST): leaving from
    # here would end mutmut itself (tests/mutation/run_mutants.py).
    if status is not None and "MUTANT_UNDER_TEST" not in os.environ:
        from harness.engine.component import remove_extractions
        remove_extractions()
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(status)


# ======================================================================================
# The command line: one way to run `lever` in a test
# ======================================================================================
# `lever` in-process for every test that runs a command; `lever_process` only where the
# test needs a process of its own (Ctrl-C sent to it, a lock another process holds, the
# environment it starts with, how it ends).


@pytest.fixture(scope="session")
def lever():
    """``lever("run", "kavz685", "--out", path)``: the command run in this process by
    click's CliRunner (arguments made strings); click's Result: ``exit_code``, ``output``
    (stdout and stderr as a terminal shows them), ``stdout``, ``stderr``.  An exception that
    escapes a command fails the test with its traceback, as a user would have seen it."""
    from click.testing import CliRunner

    from harness.cli import main

    def invoke(*args, **options):
        return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False, **options)
    return invoke


class LeverProcess:
    """``lever`` as a process of its own: the console entry under this Python (the code
    under test, whichever environment runs pytest)."""

    command = [sys.executable, "-c", "from harness.cli import entry; entry()"]

    def run(self, *args, timeout: float = 300, **options) -> "subprocess.CompletedProcess":
        """Run to the end: output captured as text."""
        import subprocess

        return subprocess.run([*self.command, *map(str, args)], capture_output=True, text=True, timeout=timeout,
                              **options)

    def start(self, *args, **options) -> "subprocess.Popen":
        """Start and return at once: stdout and stderr are pipes (text) unless ``options`` say
        otherwise."""
        import subprocess

        options = {"stdout": subprocess.PIPE, "stderr": subprocess.PIPE, "text": True, **options}
        return subprocess.Popen([*self.command, *map(str, args)], **options)


@pytest.fixture(scope="session")
def lever_process() -> LeverProcess:
    return LeverProcess()
