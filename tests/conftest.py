"""Shared fixtures and collection rules of the test suite.

Plain-Python mode (``NUMBA_DISABLE_JIT=1``, ``make coverage``, docs/coverage.md)
-------------------------------------------------------------------------------
With ``NUMBA_DISABLE_JIT=1`` every gransim kernel runs as ordinary Python, which is what lets
``coverage`` see inside them, and is 10^2-10^3 times slower. Tests that only exist to run many DEM
steps or to drive the reference codes are then skipped by one documented rule: each node-id
pattern in :data:`JIT_HEAVY` (``fnmatch`` on the node id) carries the reason it is too slow as
plain Python; matching tests get the marker ``jit_heavy`` and are skipped in that mode only (the
JIT-compiled ``make test`` runs them all). ``GRANSIM_PLAIN_PYTHON_ALL=1`` runs them anyway.

``GRANSIM_TEST_BUDGET=<seconds>`` (any mode) fails a test that runs longer than that, with the
message naming the budget: how the patterns below were found (docs/coverage.md).
"""

import fnmatch
import os
import shutil
import signal
import subprocess

import numpy as np
import pytest

os.environ.setdefault("MPLBACKEND", "Agg")

#: numba runs as plain Python (numba reads the variable once, at import; "0"/"" mean JIT on)
PLAIN_PYTHON = os.environ.get("NUMBA_DISABLE_JIT", "0") not in ("", "0")

_STEPS = "a DEM run of thousands of steps compared step for step"
_CACHE = "compiles numba kernels into a fresh cache in child processes (a JIT test by design)"
_LONG = "a long DEM run (hundreds of disks or thousands of steps)"
_CASE = "a validation case run on stored outputs: thousands of DEM steps compared step for step"
_PACK = "FIRE packings of hundreds of disks"
_COMPACTION = "a frictional DEM compaction (tens of thousands of steps)"
_RELAXED = "relaxed RVEs of 70-350 disks at many states (Newton with rattler expulsion)"

#: ``(node-id pattern, reason)``: tests too slow as plain Python. Each pattern's tests exceeded a
#: 20 s budget in one plain-Python run of the suite (docs/coverage.md, "How the rule was measured")
JIT_HEAVY: tuple[tuple[str, str], ...] = (
    (
        "tests/cli/test_slope_resume.py::test_resume_is_bitwise_the_uninterrupted_run[[]taylor[]]",
        "two FE2 slope runs with a Taylor RVE at every Gauss point",
    ),
    ("tests/dem/test_biaxial_law.py::test_hertz_law_runs_at_the_designed_indentation", _LONG),
    ("tests/dem/test_energy_balance.py::*", "energy balance over a long undamped DEM run"),
    ("tests/dem/test_fast.py::test_relaxation_of_1000_disks_within_the_chaos_envelope", _LONG),
    ("tests/dem/test_fast.py::test_threads_do_not_change_the_result", _LONG),
    ("tests/dem/test_lammps.py::test_*_run_step_for_step", _STEPS),
    ("tests/dem/test_lammps.py::test_flavours_differ_and_liggghts_flavour_misses_lammps", _STEPS),
    ("tests/dem/test_law_plugin.py::test_the_loop_of_a_law_is_loaded_from_the_disk_cache_*", _CACHE),
    ("tests/dem/test_law_plugin.py::test_a_law_registered_without_cache_leaves_the_shared_*", _CACHE),
    ("tests/dem/test_law_runs.py::test_stored_run_step_for_step*", _STEPS),
    ("tests/dem/test_law_runs.py::test_live_*", _STEPS + " (and the reference code run live)"),
    ("tests/dem/test_liggghts.py::test_*_run_step_for_step", _STEPS),
    ("tests/dem/test_physics.py::test_energy_conserved_without_damping_and_friction", _LONG),
    ("tests/dem/test_run.py::test_resume_is_bit_for_bit_and_refuses_other_runs", _LONG),
    ("tests/dem/test_run.py::test_cli_biaxial_and_export", _LONG),
    ("tests/dem/test_run.py::test_run_file_layout_and_stress_series", _LONG),
    ("tests/dem/test_run.py::test_biaxial_protocol_holds_sigma11_and_compresses", _LONG),
    ("tests/dem/test_sheared.py::test_*run_step_for_step*", _STEPS),
    ("tests/dem/test_sheared.py::test_zero_tilt_reproduces_orthogonal_engine*", _STEPS),
    ("tests/dem/test_sheared.py::test_constant_volume_shear_builds_shear_stress", _LONG),
    ("tests/dem/test_sheared_styles.py::test_box_origin_is_used_as_given", _LONG),
    ("tests/dem/test_sheared_styles.py::test_fix_deform_n_changes_the_box_on_multiples_*", _LONG),
    ("tests/dem/test_sheared_styles.py::test_linear_styles_reach_their_end_tilt*", _LONG),
    (
        "tests/rve/test_relaxed.py::test_stress_and_tangent_are_derivatives_of_relaxed_energy[[]rve-70*",
        "finite differences of the relaxed (equilibrated) energy of a 70-disk RVE: > 3 min",
    ),
    ("tests/reference_runs/test_ref_native_schema.py::test_stored_biaxial_job_in_native_*", _STEPS),
    # found by the first complete plain-Python run (docs/coverage.md, 60 s budget): each exceeded it
    ("tests/faults/test_cli_faults.py::test_measured_bytes_per_disk_cover_a_real_packing", _PACK),
    ("tests/faults/test_validation_faults.py::test_*liggghts*", _CASE + " (and LIGGGHTS live)"),
    ("tests/faults/test_validation_faults.py::test_stored_*", _CASE),
    ("tests/fem/test_parallel.py::test_*taylor*", "FE2 slope runs with a Taylor RVE at every Gauss point"),
    ("tests/fem/test_slope_relaxed.py::test_rejected_step_leaves_gauss_point_history_unchanged", _RELAXED),
    ("tests/foundation/test_bench_smoke.py::test_bench_quick_runs_every_area", "every benchmark area, quick"),
    ("tests/foundation/test_warmup.py::test_after_the_warmup_*", _CACHE),
    ("tests/foundation/test_warmup.py::test_outside_a_venv_the_user_cache_is_used", _CACHE),
    ("tests/foundation/test_warmup.py::test_second_process_loads_what_the_first_compiled*", _CACHE),
    ("tests/generation/test_cli_pack.py::test_pack_by_frictional_compaction", _COMPACTION),
    ("tests/generation/test_compaction.py::*", _COMPACTION),
    ("tests/generation/test_pack.py::test_front_method_meets_the_targets_of_the_random_start", _PACK),
    ("tests/generation/test_pack.py::test_rms_residual_option_is_checked_independently", _PACK),
    ("tests/generation/test_pack.py::test_threaded_minimiser_gives_the_serial_result_bit_for_bit", _PACK),
    ("tests/generation/test_pack.py::test_*standard_packings*", _PACK + " (the standard assemblies regenerated)"),
    ("tests/generation/test_pack.py::test_outdated_or_foreign_shipped_copy_is_regenerated", _PACK),
    ("tests/rve/test_relaxed.py::test_relaxed_energy_never_exceeds_taylor", _RELAXED),
    ("tests/rve/test_relaxed.py::test_warm_start_history_commit_and_revert", _RELAXED),
    ("tests/validation/test_impacts_rolling_wall.py::test_rolling_and_wall_scenes_pass_on_stored_outputs", _CASE),
    ("tests/validation/test_laws_short.py::test_*", _CASE),
    ("tests/validation/test_relaxation_case.py::test_*", _CASE + " (DEM relaxations of 60,000 steps)"),
    ("tests/validation/test_shear_case.py::test_*", _CASE),
    ("tests/validation/test_validation_suite.py::test_*", _CASE),
    # over the budget in the second complete run (tests merged since the first)
    ("tests/faults/test_dem_faults.py::test_*_readers_of_an_unfinished_run", _LONG + " (its fixture)"),
    ("tests/fem/test_compare.py::*", "two FE2 slope runs (Taylor and relaxed RVEs) as the fixture"),
    ("tests/fem/test_slope_relaxed.py::*", _RELAXED + " at every Gauss point of an FE2 box"),
    ("tests/fem/test_checkpoint.py::test_relaxed_path_resumed_from_a_checkpoint_is_bitwise", _RELAXED),
    ("tests/rve/test_relaxed.py::test_stress_does_not_depend_on_the_start", _RELAXED),
)


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


def pytest_configure(config):
    config.addinivalue_line(
        "markers",
        "jit_heavy: too slow as plain Python (NUMBA_DISABLE_JIT=1): skipped there, see tests/conftest.py JIT_HEAVY",
    )


def _jit_heavy_reason(nodeid: str) -> str | None:
    for pattern, reason in JIT_HEAVY:
        if fnmatch.fnmatchcase(nodeid, pattern):
            return reason
    return None


def pytest_collection_modifyitems(config, items):
    """Tests marked ``lammps`` need the LAMMPS binary ``lmp``: skipped where it is absent (as the
    ``liggghts`` marker is in tests/reference_runs/conftest.py). Tests matching :data:`JIT_HEAVY`
    are marked ``jit_heavy`` and, as plain Python, skipped with their pattern's reason."""
    if shutil.which("lmp") is None:
        skip = pytest.mark.skip(reason="LAMMPS binary lmp not installed (apt-get install lammps)")
        for item in items:
            if item.get_closest_marker("lammps") is not None:
                item.add_marker(skip)
    run_all = os.environ.get("GRANSIM_PLAIN_PYTHON_ALL", "0") not in ("", "0")
    for item in items:
        reason = _jit_heavy_reason(item.nodeid)
        if reason is None:
            continue
        item.add_marker(pytest.mark.jit_heavy)
        if PLAIN_PYTHON and not run_all:
            item.add_marker(pytest.mark.skip(reason=f"jit_heavy (NUMBA_DISABLE_JIT=1): {reason}"))


class _OverBudget(Exception):
    pass


def _budgeted():
    """Run the wrapped hook (a test's set-up or call) within ``GRANSIM_TEST_BUDGET`` seconds
    (SIGALRM; main thread, POSIX only). Over budget, the test fails with the message only: the
    traceback of an exception raised by a signal handler can hold a frame without a line number,
    which pytest cannot format (INTERNALERROR, measured)."""
    budget = float(os.environ.get("GRANSIM_TEST_BUDGET", "0") or 0)
    if budget <= 0 or not hasattr(signal, "setitimer"):
        return (yield)

    def _alarm(signum, frame):
        raise _OverBudget(f"test exceeded GRANSIM_TEST_BUDGET={budget:g} s")

    old = signal.signal(signal.SIGALRM, _alarm)
    signal.setitimer(signal.ITIMER_REAL, budget)
    try:
        return (yield)
    except _OverBudget as exc:
        signal.setitimer(signal.ITIMER_REAL, 0)
        pytest.fail(str(exc), pytrace=False)
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_setup(item):
    """The fixtures' set-up of a test counts against ``GRANSIM_TEST_BUDGET`` on its own."""
    return (yield from _budgeted())


@pytest.hookimpl(wrapper=True)
def pytest_runtest_call(item):
    """The test's call: ``GRANSIM_TEST_BUDGET`` seconds (:func:`_budgeted`)."""
    return (yield from _budgeted())


@pytest.fixture
def small_disk(tmp_path):
    """A full disk for the tests of results written to one: a 64 kB tmpfs at ``tmp_path/disk``.
    Yields ``(dir, wrap)``: as root it is mounted here (``wrap`` empty); otherwise a command run with
    the prefix ``wrap`` mounts it inside ``unshare -rm``. Skips when neither works."""
    d = tmp_path / "disk"
    d.mkdir()
    if os.geteuid() == 0 and shutil.which("mount"):
        r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(d)], capture_output=True)
        if r.returncode == 0:
            try:
                yield d, []
            finally:
                subprocess.run(["umount", str(d)], capture_output=True)
            return
    if shutil.which("unshare"):
        probe = subprocess.run(
            ["unshare", "-rm", "sh", "-c", f"mount -t tmpfs -o size=64k tmpfs {d}"], capture_output=True
        )
        if probe.returncode == 0:
            yield d, ["unshare", "-rm", "sh", "-c", f'mount -t tmpfs -o size=64k tmpfs {d} && exec "$0" "$@"']
            return
    pytest.skip("no way to mount a small tmpfs here (neither root nor unshare)")
