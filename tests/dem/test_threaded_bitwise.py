"""The kernels of the bitwise engine's threaded mode (``DEMEngine(mode="parallel")``).

Mode "parallel" is deterministic and independent of the thread count, and differs from the serial
mode only in the order of its sums (docs/dem.md). Its kernels are held to that: the SIMD force
loop of the Hooke laws (``kernels._threaded_block_loop``) equals the scalar threaded loop
(``_threaded_scalar_loop``, the loop of every other law) bit for bit; the threaded integration passes
equal the serial kernels bit for bit in every position and velocity; the threaded pair passes of
the LIGGGHTS list build give the serial list entry for entry; and a whole run gives the same bits
on one thread as on two. The cases hold several tasks of ``kernels.PARTICLE_BLOCK`` particles (a
partial last one, particles without entries of their own), which the small assemblies of
tests/dem/test_physics.py do not.
"""

from __future__ import annotations

import math
import os
import re

import numpy as np
import pytest

from gransim import Packing
from gransim._numba import num_threads
from gransim.dem import AxisControl, DEMEngine, DEMSettings, Loading
from gransim.dem import kernels as K

FLAVOURS = ("liggghts", "lammps")
FIXED = Loading(x=AxisControl("fixed"), y=AxisControl("fixed"))


def _bits(a):
    a = np.ascontiguousarray(a)
    return a.view(np.uint8) if a.dtype != bool else a


def _copy(t):
    return type(t)(*[a.copy() if isinstance(a, np.ndarray) else a for a in t])


def _assembly(seed=3, nx=60, ny=47):
    """A jittered, compressed periodic lattice of nx * ny disks (overlaps ~1e-2 d), a few
    thousand disks: more than two tasks of PARTICLE_BLOCK and a partial last one; every 97th disk
    shrunk to a rattler without partners."""
    rng = np.random.default_rng(seed)
    d = 1e-3
    Lx, Ly = nx * d * 0.985, ny * d * 0.985
    gx = (np.arange(nx) + 0.5) * (Lx / nx)
    gy = (np.arange(ny) + 0.5) * (Ly / ny)
    x = np.stack(np.meshgrid(gx, gy), axis=-1).reshape(-1, 2) + rng.normal(0.0, 0.01 * d, (nx * ny, 2))
    r = 0.5 * d * rng.uniform(0.97, 1.03, nx * ny)
    r[::97] *= 0.4  # rattlers: particles without list entries
    x %= np.array([Lx, Ly])
    return Packing(positions=x, radii=r, cell=np.diag([Lx, Ly]), density=2650.0)


def _engine(flavour="liggghts", mode="parallel", threads=2, mu=0.5, seed=3):
    p = _assembly(seed)
    rng = np.random.default_rng(seed + 1)
    s = DEMSettings(kn=1e5, kt=8e4, gamma_n=200.0, gamma_t=100.0, mu=mu, dt=1e-6, skin=2e-5, flavour=flavour, mode=mode)
    v = rng.normal(0.0, 0.05, (p.n, 2))
    w = rng.normal(0.0, 50.0, p.n)
    return DEMEngine(p, s, velocities=v, spins=w, threads=threads), s


def _threaded_loops(e, s, update, store):
    """The SIMD and the scalar threaded loops on copies of the same state, on two threads."""
    L = e.box_lengths
    out = []
    for simd in (True, False):
        p, nb = _copy(e.p), _copy(e.nb)
        pv = np.full((p.x.shape[0], 4), 7.0)  # every row must be written
        pc = np.full((p.x.shape[0], 2), 7.0)
        with num_threads(2):
            if simd:
                K._threaded_block_loop(
                    p.x, p.v, p.w, p.f, p.t, p.m, p.r, nb.a, nb.start, nb.b, nb.sx, nb.sy,
                    nb.both.view(np.uint8), nb.hist, nb.slide.view(np.uint8), nb.ef, nb.tb, nb.in_start,
                    nb.in_e, e.law, L[0], L[1], s.dt, update, pv, pc, store,
                )  # fmt: skip
            else:
                K._threaded_scalar_loop(
                    p.x, p.v, p.w, p.f, p.t, p.m, p.r, nb.start, nb.b, nb.sx, nb.sy, nb.both, nb.hist,
                    nb.slide, nb.ef, nb.tb, nb.in_start, nb.in_e, e.law, L[0], L[1], s.dt, update, pv, pc, store,
                )  # fmt: skip
        out.append((p, nb, pv, pc))
    return out


@pytest.mark.parametrize("flavour", FLAVOURS)
@pytest.mark.parametrize("update", [True, False])
@pytest.mark.parametrize("store", [True, False])
def test_threaded_simd_loop_equals_the_threaded_scalar_loop_bit_for_bit(flavour, update, store):
    e, s = _engine(flavour)
    e.advance(FIXED, 150)  # springs built up, some contacts sliding, some pairs apart
    n = e.p.x.shape[0]
    assert n > 2 * K.PARTICLE_BLOCK and n % K.PARTICLE_BLOCK, "the case must hold several tasks, a partial last one"
    own = np.diff(e.nb.start)
    assert np.any(own == 0) and np.any(~e.nb.both), "the case must hold particles without entries, boundary pairs"
    (p1, nb1, v1, c1), (p2, nb2, v2, c2) = _threaded_loops(e, s, update, store)
    for name, a, b in (
        ("force", p1.f, p2.f),
        ("torque", p1.t, p2.t),
        ("spring", nb1.hist, nb2.hist),
        ("per-particle virial", v1, v2),
        ("per-particle contacts, overlap", c1, c2),
        ("cap flag", nb1.slide, nb2.slide),
        ("entry force", nb1.ef, nb2.ef),
        ("torque on b", nb1.tb, nb2.tb),
    ):
        assert np.array_equal(_bits(a), _bits(b)), f"{name} differs from the scalar threaded loop"
    touching = c1[:, 0].sum()
    assert touching > 1000 and 0 < nb1.slide.sum() < len(nb1.slide) if store else touching > 1000


def test_threaded_simd_loop_is_compiled_to_simd_code():
    # as the serial SIMD loop (tests/dem/test_simd_bitwise.py): numba gives up vectorising
    # silently, so the compiled kernel is read for packed square roots and gathers
    import numba

    from gransim._numba import JIT_OPTIONS

    flags = open("/proc/cpuinfo").read() if os.path.exists("/proc/cpuinfo") else ""
    if " avx2" not in flags:
        pytest.skip("no AVX2 on this CPU: the gathers need it")
    e, s = _engine()
    k = numba.njit(**{**JIT_OPTIONS, "cache": False, "parallel": True})(K._threaded_block_loop.py_func)
    p, nb, L = _copy(e.p), _copy(e.nb), e.box_lengths
    n = p.x.shape[0]
    k(p.x, p.v, p.w, p.f, p.t, p.m, p.r, nb.a, nb.start, nb.b, nb.sx, nb.sy, nb.both.view(np.uint8), nb.hist,
      nb.slide.view(np.uint8), nb.ef, nb.tb, nb.in_start, nb.in_e, e.law, L[0], L[1], s.dt, True,
      np.zeros((n, 4)), np.zeros((n, 2)), True)  # fmt: skip
    asm = k.inspect_asm(k.signatures[0])
    assert re.search(r"\bvsqrtpd\b", asm), "the pair law is not vectorised (no packed square root)"
    assert re.search(r"\bvgather[dq]pd\b", asm), "the partners' loads are not gathers"


@pytest.mark.parametrize("flavour", FLAVOURS)
def test_the_hooke_laws_take_the_threaded_simd_loop_and_the_others_the_generic_one(flavour):
    import numba

    from gransim._numba import JIT_OPTIONS
    from gransim.contacts.laws import make_law

    e, s = _engine(flavour)
    L, n = e.box_lengths, e.p.x.shape[0]
    other = make_law("hertz-liggghts", youngs_modulus=5e8, poisson_ratio=0.3, restitution=0.5, friction=0.5)
    for law, simd in ((e.law, True), (other, False)):
        k = numba.njit(**{**JIT_OPTIONS, "cache": False})(K.forces_threaded.py_func)
        nb = _copy(e.nb)
        if not simd:
            nb = nb._replace(hist=np.zeros((nb.a.size, 3)))
        k(_copy(e.p), nb, law, L[0], L[1], s.dt, True, np.zeros((n, 4)), np.zeros((n, 2)), True)
        ir = k.inspect_llvm(k.signatures[0])
        what = "missing" if simd else "used"
        assert ("_threaded_block_loop" in ir) == simd, f"{type(law).__name__}: SIMD loop {what}"


def test_threaded_integration_equals_the_serial_kernels_bit_for_bit():
    e, s = _engine()
    e.advance(FIXED, 40)
    rng = np.random.default_rng(5)
    p = e.p
    n = p.x.shape[0]
    f = rng.normal(0.0, 1e-3, (n, 2))
    t = rng.normal(0.0, 1e-7, n)
    lo, hi = e.lo, e.hi
    for case in ("settled", "moved", "non-finite"):
        x0 = p.x.copy()
        xhold = x0.copy()
        if case == "moved":  # one particle of the last task beyond half the skin
            xhold[n - 5] -= 0.6 * s.skin
        if case == "non-finite":  # in the second task and in the last: the first is reported
            x0[K.PARTICLE_BLOCK + 17, 1] = np.nan
            x0[n - 3, 0] = np.inf
        serial = [x0.copy(), p.v.copy(), p.w.copy()]
        threaded = [x0.copy(), p.v.copy(), p.w.copy()]
        K.initial_integrate(serial[0], serial[1], serial[2], f, t, p.m, p.r, s.dt)
        want = K.check_rebuild(serial[0], xhold, lo, hi, lo, hi, s.skin, True)
        dsq = K.rebuild_deltasq(lo, hi, lo, hi, s.skin, True)
        with num_threads(2):
            got = K.initial_check_threaded(threaded[0], threaded[1], threaded[2], f, t, p.m, p.r, s.dt, xhold, dsq)
        assert (bool(got[0]), int(got[1])) == (bool(want[0]), int(want[1])), case
        assert want == {"settled": (False, -1), "moved": (True, -1), "non-finite": (True, K.PARTICLE_BLOCK + 17)}[case]
        for a, b in zip(serial, threaded):
            assert np.array_equal(_bits(a), _bits(b)), case
    # second half step and the sums
    v1, w1, v2, w2 = p.v.copy(), p.w.copy(), p.v.copy(), p.w.copy()
    pvir = rng.normal(0.0, 1e-6, (n, 4))
    pcont = rng.uniform(0.0, 3.0, (n, 2))
    ke1 = K.final_integrate(v1, w1, f, t, p.m, p.r, s.dt)
    vir = np.zeros(4)
    with num_threads(2):
        ke2, nc, so = K.final_threaded(v2, w2, f, t, p.m, p.r, s.dt, pvir, pcont, vir)
    assert np.array_equal(_bits(v1), _bits(v2)) and np.array_equal(_bits(w1), _bits(w2))
    assert ke2 == pytest.approx(ke1, rel=1e-13)
    for k in range(4):
        assert vir[k] == pytest.approx(math.fsum(pvir[:, k]), rel=1e-12, abs=1e-18)
    assert nc == pytest.approx(math.fsum(pcont[:, 0]), rel=1e-13)
    assert so == pytest.approx(math.fsum(pcont[:, 1]), rel=1e-13)


@pytest.mark.parametrize("squeeze", [1.0, 0.93])
def test_threaded_liggghts_list_is_the_serial_list(squeeze):
    # squeeze < 1: the disks of a box compressed affinely, denser pairs across the boundaries
    p = _assembly(seed=9)
    hi = np.diag(p.cell) * squeeze
    x = p.positions * squeeze
    lo = np.zeros(2)
    serial = K.build_list_liggghts(x, p.radii, lo, hi, 2e-5, False)
    with num_threads(2):
        threaded = K.build_list_liggghts(x, p.radii, lo, hi, 2e-5, True)
    assert serial[0].size > 1.5 * p.n and np.any(~serial[4]), "pairs, and pairs across the boundary"
    for name, a, b in zip(("a", "b", "sx", "sy", "both"), serial[:5], threaded[:5]):
        assert np.array_equal(_bits(a), _bits(b)), f"list column {name} differs"
    assert serial[5] == threaded[5] == -1


@pytest.mark.parametrize("flavour", FLAVOURS)
def test_parallel_mode_gives_the_same_bits_on_one_thread_as_on_two(flavour):
    # under a servo, so the virial sums steer the box: a thread-dependent sum would show
    ld = Loading(x=AxisControl("servo", target=50.0, gain=1e-2), y=AxisControl("rate", rate=-2.0))
    runs = []
    for threads in (1, 2):
        e, _ = _engine(flavour, threads=threads)
        out = e.advance(ld, 300)
        runs.append((e.p.x.copy(), e.p.v.copy(), e.p.w.copy(), e.nb.hist.copy(), out["stress"].copy(), e.n_rebuilds))
    assert runs[0][5] >= 3, "the run must rebuild its list"
    for a, b in zip(runs[0][:5], runs[1][:5]):
        assert np.array_equal(_bits(a), _bits(b))


def test_parallel_mode_matches_the_serial_mode_to_round_off_with_several_tasks():
    ld = Loading(x=AxisControl("servo", target=50.0, gain=1e-2), y=AxisControl("rate", rate=-2.0))
    a, _ = _engine(mode="serial", threads=1)
    b, _ = _engine(mode="parallel", threads=2)
    ra = a.advance(ld, 300)
    rb = b.advance(ld, 300)
    assert a.n_rebuilds == b.n_rebuilds >= 3
    d50 = 1e-3
    assert np.abs(a.p.x - b.p.x).max() < 1e-10 * d50
    np.testing.assert_allclose(rb["stress"], ra["stress"], rtol=0, atol=1e-9 * np.abs(ra["stress"]).max())
    np.testing.assert_array_equal(ra["n_contacts"], rb["n_contacts"])


# ----------------------------------------------------------------------------------- memory-saving rewrites
def test_ghost_room_grown_from_a_small_guess_gives_the_same_list():
    # the ghosts' room starts from a guess and is doubled until they fit: from 1, several times
    p = _assembly(seed=11)
    x, lo, hi = p.positions, np.zeros(2), np.diag(p.cell).copy()
    want = K.build_list_liggghts(x, p.radii, lo, hi, 2e-5, False)
    for room in (1, 5, 300):
        got = K.build_list_liggghts(x, p.radii, lo, hi, 2e-5, False, room)
        for name, a, b in zip(("a", "b", "sx", "sy", "both"), want[:5], got[:5]):
            assert np.array_equal(_bits(a), _bits(b)), f"room {room}: list column {name} differs"
        assert got[5] == -1
    ghosts = K._liggghts_ghosts(x, lo, 2 * p.radii.max() + 2e-5, hi[0], hi[1], hi[0], hi[1], 3)
    assert ghosts[4] == -1, "three places cannot hold the ghosts of this cell"


def test_touching_overlaps_equal_the_array_expression():
    # the engine's contact queries: an independent numpy evaluation of the same definition
    e, s = _engine(mode="serial", threads=1)
    e.advance(FIXED, 60)
    nb, L, x, r = e.nb, e.box_lengths, e.p.x, e.p.r
    shift = np.stack([nb.sx, nb.sy], axis=1)
    d = x[nb.a] - (x[nb.b] + shift * L)
    rsq = np.einsum("ij,ij->i", d, d)
    touch = (rsq < (r[nb.a] + r[nb.b]) ** 2) & (nb.a < nb.b)
    want_e = np.nonzero(touch)[0]
    want_ov = r[nb.a[want_e]] + r[nb.b[want_e]] - np.sqrt(rsq[want_e])
    got_e, got_ov = K.touching_overlaps(x, r, nb.a, nb.b, nb.sx, nb.sy, L[0], L[1])
    assert want_e.size > 1000
    assert np.array_equal(got_e, want_e) and np.array_equal(_bits(got_ov), _bits(want_ov))
    assert np.array_equal(e.eshift, shift.astype(np.int64)) and e.eshift.dtype == np.int64


def test_elastic_energy_in_chunks_is_the_sum_over_all_contacts(monkeypatch):
    from gransim.contacts.laws import elastic_energy
    from gransim.dem import engine as engine_module

    e, s = _engine(mode="serial", threads=1)
    e.advance(FIXED, 60)
    idx, ov = e._touching()
    nb = e.nb
    whole = elastic_energy(e.law, ov, nb.hist[idx], e.p.r[nb.a[idx]], e.p.r[nb.b[idx]])
    assert idx.size > engine_module.ENERGY_CHUNK / 100 and whole > 0
    assert e.elastic_energy() == whole  # one chunk: the plain sum, bit for bit
    monkeypatch.setattr(engine_module, "ENERGY_CHUNK", 97)
    assert e.elastic_energy() == pytest.approx(whole, rel=1e-13)


def test_a_parallel_engine_of_one_task_runs_on_one_thread_with_the_same_bits():
    # below PARTICLE_BLOCK disks the threaded kernels have one task: the engine runs them on one
    # thread (a second would only wait), which the thread-count independence makes invisible
    p = _assembly(seed=5, nx=20, ny=20)
    assert p.n <= K.PARTICLE_BLOCK
    s = DEMSettings(kn=1e5, kt=8e4, gamma_n=200.0, gamma_t=100.0, mu=0.5, dt=1e-6, skin=2e-5, mode="parallel")
    ld = Loading(x=AxisControl("servo", target=50.0, gain=1e-2), y=AxisControl("rate", rate=-2.0))
    runs = []
    for threads in (1, 2):
        e = DEMEngine(p, s, threads=threads)
        assert e.cell_ops.threads == 1
        e.advance(ld, 200)
        runs.append((e.p.x.copy(), e.p.v.copy(), e.nb.hist.copy()))
    for a, b in zip(*runs):
        assert np.array_equal(_bits(a), _bits(b))
    assert DEMEngine(_assembly(seed=5), s, threads=2).cell_ops.threads == 2


def test_handing_free_memory_back_changes_no_result(monkeypatch):
    # the rebuild calls glibc's malloc_trim (engine.release_free_memory): it may free only what is
    # not in use, so a run with it and one without give the same bits
    import platform

    from gransim.dem import engine as engine_module

    if platform.libc_ver()[0] == "glibc":
        assert engine_module._MALLOC_TRIM is not None, "glibc's malloc_trim was not found"
    ld = Loading(x=AxisControl("servo", target=50.0, gain=1e-2), y=AxisControl("rate", rate=-2.0))
    runs = []
    for trim in (True, False):
        if not trim:
            monkeypatch.setattr(engine_module, "_MALLOC_TRIM", None)
        e, _ = _engine(mode="serial", threads=1)
        out = e.advance(ld, 200)
        assert e.n_rebuilds >= 3
        runs.append((e.p.x.copy(), e.p.v.copy(), e.nb.hist.copy(), out["stress"].copy()))
    for a, b in zip(*runs):
        assert np.array_equal(_bits(a), _bits(b))


def test_largest_displacement_is_numpys_argmax_of_the_distances():
    # the lost-particle check's kernel against the array expression it replaced: ties give the
    # first particle, a NaN distance wins
    rng = np.random.default_rng(2)
    x = rng.normal(0.0, 1e-3, (5000, 2))
    hold = x + rng.normal(0.0, 1e-5, x.shape)
    hold[[17, 4000]] = x[[17, 4000]] + 3e-5  # two equal largest moves
    for case in ("plain", "nan"):
        if case == "nan":
            hold[2500, 1] = np.nan
        d = np.sqrt(np.einsum("ij,ij->i", x - hold, x - hold))
        i, di = K.largest_displacement(x, hold)
        assert i == int(np.argmax(d)), case
        assert np.array_equal(_bits(np.float64(di)), _bits(d[i])), case
    assert K.largest_displacement(x[:0], hold[:0])[1] < 0  # no particles: nothing moved


def test_after_a_failed_neighbour_build_the_engine_refuses_to_step_until_restored(monkeypatch):
    # a rebuild releases the old list before building the new one: when the build fails (a
    # particle near its own image) the engine has no list, so advance must refuse, not read it
    from gransim.errors import SimulationError

    e, _ = _engine(mode="serial", threads=1)
    e.advance(FIXED, 5)
    saved = {k: np.array(v) for k, v in e.state_arrays().items()}
    step = e.step
    real = K.build_list_liggghts
    monkeypatch.setattr(K, "build_list_liggghts", lambda *a: (*real(*a)[:5], 7))
    with pytest.raises(SimulationError, match="particle 7 is near its own image"):
        e._rebuild(carry=True)
    with pytest.raises(SimulationError, match="failed neighbour build"):
        e.advance(FIXED, 1)
    monkeypatch.setattr(K, "build_list_liggghts", real)
    e.restore(saved, step)
    e.advance(FIXED, 5)  # steps again from the checkpoint
    assert e.step == step + 5 and np.all(np.isfinite(e.p.x))
