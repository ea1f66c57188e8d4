"""The Taylor deck run for 0 steps in LIGGGHTS and LAMMPS: the masses and the stiffness the code
actually uses, read back from its own output, are the packing's and the settings'.

One state of the stored lattice case (F = I, periodic route), as written by the deck generator,
with a per-atom dump (``id radius mass x y``) added before its ``run 0``. Checks: 2D masses
m = density pi r^2 (LIGGGHTS: the data file's density column is mass per area; LAMMPS: ``set
density/disc``), radii and centres as written, and |f| = kn delta for every contact of the
contact dump (the deck's kn = E_n reaches the pair style). Skipped where the binary is absent; the
stored outputs are checked without it (test_ref_stored_taylor*.py::*documented_physics).
"""

from __future__ import annotations

import json
import subprocess

import numpy as np
import pytest
from deck_semantics import deck_states, read_data

from gransim.io import load_packing
from reference_runs.decks.taylor import taylor_job
from reference_runs.engines import get_engine
from reference_runs.parsers import parse_dump_custom, parse_dump_local
from reference_runs.store import STORED, TAYLOR_CASE, TAYLOR_PARAMS


@pytest.mark.parametrize("engine", ["liggghts", "lammps"])
def test_zero_step_run_reports_the_masses_and_stiffness(engine, tmp_path):
    eng = get_engine(engine)
    if not eng.available():
        pytest.skip(f"{eng.binary} not installed ({eng.install_hint})")
    packing = load_packing(STORED / TAYLOR_CASE / "packing.h5")
    kn = TAYLOR_PARAMS["kn"]
    deck, files, states = taylor_job(
        packing,
        kn,
        paths=("compression-11",),
        routes=("periodic",),
        n_steps=1,
        stride=1,
        contacts=True,
        name="readback",
        engine=engine,
    )
    st = states[0]
    assert np.array_equal(np.array(st.F), np.eye(2))
    for name, blob in files.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_bytes(blob)
    (tmp_path / st.contacts_file).parent.mkdir(parents=True, exist_ok=True)
    head, first = deck.split("# ---- state ")[:2]
    block = "# ---- state " + first
    fmt = ("line " if engine == "lammps" else "") + '"%d %.17g %.17g %.17g %.17g"'  # LIGGGHTS 3.8: no "line"
    block = block.replace(
        "\nrun             0",
        "\ndump            da all custom 1 atoms.dump id radius mass x y\n"
        f"dump_modify     da format {fmt}\nrun             0",
    )
    assert block.count("dump            da") == 1
    (tmp_path / "in.deck").write_text(head + block)
    r = subprocess.run(
        eng.command("in.deck", "log.txt"),
        cwd=tmp_path,
        env=eng.env(),
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert r.returncode == 0, (r.stdout[-2000:], r.stderr[-2000:])
    (frame,) = parse_dump_custom(tmp_path / "atoms.dump")[:1]
    order = np.argsort(frame["id"])
    radius, mass = np.asarray(frame["radius"])[order], np.asarray(frame["mass"])[order]
    data = read_data(files[st.data_file].decode())
    np.testing.assert_allclose(radius, packing.radii, rtol=1e-15)
    np.testing.assert_allclose(mass, packing.density * np.pi * packing.radii**2, rtol=1e-14)
    xy = np.column_stack([np.asarray(frame["x"])[order], np.asarray(frame["y"])[order]])
    np.testing.assert_allclose(xy, data["x"], rtol=0, atol=1e-15 * packing.cell.max())
    # the stiffness: |f| = kn delta for every contact of the code's contact dump
    meta = json.loads(files["states.json"])
    (fr,) = parse_dump_local(tmp_path / st.contacts_file, names=tuple(meta["contact_columns"]))
    assert len(fr["fx"]) > 0
    i1, i2 = np.asarray(fr["id1"], int) - 1, np.asarray(fr["id2"], int) - 1
    delta = (
        np.asarray(fr["delta"])
        if engine == "liggghts"
        else packing.radii[i1] + packing.radii[i2] - np.asarray(fr["dist"])
    )
    f = np.hypot(fr["fx"], fr["fy"])
    np.testing.assert_allclose(f, kn * delta, rtol=1e-9)  # delta loses ~4 digits by cancellation
    assert deck_states(head + block)[0]["run"] == [["0"]]
