"""LIGGGHTS and LAMMPS decks for Taylor (affine) RVE states: a packing under a prescribed F, no motion.

``taylor_job(..., engine="liggghts")`` writes the LIGGGHTS deck described first below;
``engine="lammps"`` the LAMMPS deck described at the end.

Contact law: ``pair_style gran model hooke/stiffness tangential no_history`` with
kn = E_n, kt = 0, gamman = gammat = 0 (the elastic normal contact of Meier, Steinmann & Kuhl (2007),
eqs 3-5: f = -E_n eps n), no integrator, one ``run 0`` per state. The set-up of ``run 0``
builds the neighbour list and evaluates the forces once, so the printed virial and the
``compute pair/gran/local`` rows are the clean evaluation at the given positions (docs/liggghts.md).

Each state is read from its own data file, written by gransim at ``%.17g`` with centres
x = F X exactly as numpy computes them (periodic route; the images route translates them by one
constant vector so that the box starts at 0, which rounds them at 1e-16 of the box size); one job (one
process) runs all states of a packing,
separated by ``clear``. Measured (bench/liggghts_reference.py): a LIGGGHTS process costs
about 0.47 s to start, while one job runs the 306 states of a 728-disk packing in 1.0 s (3 ms a
state), so one process per state would be ~140 times slower; the ctypes library API is not needed.

Two routes:

``periodic``
    The deformed cell in a true periodic orthogonal box (only for F that keeps an orthogonal
    reference cell orthogonal: compression paths). Stress: ``compute pressure`` (virial),
    sigma = -p (:mod:`reference_runs.conventions`).
``images``
    Triclinic boxes lose their periodic ghosts in 3.8.0 (domain.cpp:144-145), so any F is run
    as an open (``f f p``) orthogonal box holding the N deformed central particles (type 1)
    and the periodic image copies x_i + (F C) n, n in {-1, 0, 1}^2, that lie within the largest
    contact distance 2 r_max of the deformed cell (type 2). Images carry no stress: the stress
    is the sum of ``compute stress/atom`` over the central group divided by det F V_ref. With
    ``newton off`` each contact puts half its virial on each of its two atoms; a contact
    between central i and image j' = x_j + F C n gives half to i, and its periodic twin
    (central j with image x_i - F C n, also present) gives the other half to j, so the central
    sum is every periodic contact of the cell counted once: sigma = (1/(det F V_ref)) sum f (x) l.
    Running the compression states by both routes checks this construction.

LAMMPS (``engine="lammps"``, checked on LAMMPS 29 Sep 2021 - Update 2, Debian ``lammps``)
    ``pair_style gran/hooke KN 0 0 0 0 0`` (kt = gamman = gammat = mu = 0: the same elastic normal
    contact f = -E_n eps n; no history), ``comm_modify mode single vel yes`` (the granular pairs
    need ghost velocities), ``set group all density/disc RHO`` after ``read_data`` (2D masses
    pi r^2 rho; irrelevant here since nothing moves), no integrator and ``run 0`` per state, with
    ``compute pressure NULL virial`` and ``compute stress/atom NULL pair``. LAMMPS prints no
    WARNING on these decks. Its triclinic box works, so the **periodic** route exists for all four
    paths: compression in an orthogonal box, simple shear in a true periodic triclinic box whose
    lattice is the sheared cell F C, declared in the data file (``xy xz yz`` line, the
    equivalent of ``change_box all triclinic`` plus the tilt) with centres x = F X. LAMMPS needs
    the first lattice vector along x: shear-12 (F C = [[Lx, g Ly], [0, Ly]]) is that box with
    xy = g Ly; shear-21 (F C = [[Lx, 0], [g Lx, Ly]]) is run mirrored, x and y swapped (an exact
    relabelling, no rounding; the pairwise central law is mirror invariant), lx = Ly, ly = Lx,
    xy = g Lx, and the stress and forces are swapped back (``frame`` of the state in
    ``states.json``: x_lammps = Q x). ``read_data`` maps every atom of a triclinic box to box
    (lamda) coordinates and back, which rounds the centres at 1e-16 of the box size (as the
    images route's translation does). The **images** route is the same construction as
    LIGGGHTS' (open ``f f p`` box, central atoms type 1, image copies type 2). Contacts:
    ``compute property/local patom1 patom2 cutoff radius`` and ``compute pair/local dist fx fy
    fz cutoff radius`` in one ``dump local`` (the same neighbour list, so the rows match): the
    force is the pair's ``single()`` evaluation, f on ``id1`` = (x_1 - x_2) fpair, and each
    periodic contact appears once (LAMMPS' itag/jtag rule with ``newton off``).
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np

from gransim.errors import InputError
from gransim.geometry import Packing

from ..datafile import data_file_text
from ..parsers import pair_gran_local_names

#: the four study paths of Meier, Steinmann & Kuhl (2007) (Figs 4-5): driving component of F
PATHS = ("compression-11", "compression-22", "shear-12", "shear-21")
ROUTES = ("periodic", "images")
#: engines the decks are written for
TAYLOR_ENGINES = ("liggghts", "lammps")


def path_F(path: str, n_steps: int = 50, max_strain: float = 0.1, stride: int = 1) -> np.ndarray:
    """Deformation gradients along a study path, (T, 2, 2).

    compression-11: F11 = 1 - max_strain t; compression-22: F22 likewise; shear-12:
    F12 = max_strain t; shear-21: F21 = max_strain t; t = k / n_steps, k = 0, stride, ...,
    and always the last state k = n_steps.
    """
    if path not in PATHS:
        raise InputError(f"unknown path {path!r}; choose one of: {', '.join(PATHS)}")
    if n_steps < 1 or stride < 1:
        raise InputError(f"n_steps and stride must be >= 1 (got {n_steps}, {stride})")
    ks = list(range(0, n_steps + 1, stride))
    if ks[-1] != n_steps:
        ks.append(n_steps)
    t = np.array(ks, float) / n_steps
    F = np.repeat(np.eye(2)[None], len(t), axis=0)
    a, b = {"compression-11": (0, 0), "compression-22": (1, 1), "shear-12": (0, 1), "shear-21": (1, 0)}[path]
    F[:, a, b] = 1.0 - max_strain * t if a == b else max_strain * t
    return F


@dataclass(frozen=True)
class TaylorState:
    """One state of a Taylor job: its path, route, index along the path and F."""

    index: int  # global index in the deck (the thermo Step of its run)
    path: str
    route: str
    k: int  # index along the path
    F: tuple  # ((F11, F12), (F21, F22))
    data_file: str
    contacts_file: str | None
    n_central: int
    n_atoms: int
    frame: tuple = ((1.0, 0.0), (0.0, 1.0))  # Q: x_engine = Q x (LAMMPS shear-21: x and y swapped)


def _wrapped_reference(packing: Packing) -> tuple[np.ndarray, np.ndarray]:
    """Fractional coordinates in [0, 1) and reference centres X = C s (wrapped)."""
    C = packing.cell
    s = np.linalg.solve(C, packing.positions.T).T
    s -= np.floor(s)
    s[s >= 1.0] = 0.0
    return s, s @ C.T


def periodic_state_packing(packing: Packing, F) -> Packing:
    """The deformed packing for the periodic route (F diagonal, reference cell orthogonal)."""
    F = np.asarray(F, float)
    C = packing.cell
    if F[0, 1] != 0 or F[1, 0] != 0 or C[0, 1] != 0 or C[1, 0] != 0:
        raise InputError(
            "the periodic route needs a diagonal F and an orthogonal reference cell "
            "(tilted boxes are broken in LIGGGHTS 3.8.0: use route 'images')"
        )
    _, X = _wrapped_reference(packing)
    x = X @ F.T
    L = np.diag(F @ C)
    if np.any(x < 0) or np.any(x > L):
        raise InputError("periodic route: F must have positive diagonal entries")
    return packing.replace(positions=x, cell=F @ C)


def triclinic_state(packing: Packing, F):
    """Centres and LAMMPS box of the periodic route for any F with F C having a zero below or
    above the diagonal (the compression and simple-shear paths).

    Returns ``(x, (lx, ly, xy), Q)``: centres (N, 2) in the engine frame x_engine = Q F X, the
    box (a = (lx, 0), b = (xy, ly)) and Q, the identity or the x/y swap. Raises InputError
    when F C has both off-diagonal entries (it would need a rotation, which rounds).
    """
    F = np.asarray(F, float)
    C = packing.cell
    if C[0, 1] != 0 or C[1, 0] != 0:
        raise InputError("the periodic route needs an orthogonal reference cell")
    _, X = _wrapped_reference(packing)
    x = X @ F.T
    c = F @ C
    if c[1, 0] == 0:
        Q = np.eye(2)
        box = (float(c[0, 0]), float(c[1, 1]), float(c[0, 1]))
    elif c[0, 1] == 0:
        Q = np.array([[0.0, 1.0], [1.0, 0.0]])
        x = x[:, ::-1].copy()
        box = (float(c[1, 1]), float(c[0, 0]), float(c[1, 0]))
    else:
        raise InputError(
            f"periodic route: F C must have a zero off-diagonal entry (compression or simple shear), got {c.tolist()}"
        )
    if box[0] <= 0 or box[1] <= 0:
        raise InputError("periodic route: F must have positive diagonal entries")
    if abs(box[2]) > 0.5 * box[0]:
        raise InputError(
            f"periodic route: tilt {box[2]:.4g} m exceeds half the box length {box[0]:.4g} m "
            "(LAMMPS refuses such a skewed box)"
        )
    return x, box, Q


def _lammps_data_text(x, radii, density: float, box, types=None) -> str:
    """The text of a LAMMPS ``atom_style sphere`` data file (2D, box [0, lx] x [0, ly], tilt xy),
    ``%.17g``. The density column is 2D (mass per area); the deck sets it again with ``density/disc``."""
    lx, ly, xy = box
    n = len(radii)
    z = max(0.5, 2.0 * float(np.max(radii)))
    t = np.ones(n, np.int64) if types is None else np.asarray(types, np.int64)
    lines = [
        "LAMMPS data file written by gransim (reference_runs.decks.taylor; 2D, density = mass per area)",
        "",
        f"{n} atoms",
        f"{int(t.max())} atom types",
        "",
        f"0 {_g(lx)} xlo xhi",
        f"0 {_g(ly)} ylo yhi",
        f"{_g(-z)} {_g(z)} zlo zhi",
    ]
    if xy != 0:
        lines.append(f"{_g(xy)} 0 0 xy xz yz")
    lines += ["", "Atoms # sphere", ""]
    # one format per row on Python floats and ints (numpy scalars format the same digits, 3x slower)
    rho = _g(density)
    d = (2.0 * np.asarray(radii, float)).tolist()
    lines += [
        f"{k} {tk} {dk:.17g} {rho} {xk:.17g} {yk:.17g} 0"
        for k, tk, dk, (xk, yk) in zip(range(1, n + 1), t.tolist(), d, np.asarray(x, float).tolist())
    ]
    return "\n".join(lines) + "\n"


def image_state_packing(packing: Packing, F, margin: float = 1e-9):
    """Central particles and periodic image copies for the images route.

    Returns ``(packing_box, n_central, source, shift)``: a Packing in an orthogonal box
    [0, Lx] x [0, Ly] holding the N deformed centres first (in packing order), then the
    images x_i + (F C) n within reach 2 r_max (1 + margin) of the deformed cell; ``source``
    (M,) is the original index and ``shift`` (M, 2) the image n of every atom. Positions are
    translated by one constant vector so that the box starts at the origin (a rigid
    translation changes no contact).
    """
    F = np.asarray(F, float)
    C = packing.cell
    s, X = _wrapped_reference(packing)
    c = F @ C
    x = X @ F.T
    r = packing.radii
    A = abs(np.linalg.det(c))
    h = A / np.linalg.norm(c, axis=0)[::-1]  # heights of the deformed cell
    reach = 2.0 * r.max() * (1.0 + margin)
    if h.min() <= reach:
        raise InputError(f"deformed cell height {h.min():.4g} m below the contact reach {reach:.4g} m")
    band = reach / h
    pos, src, shf = [x], [np.arange(len(r))], [np.zeros((len(r), 2), np.int64)]
    for n1 in (-1, 0, 1):
        for n2 in (-1, 0, 1):
            if n1 == 0 and n2 == 0:
                continue
            t = s + np.array([n1, n2])
            keep = np.all((t > -band) & (t < 1.0 + band), axis=1)
            pos.append(x[keep] + c @ np.array([n1, n2], float))
            src.append(np.nonzero(keep)[0])
            shf.append(np.repeat(np.array([[n1, n2]]), keep.sum(), axis=0))
    pos = np.concatenate(pos)
    lo = pos.min(axis=0) - 2.0 * r.max()
    hi = pos.max(axis=0) + 2.0 * r.max()
    src = np.concatenate(src)
    box = Packing(pos - lo, r[src], np.diag(hi - lo), density=packing.density, metadata={"route": "images"})
    return box, len(r), src, np.concatenate(shf)


_HEADER = """\
# LIGGGHTS-PUBLIC 3.8.0 deck written by gransim (reference_runs.decks.taylor)
# Taylor (affine) RVE states: {n_states} states of packing '{name}' ({n} disks), one 'run 0' each.
# Contact: hooke/stiffness, tangential no_history, kn = E_n = {kn} N/m, kt = 0, gamman = gammat = 0:
#   f = -E_n eps n, eqs (3)-(5) of Meier, Steinmann & Kuhl 2007, "Towards completeness: a multiscale
#   approach of confined particulate systems". No integrator: positions are exactly x = F X.
# Output per state (one thermo row, Step = state index):
#   c_p[1] c_p[2] c_p[4]   virial pressure of the box, compression positive (periodic route)
#   c_sc[1] c_sc[2] c_sc[3] sum of stress/atom (xx yy xy) over the central particles (type 1),
#                           = sigma * det F * V_ref, tension positive (both routes)
# The list of states (path, route, F, files) is in states.json.
"""

_STATE = """\
# ---- state {index}: path {path}, route {route}, k = {k}, F = [[{F11}, {F12}], [{F21}, {F22}]]
clear
units           si
atom_style      sphere
dimension       2
boundary        {boundary} p
newton          off
communicate     single vel yes
atom_modify     map array sort 0 0.0
read_data       {data_file}
neighbor        {skin} bin
neigh_modify    delay 0 every 1 check yes
fix             m1 all property/global kn peratomtypepair {nt} {kn_list}
fix             m2 all property/global kt peratomtypepair {nt} {zero_list}
fix             m3 all property/global gamman peratomtypepair {nt} {zero_list}
fix             m4 all property/global gammat peratomtypepair {nt} {zero_list}
fix             m5 all property/global coefficientFriction peratomtypepair {nt} {zero_list}
pair_style      gran model hooke/stiffness tangential no_history
pair_coeff      * *
group           central type 1
compute         t all temp
compute         p all pressure t virial
compute         sa all stress/atom pair
compute         sc central reduce sum c_sa[1] c_sa[2] c_sa[4]
{contacts}thermo_style    custom step atoms lx ly c_p[1] c_p[2] c_p[4] c_sc[1] c_sc[2] c_sc[3]
thermo_modify   format float %.17g lost error
reset_timestep  {index}
run             0
"""

_CONTACTS = """\
compute         pl all pair/gran/local id pos force delta
dump            dc all local 1 {contacts_file} {cols}
dump_modify     dc format "{fmt}"
"""

#: keywords of the contact dump (columns: pair_gran_local_names(CONTACT_KEYWORDS))
CONTACT_KEYWORDS = ("id", "pos", "force", "delta")
_N_CONTACT_COLS = 13


def _g(v: float) -> str:
    return f"{v:.17g}"


_LAMMPS_HEADER = """\
# LAMMPS deck written by gransim (reference_runs.decks.taylor), for LAMMPS 29 Sep 2021 (Debian lammps)
# Taylor (affine) RVE states: {n_states} states of packing '{name}' ({n} disks), one 'run 0' each.
# Contact: pair_style gran/hooke KN 0 0 0 0 0 with KN = E_n = {kn} N/m (kt = gamman = gammat = mu = 0):
#   f = -E_n eps n, eqs (3)-(5) of Meier, Steinmann & Kuhl 2007, "Towards completeness: a multiscale
#   approach of confined particulate systems". No integrator: positions are exactly x = F X.
# Periodic route: orthogonal box (compression) or true periodic triclinic box = the sheared cell (shear);
# shear-21 runs with x and y swapped (states.json: frame). Images route as in the LIGGGHTS deck.
# Output per state (one thermo row, Step = state index):
#   c_p[1] c_p[2] c_p[4]   virial pressure of the box, compression positive (periodic route)
#   c_sc[1] c_sc[2] c_sc[3] sum of stress/atom (xx yy xy) over the central particles (type 1),
#                           = sigma * det F * V_ref, tension positive (both routes)
# The list of states (path, route, F, frame, files) is in states.json.
"""

_LAMMPS_STATE = """\
# ---- state {index}: path {path}, route {route}, k = {k}, F = [[{F11}, {F12}], [{F21}, {F22}]]{swap}
clear
units           si
atom_style      sphere
dimension       2
boundary        {boundary} p
newton          off
comm_modify     mode single vel yes
atom_modify     map array sort 0 0.0
read_data       {data_file}
set             group all density/disc {density}
neighbor        {skin} bin
neigh_modify    delay 0 every 1 check yes
pair_style      gran/hooke {kn} 0 0 0 0 0
pair_coeff      * *
group           central type 1
compute         p all pressure NULL virial
compute         sa all stress/atom NULL pair
compute         sc central reduce sum c_sa[1] c_sa[2] c_sa[4]
{contacts}thermo_style    custom step atoms lx ly c_p[1] c_p[2] c_p[4] c_sc[1] c_sc[2] c_sc[3]
thermo_modify   format float %.17g lost error
reset_timestep  {index}
run             0
"""

_LAMMPS_CONTACTS = """\
compute         pp all property/local patom1 patom2 cutoff radius
compute         pl all pair/local dist fx fy fz cutoff radius
dump            dc all local 1 {contacts_file} c_pp[1] c_pp[2] c_pl[1] c_pl[2] c_pl[3] c_pl[4]
dump_modify     dc format line "%.17g %.17g %.17g %.17g %.17g %.17g"
"""

#: column names of the LAMMPS contact dump (force on id1, in the engine frame; dist = |x_1 - x_2|)
LAMMPS_CONTACT_COLUMNS = ("id1", "id2", "dist", "fx", "fy", "fz")


def taylor_job(
    packing: Packing,
    kn: float,
    paths=PATHS,
    routes=ROUTES,
    n_steps: int = 50,
    max_strain: float = 0.1,
    stride: int = 1,
    contacts: bool = False,
    name: str = "packing",
    skin: float | None = None,
    engine: str = "liggghts",
):
    """Deck text, input files and the state list of one Taylor job (all states of one packing).

    Parameters
    ----------
    packing : reference packing (orthogonal cell needed for the periodic route).
    kn : E_n (N/m).
    paths : subset of :data:`PATHS`.
    routes : subset of :data:`ROUTES`; the periodic route is used only on compression paths.
    n_steps, max_strain, stride : see :func:`path_F`.
    contacts : also dump the contacts of every state (LIGGGHTS ``compute pair/gran/local``,
        LAMMPS ``compute property/local`` + ``pair/local``).
    skin : neighbour skin (m); default 0.1 r_min (any value >= 0 gives the same contacts).
    engine : ``"liggghts"`` (periodic route on compression paths only) or ``"lammps"`` (periodic
        route on all four paths, the shear paths in a triclinic box).

    Returns
    -------
    ``(deck_text, files, states)``: ``files`` maps job-relative names to bytes (the data
    files and ``states.json``), ``states`` a list of :class:`TaylorState` in deck order.
    """
    if not kn > 0:
        raise InputError(f"kn: must be > 0, got {kn!r}")
    if engine not in TAYLOR_ENGINES:
        raise InputError(f"engine: unknown DEM code {engine!r}; choose one of: {', '.join(TAYLOR_ENGINES)}")
    if engine == "lammps":
        return _lammps_taylor_job(packing, kn, paths, routes, n_steps, max_strain, stride, contacts, name, skin)
    for r in routes:
        if r not in ROUTES:
            raise InputError(f"unknown route {r!r}; choose one of: {', '.join(ROUTES)}")
    skin = 0.1 * float(packing.radii.min()) if skin is None else float(skin)

    files, states, blocks = {}, [], []
    cols = " ".join(f"c_pl[{a + 1}]" for a in range(_N_CONTACT_COLS))
    fmt = " ".join(["%.17g"] * _N_CONTACT_COLS)
    for path in paths:
        Fs = path_F(path, n_steps, max_strain, stride)
        ks = list(range(0, n_steps + 1, stride))
        if ks[-1] != n_steps:
            ks.append(n_steps)
        for route in routes:
            if route == "periodic" and not path.startswith("compression"):
                continue
            for k, F in zip(ks, Fs):
                index = len(states)
                data_name = f"states/{path}/{route}_{k:04d}.data"
                if route == "periodic":
                    box = periodic_state_packing(packing, F)
                    nt, types, n_atoms = 1, None, packing.n
                else:
                    box, _, src, _ = image_state_packing(packing, F)
                    nt, n_atoms = 2, box.n
                    types = np.where(np.arange(box.n) < packing.n, 1, 2)
                # no re-wrapping: it would round the centres again (they already lie in the box)
                files[data_name] = data_file_text(box, types=types, wrap=False).encode()
                cfile = f"contacts/{path}/{route}_{k:04d}.dump" if contacts else None
                st = TaylorState(
                    index, path, route, k, tuple(map(tuple, F.tolist())), data_name, cfile, packing.n, n_atoms
                )
                states.append(st)
                blocks.append(
                    _STATE.format(
                        index=index,
                        path=path,
                        route=route,
                        k=k,
                        F11=_g(F[0, 0]),
                        F12=_g(F[0, 1]),
                        F21=_g(F[1, 0]),
                        F22=_g(F[1, 1]),
                        boundary="p p" if route == "periodic" else "f f",
                        data_file=data_name,
                        skin=_g(skin),
                        nt=nt,
                        kn_list=" ".join([_g(kn)] * nt * nt),
                        zero_list=" ".join(["0"] * nt * nt),
                        contacts=_CONTACTS.format(contacts_file=cfile, cols=cols, fmt=fmt) if contacts else "",
                    )
                )
    header = _HEADER.format(n_states=len(states), name=name, n=packing.n, kn=_g(kn))
    deck = header + "\n" + "\n".join(blocks)
    meta = {
        "name": name,
        "kn": kn,
        "n": packing.n,
        "reference_cell": packing.cell.tolist(),
        "reference_area": float(abs(np.linalg.det(packing.cell))),
        "n_steps": n_steps,
        "max_strain": max_strain,
        "stride": stride,
        "skin": skin,
        "contact_columns": list(_contact_names()) if contacts else None,
        "states": [{k: v for k, v in st.__dict__.items() if k != "frame"} for st in states],
    }
    files["states.json"] = json.dumps(meta, indent=1).encode()
    return deck, files, states


def _lammps_taylor_job(packing, kn, paths, routes, n_steps, max_strain, stride, contacts, name, skin):
    for r in routes:
        if r not in ROUTES:
            raise InputError(f"unknown route {r!r}; choose one of: {', '.join(ROUTES)}")
    skin = 0.1 * float(packing.radii.min()) if skin is None else float(skin)
    files, states, blocks = {}, [], []

    for path in paths:
        Fs = path_F(path, n_steps, max_strain, stride)
        ks = list(range(0, n_steps + 1, stride))
        if ks[-1] != n_steps:
            ks.append(n_steps)
        for route in routes:
            for k, F in zip(ks, Fs):
                index = len(states)
                data_name = f"states/{path}/{route}_{k:04d}.data"
                Q = np.eye(2)
                if route == "periodic":
                    x, box, Q = triclinic_state(packing, F)
                    text = _lammps_data_text(x, packing.radii, packing.density, box)
                    n_atoms = packing.n
                else:
                    ibox, _, _, _ = image_state_packing(packing, F)
                    types = np.where(np.arange(ibox.n) < packing.n, 1, 2)
                    text = _lammps_data_text(
                        ibox.positions,
                        ibox.radii,
                        packing.density,
                        (ibox.cell[0, 0], ibox.cell[1, 1], 0.0),
                        types,
                    )
                    n_atoms = ibox.n
                files[data_name] = text.encode()
                cfile = f"contacts/{path}/{route}_{k:04d}.dump" if contacts else None
                st = TaylorState(
                    index,
                    path,
                    route,
                    k,
                    tuple(map(tuple, F.tolist())),
                    data_name,
                    cfile,
                    packing.n,
                    n_atoms,
                    tuple(map(tuple, Q.tolist())),
                )
                states.append(st)
                swap = "; x and y swapped (frame Q = [[0, 1], [1, 0]])" if Q[0, 1] else ""
                blocks.append(
                    _LAMMPS_STATE.format(
                        index=index,
                        path=path,
                        route=route,
                        k=k,
                        F11=_g(F[0, 0]),
                        F12=_g(F[0, 1]),
                        F21=_g(F[1, 0]),
                        F22=_g(F[1, 1]),
                        swap=swap,
                        boundary="p p" if route == "periodic" else "f f",
                        data_file=data_name,
                        density=_g(packing.density),
                        skin=_g(skin),
                        kn=_g(kn),
                        contacts=_LAMMPS_CONTACTS.format(contacts_file=cfile) if contacts else "",
                    )
                )
    header = _LAMMPS_HEADER.format(n_states=len(states), name=name, n=packing.n, kn=_g(kn))
    deck = header + "\n" + "\n".join(blocks)
    meta = {
        "name": name,
        "engine": "lammps",
        "kn": kn,
        "n": packing.n,
        "reference_cell": packing.cell.tolist(),
        "reference_area": float(abs(np.linalg.det(packing.cell))),
        "n_steps": n_steps,
        "max_strain": max_strain,
        "stride": stride,
        "skin": skin,
        "contact_columns": list(LAMMPS_CONTACT_COLUMNS) if contacts else None,
        "states": [dict(st.__dict__) for st in states],
    }
    files["states.json"] = json.dumps(meta, indent=1).encode()
    return deck, files, states


def _contact_names():
    return pair_gran_local_names(CONTACT_KEYWORDS)
