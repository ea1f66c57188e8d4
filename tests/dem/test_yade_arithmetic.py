"""The native ``yade`` arithmetic (gransim.dem.yade_arithmetic, gransim.contacts.yade_cundall_strack)
against YADE 2023.02a itself.

What is checked, and why it can fail:

* two disks whose numbers are exact in binary, by hand: the normal force kn delta, the shear force
  of the first step -ks dt v_t, the Coulomb cap mu |F_n| (a friction coefficient whose
  tan(atan(mu)) is mu to the bit), the torques (r - delta/2) (n x f) on both disks, the periodic
  image across the boundary (the same forces), and the leapfrog step v += dt f/m, x += dt v;
* YADE's own output of the decks' three short cases (biaxial with its servo, simple shear at
  constant volume and under the servo; 120 disks, 3000 steps), stored with its provenance in
  tests/dem/data/yade: the cell, the stress and the velGrad of every 10th step and full frames
  (positions, velocities, spins, forces, torques, every real interaction in YADE's container order
  with its cellDist, normal and shear force and penetration) at every 500th, all equal to the bit;
* with YADE installed, live runs of the same cases and of a fixed cell with random velocities and
  spins (contacts open, close and slide): cell, stress and velGrad at every step and full frames
  at every 10th step, equal to the bit.

Each comparison also checks that its evidence is not trivial: the run's contacts change (the
collider ran and interactions were created and erased), some contacts cross the periodic boundary,
and contacts slide at the Coulomb cap.
"""

from __future__ import annotations

import gzip
import hashlib
import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from gransim.contacts.yade_cundall_strack import friction_tangent
from gransim.dem.settings import AxisControl, DEMSettings, Loading
from gransim.dem.yade_arithmetic import yade_cell_z, yade_run
from gransim.geometry import Packing
from reference_runs.decks.shear import wrapped_packing
from reference_runs.yade.dem import biaxial_job, read_yade_dem, run_yade_dem, shear_job, short_biaxial, short_shear
from reference_runs.yade.dem_script import DEM_SCRIPT
from reference_runs.yade.taylor import cell_z

DATA = Path(__file__).parent / "data" / "yade"
STORED = ("biaxial", "constant-volume", "servo")
HAVE_YADE = shutil.which("yade") is not None


def case(name: str):
    """(packing, settings, loading, nsteps, job, job kwargs) of a YADE comparison case."""
    if name == "biaxial":
        p, s, ld, n = short_biaxial()
        return p, s, ld, n, biaxial_job, {}
    if name == "random":  # a fixed cell, random velocities and spins: contacts open, close and slide
        p, s, _, _ = short_biaxial()
        rng = np.random.default_rng(7)
        kw = {"velocities": rng.normal(scale=0.05, size=(p.n, 2)), "spins": rng.normal(scale=50.0, size=p.n)}
        return p, s, Loading(x=AxisControl("fixed"), y=AxisControl("fixed")), 2000, biaxial_job, kw
    p, s, ld, n = short_shear(name)
    return p, s, ld, n, shear_job, {}


def native(name: str):
    p, s, ld, n, _, kw = case(name)
    return yade_run(wrapped_packing(p), s, ld, n, **kw)


def compare(run, out) -> dict:
    """Assert every thermo step and frame of YADE's output equals the native run to the bit; return
    what the evidence covered."""
    assert len(out.step) > 1 and len(out.frames) > 1
    k = out.step
    assert np.array_equal(run.cell[k], out.cell), "cell"
    assert np.array_equal(run.stress[k], out.stress), "stress"
    assert np.array_equal(run.vel_grad[k], out.vel_grad), "velGrad"
    assert np.array_equal(run.n_contacts[k], out.n_contacts), "number of contacts"
    pairs, crossing, sliding = set(), 0, 0
    for step, fr in sorted(out.frames.items()):
        for what, mine, theirs in (
            ("positions", run.positions[step], fr.positions),
            ("velocities", run.velocities[step], fr.velocities),
            ("spins", run.spins[step], fr.spins),
            ("forces", run.forces[step], fr.forces),
            ("torques", run.torques[step], fr.torques),
            ("mass", run.mass, fr.mass),
        ):
            assert np.array_equal(mine, theirs), f"step {step}: {what}"
        ids, cd, fn, fs, pen = run.contacts[step]
        for what, mine, theirs in (
            ("interaction ids and order", ids, fr.ids),
            ("cellDist", cd, fr.cell_dist),
            ("normal force", fn, fr.normal_force),
            ("shear force", fs, fr.shear_force),
            ("penetration", pen, fr.penetration),
        ):
            assert mine.shape == theirs.shape and np.array_equal(mine, theirs), f"step {step}: {what}"
        pairs |= {tuple(i) for i in ids}
        crossing += int(np.any(cd != 0, axis=1).sum())
        ratio = np.linalg.norm(fs, axis=1) / (np.linalg.norm(fn, axis=1) * 0.5)
        sliding += int((np.abs(ratio - 1.0) < 1e-12).sum())
    return {"pairs": len(pairs), "crossing": crossing, "sliding": sliding, "frames": len(out.frames)}


# ----------------------------------------------------------------------------------------------
# two disks by hand


#: z of the two-disk cell: YADE needs each bound's z extent, 2 (r + verletDist) = 1.5, below half of it
Z = 4.0


def two_disks(x1, x2, L=8.0, v2=(0.0, 1.0), mu=0.625):
    """Radii 1/2, kn 1024, ks 512, dt 2^-10: every number below is exact in binary."""
    p = Packing(np.array([x1, x2]), np.array([0.5, 0.5]), np.diag([L, L]), density=1.0)
    s = DEMSettings(kn=1024.0, kt=512.0, mu=mu, dt=2.0**-10, skin=0.1)
    return p, s, np.array([[0.0, 0.0], v2])


@pytest.mark.parametrize("x2", [(1.875, 4.0), (-6.125, 4.0)], ids=["inside", "across-the-boundary"])
def test_two_disks_by_hand(x2):
    # centres 0.875 apart along x (directly or through the periodic image): delta = 1/8, n = (1, 0)
    p, s, v = two_disks((1.0, 4.0), x2)
    run = yade_run(p, s, Loading(), 1, velocities=v, z=Z)
    ids, cd, fn, fs, pen = run.contacts[0]
    assert ids.tolist() == [[0, 1]] and pen.tolist() == [0.125]
    assert cd.tolist() == [[0, 0]] if x2[0] > 0 else cd.tolist() == [[1, 0]]
    assert fn.tolist() == [[128.0, 0.0]]  # kn delta n = 1024/8
    # a new contact: F_s = -ks dt v_t = -512 * 2^-10 * (0, 1) (disk 2 slides up along disk 1)
    assert fs.tolist() == [[0.0, -0.5]]
    f = np.array([[-128.0, 0.5], [128.0, -0.5]])  # -F_n - F_s on disk 1, the opposite on disk 2
    assert np.array_equal(run.forces[0], f)
    # (r - delta/2) (n x f_1) = 0.4375 * 0.5 on both disks
    assert run.torques[0].tolist() == [0.21875, 0.21875]
    # the leapfrog step: v += dt f/m, w += dt t/I, x += dt v (m = pi/4, I = m/8)
    m = 1.0 * math.pi * 0.5 * 0.5
    inertia = 0.5 * m * 0.5 * 0.5
    assert run.mass.tolist() == [m, m] and run.inertia.tolist() == [inertia, inertia]
    v1 = v + s.dt * (f / m)
    assert np.array_equal(run.velocities[1], v1)
    assert np.array_equal(run.spins[1], s.dt * (np.array([0.21875, 0.21875]) / inertia))
    assert np.array_equal(run.positions[1], p.positions + v1 * s.dt)


def test_two_disks_slide_at_the_coulomb_cap():
    # v_t = 4096 m/s: -ks dt v_t = -2048 N, above mu |F_n| = 0.625 * 128 = 80 N: scaled to 80 N exactly
    p, s, v = two_disks((1.0, 4.0), (1.875, 4.0), v2=(0.0, 4096.0))
    assert friction_tangent(s.mu) == s.mu
    run = yade_run(p, s, Loading(), 0, velocities=v, z=Z)
    assert run.contacts[0][3].tolist() == [[0.0, -80.0]]
    assert run.forces[0].tolist() == [[-128.0, 80.0], [128.0, -80.0]]


def test_friction_tangent_is_yades_tan_of_atan():
    # YADE stores tan(atan(mu)) (FrictPhys.cpp:41): 0.5 comes back 1 ulp low; the cap uses that
    assert friction_tangent(0.5) == 0.49999999999999994 and friction_tangent(0.625) == 0.625


def test_cell_z_is_the_yade_scripts():
    p, *_ = short_biaxial()
    assert yade_cell_z(p.radii) == cell_z(p) == 2.0**-7


# ----------------------------------------------------------------------------------------------
# YADE's stored output


def _sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


@pytest.mark.parametrize("name", STORED)
def test_stored_yade_run_equals_the_native_run_bit_for_bit(name, tmp_path):
    d = DATA / name
    manifest = json.loads((d / "manifest.json").read_text())
    text = gzip.decompress((d / "dem.out.gz").read_bytes())
    # provenance: the output, YADE's version, the script and the input of this very case
    assert _sha(text) == manifest["outputs"]["dem.out"]
    assert manifest["status"] == "ok" and manifest["engine_version"] == "YADE 2023.02a"
    assert manifest["deck_sha256"] == _sha(DEM_SCRIPT.encode())
    p, s, ld, n, job, kw = case(name)
    meta = manifest["stored"]
    _, files = job(p, s, ld, n, thermo_every=meta["thermo_every"], dump_every=meta["dump_every"], **kw)
    assert _sha(files["input.json"]) == manifest["inputs"]["input.json"]
    (tmp_path / "dem.out").write_bytes(text)
    out = read_yade_dem(tmp_path / "dem.out")
    assert out.n_steps == n == 3000 and len(out.frames) == 7
    seen = compare(native(name), out)
    assert seen["pairs"] > 150 and seen["crossing"] > 0 and seen["sliding"] > 0, seen


# ----------------------------------------------------------------------------------------------
# live YADE


@pytest.mark.skipif(not HAVE_YADE, reason="yade binary not installed (apt-get install yade; make engines)")
@pytest.mark.parametrize("name", ["biaxial", "constant-volume", "servo", "random"])
def test_live_yade_run_equals_the_native_run_bit_for_bit(name, tmp_path):
    p, s, ld, n, job, kw = case(name)
    script, files = job(p, s, ld, n, thermo_every=1, dump_every=10, **kw)
    out, manifest = run_yade_dem(tmp_path / "job", script, files)
    assert manifest["engine_version"] == "YADE 2023.02a"
    assert list(out.step) == list(range(n + 1))
    seen = compare(native(name), out)
    assert seen["pairs"] > 150 and seen["crossing"] > 0 and seen["sliding"] > 0, seen


@pytest.mark.parametrize("radii", [[0.25, 0.25], [0.25, 0.1], [1e-3, 4e-4, 5e-4], [0.3, 0.3, 0.3]])
def test_cell_z_clears_every_bound(radii):
    """YADE's cell in z is a power of two above 4 r_max + 2 r_min: a bound's extent in z,
    2 (r_max + verletDist) with verletDist = 0.5 r_min, stays below half of it (equal radii with
    4 r a power of two, 0.25 here, made YADE stop with the rule 'power of two >= 4 r_max')."""
    r = np.asarray(radii)
    z = yade_cell_z(r)
    assert 2.0 * (r.max() + 0.5 * r.min()) < z / 2
    assert np.log2(z) == np.round(np.log2(z))
    assert z / 2 <= 4 * r.max() + 2 * r.min()  # the smallest such power of two
