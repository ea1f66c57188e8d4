"""The codes of the validation matrix, its columns, and what sets two codes apart, in words.

:data:`CODES` lists the reference codes the matrix has columns for, in column order; each is an
engine of :mod:`reference_runs.engines` (binary, version, Debian package, display name). The
columns follow from it (:func:`pairs`): native against each code (the native engine in that
code's arithmetic), then every two codes against each other. Adding a code (YADE's engine
``"yade"`` exists) is one more entry here: its columns appear in every case, and a case that
declares a run of that code (:mod:`validation.matrix`) fills them with the shared judges.

:data:`DIFFERENCES` says, for a pair of codes, why their runs of the same deck differ beyond
round-off: the operation that differs, where it is in each code's source (file:line, from
docs/lammps.md "Every arithmetic difference"), and what it moves. The report shows it beside the
raw cross-code differences, which are figures for the reader, not verdicts.
"""

from __future__ import annotations

from dataclasses import dataclass

from reference_runs.engines import get_engine

NATIVE = "native"
#: the reference codes with matrix columns, in column order (names of reference_runs.engines)
CODES: tuple[str, ...] = ("liggghts", "lammps")


def code_label(code: str) -> str:
    """Display name: ``native``, ``LIGGGHTS``, ``LAMMPS`` (the engine's label)."""
    if code == NATIVE:
        return NATIVE
    return get_engine(code).label


def pair_key(a: str, b: str) -> str:
    """The matrix column of two runs' codes, native first then in :data:`CODES` order:
    ``pair_key("lammps", "native") == "native-lammps"``. ValueError for an unknown code or a code
    set against itself (no column: two runs of one code are an envelope, not a pair)."""
    order = (NATIVE, *CODES)
    for c in (a, b):
        if c not in order:
            raise ValueError(f"code: expected one of {order}, got {c!r}")
    if a == b:
        raise ValueError(f"a matrix column sets two different codes against each other, got {a!r} twice")
    x, y = sorted((a, b), key=order.index)
    return f"{x}-{y}"


def pairs() -> dict[str, str]:
    """The columns of the matrix: ``{"native-liggghts": "native vs LIGGGHTS", ...,
    "liggghts-lammps": "LIGGGHTS vs LAMMPS"}`` (native against each code, then each two codes)."""
    out = {pair_key(NATIVE, c): f"native vs {code_label(c)}" for c in CODES}
    for i, a in enumerate(CODES):
        for b in CODES[i + 1 :]:
            out[pair_key(a, b)] = f"{code_label(a)} vs {code_label(b)}"
    return out


def pair_codes(pair: str) -> tuple[str, ...]:
    """The reference codes a column involves (native left out): ``("liggghts", "lammps")``."""
    return tuple(c for c in pair.split("-") if c != NATIVE)


@dataclass(frozen=True)
class Difference:
    """One operation in which two codes' arithmetic differs.

    item : its row in docs/lammps.md ("A", "B", ...).
    what : the operation, in words.
    where : {code: "file:line ..."} in each code's source (the build's line numbers).
    moves : what putting back the other code's way of this item alone moves on biaxial-short
        (3000 steps; relative stress / positions in D50), measured as docs/lammps.md says.
    """

    item: str
    what: str
    where: dict
    moves: str


#: why two codes' runs of one deck differ beyond round-off (key: :func:`pair_key`)
DIFFERENCES: dict[str, tuple[Difference, ...]] = {
    "liggghts-lammps": (
        Difference(
            "A",
            "the lever arm of the spins in the tangential relative velocity and in the torque: LIGGGHTS "
            "takes the contact point, c = r - delta/2; LAMMPS the full radius r",
            {
                "liggghts": "surface_model_default.h:182-186, 192-194; tangential_model_history.h:230-232, 254-261",
                "lammps": "GRANULAR/pair_gran_hooke_history.cpp:222-224, 249-251, 312-317, 323-325",
            },
            "7.4e-2 of the stress and 1.6e-2 D50 (from step 2)",
        ),
        Difference(
            "B",
            "the Coulomb cap: LIGGGHTS caps the spring force alone and adds the tangential damping below the "
            "cap (so the total may exceed mu |F_n|); LAMMPS caps spring plus damping and rescales the spring",
            {
                "liggghts": "tangential_model_history.h:166-178, 191-199, 212-217",
                "lammps": "GRANULAR/pair_gran_hooke_history.cpp:279-300",
            },
            "8.8e-3 of the stress and 1.9e-3 D50 (from step 13, once contacts slide)",
        ),
        Difference(
            "C",
            "the spring of a pair that stops touching: LAMMPS zeroes it at once, LIGGGHTS keeps it while the "
            "pair stays in the neighbour list",
            {
                "liggghts": "pair_gran_base.h:356, 414; fix_contact_history.cpp:305-420",
                "lammps": "GRANULAR/pair_gran_hooke_history.cpp:186-194",
            },
            "nothing on biaxial-short (no pair re-touched before the next list build)",
        ),
    ),
}

#: the source trees the lines of :data:`DIFFERENCES` refer to
SOURCES = {
    "liggghts": "src/ of LIGGGHTS-PUBLIC 3.8.0 (Debian source package liggghts 3.8.0+repack1)",
    "lammps": "src/ of LAMMPS 29 Sep 2021 (Debian source package lammps 20220106.git7586adbb6a+ds1-2)",
}


def why_they_differ(pair: str) -> str:
    """The reason, in words, why the two codes of ``pair`` differ beyond round-off on the same
    deck ("" when no difference is documented for the pair)."""
    diffs = DIFFERENCES.get(pair)
    if not diffs:
        return ""
    a, b = pair_codes(pair)
    parts = [
        f"({d.item}) {d.what} [{code_label(a)} {d.where[a]}; {code_label(b)} {d.where[b]}]: alone it moves {d.moves}"
        for d in diffs
    ]
    return (
        f"{code_label(a)} and {code_label(b)} run the same deck with different contact-law arithmetic "
        "(docs/lammps.md, 'Every arithmetic difference'): "
        + "; ".join(parts)
        + f". Lines: {SOURCES[a]}; {SOURCES[b]}. The remaining items differ by round-off only (1e-12)."
    )
