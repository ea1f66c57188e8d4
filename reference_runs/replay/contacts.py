"""Contact rows of ``dump local``, evaluated natively: LIGGGHTS' ``compute pair/gran/local`` and
LAMMPS' ``compute pair/local`` + ``compute property/local``.

Both computes re-evaluate the contact law at output time, without a spring increment, over the
pair's half neighbour list (``newton off``): LIGGGHTS ``ComputePairGranLocal::compute_local`` ->
``PairGran::compute_pgl`` -> ``add_pair`` (compute_pair_gran_local.cpp), LAMMPS
``ComputePairLocal::compute_pairs`` -> ``PairGranHookeHistory::single``. The native rows are the
same evaluation: the law of the deck's code (:func:`gransim.contacts.hooke.hooke_history` or
:func:`~gransim.contacts.hooke.hooke_history_lammps`, ``update`` False) on every touching entry
(rsq < (r_i + r_j)^2) of the engine's list kept with the state, branch d = x_i - (x_j + s L).

Which entries give a row (``newton off``: a pair across the periodic boundary is in both owners'
lists, each against the other's ghost):

* an owned pair: one row, i the list owner (id1, patom1);
* a periodic pair, LIGGGHTS: the copy whose owner has the larger id (``add_pair``: skipped when
  ``tag[i] <= tag[j]`` for a ghost j); LAMMPS: by parity, the copy with itag > jtag when
  itag + jtag is odd, else the one with itag < jtag (compute_pair_local.cpp, property/local
  alike).

Columns compared (others are printed, not compared): LIGGGHTS ``id`` (id1 id2 periodic), ``force``
(on id1), ``torque`` (on id1), ``history`` (the stored spring, z = 0: LIGGGHTS writes no spring
in this evaluation), ``delta`` (r_i + r_j - |d|), ``contactArea`` (-(pi/4)((r - ri - rj)(r + ri -
rj)(r - ri + rj)(r + ri + rj))/r^2), ``vel``, and ``pos`` to the position tolerance (the code
remaps the ghost's copy into the box); LAMMPS ``patom1 patom2``, ``dist`` = |d|, ``force`` = |d|
ccel (the normal force; the law returns ccel r), ``eng`` = 0. LAMMPS' rows also hold neighbour
pairs within the cut-off that do not touch (``single`` gives 0 for them).

At a frame written after a step (not at a run's set-up) the codes evaluate a periodic pair
against a ghost atom not updated since the step's communication (position before the ``fix
deform`` remap, half-step velocity; docs/liggghts.md): those rows are checked for presence only.
"""

from __future__ import annotations

import math
import re

from gransim.contacts.hooke import hooke_history, hooke_history_lammps
from reference_runs.parsers import pair_gran_local_names

#: LIGGGHTS pair/gran/local columns compared exactly; positions to the position tolerance
PGL_EXACT = (
    "vx1",
    "vy1",
    "vz1",
    "vx2",
    "vy2",
    "vz2",
    "periodic",
    "fx",
    "fy",
    "fz",
    "tqx",
    "tqy",
    "tqz",
    "h1",
    "h2",
    "h3",
    "area",
    "delta",
)
PGL_POSITION = ("x1", "y1", "z1", "x2", "y2", "z2")
#: LAMMPS pair/local keywords compared
PL_EXACT = ("dist", "force", "eng")


def _keep(style: str, both: bool, ida: int, idb: int) -> bool:
    if both:
        return True
    if style == "pair/gran/local":
        return ida > idb
    if ida > idb:
        return (ida + idb) % 2 == 1
    return (ida + idb) % 2 == 0


def native_rows(state, deck, style: str, ids, m, r) -> dict:
    """{(id1, id2): {column: value}} of the touching pairs of ``state`` as ``style``
    (``pair/gran/local`` or ``pair/local``) lists them, plus ``"_periodic"`` (bool) per row."""
    c = state.contacts
    s = deck.settings
    law = hooke_history if deck.engine == "liggghts" else hooke_history_lammps
    L0 = state.hi[0] - state.lo[0]
    L1 = state.hi[1] - state.lo[1]
    x, v, w = state.x, state.v, state.w
    out = {}
    for e in range(c["a"].size):
        a, b = int(c["a"][e]), int(c["b"][e])
        both = bool(c["both"][e])
        ida, idb = int(ids[a]), int(ids[b])
        if not _keep(style, both, ida, idb):
            continue
        delx = x[a, 0] - (x[b, 0] + c["sx"][e] * L0)
        dely = x[a, 1] - (x[b, 1] + c["sy"][e] * L1)
        rsq = delx * delx + dely * dely
        radi, radj = float(r[a]), float(r[b])
        radsum = radi + radj
        if not rsq < radsum * radsum:
            continue
        fx, fy, ti, _, _, _, _, fn = law(
            delx, dely, rsq, radi, radj, v[a, 0], v[a, 1], v[b, 0], v[b, 1], w[a], w[b], m[a], m[b],
            s.kn, s.kt, s.gamma_n, s.gamma_t, s.mu, s.dt, c["hist"][e, 0], c["hist"][e, 1], False,
        )  # fmt: skip
        dist = math.sqrt(rsq)
        row = {"_periodic": not both}
        if style == "pair/gran/local":
            rr = math.sqrt(delx * delx + dely * dely + 0.0 * 0.0)
            area = -math.pi / 4 * ((rr - radi - radj) * (rr + radi - radj) * (rr - radi + radj) * (rr + radi + radj))
            row.update(
                x1=x[a, 0], y1=x[a, 1], z1=0.0, x2=x[b, 0], y2=x[b, 1], z2=0.0,
                vx1=v[a, 0], vy1=v[a, 1], vz1=0.0, vx2=v[b, 0], vy2=v[b, 1], vz2=0.0,
                id1=ida, id2=idb, periodic=0.0 if both else 1.0,
                fx=fx, fy=fy, fz=0.0, tqx=0.0, tqy=0.0, tqz=ti, h1=c["hist"][e, 0], h2=c["hist"][e, 1], h3=0.0,
                area=area / (delx * delx + dely * dely + 0.0 * 0.0), delta=radsum - rr,
            )  # fmt: skip
        else:
            # force: the law's ccel r; LAMMPS prints sqrt(rsq) ccel (compute_pair_local.cpp), the same product
            row.update(patom1=ida, patom2=idb, ptype1=1.0, ptype2=1.0, dist=dist, force=fn, eng=0.0)
        out[(ida, idb)] = {k: float(val) for k, val in row.items()}
    return out


def local_columns(deck, dump) -> tuple:
    """Names of a ``dump local``'s columns: ``index``, the pair/gran/local names of
    :func:`reference_runs.parsers.pair_gran_local_names`, or the pair/local and property/local
    keywords."""
    names = []
    for col in dump.columns:
        if col == "index":
            names.append("index")
            continue
        mt = re.fullmatch(r"c_([A-Za-z0-9_]+)(\[(\d+)\])?", col)
        comp = deck.computes[mt.group(1)]
        k = int(mt.group(3)) - 1 if mt.group(3) else 0
        keys = pair_gran_local_names(comp.args, 3) if comp.style == "pair/gran/local" else comp.args
        names.append(keys[k])
    return tuple(names)


def local_style(deck, dump) -> str:
    """``pair/gran/local`` or ``pair/local`` (the LAMMPS computes), from the dump's computes."""
    for col in dump.columns:
        mt = re.fullmatch(r"c_([A-Za-z0-9_]+)(\[(\d+)\])?", col)
        if mt and deck.computes[mt.group(1)].style == "pair/gran/local":
            return "pair/gran/local"
    return "pair/local"


__all__ = ["PGL_EXACT", "PGL_POSITION", "PL_EXACT", "local_columns", "local_style", "native_rows"]
