"""The fault kinds ``tests/faults`` injects, listed in the report.

A verdict is worth something only if it can fail. Each entry names a fault (a broken reference
code, cut evidence, a perturbed native path, bad input), the outcome the suite requires (a
failing verdict or a clear error, never a pass, and no process left behind), and the test that
shows it (``tests/faults/<file>::<test>``; ``tests/faults/test_fault_catalogue.py`` checks that
every test named here exists).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class FaultKind:
    fault: str
    outcome: str
    test: str


_R = "tests/faults/test_runner_faults.py::"
_V = "tests/faults/test_validation_faults.py::"
_D = "tests/faults/test_dem_faults.py::"
_C = "tests/faults/test_cli_faults.py::"
_S = "tests/validation/test_validation_suite.py::"
_F = "tests/fem/test_output.py::"
_N = "tests/faults/test_nonfinite_judges.py::"
_K = "tests/faults/test_children_die.py::"
_H = "tests/faults/test_harness_options.py::"
_L = "tests/faults/test_run_lifecycle.py::"
_Y = "tests/faults/test_yade_faults.py::"
_YI = "tests/faults/test_yade_impact_faults.py::"
_YV = "tests/faults/test_yade_validation_faults.py::"
_YC = "tests/validation/test_yade_columns.py::"
_O = "tests/foundation/test_cli_options.py::"

FAULT_KINDS: tuple[FaultKind, ...] = (
    # reference code broken or evidence cut
    FaultKind(
        "LIGGGHTS exits 1 with an ERROR line",
        "job failed, case not run, the ERROR quoted",
        _V + "test_live_liggghts_failures_fail_the_case",
    ),
    FaultKind(
        "LIGGGHTS exits 0 writing nothing",
        "job failed (no log), case not run",
        _V + "test_live_liggghts_failures_fail_the_case",
    ),
    FaultKind(
        "LIGGGHTS writes a WARNING line",
        "job failed, the WARNING quoted",
        _V + "test_live_liggghts_failures_fail_the_case",
    ),
    FaultKind(
        "LIGGGHTS hangs (with a grandchild ignoring SIGTERM)",
        "killed at the timeout, the report names the job, no process left",
        _V + "test_hung_liggghts_times_out_names_the_job_and_leaves_no_process",
    ),
    FaultKind(
        "LIGGGHTS truncates its log",
        "job refused: incomplete runs/steps",
        _V + "test_live_liggghts_with_a_truncated_log_fails",
    ),
    FaultKind(
        "LIGGGHTS leaves only the first frame of each dump",
        "job refused or 'incomplete: expected N frames, got 1'",
        _V + "test_live_liggghts_leaving_only_the_first_dump_frame_fails",
    ),
    FaultKind(
        "a reused job whose log was cut to 12 steps",
        "verified on reuse, rerun (or refused naming --force)",
        _R + "test_reuse_of_a_log_cut_to_12_steps_reruns",
    ),
    FaultKind(
        "a reused job whose outputs were edited",
        "hash mismatch: rerun or refused",
        _R + "test_reuse_verifies_hashes_and_evidence",
    ),
    FaultKind(
        "the stored reference log cut to 12 of 3000 steps",
        "'incomplete: expected 3001 LIGGGHTS series steps, got 13'",
        _V + "test_stored_log_cut_to_12_steps_fails",
    ),
    FaultKind(
        "the stored reference dump cut to its first frame",
        "'incomplete: expected 7 LIGGGHTS frames, got 1' in biaxial-short and voidcell",
        _V + "test_stored_dump_with_only_the_first_frame_fails",
    ),
    FaultKind(
        "a stored Taylor job missing a state",
        "incomplete Taylor series",
        _V + "test_a_stored_taylor_state_missing_fails",
    ),
    # process control
    FaultKind(
        "SIGTERM / SIGINT to gransim validate while LIGGGHTS runs",
        "non-zero exit, no traceback, no LIGGGHTS process left",
        _V + "test_signal_to_validate_leaves_no_liggghts",
    ),
    FaultKind(
        "a second validate into the same results directory",
        "refused at once naming the holder (exit 2)",
        _V + "test_second_validate_into_the_same_results_fails_at_once",
    ),
    FaultKind(
        "a second writer of the same LIGGGHTS job",
        "waits for the first, then reuses its job",
        _R + "test_second_writer_waits_then_reuses",
    ),
    FaultKind(
        "temporaries left by a killed writer",
        "removed by the next run",
        _V + "test_stray_temporaries_of_a_killed_run_are_removed",
    ),
    # perturbed native paths
    FaultKind(
        "native contacts 1% stiffer",
        "biaxial-short and voidcell fail (positions, stress)",
        _S + "test_one_percent_stiffer_native_contacts_fail",
    ),
    FaultKind("native lateral servo removed", "biaxial-short fails", _S + "test_dropped_servo_fails"),
    FaultKind(
        "stored LAMMPS log of biaxial-short cut at step 1200",
        "'incomplete: expected 3001 LAMMPS series steps, got 1201' fails native vs LAMMPS and LIGGGHTS vs "
        "LAMMPS; native vs LIGGGHTS still passes",
        "tests/validation/test_biaxial_short_case.py::test_a_lammps_log_cut_short_fails_both_lammps_columns",
    ),
    FaultKind(
        "stored LAMMPS series of biaxial-full cut to half",
        "the LAMMPS columns fail as incomplete, no envelope or curve verdict on what remains",
        _S + "test_biaxial_full_with_a_stored_series_cut_short_makes_no_envelope_verdict",
    ),
    FaultKind(
        "native Taylor path dropping half the contacts",
        "contact counts differ, LIGGGHTS rows unmatched",
        _V + "test_native_path_dropping_half_the_contacts_fails_taylor",
    ),
    FaultKind(
        "an FE2 material whose tangent is 20% off",
        "Newton-rate and small-load checks fail",
        _F + "test_acceptance_checks_fail_for_an_inconsistent_tangent",
    ),
    # native DEM producing garbage
    FaultKind(
        "a time step above the damped stability limit",
        "refused before the run (exit 2)",
        _D + "test_cli_refuses_a_step_above_the_damped_limit",
    ),
    FaultKind(
        "a consolidation that never settles",
        "run stopped, stop_reason in the file, exit 2",
        _D + "test_cli_unsettled_exit_2_and_info",
    ),
    FaultKind(
        "kinetic-energy blow-up / a lost particle / NaN",
        "SimulationError with the step",
        _D + "test_kinetic_energy_blow_up_is_detected",
    ),
    FaultKind(
        "an unfinished (killed) run file read by voidcells, dem-export, info",
        "refused or flagged",
        _D + "test_cli_readers_of_an_unfinished_run",
    ),
    FaultKind(
        "truncated or corrupt run files",
        "ResultFileError naming the dataset",
        _D + "test_truncated_or_corrupt_run_files",
    ),
    # bad input
    FaultKind(
        "output path naming a directory or an unknown image suffix",
        "exit 2 before computing",
        _C + "test_output_paths_checked_first",
    ),
    FaultKind(
        "malformed packing files (bad JSON, shapes, negative radii)",
        "ResultFileError naming the file",
        _C + "test_malformed_packing_file",
    ),
    FaultKind(
        "a packing too large for memory",
        "refused with the estimate before allocating",
        _C + "test_huge_packing_refused_before_allocation",
    ),
    FaultKind("coincident disks in an RVE", "error naming the two disks", _C + "test_coincident_disks"),
    FaultKind(
        "a closed output pipe (gransim ... | head)", "quiet exit, no traceback", _C + "test_shell_pipe_into_head"
    ),
    # NaN and inf evidence
    FaultKind(
        "NaN or inf on either side of any comparison, or nothing to compare",
        "the judge fails, naming the quantity and side",
        _N + "test_max_rel_diff_refuses_nan_or_inf_on_either_side",
    ),
    FaultKind(
        "two coincident disks: every Taylor stress NaN in the code and in numpy",
        "gransim reference taylor exits 1 naming the NaN",
        _N + "test_reference_taylor_on_two_coincident_disks_fails_naming_the_nan",
    ),
    FaultKind(
        "a NaN in a later replay dump frame",
        "the dump check fails naming column, step and side",
        _N + "test_replay_dump_check_fails_on_a_nan_in_a_later_frame",
    ),
    FaultKind(
        "a NaN rate in a benchmark", "a failed record, exit 1", _N + "test_bench_suite_exits_1_naming_a_nan_record"
    ),
    FaultKind(
        "a NaN patch-test error or Newton order of the slope",
        "the acceptance check fails",
        _F + "test_acceptance_checks_fail_on_a_nan",
    ),
    # signals, kills and full disks
    FaultKind(
        "SIGTERM, SIGINT or SIGKILL to replay, reference or validate while the code runs",
        "no code process, no MPI daemon, no temporary directory left",
        _K + "test_signal_to_gransim_leaves_no_code_and_no_temporary_directory",
    ),
    FaultKind(
        "SIGKILL of gransim during an MPI job (mpirun, 2 ranks)",
        "the watchdog kills mpirun and every rank",
        _K + "test_sigkill_leaves_no_mpirun_and_no_rank",
    ),
    FaultKind(
        "SIGINT at a random moment of a DEM run",
        "exit 130, the file incomplete, --resume gives the same bits",
        _L + "test_sigint_at_random_moments_always_stops_and_resumes_to_the_same_bits",
    ),
    FaultKind(
        "a full disk while pack or biaxial writes",
        "one error naming the file and the cause, nothing partial left",
        _L + "test_full_disk_is_one_error_naming_the_file",
    ),
    FaultKind(
        "temporaries left by a killed writer",
        "removed by the next run or resume of that file, never a live writer's",
        _L + "test_stale_temporaries_of_the_run_are_removed_never_a_live_ones",
    ),
    FaultKind(
        "a kill between two checkpoint parts",
        "--resume from the last whole part, the same bits",
        _L + "test_checkpoints_append_parts_and_a_kill_between_them_resumes_bitwise",
    ),
    # YADE evidence
    FaultKind(
        "a YADE output cut short, a state or contact missing",
        "refused as incomplete",
        _Y + "test_damaged_yade_output_is_refused_as_incomplete",
    ),
    FaultKind(
        "a hung YADE job",
        "killed at its timeout, nothing left running or listening",
        _Y + "test_hung_yade_job_is_killed_with_nothing_left",
    ),
    FaultKind(
        "a YADE DEM output cut short, a step, frame, particle or contact missing",
        "refused as incomplete; the job failed, never ok",
        _Y + "test_damaged_yade_dem_output_is_refused_as_incomplete",
    ),
    FaultKind(
        "a YADE DEM run that hangs inside a step",
        "killed at its timeout, nothing left running or listening",
        _Y + "test_hung_yade_dem_run_is_killed_with_nothing_left_listening",
    ),
    FaultKind(
        "a YADE impact output cut short, a frame or a particle missing, a NaN",
        "refused as incomplete",
        _YI + "test_damaged_impact_output_is_refused_as_incomplete",
    ),
    FaultKind(
        "a YADE impact run that hangs inside a step",
        "killed at its timeout, nothing left running or listening",
        _YI + "test_hung_impact_job_is_killed_with_nothing_left_listening",
    ),
    # YADE inside a validation run (a fake yade on PATH)
    FaultKind(
        "YADE's outputs cut short during gransim validate",
        "taylor-rve's YADE column fails: 'incomplete: expected 1 RVEs run by YADE, got 0', the job's "
        "'cut short' named; nothing judged on what remains",
        _YV + "test_a_yade_output_cut_short_is_an_incomplete_verdict",
    ),
    FaultKind(
        "a YADE script that raises (exit 1)",
        "the YADE column fails, quoting the exception",
        _YV + "test_a_yade_script_that_fails_is_a_failing_verdict_quoting_the_error",
    ),
    FaultKind(
        "YADE hangs during gransim validate, a grandchild ignoring SIGTERM and a TCP port open",
        "killed at --timeout, the column says 'timed out', no process left, the port closed",
        _YV + "test_a_hung_yade_job_is_killed_at_the_timeout_with_no_process_and_no_port_left",
    ),
    FaultKind(
        "a particle missing from YADE's run of biaxial-short",
        "case not run, naming 'frame of step 0 has 119 of 120 particles'",
        _YV + "test_a_particle_missing_from_a_yade_run_stops_the_case_naming_it",
    ),
    FaultKind(
        "a stored YADE output cut short (YADE absent)",
        "the YADE column fails as incomplete (taylor-rve, voidcell, impacts)",
        _YC + "test_taylor_rve_fails_on_a_cut_yade_output",
    ),
    FaultKind(
        "the stored YADE run of biaxial-short cut short (YADE absent)",
        "voidcell's YADE column fails: 'incomplete: expected 7 YADE frames, got 0'",
        _YC + "test_voidcell_fails_on_a_cut_yade_output",
    ),
    FaultKind(
        "a stored YADE impact output cut short (YADE absent)",
        "that scene's YADE records fail as incomplete, the others pass",
        _YC + "test_impacts_fail_on_a_cut_yade_output",
    ),
    # options
    FaultKind(
        "bad numbers for the options of replay, reference and validate (0, negative, NaN, inf, no number)",
        "exit 2 naming the option, no job started",
        _H + "test_bad_numeric_option_exits_2_naming_it",
    ),
    FaultKind(
        "bad values for every option of every gransim command",
        "exit 2 naming the option, nothing computed",
        _O + "test_bad_value_exits_2_naming_the_option",
    ),
    FaultKind(
        "-o naming the input packing (same path, relative, symlink, hard link)",
        "exit 2, the input unchanged",
        _O + "test_output_equal_to_the_packing_is_refused",
    ),
    FaultKind(
        "--threads without the parallel mode", "exit 2 naming --threads", _O + "test_threads_need_the_parallel_mode"
    ),
)
