"""laws-short: every contact law of gransim.contacts, native vs its code, step for step.

The biaxial short case of :func:`reference_runs.decks.biaxial.short_case` (120 disks on a jittered
lattice in a periodic box, servo on x, compression on y, contacts across the boundary, neighbour-list
rebuilds with history hand-over) run with each law of
:data:`reference_runs.decks.biaxial.SHORT_CASE_LAWS` for 3000 steps at dt = 2e-6 s, in the law's own
code: LIGGGHTS 3.8.0 for ``hertz-liggghts`` and the rolling laws ``hooke-epsd2/epsd/cdt-liggghts``,
LAMMPS 29 Sep 2021 for ``hertz-lammps`` (gran/hertz/history), ``hertz-granular-lammps``
(granular hertz/material ... tangential mindlin) and ``hooke-sds-lammps`` (granular ... rolling sds).
The reference is the stored run ``reference_runs/stored/biaxial-short-<law>/`` (verified against its
deck) and, when the code is installed, the same deck run now. The native engine runs the law in that
code's arithmetic (docs/laws.md), so the expected difference is zero; the tolerances are the
biaxial-short ones (1e-10 D50, 1e-8 relative), and the table lists the measured difference of every law.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from gransim.contacts.laws import law_code
from gransim.errors import ResultFileError
from reference_runs.decks.biaxial import SHORT_CASE_DUMP_EVERY, SHORT_CASE_LAWS, short_case, short_case_law

from ..codes import CODES, NATIVE
from ..core import CaseResult, Context, Record, case, stored_dir, stored_job_record
from ..dem_compare import Trajectory, read_reference, run_native, run_reference_job
from ..matrix import Comparison, Run, evaluate
from .biaxial import CODE, SHORT_BOUNDS, _stored_log, short_row

REASON = (
    "bit for bit: the native engine runs each law in its code's floating-point order (docs/laws.md), so "
    "the doubles are equal; 1e-10 D50 / 1e-8 relative (the biaxial-short bounds) leaves room for another "
    "CPU or compiler and still lies decades below what a 1% change of any law parameter moves"
)


def _read_stored(d) -> Trajectory:
    """The stored run in ``d``; a cut or corrupt output reads as a run without steps or frames (the
    evidence records then name everything as missing: missing evidence, not a crash), and the
    reader's message is kept for :func:`_verify_stored`."""
    try:
        return read_reference(_stored_log(d), d / "dump.atoms")
    except ResultFileError as exc:
        _UNREADABLE[str(d)] = str(exc)
        return Trajectory(np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 2)), {})


#: stored directory -> why it could not be read (filled by _read_stored)
_UNREADABLE: dict = {}


def _verify_stored(d, label: str, tr) -> list:
    """The stored job verified against its deck, and a failing record when it could not be read."""
    recs = [stored_job_record(label, d)]
    why = _UNREADABLE.pop(str(d), None)
    if why is not None:
        recs.append(
            Record(
                label,
                "evidence",
                f"unreadable stored run: {why}",
                1.0,
                0.0,
                False,
                "every stored frame and step must be readable",
            )
        )
    return recs


def laws_plan(ctx: Context) -> tuple[list, list]:
    """Every law of SHORT_CASE_LAWS: native in its code's arithmetic against the code's stored run
    and, with the code installed, the same deck run now; step for step at the biaxial bounds."""
    p, s, ld, n = short_case()
    runs, comps = [], []
    for name in SHORT_CASE_LAWS:
        engine = law_code(name)
        if engine not in CODES:
            continue
        settings = dataclasses.replace(s, flavour=engine)
        law = short_case_law(name)
        d = stored_dir(f"biaxial-short-{name}")

        def live(name=name, engine=engine, settings=settings, law=law):
            tr, _ = run_reference_job(
                ctx.work("reference", "laws-short", name),
                p,
                settings,
                ld,
                n,
                SHORT_CASE_DUMP_EVERY,
                timeout=ctx.job_timeout(p.n * n),
                engine=engine,
                law=law,
            )
            return tr

        native = Run(
            f"native/{name}",
            NATIVE,
            engine,
            f"native {name}, {engine} arithmetic",
            functools.partial(run_native, p, settings, ld, n, SHORT_CASE_DUMP_EVERY, law=law, check_dt=False),
        )
        stored = Run(
            f"stored/{name}",
            engine,
            engine,
            f"stored biaxial-short-{name}",
            functools.partial(_read_stored, d),
            verify=functools.partial(_verify_stored, d),
        )
        runs += [native, stored, Run(f"live/{name}", engine, engine, f"{name} deck run now", live, live=True)]
        params = {"d50": p.d50, "nsteps": n, "dump_every": SHORT_CASE_DUMP_EVERY, "bounds": SHORT_BOUNDS}
        for kind in ("stored", "live"):
            comps.append(
                Comparison("step", f"laws-short/{name}/{kind}", (native.key, f"{kind}/{name}"), REASON, params)
            )
    return runs, comps


@case(
    "laws-short",
    "Every contact law step for step on the periodic short case: native vs its code",
    suites=("default", "full"),
    order=21,
)
def laws_short(ctx: Context) -> CaseResult:
    res = CaseResult(
        "laws-short",
        "Every contact law step for step on the periodic short case: native vs its code",
        __doc__.split("\n\n", 1)[1].replace("\n", " "),
    )
    codes = {law_code(name) for name in SHORT_CASE_LAWS}
    for engine in CODES:
        if engine not in codes:
            res.skip_pair(f"native-{engine}", f"no law of {CODE[engine]} in this run")
    res.skip_code(
        "yade",
        "no YADE run: these are LIGGGHTS' and LAMMPS' damped Hertz-Mindlin and rolling-resistance laws, each in its "
        "code's parametrisation; YADE's damped Hertz law (Thornton's fit, a clipped dashpot, HertzMindlin.cpp:72-109) "
        "and its rolling laws are other laws (docs/yade.md), and its damped linear law errs across the periodic "
        "boundary (ViscoelasticPM.cpp:118)",
    )
    res.skip_pair(
        "liggghts-lammps",
        "each of these laws is one code's (its parametrisation and arithmetic); "
        "the two codes' Hertz laws meet in the impacts case against Hertz theory",
    )
    header = [
        "law",
        "code",
        "run",
        "steps",
        "frames",
        "max|dx|/D50",
        "max|dv|/max|v|",
        "max|df|/max|f|",
        "max rel stress",
    ]
    runs, comps = laws_plan(ctx)
    out = evaluate(res, ctx, runs, comps)
    rows = []
    for c in comps:
        if c.label in out.summaries:
            name = c.label.split("/")[1]
            rows.append([name, CODE[law_code(name)], *short_row(out.summaries[c.label])])
    res.tables.append(("Largest differences per law and code (0 = bitwise equal)", header, rows))
    return res
