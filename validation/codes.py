"""The codes of the validation matrix, its columns, and what sets two codes apart, in words.

:data:`CODES` lists the reference codes the matrix has columns for, in column order; each is an
engine of :mod:`reference_runs.engines` (binary, version, Debian package, display name). The
columns follow from it (:func:`pairs`): native against each code (the native engine in that
code's arithmetic), then every two codes against each other. Adding a code is one more entry
here: its columns appear in every case, and a case that declares a run of that code
(:mod:`validation.matrix`) fills them with the shared judges (YADE 2023.02a, the third code, is
the last entry: a code written independently of the LIGGGHTS and LAMMPS lineage, docs/yade.md).

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
CODES: tuple[str, ...] = ("liggghts", "lammps", "yade")


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
#: what sets YADE 2023.02a's periodic runs (reference_runs/yade/dem_script.py, undamped
#: Cundall-Strack) apart from the decks' (docs/yade.md, "How YADE's arithmetic differs")
_YADE_ITEMS = (
    (
        "Y1",
        "the cell kinematics: YADE's disks carry the mean field velGrad x in their velocities (homoDeform 2) and a "
        "contact across the boundary adds the image's velocity velGrad hSize cellDist, so the tangential relative "
        "velocity, and with it the shear spring, sees the affine strain rate; the decks' fix deform remaps the "
        "positions and leaves the velocities without the mean field, so their springs see the fluctuations only",
        "core/Cell.cpp:12-19, pkg/dem/NewtonIntegrator.cpp:262, 321-323, pkg/dem/ScGeom.cpp:88-92",
    ),
    (
        "Y2",
        "the integrator: leapfrog with one kick per step (v += dt F/m, then x += dt v), the velocity half a step "
        "behind the positions; the decks' velocity Verlet kicks twice by dt/2 (the same positions in exact "
        "arithmetic for forces that do not depend on velocity, rounded differently)",
        "pkg/dem/NewtonIntegrator.cpp:264, 270, 324",
    ),
    (
        "Y3",
        "the shear history: YADE keeps the shear force, rotated to first order (F_s -= F_s x (n_old x n_new), not "
        "norm-preserving, not projected) and then incremented by -ks dt v_t; the decks keep the spring displacement, "
        "projected on the tangent plane",
        "pkg/dem/ScGeom.cpp:15-23, 48-61, pkg/dem/ElasticContactLaw.cpp:72-82",
    ),
)
_DECK_LINES = {
    "liggghts": "fix deform remap x and fix nve/sphere (docs/lammps.md); tangential_model_history.h:166-199",
    "lammps": "fix deform remap x/v and fix nve/sphere (docs/lammps.md); GRANULAR/pair_gran_hooke_history.cpp:255-300",
}
_TOGETHER = "an amount not measured on its own (the items act together)"
for _code in ("liggghts", "lammps"):
    DIFFERENCES[f"{_code}-yade"] = tuple(
        Difference(item, what, {_code: _DECK_LINES[_code], "yade": where}, _TOGETHER)
        for item, what, where in _YADE_ITEMS
    ) + (
        (
            Difference(
                "Y4",
                "the lever arm of the spins: YADE takes the contact point, r - delta/2 (as LIGGGHTS); LAMMPS the full "
                "radius r",
                {
                    "lammps": "GRANULAR/pair_gran_hooke_history.cpp:222-224, 249-251, 312-317, 323-325",
                    "yade": "pkg/dem/Ig2_Sphere_Sphere_ScGeom.cpp:52, pkg/dem/ElasticContactLaw.cpp:108-112",
                },
                "7.4e-2 of the stress and 1.6e-2 D50 between LIGGGHTS and LAMMPS (item A)",
            ),
        )
        if _code == "lammps"
        else ()
    )


#: the source trees the lines of :data:`DIFFERENCES` refer to
SOURCES = {
    "liggghts": "src/ of LIGGGHTS-PUBLIC 3.8.0 (Debian source package liggghts 3.8.0+repack1)",
    "lammps": "src/ of LAMMPS 29 Sep 2021 (Debian source package lammps 20220106.git7586adbb6a+ds1-2)",
    "yade": "YADE 2023.02a (tag 2023.02a, commit d081c80d0; docs/yade.md)",
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
    where = "docs/lammps.md, 'Every arithmetic difference'"
    if "yade" in (a, b):
        where = "docs/yade.md, 'How YADE's arithmetic differs'"
    return (
        f"{code_label(a)} and {code_label(b)} run the same deck with different contact-law arithmetic "
        f"({where}): "
        + "; ".join(parts)
        + f". Lines: {SOURCES[a]}; {SOURCES[b]}."
        + ("" if "yade" in (a, b) else " The remaining items differ by round-off only (1e-12).")
    )
