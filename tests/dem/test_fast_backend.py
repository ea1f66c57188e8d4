"""The fast ordering (gransim.dem.fast.FastEngine) as a backend of the engine: the loadings of the
orthogonal cell (servo, rate, prescribed box), the sheared cell with Lees-Edwards images and its
y servo, both codes' arithmetic, checkpoints, threads, the checks and the clean errors.

The fast ordering sums in another order than the code order, so it is compared with it to
round-off over short horizons and, over long ones, by the divergence envelope of the code order
itself (runs from 1e-12 perturbed starts), never by equality. Checkpoints and threads are held to
equality: the fast ordering's sums have a fixed order.
"""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from gransim import Packing
from gransim.contacts.laws import make_law
from gransim.dem import AxisControl, DEMEngine, DEMSettings, Integration, Loading, PrescribedBox, fast
from gransim.dem.fast import FastEngine
from gransim.dem.lattice import lattice_packing
from gransim.dem.sheared import ShearEngine, ShearLoading
from gransim.errors import InputError, SimulationError

S = DEMSettings(kn=1e5, kt=1e5, gamma_n=50.0, gamma_t=50.0, mu=0.5, dt=2e-6, skin=2e-5)
S_LMP = DEMSettings(**{**S.to_dict(), "flavour": "lammps"})


@pytest.fixture
def threaded_small(monkeypatch):
    """The threaded kernels even for the small test assemblies (below fast.MIN_PER_THREAD
    particles per thread they run on one thread)."""
    monkeypatch.setattr(fast, "MIN_PER_THREAD", 0)


def _rel(a, b):
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


def _image_diff(a, b, cell):
    """Largest |a - b| (m) with each difference taken to its nearest periodic image of ``cell``
    (2, 2), columns the lattice vectors."""
    d = (a - b) @ np.linalg.inv(cell).T
    d -= np.rint(d)
    return float(np.max(np.abs(d @ cell.T)))


def sheared_lattice(tilt_spacings=4, nx=24, ny=28, seed=3):
    """A compressed triangular lattice in a sheared cell whose tilt is a whole number of lattice
    spacings (the lattice stays periodic across the tilted boundary)."""
    p = lattice_packing(nx, ny, seed=seed, spread=0.15, compression=0.06)
    C = p.cell.copy()
    C[0, 1] = tilt_spacings * 2e-3
    return Packing(positions=p.positions, radii=p.radii, cell=C, density=p.density)


# --------------------------------------------------------------------------- orthogonal cell
@pytest.mark.parametrize("settings", [S, S_LMP], ids=["liggghts", "lammps"])
def test_servo_and_rate_agree_with_the_code_order_to_round_off(settings):
    # x under a stress servo to half the set-up stress, y compressed at a rate: the box moves
    # every step (the servo from the virial of the step), the positions are remapped
    p = lattice_packing(12, 14, seed=4, spread=0.15, compression=0.06)
    fe = FastEngine(p, settings)
    de = DEMEngine(p, settings)
    assert _rel(fe.stress, de.stress) < 1e-13
    target = 0.5 * float(de.stress[0, 0])
    ld = Loading(x=AxisControl("servo", target=target, gain=2e-3), y=AxisControl("rate", rate=-5.0))
    for _ in range(3):
        a = fe.advance(ld, 100, 0, (np.zeros(2), np.diag(p.cell)))
        b = de.advance(ld, 100, 0, (np.zeros(2), np.diag(p.cell)))
        assert set(a) == set(b)
        np.testing.assert_allclose(a["lengths"], b["lengths"], rtol=1e-13, atol=0)
        assert _rel(a["stress"], b["stress"]) < 1e-11
        np.testing.assert_array_equal(a["n_contacts"], b["n_contacts"])
        assert _rel(a["kinetic_energy"], b["kinetic_energy"]) < 1e-9
    assert b["lengths"][-1, 0] > 1.0002 * p.cell[0, 0]  # the servo opened the box (less stress wanted)
    assert fe.n_rebuilds > 3
    assert _image_diff(fe.x, de.x, de.cell) < 1e-12 * p.radii.max()
    assert _rel(fe.w, de.w) < 1e-8


def test_prescribed_box_agrees_with_the_code_order():
    # a box table (a replayed fix deform): shrinking, remapped on every other step only
    p = lattice_packing(12, 14, seed=5, spread=0.15, compression=0.04)
    T = 301
    k = np.arange(T)[:, None]
    L = np.diag(p.cell)
    lo = 0.5 * (k * 1e-4 * L) * np.array([[0.3, 1.0]])
    hi = L - lo
    box = PrescribedBox(lo=lo, hi=hi, remap=(np.arange(T) % 2 == 0), step0=0)
    fe = FastEngine(p, S)
    de = DEMEngine(p, S)
    a = fe.advance(box, 300)
    b = de.advance(box, 300)
    np.testing.assert_array_equal(a["lengths"], b["lengths"])
    assert b["lengths"][-1, 1] < 0.98 * L[1]
    assert _rel(a["stress"], b["stress"]) < 1e-11
    with pytest.raises(InputError, match="prescribed box"):
        fe.advance(box, 10)  # the table ends at step 300


def test_long_servo_run_within_the_code_orders_chaos_envelope():
    # 3000 steps under the servo: the code order from 1e-12 perturbed starts spans the envelope
    # E(t); the fast ordering stays within 10 E(t) (+ 1e-13: the first steps' round-off)
    p = lattice_packing(12, 14, seed=6, spread=0.15, compression=0.06)
    steps = 3000
    target = 0.5 * float(DEMEngine(p, S).stress[1, 1])
    ld = Loading(x=AxisControl("servo", target=target, gain=2e-3), y=AxisControl("servo", target=target, gain=2e-3))

    def run(q, eng=DEMEngine):
        return eng(q, S).advance(ld, steps)["stress"]

    ref = run(p)
    env = np.zeros(steps)
    rng = np.random.default_rng(7)
    for k in range(4):
        x = p.positions.copy()
        x[rng.integers(p.n), k % 2] *= 1.0 + (1e-12 if k < 2 else -1e-12)
        q = Packing(positions=x, radii=p.radii, cell=p.cell, density=p.density)
        env = np.maximum(env, np.abs(run(q) - ref).reshape(steps, -1).max(axis=1) / np.abs(ref).max())
    d = np.abs(run(p, FastEngine) - ref).reshape(steps, -1).max(axis=1) / np.abs(ref).max()
    assert np.all(d <= 10.0 * env + 1e-13), f"worst step {int(np.argmax(d - 10 * env))}"
    assert env[-1] > 1e-14 and d.max() > 0.0  # an envelope above round-off; the orders do differ


# --------------------------------------------------------------------------- sheared cell
def test_sheared_cell_with_y_servo_agrees_with_the_code_order_to_round_off():
    # a tilted cell sheared at a rate (Lees-Edwards images, velocity jumps at the wrap), y under
    # the normal-stress servo: LAMMPS' arithmetic, the code order's sheared cell as reference
    p = sheared_lattice()
    fe = FastEngine(p, S_LMP, cell="sheared")
    se = ShearEngine(p, S_LMP, flavour="lammps")
    assert _rel(fe.stress, se.stress) < 1e-13
    ld = ShearLoading(erate=40.0, y="servo", target=0.7 * float(se.stress[1, 1]), gain=3e-3)
    a0, b0 = fe.start_run(ld, 600), se.start_run(ld, 600)
    assert _rel(a0, b0) < 1e-13
    for _ in range(3):
        a = fe.advance(200)
        b = se.advance(200)
        assert set(a) == set(b)
        np.testing.assert_allclose(a["box"], b["box"], rtol=1e-13, atol=1e-18)
        assert _rel(a["stress"], b["stress"]) < 1e-11
        np.testing.assert_array_equal(a["n_contacts"], b["n_contacts"])
        assert _rel(a["kinetic_energy"], b["kinetic_energy"]) < 1e-10
    assert b["box"][-1, 2] > p.cell[0, 1] + 1e-4 and b["box"][-1, 1] > p.cell[1, 1]  # sheared, y opened
    assert fe.n_rebuilds > 3
    assert _image_diff(fe.x, se.x, se.cell) < 1e-12 * p.radii.max()
    assert _rel(fe.v, se.v) < 1e-10


@pytest.mark.parametrize(
    "drive",
    [
        {"x_erate": 20.0},
        {"y": "erate", "y_erate": -20.0},
        {"remap": "x"},
        {"remap": "x", "x_erate": -10.0, "y": "servo", "target": 1.0, "gain": 3e-3},
    ],
    ids=["x-erate", "y-erate", "remap-x", "remap-x-servo"],
)
def test_any_velocity_gradient_agrees_with_the_code_order_to_round_off(drive):
    # the sheared cell under a general upper-triangular velocity gradient (xy shear with x and y
    # strain rates), the images moving with the box (remap v: velocity jumps across both boundaries)
    # or the positions following it through lamda (remap x: an affine deformation, as a material
    # point driven by F(t)): the fast order against the code order's sheared cell
    p = sheared_lattice()
    ld = ShearLoading(erate=30.0, **drive)
    fe = FastEngine(p, S_LMP, cell="sheared")
    se = ShearEngine(p, S_LMP, flavour="lammps")
    assert _rel(fe.start_run(ld, 400), se.start_run(ld, 400)) < 1e-13
    np.testing.assert_array_equal(fe.h_rate, se.h_rate)
    for _ in range(2):
        a = fe.advance(200)
        b = se.advance(200)
        # (y lo and hi under the servo follow the stress: round-off of the cell's size)
        np.testing.assert_allclose(a["box"], b["box"], rtol=1e-13, atol=1e-15 * p.cell[1, 1])
        assert _rel(a["stress"], b["stress"]) < 1e-11
        np.testing.assert_array_equal(a["n_contacts"], b["n_contacts"])
    L0 = p.cell
    moved = np.abs(b["box"][-1, :3] - [L0[0, 0], L0[1, 1], L0[0, 1]]) > 1e-5
    assert moved[2] and (moved[0] or moved[1] or drive.get("remap") == "x")
    assert fe.n_rebuilds > 2
    assert _image_diff(fe.x, se.x, se.cell) < 1e-12 * p.radii.max()
    assert _rel(fe.v, se.v) < 1e-10


def test_sheared_long_run_within_the_code_orders_chaos_envelope():
    p = sheared_lattice(tilt_spacings=3, nx=20, ny=22, seed=8)
    steps = 3000
    ld = ShearLoading(erate=30.0)

    def run(q, fast_order=False):
        e = FastEngine(q, S_LMP, cell="sheared") if fast_order else ShearEngine(q, S_LMP, flavour="lammps")
        e.start_run(ld, steps)
        return e.advance(steps)["stress"]

    ref = run(p)
    env = np.zeros(steps)
    rng = np.random.default_rng(9)
    for k in range(4):
        x = p.positions.copy()
        x[rng.integers(p.n), k % 2] *= 1.0 + (1e-12 if k < 2 else -1e-12)
        q = Packing(positions=x, radii=p.radii, cell=p.cell, density=p.density)
        env = np.maximum(env, np.abs(run(q) - ref).reshape(steps, -1).max(axis=1) / np.abs(ref).max())
    d = np.abs(run(p, True) - ref).reshape(steps, -1).max(axis=1) / np.abs(ref).max()
    assert np.all(d <= 10.0 * env + 1e-13), f"worst step {int(np.argmax(d - 10 * env))}"
    assert env[-1] > 1e-14 and d.max() > 0.0


def test_sheared_cell_threads_do_not_change_the_result(threaded_small):
    p = sheared_lattice()
    ld = ShearLoading(erate=40.0, y="servo", target=1.0, gain=1e-3)
    e1, e2 = (FastEngine(p, S_LMP, cell="sheared", threads=t) for t in (1, 2))
    assert e2.cell_ops._parallel and not e1.cell_ops._parallel
    a, b = (e.start_run(ld, 400) for e in (e1, e2))
    np.testing.assert_array_equal(a, b)
    a, b = (e.advance(400) for e in (e1, e2))
    assert e1.n_rebuilds > 2
    for k in a:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)
    np.testing.assert_array_equal(e1.x, e2.x)
    np.testing.assert_array_equal(e1.v, e2.v)


# --------------------------------------------------------------------------- checkpoints
def _through_hdf5(arrays: dict, path) -> dict:
    """The checkpoint arrays written to and read from an HDF5 file, as a run file keeps them."""
    with h5py.File(path, "w") as f:
        for k, v in arrays.items():
            f[k] = v
    out = {}
    with h5py.File(path, "r") as f:
        f.visititems(lambda name, obj: out.__setitem__(name, obj[()]) if isinstance(obj, h5py.Dataset) else None)
    return out


@pytest.mark.parametrize("threads", [(1, 1), (1, 2), (2, 1)], ids=["1-1", "1-2", "2-1"])
def test_orthogonal_checkpoint_continues_bit_for_bit(threads, threaded_small, tmp_path):
    # a run under the servo checkpointed at step 170 (between two list builds) and restored into
    # a new engine, on the same or another thread count, continues with the bits of the run
    p = lattice_packing(12, 14, seed=10, spread=0.15, compression=0.06)
    ld = Loading(x=AxisControl("servo", target=1.0, gain=2e-3), y=AxisControl("rate", rate=-5.0))
    box0 = (np.zeros(2), np.diag(p.cell))
    full = FastEngine(p, S, threads=threads[0])
    want = full.advance(ld, 400, 0, box0)
    first = FastEngine(p, S, threads=threads[0])
    first.advance(ld, 170, 0, box0)
    # on two threads the list of the last build has gaps after its bands (read where they are);
    # the checkpoint holds it moved together, the uninterrupted run never moves it
    assert (first._gaps is not None) == (threads[0] == 2)
    arrays = _through_hdf5(first.state_arrays(), tmp_path / "ck.h5")
    again = FastEngine(p, S, threads=threads[1])
    again.restore(arrays, 170)
    got = again.advance(ld, 230, 0, box0)
    for k in ("stress", "lengths", "kinetic_energy", "n_contacts"):
        np.testing.assert_array_equal(got[k], want[k][170:], err_msg=k)
    for name in ("x", "v", "w", "f", "t"):
        np.testing.assert_array_equal(getattr(again, name), getattr(full, name), err_msg=name)
    assert full.n_rebuilds > 4


@pytest.mark.parametrize("threads", [(1, 1), (2, 1)], ids=["1-1", "2-1"])
def test_sheared_checkpoint_continues_bit_for_bit(threads, threaded_small, tmp_path):
    p = sheared_lattice()
    ld = ShearLoading(erate=40.0, y="servo", target=1.0, gain=1e-3)
    full = FastEngine(p, S_LMP, cell="sheared", threads=threads[0])
    full.start_run(ld, 500)
    want = full.advance(500)
    first = FastEngine(p, S_LMP, cell="sheared", threads=threads[0])
    first.start_run(ld, 500)
    first.advance(230)
    arrays = _through_hdf5(first.state_arrays(), tmp_path / "ck.h5")
    again = FastEngine(p, S_LMP, cell="sheared", threads=threads[1])
    again.restore(arrays, 230)  # the run (fix deform) comes with the checkpoint
    got = again.advance(270)
    for k in ("stress", "box", "kinetic_energy", "n_contacts"):
        np.testing.assert_array_equal(got[k], want[k][230:], err_msg=k)
    np.testing.assert_array_equal(again.x, full.x)
    np.testing.assert_array_equal(again.v, full.v)
    assert full.n_rebuilds > 3
    with pytest.raises(InputError, match="run ends"):
        again.advance(1)


def test_restore_refuses_a_foreign_checkpoint():
    p = lattice_packing(12, 14)
    e = FastEngine(p, S)
    with pytest.raises(InputError, match="lacks"):
        e.restore({"positions": p.positions}, 3)
    arrays = FastEngine(lattice_packing(12, 16), S).state_arrays()
    with pytest.raises(InputError, match="does not fit"):
        e.restore(arrays, 3)


# --------------------------------------------------------------------------- views and checks
@pytest.mark.parametrize("cell", ["orthogonal", "sheared"])
def test_contacts_and_energies_are_the_code_orders(cell):
    # after the set-up both orders hold the forces of the same evaluation (no spring increment):
    # the same contacts (original indices, shifts), overlaps and forces to round-off, and the
    # same elastic and kinetic energies
    if cell == "sheared":
        p = sheared_lattice()
        fe, ce = FastEngine(p, S_LMP, cell="sheared"), ShearEngine(p, S_LMP, flavour="lammps")
    else:
        p = lattice_packing(12, 14, seed=11, spread=0.15, compression=0.06)
        fe, ce = FastEngine(p, S_LMP), DEMEngine(p, S_LMP)
    a, b = fe.contacts(), ce.contacts()
    ka = np.lexsort((a["shift"][:, 1], a["shift"][:, 0], a["j"], a["i"]))
    kb = np.lexsort((b["shift"][:, 1], b["shift"][:, 0], b["j"], b["i"]))
    assert a["i"].size == b["i"].size == fe.n_contacts > 100
    assert np.any(a["shift"] != 0)  # contacts across the periodic boundary
    for k in ("i", "j", "shift", "sliding"):
        np.testing.assert_array_equal(a[k][ka], b[k][kb], err_msg=k)
    # the code order's sheared cell takes the images from lamda coordinates after a build: the
    # positions differ by round-off of the cell size (1e-17 m), small overlaps relatively more
    np.testing.assert_allclose(a["overlap"][ka], b["overlap"][kb], rtol=1e-12, atol=1e-14 * p.radii.max())
    assert _rel(a["force"][ka], b["force"][kb]) < 1e-12
    assert fe.elastic_energy() == pytest.approx(ce.elastic_energy(), rel=1e-12)
    assert fe.kinetic_energy() == ce.kinetic_energy() == 0.0
    # set-up: nothing moved (the sheared code order maps the positions to lamda and back: round-off)
    assert _image_diff(fe.x, ce.x, ce.cell) <= 1e-14 * p.radii.max()
    np.testing.assert_allclose(fe.f, ce.f, rtol=0, atol=1e-12 * np.abs(ce.f).max())


def test_an_unstable_time_step_is_stopped():
    # dt 1.6x the critical step 2/omega of the lightest pair (check_dt off): the divergence check
    # stops the run, naming the step
    p = lattice_packing(12, 14, seed=12, spread=0.15, compression=0.06)
    s = DEMSettings(kn=1e10, kt=1e10, gamma_n=0.0, gamma_t=0.0, mu=0.5, dt=2e-6, skin=2e-5)
    fe = FastEngine(p, s, check_dt=False)
    with pytest.raises(SimulationError, match=r"step \d+: (kinetic energy blow-up|particle \d+ lost)"):
        fe.advance(Loading(), 2000)


def test_a_lost_particle_is_named():
    # one disk shot through the assembly at 2 skins per step: the check before the list build
    # names it (original index) and the step
    p = lattice_packing(12, 14, seed=13, spread=0.15, compression=0.0)
    v = np.zeros((p.n, 2))
    v[37] = (2.0 * S.skin / S.dt, 0.0)
    fe = FastEngine(p, S, velocities=v, check_dt=False)
    with pytest.raises(SimulationError, match=r"step 1: particle 37 lost"):
        fe.advance(Loading(), 5)


def test_bad_choices_are_refused():
    p = lattice_packing(12, 14)
    hertz = make_law("hertz-liggghts", youngs_modulus=1e8, poisson_ratio=0.3, restitution=0.5, friction=0.5)
    with pytest.raises(InputError, match="block path"):
        FastEngine(p, Integration(dt=1e-7, skin=2e-5), law=hertz)
    with pytest.raises(InputError, match="cell"):
        FastEngine(p, S, cell="cubic")
    with pytest.raises(InputError, match="cell='sheared'"):
        FastEngine(sheared_lattice(), S_LMP)
    with pytest.raises(InputError, match="orthogonal cell"):
        FastEngine(p, S).start_run(ShearLoading(erate=1.0), 10)
    with pytest.raises(InputError, match="loading"):
        FastEngine(p, S).advance(ShearLoading(erate=1.0), 10)
    sh = FastEngine(sheared_lattice(), S_LMP, cell="sheared")
    with pytest.raises(InputError, match="start_run"):
        sh.advance(10)
    with pytest.raises(InputError, match="loading"):
        sh.start_run(Loading(), 10)
    with pytest.raises(InputError, match="liggghts"):
        FastEngine(lattice_packing(24, 28), S, cell="sheared").start_run(ShearLoading(erate=1.0), 10)
    with pytest.raises(InputError, match="liggghts"):
        FastEngine(sheared_lattice(), S, cell="sheared")
    with pytest.raises(InputError, match="settings"):
        FastEngine(p, {"dt": 1e-6})


def test_an_orthogonal_run_advances_in_pieces_as_the_code_order():
    # start_run(loading, n) then advance(k) calls: the phase is measured from the run's start
    # (rate and servo), as advance(loading, k, step0, box0) with the run's step and box
    p = lattice_packing(12, 14, seed=14, spread=0.15, compression=0.06)
    ld = Loading(x=AxisControl("servo", target=1.0, gain=2e-3), y=AxisControl("rate", rate=-5.0))
    a, b = FastEngine(p, S), FastEngine(p, S)
    a.advance(Loading(), 30)
    b.advance(Loading(), 30)
    np.testing.assert_array_equal(a.start_run(ld, 200), a.stress)
    got = [a.advance(k)["stress"] for k in (50, 70, 80)]
    want = b.advance(ld, 200, 30, (b.lo.copy(), b.hi.copy()))["stress"]
    np.testing.assert_array_equal(np.concatenate(got), want)
    with pytest.raises(InputError, match="run ends at step 230"):
        a.advance(1)
    with pytest.raises(InputError, match="start_run"):
        FastEngine(p, S).advance(5)


_KILLED_CHILD = r"""
import os, sys, time
import h5py
import numpy as np
from gransim import Packing
from gransim.dem import DEMSettings, fast
from gransim.dem.fast import FastEngine
from gransim.dem.lattice import lattice_packing
from gransim.dem.sheared import ShearLoading

fast.MIN_PER_THREAD = 0  # the threaded kernels on this small assembly
path, every = sys.argv[1], int(sys.argv[2])
p = lattice_packing(24, 28, seed=3, spread=0.15, compression=0.06)
C = p.cell.copy()
C[0, 1] = 8e-3
p = Packing(positions=p.positions, radii=p.radii, cell=C, density=p.density)
s = DEMSettings(kn=1e5, kt=1e5, gamma_n=50.0, gamma_t=50.0, mu=0.5, dt=2e-6, skin=2e-5, flavour="lammps")
eng = FastEngine(p, s, cell="sheared", threads=2)
eng.start_run(ShearLoading(erate=40.0, y="servo", target=1.0, gain=1e-3), 10**6)
while True:
    eng.advance(every)
    with h5py.File(path + ".tmp", "w") as f:  # written whole, then moved over the last one
        f.attrs["step"] = eng.step
        for k, v in eng.state_arrays().items():
            f[k] = v
    os.replace(path + ".tmp", path)
    print(eng.step, flush=True)
"""


def test_a_killed_threaded_sheared_run_resumes_bit_for_bit(threaded_small, tmp_path):
    # a sheared run on 2 threads writing a checkpoint every 50 steps, killed (SIGKILL) while it
    # runs, resumed from its last checkpoint into a new engine: it ends on the bits of the
    # uninterrupted run (which needs neither the kill's timing nor the thread count)
    import os
    import signal
    import subprocess
    import sys

    ck = tmp_path / "ck.h5"
    env = {**os.environ, "NUMBA_NUM_THREADS": "2"}
    child = subprocess.Popen(
        [sys.executable, "-c", _KILLED_CHILD, str(ck), "50"], stdout=subprocess.PIPE, text=True, env=env
    )
    try:
        for line in child.stdout:
            if int(line) >= 150:
                break
        child.send_signal(signal.SIGKILL)
    finally:
        child.kill()
        child.wait()
    assert child.returncode == -signal.SIGKILL
    with h5py.File(ck, "r") as f:
        step = int(f.attrs["step"])
        arrays = {}
        f.visititems(lambda name, obj: arrays.__setitem__(name, obj[()]) if isinstance(obj, h5py.Dataset) else None)
    assert step >= 150 and step % 50 == 0
    end = step + 200
    p = sheared_lattice()
    ld = ShearLoading(erate=40.0, y="servo", target=1.0, gain=1e-3)
    again = FastEngine(p, S_LMP, cell="sheared", threads=2)
    again.restore(arrays, step)
    got = again.advance(end - step)
    full = FastEngine(p, S_LMP, cell="sheared", threads=1)
    full.start_run(ld, 10**6)
    want = full.advance(end)
    for k in ("stress", "box", "kinetic_energy"):
        np.testing.assert_array_equal(got[k], want[k][step:], err_msg=k)
    np.testing.assert_array_equal(again.x, full.x)
    np.testing.assert_array_equal(again.v, full.v)
    np.testing.assert_array_equal(again.w, full.w)


def test_integration_settings_with_a_law_object_are_the_hooke_settings():
    # the law given as an object with Integration settings runs the same arithmetic as the Hooke
    # law a DEMSettings makes in its flavour: the same bits
    p = lattice_packing(12, 14, seed=15, spread=0.15, compression=0.06)
    law = make_law("hooke-lammps", kn=S.kn, kt=S.kt, gamma_n=S.gamma_n, gamma_t=S.gamma_t, mu=S.mu)
    a = FastEngine(p, Integration(dt=S.dt, skin=S.skin, flavour="lammps"), law=law)
    b = FastEngine(p, S_LMP)
    ld = Loading(y=AxisControl("rate", rate=-5.0))
    np.testing.assert_array_equal(a.advance(ld, 200)["stress"], b.advance(ld, 200)["stress"])
    np.testing.assert_array_equal(a.x, b.x)
    with pytest.raises(InputError, match="law"):
        FastEngine(p, Integration(dt=S.dt, skin=S.skin))
