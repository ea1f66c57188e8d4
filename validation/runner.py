"""Run a validation suite and write its outputs."""

from __future__ import annotations

import dataclasses
import datetime as _dt
import platform
import time
import traceback
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from gransim import __version__
from gransim._validate import as_positive_float, check_choice
from gransim.io import git_commit, lammps_version, liggghts_version
from reference_runs.engines import get_engine
from reference_runs.locks import DirectoryLock, remove_stray_tmp
from reference_runs.runner import kill_children_on_signals

from .codes import CODES
from .core import (
    SUITES,
    CaseResult,
    Context,
    lammps_available,
    liggghts_available,
    registered_cases,
)
from .report import write_h5, write_html, write_json


def run_validation(
    suite: str = "default",
    results: Path | str = "results",
    jobs: int = 1,
    only: list[str] | None = None,
    log=print,
    timeout: float | None = None,
) -> tuple[bool, list[CaseResult]]:
    """Run every case of ``suite``; write results/validation.{json,h5} and results/report/index.html.

    ``timeout`` (s) bounds every reference job (None: scaled with the job's work,
    :meth:`Context.job_timeout`); a job that exceeds it is killed with its process group and its
    case is reported as not run, naming the job. Returns ``(all_passed, results)``. A case that
    raises is reported as not run (a failure), with its error, and the other cases still run.
    """
    check_choice(suite, "suite", SUITES)
    if timeout is not None:
        timeout = as_positive_float(timeout, "--timeout")
    have = {code: _available(code) for code in CODES}
    ctx = Context(
        suite=suite,
        results=Path(results),
        jobs=int(jobs),
        liggghts=have.get("liggghts", False),
        lammps=have.get("lammps", False),
        timeout=timeout,
        available=frozenset(c for c, ok in have.items() if ok),
    )

    # one validation run per results directory (a second fails at once, naming the first); a
    # signal kills every LIGGGHTS job this run started before the exception ends it
    with (
        DirectoryLock(ctx.results, fail_fast=True, what=f"results directory {ctx.results}"),
        kill_children_on_signals(),
    ):
        # temporaries a killed validation run left in its own files (not below: job directories
        # are cleaned by their own locks)
        for d in (ctx.results, ctx.report_dir):
            if d.is_dir():
                remove_stray_tmp(d, recursive=False)
        return _run_cases(ctx, suite, only, log, timeout)


def _available(code: str) -> bool:
    """Whether ``code`` (a name of validation.codes.CODES) is installed: its binary on PATH."""
    known = {"liggghts": liggghts_available, "lammps": lammps_available}  # looked up now: tests replace them
    return known[code]() if code in known else get_engine(code).available()


def _version(code: str) -> str | None:
    """The version ``code``'s binary reports about itself (None when absent)."""
    known = {"liggghts": liggghts_version, "lammps": lammps_version}
    return known[code]() if code in known else get_engine(code).version()


def _run_cases(ctx, suite, only, log, timeout) -> tuple[bool, list[CaseResult]]:
    ctx.report_dir.mkdir(parents=True, exist_ok=True)
    cases = registered_cases(suite)
    if only:
        known = {c.id for c in cases}
        for o in only:
            check_choice(o, "case", known)
        cases = [c for c in cases if c.id in only]
    out: list[CaseResult] = []
    t_all = time.perf_counter()
    # one pool for the background work of every case (jobs - 1 threads, first submitted first run):
    # the cases' long runs queue behind each other in case order, beside the case in progress
    bg = None
    if int(ctx.jobs) >= 2 and any(c.prefetch is not None for c in cases):
        bg = ThreadPoolExecutor(max_workers=int(ctx.jobs) - 1, thread_name_prefix="validate-background")
        ctx = dataclasses.replace(ctx, background=bg)
    run = execution_order(cases) if bg is not None else cases
    try:
        _cases_loop(ctx, run, log, out)
    finally:
        for c in cases:  # background work a case did not collect (a case that raised, a signal)
            if c.cancel is not None:
                c.cancel()
        if bg is not None:
            bg.shutdown(wait=True, cancel_futures=True)
    rank = {c.id: k for k, c in enumerate(cases)}  # the report in the suite's order
    out = [res for _, res in sorted(zip((rank[c.id] for c in run), out), key=lambda p: p[0])]
    return _write_reports(ctx, suite, out, t_all, timeout, log)


def execution_order(cases: list) -> list:
    """The order in which a run with a background pool makes ``cases`` (given in the suite's order):
    first every case that neither starts background work (``Case.prefetch``) nor reads the runs of
    one that does (``Case.uses``, transitively), then those, each group in the suite's order.

    The long runs of the second group start at the beginning of the run and take the background
    pool's worker(s); the first group's cases run meanwhile on the other core. Had a short case come
    after them (voidcell, slope, femxdem-short after biaxial-full and simple-shear in the default
    suite), it would run alone at the end, with the pool idle. Each case's records are the same in
    any order: a case that reads another's runs makes them through that case's cached functions."""
    waits = {c.id for c in cases if c.prefetch is not None}
    grew = True
    while grew:
        more = {c.id for c in cases if c.id not in waits and set(c.uses) & waits}
        grew = bool(more)
        waits |= more
    return [c for c in cases if c.id not in waits] + [c for c in cases if c.id in waits]


def _cases_loop(ctx, cases, log, out) -> None:
    # long background work first (biaxial-full's reference jobs and native runs, then simple-shear's
    # long horizon, on the core the other cases leave to it: execution_order); a prefetch that fails
    # leaves the work to its case, which reports the error
    early = {}
    for c in cases:
        if c.prefetch is not None:
            t0 = time.perf_counter()
            try:
                c.prefetch(ctx)
                early[c.id] = time.perf_counter() - t0
                log(f"[validate] {c.id}: reference jobs started in the background ({early[c.id]:.1f} s)")
            except Exception as exc:  # the case itself will meet (and report) the same problem
                log(f"[validate] {c.id}: could not start its jobs early ({type(exc).__name__}: {exc})")
    for c in cases:
        log(f"[validate] {c.id}: {c.title} ...")
        t0 = time.perf_counter()
        try:
            res = c.func(ctx)
        except Exception as exc:  # a broken case must not hide the others
            res = CaseResult(c.id, c.title, "", error=f"{type(exc).__name__}: {exc}")
            res.notes.append("<pre>" + traceback.format_exc()[-3000:] + "</pre>")
        dt = time.perf_counter() - t0
        if c.id in early:
            dt += early[c.id]
            res.notes.append(
                f"Wall time of this case: {dt:.1f} s, of which {early[c.id]:.1f} s at the start of the run; "
                "its reference jobs were started then and ran beside the cases before it."
            )
        else:
            res.notes.append(f"Wall time of this case: {dt:.1f} s.")
        res.seconds = dt
        word = "pass" if res.passed else ("NOT RUN: " + res.error if res.error else "FAIL")
        log(f"[validate] {c.id}: {word} ({len(res.records)} records, {dt:.1f} s)")
        out.append(res)


def _code_header(ctx, code: str) -> dict:
    """``{code}_available`` and ``{code}_version`` of the run's header."""
    return {f"{code}_available": ctx.has(code), f"{code}_version": _version(code) or "absent"}


def _write_reports(ctx, suite, out, t_all, timeout, log) -> tuple[bool, list[CaseResult]]:
    header = {
        "suite": suite,
        "gransim_version": __version__,
        "git_commit": git_commit(),
        "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        **{k: v for code in CODES for k, v in _code_header(ctx, code).items()},
        "machine": f"{platform.node()} ({platform.machine()}, {__import__('os').cpu_count()} cores)",
        "wall_time_s": round(time.perf_counter() - t_all, 1),
        "job_timeout_s": timeout if timeout is not None else "scaled with each job's work",
    }
    write_json(ctx.results / "validation.json", out, header)
    write_h5(ctx.results / "validation.h5", out, header)
    index = write_html(ctx.report_dir, out, header)
    ok = all(r.passed for r in out) and bool(out)
    log(f"[validate] report: {index}  ({'all cases pass' if ok else 'SOME CASES FAIL'})")
    return ok, out
