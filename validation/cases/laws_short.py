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

from gransim.contacts.laws import law_code
from gransim.errors import ResultFileError
from reference_runs.decks.biaxial import SHORT_CASE_DUMP_EVERY, SHORT_CASE_LAWS, short_case, short_case_law

from ..core import CaseResult, Context, Record, case, in_pair, stored_dir, stored_job_record
from ..dem_compare import read_reference, run_native, run_reference_job
from .biaxial import CODE, _stored_log, step_records

REASON = (
    "bit for bit: the native engine runs each law in its code's floating-point order (docs/laws.md), so "
    "the doubles are equal; 1e-10 D50 / 1e-8 relative (the biaxial-short bounds) leaves room for another "
    "CPU or compiler and still lies decades below what a 1% change of any law parameter moves"
)


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
    for engine in ("liggghts", "lammps"):
        if engine in codes:
            res.declare(f"native-{engine}", REASON)
        else:
            res.skip_pair(f"native-{engine}", f"no law of {CODE[engine]} in this run")
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
    rows = []
    p, s, ld, n = short_case()
    for name in SHORT_CASE_LAWS:
        engine = law_code(name)
        settings = dataclasses.replace(s, flavour=engine)
        law = short_case_law(name)
        nat = run_native(p, settings, ld, n, SHORT_CASE_DUMP_EVERY, law=law, check_dt=False)
        stored = stored_dir(f"biaxial-short-{name}")
        label = f"laws-short/{name}/stored"
        try:
            ref = read_reference(_stored_log(stored), stored / "dump.atoms")
        except ResultFileError as exc:  # a cut or corrupt stored output is missing evidence, not a crash
            res.records += in_pair(
                [
                    stored_job_record(label, stored),
                    Record(
                        label,
                        "evidence",
                        f"unreadable stored run: {exc}",
                        1.0,
                        0.0,
                        False,
                        "every stored frame and step must be readable",
                    ),
                ],
                f"native-{engine}",
            )
            continue
        recs, row = step_records(label, nat, ref, p.d50, n, SHORT_CASE_DUMP_EVERY, code=CODE[engine])
        res.records += in_pair([stored_job_record(label, stored)] + recs, f"native-{engine}")
        rows.append([name, CODE[engine], *row])
        if not getattr(ctx, engine):
            res.notes.append(f"{CODE[engine]} is absent: {name} is compared with its stored run only.")
            continue
        job = ctx.work("reference", "laws-short", name)
        live, man = run_reference_job(
            job, p, settings, ld, n, SHORT_CASE_DUMP_EVERY, timeout=ctx.job_timeout(p.n * n), engine=engine, law=law
        )
        label = f"laws-short/{name}/live"
        recs, row = step_records(label, nat, live, p.d50, n, SHORT_CASE_DUMP_EVERY, code=CODE[engine])
        res.records += in_pair(recs, f"native-{engine}")
        rows.append([name, CODE[engine], *row])
    res.tables.append(("Largest differences per law and code (0 = bitwise equal)", header, rows))
    return res
