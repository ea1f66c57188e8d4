"""Parsers on synthetic text with known content and on the stored LIGGGHTS output."""

import json

import numpy as np
import pytest

from gransim.errors import ResultFileError
from reference_runs.h5 import read_frames_h5, read_thermo_h5, write_output_h5
from reference_runs.parsers import pair_gran_local_names, parse_dump_custom, parse_dump_local, parse_log
from reference_runs.store import STORED, TAYLOR_CASE

STORE = STORED / TAYLOR_CASE

LOG = """\
LIGGGHTS (Version LIGGGHTS-PUBLIC 3.8.0, compiled 2022-01-26-19:42:32 by buildd, git commit unknown)
run 2
WARNING: It is heavily recommended to use 'neigh_modify delay 0' with granular pair styles (x.cpp:1)
Memory usage per processor = 4.38 Mbytes
    Step    Atoms             Lx           p[1]
       0       3 6 0.10000000000000001
       1       3 6 -2.5e-07
WARNING: something in the middle of a run (y.cpp:2)
       2       3 6 3
Loop time of 4.61e-07 on 1 procs for 2 steps with 3 atoms
run 1
    Step    Atoms             Lx           p[1]
       2       3 6 3
       3       2 6 4
Loop time of 1e-07 on 1 procs for 1 steps with 2 atoms
run 5
    Step    Atoms             Lx           p[1]
       3       2 6 4
ERROR: Lost atoms: original 3 current 2 (./src/thermo.cpp:445)
"""


def test_log_runs_rows_warnings_errors():
    log = parse_log(LOG)
    assert log.version == "LIGGGHTS-PUBLIC 3.8.0"
    assert len(log.runs) == 3
    r0 = log.runs[0]
    assert r0.columns == ("Step", "Atoms", "Lx", "p[1]")
    assert r0.complete and r0.steps.tolist() == [0, 1, 2]
    # full precision kept, and the compute prefix accepted
    assert r0["c_p[1]"].tolist() == [0.1, -2.5e-7, 3.0]
    assert [r.complete for r in log.runs] == [True, True, False]
    assert len(log.warnings) == 2 and log.warnings[1].lineno == 8
    assert len(log.errors) == 1 and "Lost atoms" in log.errors[0].text
    assert log.lost_atoms
    with pytest.raises(KeyError, match="not in"):
        r0.column("pxx")


def test_log_lost_atoms_from_atoms_column():
    text = "    Step    Atoms\n 0 10\n 5 9\nLoop time of 1 on 1 procs\n"
    assert parse_log(text).lost_atoms
    assert not parse_log(text.replace(" 5 9", " 5 10")).lost_atoms


DUMP = """\
ITEM: TIMESTEP
100
ITEM: NUMBER OF ATOMS
3
ITEM: BOX BOUNDS pp pp pp
0 6
0 5.19615
-1.1 1.1
ITEM: ATOMS id type x y fx
3 1 0.30000000000000004 3 -1e-300
1 2 0.1 1 5
2 1 0.2 2 6
ITEM: TIMESTEP
200
ITEM: NUMBER OF ATOMS
0
ITEM: BOX BOUNDS xy xz yz pp pp pp
0 6 0.5
0 5 0
-1 1 0
ITEM: ATOMS id type x y fx
"""


def test_dump_custom_sorted_by_id(tmp_path):
    p = tmp_path / "d.dump"
    p.write_text(DUMP)
    f0, f1 = parse_dump_custom(p)
    assert f0.step == 100 and f1.step == 200
    assert f0["id"].tolist() == [1, 2, 3] and f0["id"].dtype == np.int64
    assert f0["type"].tolist() == [2, 1, 1]
    assert f0["x"].tolist() == [0.1, 0.2, 0.30000000000000004]
    assert f0["fx"][2] == -1e-300
    assert f0.box.tolist() == [[0, 6], [0, 5.19615], [-1.1, 1.1]] and f0.tilt is None
    assert len(f1) == 0 and f1.tilt.tolist() == [0.5, 0, 0]
    with pytest.raises(ValueError):
        f0["x"][0] = 1.0  # read-only


def test_dump_errors(tmp_path):
    p = tmp_path / "bad.dump"
    p.write_text(DUMP.replace("2 1 0.2 2 6\n", "", 1))
    with pytest.raises(ResultFileError, match="bad.dump:"):
        parse_dump_custom(p)
    p.write_text(DUMP)
    with pytest.raises(ResultFileError, match="NUMBER OF ENTRIES"):
        parse_dump_local(p)
    with pytest.raises(ResultFileError, match="cannot read"):
        parse_dump_custom(tmp_path / "missing.dump")


def test_pair_gran_local_names():
    assert pair_gran_local_names(("delta", "id", "pos", "force")) == (
        "x1",
        "y1",
        "z1",
        "x2",
        "y2",
        "z2",
        "id1",
        "id2",
        "periodic",
        "fx",
        "fy",
        "fz",
        "delta",
    )
    assert len(pair_gran_local_names((), n_history=3)) == 6 + 6 + 3 + 3 + 3 + 3 + 1
    with pytest.raises(ValueError, match="unknown"):
        pair_gran_local_names(("forces",))


def test_stored_log_one_complete_run_per_state():
    meta = json.loads((STORE / "states.json").read_text())
    log = parse_log(STORE / "log.lammps")
    assert log.version == "LIGGGHTS-PUBLIC 3.8.0"
    assert not log.errors and not log.warnings and not log.lost_atoms
    assert len(log.runs) == len(meta["states"]) == 36
    for st, run in zip(meta["states"], log.runs):
        assert run.complete and run.steps.tolist() == [st["index"]]
        assert run["Atoms"][0] == st["n_atoms"]


def test_stored_contact_dump_rows():
    meta = json.loads((STORE / "states.json").read_text())
    names = tuple(meta["contact_columns"])
    st = next(s for s in meta["states"] if s["route"] == "periodic" and s["k"] == 50)
    (fr,) = parse_dump_local(STORE / st["contacts_file"], names=names)
    assert fr.step == st["index"]
    # rows sorted by (id1, id2), ids of real particles, overlaps positive, force repulsive
    key = fr["id1"] * 10**6 + fr["id2"]
    assert np.all(np.diff(key) >= 0)
    assert fr["id1"].min() >= 1 and fr["id2"].max() <= meta["n"]
    assert np.all(fr["delta"] > 0)


def test_h5_roundtrip(tmp_path):
    log = parse_log(STORE / "log.lammps")
    meta = json.loads((STORE / "states.json").read_text())
    st = meta["states"][-1]
    frames = parse_dump_local(STORE / st["contacts_file"], names=tuple(meta["contact_columns"]))
    out = write_output_h5(tmp_path / "o.h5", log, {"contacts": frames}, parameters={"case": "stored"})
    runs = read_thermo_h5(out)
    assert len(runs) == len(log.runs)
    assert np.array_equal(runs[5].data, log.runs[5].data) and runs[5].columns == log.runs[5].columns
    (back,) = read_frames_h5(out, "contacts")
    for c in frames[0].names:
        assert np.array_equal(back[c], frames[0][c])
    import h5py

    with h5py.File(out) as f:
        assert "liggghts_version" in f.attrs and f.attrs["kind"] == "liggghts-output"


def test_stress_series_sign_and_repeated_steps():
    from reference_runs.convert import stress_series

    log = parse_log(
        "    Step    c_p[1]    c_p[2]    c_p[4]\n 0 1 2 3\n 5 4 5 6\nLoop time of 1\n"
        "    Step    c_p[1]    c_p[2]    c_p[4]\n 5 4 5 6\n 10 7 8 9\nLoop time of 1\n"
    )
    steps, sig = stress_series(log.runs)
    assert steps.tolist() == [0, 5, 10]
    # compression-positive pressure p = (1, 2, 3) is sigma = -[[1, 3], [3, 2]]
    assert sig[0].tolist() == [[-1, -3], [-3, -2]] and sig[2, 1, 1] == -8


def test_particle_series(tmp_path):
    from reference_runs.convert import particle_series

    p = tmp_path / "d.dump"
    frame2 = DUMP.split("ITEM: TIMESTEP\n200")[0].replace("100\n", "300\n", 1)
    p.write_text(DUMP.split("ITEM: TIMESTEP\n200")[0] + frame2)
    frames = parse_dump_custom(p)
    steps, ids, cols = particle_series(frames, ("x", "fx"))
    assert steps.tolist() == [100, 300] and ids.tolist() == [1, 2, 3] and cols["x"].shape == (2, 3)
    p.write_text(DUMP)
    with pytest.raises(ResultFileError, match="other particles"):
        particle_series(parse_dump_custom(p), ("x",))
