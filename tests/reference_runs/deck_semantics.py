"""What a Taylor deck means, read back independently of the deck generator.

The helpers parse a written deck (per state: the commands and their arguments) and the data files
it reads (box and atoms), so that tests can check every physical parameter against the settings
(kn, the zero tangential stiffness, damping and friction, the density) and every state against
the deformation it stands for (x = F X up to periodic images and one rigid translation; the box
F C), and read the same quantities back from the code's own output (thermo atoms/lx/ly, the
contact dumps' force/overlap ratio, per-atom masses).
"""

from __future__ import annotations

import numpy as np


def deck_states(deck: str) -> list[dict]:
    """The state blocks of a Taylor deck (``# ---- state`` headers), each as {command: [args, ...]}
    (a command given twice keeps both argument lists, in order)."""
    blocks = deck.split("# ---- state ")[1:]
    out = []
    for b in blocks:
        cmds: dict = {}
        for line in b.splitlines()[1:]:
            line = line.split("#", 1)[0].strip()
            if line:
                word, *args = line.split()
                cmds.setdefault(word, []).append(args)
        out.append(cmds)
    return out


def fix_values(cmds: dict, name: str) -> list[float]:
    """LIGGGHTS ``fix ID all property/global NAME peratomtypepair NT v...``: the values of NAME."""
    for args in cmds.get("fix", []):
        if len(args) > 4 and args[2] == "property/global" and args[3] == name:
            nt = int(args[5])
            vals = [float(v) for v in args[6:]]
            assert len(vals) == nt * nt, (name, args)
            return vals
    raise AssertionError(f"no fix property/global {name} in the state block")


def read_data(text: str) -> dict:
    """A LIGGGHTS/LAMMPS ``atom_style sphere`` data file: box lo/hi (2,), tilt xy, and the atoms
    (id, type, diameter, density, x, y) in file order."""
    lines = text.splitlines()
    lo, hi, xy, n = np.zeros(2), np.zeros(2), 0.0, None
    for line in lines:
        w = line.split()
        if len(w) == 2 and w[1] == "atoms":
            n = int(w[0])
        elif len(w) == 4 and w[2:] == ["xlo", "xhi"]:
            lo[0], hi[0] = float(w[0]), float(w[1])
        elif len(w) == 4 and w[2:] == ["ylo", "yhi"]:
            lo[1], hi[1] = float(w[0]), float(w[1])
        elif len(w) == 6 and w[3:] == ["xy", "xz", "yz"]:
            xy = float(w[0])
    start = next(i for i, line in enumerate(lines) if line.split()[:1] == ["Atoms"]) + 1
    rows = [line.split() for line in lines[start:] if line.strip()][:n]
    a = np.array(rows, float)
    assert a.shape == (n, 7), a.shape
    return {
        "lo": lo,
        "hi": hi,
        "xy": xy,
        "id": a[:, 0].astype(int),
        "type": a[:, 1].astype(int),
        "diameter": a[:, 2],
        "density": a[:, 3],
        "x": a[:, 4:6],
    }


def lattice_coordinates(cell: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Coordinates of the vectors d (M, 2) in the lattice of ``cell`` (columns): C^-1 d."""
    return np.linalg.solve(cell, np.atleast_2d(d).T).T


def check_affine_state(packing, F, Q, data: dict, n_central: int, tol: float = 1e-9) -> None:
    """The atoms of a state are the packing mapped by F (in the engine frame Q): the N central
    atoms (the first N, in packing order) are Q F X_i + t for one translation t, up to whole
    periods of the deformed cell Q F C; every further atom is a periodic image of a central atom
    of the same radius; diameters are 2 r and the density column is the packing's mass per area.
    ``tol``: in units of the lattice (fractions of a period)."""
    F, Q = np.asarray(F, float), np.asarray(Q, float)
    cell = Q @ F @ packing.cell
    x = data["x"]
    assert len(x) >= n_central == packing.n
    np.testing.assert_allclose(data["diameter"][:n_central], 2.0 * packing.radii, rtol=1e-15)
    np.testing.assert_array_equal(data["density"], packing.density)
    d = x[:n_central] - packing.positions @ (Q @ F).T
    s = lattice_coordinates(cell, d - d[0])
    assert np.abs(s - np.round(s)).max() < tol, "central atoms are not Q F X + t modulo the cell"
    for a in range(n_central, len(x)):
        s = lattice_coordinates(cell, x[a] - x[:n_central])
        whole = np.abs(s - np.round(s)).max(axis=1) < tol
        same_r = np.isclose(data["diameter"][:n_central], data["diameter"][a], rtol=1e-15)
        assert np.any(whole & same_r & (np.abs(np.round(s)).max(axis=1) > 0)), f"atom {a + 1} is no image"


def check_taylor_job(job, packing, kn: float, engine: str, files: dict) -> int:
    """Every state of the finished Taylor job directory ``job`` means what its states.json says.

    The deck run (``in.liggghts`` / ``in.lammps`` as stored) sets kn, and zero tangential
    stiffness, damping and friction (LIGGGHTS: the property/global fixes; LAMMPS: the pair_style
    arguments; its ``set density/disc`` is the packing's density); it reads the state's data file,
    whose atoms are the packing mapped by F (:func:`check_affine_state`) in the box F C (periodic
    route). From the code's own output: each state's thermo row reports all the data file's atoms
    and its box, and every contact of the contact dumps has |f| = kn delta along the line of
    centres (the stiffness the code used). ``files``: the data files by job-relative name (the
    stored ones, or regenerated where the store keeps only their hashes). Returns the number of
    contact rows checked."""
    import json

    from reference_runs.parsers import parse_dump_local, parse_log

    meta = json.loads((job / "states.json").read_text())
    deck = (job / ("in.lammps" if engine == "lammps" else "in.liggghts")).read_text()
    blocks = deck_states(deck)
    runs = parse_log(job / "log.lammps").runs
    assert len(blocks) == len(meta["states"]) == len(runs)
    assert meta["kn"] == kn
    n_contacts = 0
    for st, cmds, run in zip(meta["states"], blocks, runs):
        assert cmds["units"] == [["si"]] and cmds["dimension"] == [["2"]]
        assert cmds["atom_style"] == [["sphere"]]
        assert cmds["boundary"][0][:2] == (["p", "p"] if st["route"] == "periodic" else ["f", "f"])
        assert cmds["read_data"] == [[st["data_file"]]]
        assert cmds["run"] == [["0"]]  # no motion: positions stay x = F X
        if engine == "lammps":
            (ps,) = cmds["pair_style"]
            assert ps[0] == "gran/hooke" and float(ps[1]) == kn and [float(v) for v in ps[2:]] == [0.0] * 5
            (st_set,) = cmds["set"]  # masses m = density pi r^2 (2D)
            assert st_set[:3] == ["group", "all", "density/disc"] and float(st_set[3]) == packing.density
        else:
            assert cmds["pair_style"] == [["gran", "model", "hooke/stiffness", "tangential", "no_history"]]
            assert set(fix_values(cmds, "kn")) == {kn}
            for name in ("kt", "gamman", "gammat", "coefficientFriction"):
                assert set(fix_values(cmds, name)) == {0.0}, name
        data = read_data(files[st["data_file"]].decode())
        F, Q = np.array(st["F"]), np.array(st.get("frame", np.eye(2)))
        check_affine_state(packing, F, Q, data, st["n_central"])
        assert len(data["x"]) == st["n_atoms"]
        box = np.array([[data["hi"][0] - data["lo"][0], data["xy"]], [0.0, data["hi"][1] - data["lo"][1]]])
        if st["route"] == "periodic":  # the box is the deformed cell (same lattice)
            cell = Q @ F @ packing.cell
            s = lattice_coordinates(cell, box.T)
            assert np.abs(s - np.round(s)).max() < 1e-9
            assert np.isclose(abs(np.linalg.det(box)), abs(np.linalg.det(cell)), rtol=1e-14)
        # the code's output: its thermo row of this state
        assert len(run) == 1 and run["Step"][0] == st["index"]
        assert run["Atoms"][0] == len(data["x"])
        assert run["Lx"][0] == box[0, 0] and np.isclose(run["Ly"][0], box[1, 1], rtol=1e-15)
        if st["contacts_file"]:
            (fr,) = parse_dump_local(job / st["contacts_file"], names=tuple(meta["contact_columns"]))
            r = 0.5 * data["diameter"]
            i1, i2 = np.asarray(fr["id1"], int) - 1, np.asarray(fr["id2"], int) - 1
            f = np.column_stack([fr["fx"], fr["fy"]])
            if engine == "lammps":
                delta = r[i1] + r[i2] - np.asarray(fr["dist"])
            else:
                delta = np.asarray(fr["delta"])
                branch = np.column_stack([fr["x2"] - fr["x1"], fr["y2"] - fr["y1"]])
                if st["route"] == "periodic":  # a pair across the boundary: the owned atoms' centres
                    branch -= np.round(lattice_coordinates(box, branch)) @ box.T
                cross = f[:, 0] * branch[:, 1] - f[:, 1] * branch[:, 0]
                assert np.abs(cross).max() <= 1e-12 * np.abs(f).max() * np.abs(branch).max()
                np.testing.assert_allclose(
                    delta, r[i1] + r[i2] - np.linalg.norm(branch, axis=1), rtol=0, atol=1e-12 * r.max()
                )
            assert np.all(delta > 0)
            # |f| = kn delta; delta = r_i + r_j - |l| loses ~4 digits by cancellation (|l|/delta ~ 4e3)
            np.testing.assert_allclose(np.linalg.norm(f, axis=1), kn * delta, rtol=1e-9)
            n_contacts += len(f)
    return n_contacts


def stored_inputs(d, packing, engine="liggghts"):
    """The data files of a stored job: the stored ones, or (where the store keeps only their
    SHA-256) regenerated from packing.h5; either way equal to what the code read, by the hashes
    the runner recorded in the manifest before the run."""
    import hashlib
    import json

    from reference_runs.decks.taylor import taylor_job
    from reference_runs.store import TAYLOR_CASE, TAYLOR_PARAMS

    p = TAYLOR_PARAMS
    _, files, _ = taylor_job(
        packing,
        p["kn"],
        n_steps=p["n_steps"],
        stride=p["stride"],
        max_strain=p["max_strain"],
        contacts=(d.name.startswith(TAYLOR_CASE)),
        name=d.name,
        engine=engine,
    )
    files = {k: (d / k).read_bytes() if (d / k).exists() else v for k, v in files.items()}
    manifest = json.loads((d / "manifest.json").read_text())
    assert manifest["status"] == "ok"
    assert {k: hashlib.sha256(v).hexdigest() for k, v in files.items()} == manifest["inputs"]
    return files
