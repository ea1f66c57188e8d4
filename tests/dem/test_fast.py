"""The fast ordering of the DEM (gransim.dem.fast) in the orthogonal cell against the code order
and against physics (its loadings, the sheared cell, checkpoints: test_fast_backend.py).

The fast ordering reorders particles and sums (spatial sort, half list with the symmetric update,
per-band sums), so it is compared with DEMEngine to round-off over short horizons and, over a
long relaxation, by the divergence envelope of DEMEngine itself (docs/validation.md's rule:
within 10 times the spread of runs from 1e-12 perturbed starts), never by equality.
"""

from __future__ import annotations

import numpy as np
import pytest

from gransim import Packing
from gransim.dem import AxisControl, DEMEngine, DEMSettings, Loading, fast
from gransim.dem.fast import FastEngine
from gransim.dem.lattice import lattice_packing
from gransim.errors import InputError

S = DEMSettings(kn=1e5, kt=1e5, gamma_n=50.0, gamma_t=50.0, mu=0.5, dt=2e-6, skin=2e-5)


@pytest.fixture
def threaded_small(monkeypatch):
    """The threaded kernels even for the small test assemblies (they fall back to the serial
    kernels below fast.MIN_PER_THREAD particles per thread)."""
    monkeypatch.setattr(fast, "MIN_PER_THREAD", 0)


def advance(e, n, loading=None, **kw):
    """``e.advance(loading, n, ...)`` (default: a fixed box) with the list builds of the call added
    as ``rebuilds``."""
    r0 = e.n_rebuilds
    out = e.advance(Loading() if loading is None else loading, n, **kw)
    out["rebuilds"] = e.n_rebuilds - r0
    return out


def _rel(a, b):
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


def _image_diff(a, b, L):
    """Largest |a - b| over components, each difference taken to its nearest periodic image (m)."""
    d = a - b
    d -= np.rint(d / L) * L
    return float(np.max(np.abs(d)))


def two_disks(offset=0.3e-3):
    L = 0.02
    r1, r2 = 1e-3, 1.5e-3
    x = np.array(
        [
            [0.5 * L - r1 - 5e-6, 0.5 * L - 0.5 * offset],
            [0.5 * L + r2 + 5e-6, 0.5 * L + 0.5 * offset],
        ]
    )
    return Packing(positions=x, radii=[r1, r2], cell=np.diag([L, L]), density=2650.0)


def test_two_disks_oblique_collision_agrees_with_bitwise_engine():
    # an oblique, spinning impact: normal damping, tangential spring, Coulomb slip, torques on both
    p = two_disks()
    v = np.array([[0.3, 0.05], [-0.2, 0.0]])
    w = np.array([30.0, -10.0])
    s = DEMSettings(kn=1e5, kt=8e4, gamma_n=300.0, gamma_t=100.0, mu=0.3, dt=1e-6, skin=1e-5)
    fe = FastEngine(p, s, velocities=v, spins=w)
    de = DEMEngine(p, s, velocities=v, spins=w)
    touched = 0
    for _ in range(60):  # 600 steps: approach, contact (~200 steps) and separation
        a = advance(fe, 10)
        b = de.advance(Loading(), 10)
        touched += int(b["n_contacts"].max())
        # the same operations on the pair, only i/j possibly swapped: round-off
        assert _rel(fe.v, de.v) < 1e-12
        assert _rel(fe.w, de.w) < 1e-12
        assert _image_diff(fe.x, de.x, 0.02) < 1e-15
        assert np.abs(a["stress"] - b["stress"]).max() <= 1e-12 * max(np.abs(b["stress"]).max(), 1e-30)
    assert touched > 0


@pytest.mark.parametrize("threads", [1, 2])
def test_small_assembly_agrees_with_bitwise_engine_to_round_off(threads, threaded_small):
    # 120 overlapping disks relaxing, contacts across the periodic boundary, rebuilds: over 400
    # steps the reordered sums differ from DEMEngine only by round-off (1e-12 relative)
    p = lattice_packing(10, 12, seed=3, spread=0.15, compression=0.06)
    fe = FastEngine(p, S, threads=threads)
    de = DEMEngine(p, S)
    assert _rel(fe.stress, de.stress) < 1e-13
    assert _rel(fe.f, de.f) < 1e-12
    a = advance(fe, 400)
    b = de.advance(Loading(), 400)
    assert a["rebuilds"] == de.n_rebuilds - 1 > 3
    scale = np.abs(b["stress"]).max()
    assert np.abs(a["stress"] - b["stress"]).max() < 1e-12 * scale
    np.testing.assert_array_equal(a["n_contacts"], b["n_contacts"])
    assert _image_diff(fe.x, de.x, np.diag(p.cell)) < 1e-12 * p.radii.max()
    assert _rel(fe.v, de.v) < 1e-9  # velocities near rest: relative to their own size
    assert np.abs(a["kinetic_energy"] - b["kinetic_energy"]).max() < 1e-10 * b["kinetic_energy"].max()


def test_strain_rate_box_agrees_with_bitwise_engine():
    # compression at a prescribed strain rate on y (fix deform erate + remap x)
    p = lattice_packing(10, 12, seed=4, spread=0.15, compression=0.04)
    ld = Loading(y=AxisControl("rate", rate=-2.0))
    fe = FastEngine(p, S)
    de = DEMEngine(p, S)
    a = fe.advance(ld, 300)
    b = de.advance(ld, 300)
    np.testing.assert_allclose(a["lengths"], b["lengths"], rtol=1e-15)
    assert b["lengths"][-1, 1] < p.cell[1, 1]
    assert np.abs(a["stress"] - b["stress"]).max() < 1e-12 * np.abs(b["stress"]).max()
    assert _image_diff(fe.x, de.x, b["lengths"][-1]) < 1e-12 * p.radii.max()


def test_threads_do_not_change_the_result(threaded_small):
    # the sums have a fixed order (bands, entries, spills): 1 and 2 threads agree bit for bit; a
    # race between the threads (two bands writing one particle) would break this
    from bench.dem import assembly

    p = assembly(5000)
    e1 = FastEngine(p, S, threads=1)
    e2 = FastEngine(p, S, threads=2)
    assert e2.cell_ops._parallel and not e1.cell_ops._parallel
    a = advance(e1, 150)
    b = advance(e2, 150)
    assert a["rebuilds"] > 0
    np.testing.assert_array_equal(a["stress"], b["stress"])
    np.testing.assert_array_equal(e1.x, e2.x)
    np.testing.assert_array_equal(e1.v, e2.v)


def _lists(e):
    e.cell_ops._flat(e)  # the banded build's bands moved together (the same entries, in order)
    m = e.n_entries
    return (e._start.copy(), e._ni[:m].copy(), e._nj[:m].copy(), e._code[:m].copy(), e._hist[:, :m].copy())


@pytest.mark.parametrize("slack", ["room", "overflow"])
def test_threaded_list_build_is_the_serial_list(threaded_small, monkeypatch, slack):
    """The threaded build (one pass per band into its own region, then the bands moved together)
    gives the serial one-pass list entry for entry: partners, owners, images and the springs
    handed over; when a band's region is too small, the count and fill passes give it too."""
    from bench.dem import assembly

    if slack == "overflow":
        monkeypatch.setattr(fast, "BAND_SLACK", 0.5)
        monkeypatch.setattr(fast, "BAND_PAD", 0)
    p = assembly(5000)
    e1 = FastEngine(p, S, threads=1)
    e2 = FastEngine(p, S, threads=2)
    for _ in range(3):
        a = advance(e1, 60)
        b = advance(e2, 60)
        assert a["rebuilds"] == b["rebuilds"] > 0
        for u, v in zip(_lists(e1), _lists(e2)):
            np.testing.assert_array_equal(u, v)
        assert np.count_nonzero(e1._hist[:, : e1.n_entries]) > 0  # springs were handed over
    if slack == "room":
        assert e2.n_banded_builds == e2.n_rebuilds - 1  # all but the first build (no last list)
    else:
        assert e2.n_banded_builds == 0


def test_threaded_list_build_under_a_shrinking_box(threaded_small):
    """Compressed at a prescribed rate, the box loses bin rows, so the bands change between two
    builds (the regions are then sized from the whole last list): 1 and 2 threads still give the
    same list, entry for entry, and the same state, bit for bit."""
    from bench.dem import assembly

    p = assembly(5000)
    ld = Loading(y=AxisControl("rate", rate=-60.0))
    e1 = FastEngine(p, S, threads=1)
    e2 = FastEngine(p, S, threads=2)
    bands = {e2._cstart.size}
    for _ in range(6):
        e1.advance(ld, 50, phase_step0=0, phase_box0=(np.zeros(2), np.diag(p.cell)))
        e2.advance(ld, 50, phase_step0=0, phase_box0=(np.zeros(2), np.diag(p.cell)))
        bands.add(e2._cstart.size)
        for u, v in zip(_lists(e1), _lists(e2)):
            np.testing.assert_array_equal(u, v)
    np.testing.assert_array_equal(e1.x, e2.x)
    assert len(bands) > 1, f"the bands never changed ({bands})"
    assert e2.n_banded_builds > 0


def test_threaded_hand_over_table_is_the_serial_one():
    """The hand-over table (entries with a non-zero spring, CSR by particle) built band by band on
    the threads equals :func:`fast_kernels.compact_history`'s, and the per-band counts add up to
    :func:`fast_kernels.count_history`."""
    from bench.dem import assembly
    from gransim.dem import fast_kernels as FK

    p = assembly(3000)
    e = FastEngine(p, S, threads=1)
    advance(e, 80)
    n = e.n
    k = FK.count_history(e._start, e._hist[0], e._hist[1], n)
    assert k > 0
    want = (np.zeros(n + 1, np.int32), np.zeros(k, np.int32), np.zeros((k, 2)))
    FK.compact_history(e._start, e._stop, e._nj, e._hist[0], e._hist[1], n, *want)
    bc = np.zeros(e._cstart.size - 1, np.int64)
    with fast.dynamic_chunks(1):
        FK.history_counts(e._cstart, e._start, e._stop, e._hist[0], e._hist[1], bc)
        got = (np.zeros(n + 1, np.int32), np.zeros(k, np.int32), np.zeros((k, 2)))
        assert FK.compact_history_banded(e._cstart, e._start, e._stop, e._nj, e._hist[0], e._hist[1], bc, *got) == k
    assert int(bc.sum()) == k
    for u, v in zip(want, got):
        np.testing.assert_array_equal(u, v)


def _stress_divergence(s, ref):
    """Relative stress difference at every step: max over components |s - ref| / max |ref|."""
    return np.abs(s - ref).reshape(len(ref), -1).max(axis=1) / np.abs(ref).max()


def test_relaxation_of_1000_disks_within_the_chaos_envelope():
    # the bench assembly (1,020 disks overlapping ~8% of a radius) relaxing for 2000 steps:
    # DEMEngine from the unperturbed state is the reference; its runs from 1e-12 perturbed
    # positions span the envelope E(t) (max over them of the relative stress difference); the
    # fast path must stay within 10 E(t) (+ 1e-13 for the first steps, where E is round-off)
    from bench.dem import assembly

    p = assembly(1000)
    steps = 2000
    ref = DEMEngine(p, S).advance(Loading(), steps)["stress"]
    env = np.zeros(steps)
    rng = np.random.default_rng(7)
    for k in range(4):
        x = p.positions.copy()
        i = rng.integers(p.n)
        x[i, k % 2] *= 1.0 + (1e-12 if k < 2 else -1e-12)
        q = Packing(positions=x, radii=p.radii, cell=p.cell, density=p.density)
        env = np.maximum(env, _stress_divergence(DEMEngine(q, S).advance(Loading(), steps)["stress"], ref))
    fast = advance(FastEngine(p, S), steps)
    d = _stress_divergence(fast["stress"], ref)
    assert fast["rebuilds"] > 10
    assert np.all(d <= 10.0 * env + 1e-13), f"worst step {int(np.argmax(d - 10 * env))}"
    # the relaxation is damped (the perturbations neither die out nor explode: E ends at a few
    # 1e-13 here); the envelope stays above the round-off of one step, and the fast path does
    # differ from the reference (its sums are reordered), so the comparison is not vacuous
    assert env[-1] > 1e-14
    assert d.max() > 0.0


def test_momentum_is_conserved_and_energy_dissipated(threaded_small):
    # periodic cell, no external force: sum m v is constant (the symmetric update gives equal
    # and opposite pair forces; the spilled j-side forces too); damping and friction only
    # dissipate: kinetic + elastic energy never grows
    p = lattice_packing(10, 12, seed=5, spread=0.15, compression=0.05)
    rng = np.random.default_rng(1)
    v = rng.normal(0.0, 0.05, (p.n, 2))
    fe = FastEngine(p, S, velocities=v, spins=rng.normal(0.0, 20.0, p.n), threads=2)
    m = np.pi * p.radii**2 * p.density
    P0 = m @ v
    e_prev = e_start = fe.kinetic_energy() + _elastic_energy(fe, p, S.kn)
    for _ in range(20):
        advance(fe, 50)
        P = m @ fe.v
        assert np.abs(P - P0).max() < 1e-13 * np.abs(m[:, None] * v).sum()
        e = fe.kinetic_energy() + _elastic_energy(fe, p, S.kn)
        # the tangential spring stores energy too (not counted): allow the last 1% of it
        assert e <= e_prev * (1 + 1e-2)
        e_prev = min(e, e_prev)
    assert e_prev < 0.8 * e_start  # and it does dissipate (to 0.53 here)


def _elastic_energy(fe, p, kn):
    """sum kn delta^2 / 2 over overlapping pairs, brute force O(N^2) with the nearest image."""
    x = fe.x
    L = fe.box_lengths
    d = x[:, None, :] - x[None, :, :]
    d -= np.rint(d / L) * L
    dist = np.sqrt((d**2).sum(axis=2))
    ov = p.radii[:, None] + p.radii[None, :] - dist
    iu = np.triu_indices(p.n, 1)
    o = ov[iu]
    return float(0.5 * kn * np.sum(o[o > 0] ** 2))


def test_energy_conserved_without_damping_or_friction():
    # kn springs only (gamma = 0, mu = 0: no tangential force): velocity Verlet conserves the
    # energy to O(dt^2), no drift over 2000 steps
    p = lattice_packing(10, 12, seed=6, spread=0.15, compression=0.05)
    s = DEMSettings(kn=1e5, kt=1e5, gamma_n=0.0, gamma_t=0.0, mu=0.0, dt=1e-6, skin=2e-5)
    fe = FastEngine(p, s)
    e0 = fe.kinetic_energy() + _elastic_energy(fe, p, s.kn)
    es = []
    for _ in range(10):
        advance(fe, 200)
        es.append(fe.kinetic_energy() + _elastic_energy(fe, p, s.kn))
    assert fe.kinetic_energy() > 0.1 * e0  # energy moved into motion
    assert np.max(np.abs(np.array(es) - e0)) < 1e-3 * e0


def test_the_permutation_is_undone_exactly():
    # free flight (no contacts) with many list builds: each build re-sorts the particles, the
    # outputs come back in the original order; velocities and spins are untouched bit for bit
    rng = np.random.default_rng(2)
    n = 200
    L = 0.2
    g = np.stack(np.meshgrid(np.arange(20), np.arange(10)), axis=-1).reshape(-1, 2)
    x = (g + 0.5) * np.array([L / 20, L / 10])
    r = rng.uniform(0.8e-3, 1e-3, n)
    p = Packing(positions=x, radii=r, cell=np.diag([L, L]), density=2650.0)
    v = rng.normal(0.0, 1.0, (n, 2))
    w = rng.normal(0.0, 10.0, n)
    fe = FastEngine(p, S, velocities=v, spins=w)
    np.testing.assert_array_equal(fe.x, x)
    out = advance(fe, 300)
    assert out["rebuilds"] > 20
    assert fe.n_contacts == 0
    np.testing.assert_array_equal(fe.v, v)
    np.testing.assert_array_equal(fe.w, w)
    ref = x.copy()
    for _ in range(300):
        ref += S.dt * v
    assert _image_diff(fe.x, ref, L) < 1e-15
    assert not np.array_equal(fe.perm, np.arange(n))  # the particles really were re-sorted


@pytest.mark.parametrize("threads", [1, 2])
def test_entry_views_agree_with_each_other(threads, threaded_small):
    """``ea``, ``eb``, ``xi`` and ``eshift`` describe the same entries, one row each, in the same
    order, also right after a threaded build (a list with a gap after each band): every listed
    pair's image lies within the list's reach, r_a + r_b + skin at the build plus the skin the two
    may have moved since (each less than half of it)."""
    p = lattice_packing(40, 40, seed=3, spread=0.1, compression=0.03)
    fe = FastEngine(p, S, threads=threads)
    advance(fe, 50)
    assert (fe._gaps is not None) == (threads == 2)  # a threaded build leaves gaps; the views close them
    s = fe.eshift  # first: each view must close the gaps itself
    a, b = fe.ea, fe.eb
    assert a.shape == b.shape == (fe.n_entries,) and s.shape == (fe.n_entries, 2) and fe.xi.shape[0] == fe.n_entries
    d = np.linalg.norm(fe.x[b] + s * fe.box_lengths - fe.x[a], axis=1)
    assert np.all(d < fe.r[a] + fe.r[b] + 2 * S.skin), d.max()
    assert fe.n_contacts > 0


def test_bad_input_is_refused():
    p = lattice_packing(10, 12)
    with pytest.raises(InputError, match="threads"):
        FastEngine(p, S, threads=0)
    with pytest.raises(InputError, match="velocities"):
        FastEngine(p, S, velocities=np.zeros((3, 2)))
    with pytest.raises(InputError, match="nsteps"):
        FastEngine(p, S).advance(Loading(), -1)
    small = lattice_packing(3, 4)
    with pytest.raises(InputError, match="cell heights"):
        FastEngine(small, S)
    with pytest.raises(InputError, match="dt"):
        FastEngine(p, DEMSettings(kn=1e9, dt=1e-3))


def _scalar_forces(eng):
    """An independent scalar implementation of the fast path's force sums (plain Python, one
    entry at a time: the law's block path (its ``select``, masked where the pair does not touch, as
    :func:`fast_kernels.forces_v` masks it) on Python floats, then the
    i side, j side or spill, virial, contacts and overlap in list order, band by band: even bands,
    odd bands, then the spills in band order). Python floats are IEEE doubles and ``math.sqrt`` is correctly rounded, so
    the vectorised kernel must give these sums bit for bit."""

    from gransim.contacts.laws import law_spec

    select = law_spec(eng.law).select.py_func
    s = eng.settings
    L = eng.hi - eng.lo
    n = eng.n
    fx, fy, t = np.zeros(n), np.zeros(n), np.zeros(n)
    h0, h1 = eng._hist[0].copy(), eng._hist[1].copy()
    cs, st, sp = eng._cstart, eng._start, eng._stop  # a threaded build's list: gaps after the bands
    nch = cs.size - 1
    acc = np.zeros((nch, 6))
    spills = [[] for _ in range(nch)]  # per band: _scatter adds them in band order
    ps = eng.ps  # the sorted state
    x, y, vx, vy, w, r, m = (ps.x, ps.y, ps.vx, ps.vy, ps.w, ps.r, ps.m)
    for colour in range(2):
        for c in range(colour, nch, 2):
            jmax = cs[min(c + 2, nch)]
            sums = [0.0] * 6
            for i in range(cs[c], cs[c + 1]):
                fi = [0.0, 0.0, 0.0]
                for e in range(st[i], sp[i]):
                    j = int(eng._nj[e])
                    sx, sy = int(eng._code[e]) % 3 - 1, int(eng._code[e]) // 3 - 1
                    dx = float(x[i]) - (float(x[j]) + sx * float(L[0]))
                    dy = float(y[i]) - (float(y[j]) + sy * float(L[1]))
                    rsq = dx * dx + dy * dy
                    args = (float(r[i]), float(r[j]), float(vx[i]), float(vy[i]), float(vx[j]), float(vy[j]))
                    args += (float(w[i]), float(w[j]), float(m[i]), float(m[j]), s.dt, float(h0[e]), float(h1[e]), True)
                    tc, fxe, fye, tie, tje, s0, s1, _, dn = select(eng.law, dx, dy, rsq, *args)
                    fxe, fye, tie, tje, dn = tc * fxe, tc * fye, tc * tie, tc * tje, tc * dn
                    h0[e], h1[e] = s0, s1
                    fi[0] += fxe
                    fi[1] += fye
                    fi[2] += tie
                    if j < jmax:
                        fx[j] -= fxe
                        fy[j] -= fye
                        t[j] += tje
                    else:
                        spills[c].append((j, -fxe, -fye, tje))
                    sums[0] += dx * fxe
                    sums[1] += dy * fye
                    sums[2] += dx * fye
                    sums[3] += dy * fxe
                    sums[4] += tc
                    sums[5] += dn
                fx[i] += fi[0]
                fy[i] += fi[1]
                t[i] += fi[2]
            acc[c] = sums
    for j, a, b, d in (q for band in spills for q in band):
        fx[j] += a
        fy[j] += b
        t[j] += d
    return fx, fy, t, h0, h1, acc


@pytest.mark.parametrize("threads", [1, 2])
def test_vectorised_forces_equal_the_scalar_loop_bit_for_bit(threads, threaded_small):
    # the force kernel runs the pair law over a block's entries as SIMD code (vector square
    # roots and divisions, exact IEEE operations) and sums in list order: it must give the
    # scalar one-entry-at-a-time sums exactly, in a state with sliding, sticking and separated
    # list entries, springs carried over and pairs across both periodic boundaries
    from bench.dem import assembly

    p = assembly(1000)
    rng = np.random.default_rng(11)
    fe = FastEngine(p, S, velocities=rng.normal(0.0, 0.02, (p.n, 2)), spins=rng.normal(0.0, 30.0, p.n), threads=threads)
    advance(fe, 40)
    ref = _scalar_forces(fe)
    touch = ref[5][:, 4].sum()
    assert 0 < touch < fe.n_entries  # some entries touch, some do not
    assert fe._nspill > 0  # pairs across the periodic y boundary
    h0 = fe._hist[0].copy()
    fe._forces(update=True)
    if threads == 2:
        assert fe._gaps is not None  # the list of the banded build, read band by band
    got = (fe.ps.fx, fe.ps.fy, fe.ps.t, fe._hist[0], fe._hist[1], fe._acc)
    want = ref
    for name, a, b in zip(("fx", "fy", "t", "h0", "h1", "acc"), got, want):
        np.testing.assert_array_equal(a, b, err_msg=name)
    slid = np.sum((np.abs(fe._hist[0] - h0) > 0) & (fe._hist[0] != 0))
    assert slid > 0  # the springs moved


@pytest.mark.parametrize("cell", ["orthogonal", "sheared"])
def test_the_force_kernel_is_compiled_to_simd_code(cell):
    # the speed of the fast path rests on LLVM vectorising the pair law (docs/performance.md);
    # numba gives up silently when the loop body changes shape (a bool out of the law's tuple,
    # an inlined helper taking arrays, a 2D spring array), so the compiled kernel is checked for
    # packed square roots and gathers, with the image of either cell (the sheared one adds the
    # tilt and the Lees-Edwards velocity). Compiled afresh (inspection is off for cached code).
    import re

    import numba

    from gransim._numba import JIT_OPTIONS
    from gransim.dem import fast_kernels as FK

    flags = open("/proc/cpuinfo").read() if __import__("os").path.exists("/proc/cpuinfo") else ""
    if " avx2" not in flags:
        pytest.skip("no AVX2 on this CPU: the gathers need it")
    opts = {**JIT_OPTIONS, "cache": False, "parallel": True}
    k = numba.njit(**opts)(FK.forces_v.py_func)
    p = lattice_packing(10, 12)
    if cell == "sheared":
        C = p.cell.copy()
        C[0, 1] = 4e-3
        p = Packing(positions=p.positions, radii=p.radii, cell=C, density=p.density)
    s = DEMSettings(**{**S.to_dict(), "flavour": "lammps"}) if cell == "sheared" else S
    fe = FastEngine(p, s, cell=cell)
    img = fe.cell_ops._image(fe)
    assert len(img) == (6 if cell == "sheared" else 2)
    with fe.cell_ops._kernels(fe):
        p = fe.ps
        k(False, fe._cstart, fe._start, fe._stop, fe._ni, fe._nj, fe._code, fe._hist[0], fe._hist[1], p.x, p.y,
          p.vx, p.vy, p.w, p.r, p.m, p.fx, p.fy, p.t, img, fe.law, fe.settings.dt, False, fe._sp_start,
          *fe.cell_ops._spill(fe), fe._acc)  # fmt: skip
    asm = k.inspect_asm(k.signatures[0])
    assert re.search(r"\bvsqrtpd\b", asm), "the pair law is not vectorised (no packed square root)"
    assert re.search(r"\bvdivpd\b", asm)
    assert re.search(r"\bvgather[dq]pd\b", asm), "the partners' loads are not gathers"
    # unsigned owner and partner indices: each gather takes base + 8 index; with the indices as
    # read (int32) every gather computed its addresses with a wrap-around select (docs/performance.md)
    assert not re.search(r"\bvgather[dq]pd\s+\(,", asm), "a gather computes its addresses (a signed index)"


def test_the_threaded_wrap_is_the_serial_wrap():
    """Each particle's wrap is its own: on 2 threads the positions (and the sheared cell's
    velocity jumps) are the same bits as on one, and the particle named as still outside after
    one wrap is the same (the first along x, else along y; the first in the sheared cell)."""
    from gransim._numba import dynamic_chunks, num_threads
    from gransim.dem import fast_kernels as FK

    rng = np.random.default_rng(11)
    n = 50_000
    lo, hi = np.array([0.1, -0.2]), np.array([1.3, 0.7])
    for far in (None, (31_000, 1), (4_000, 0)):
        x, y = rng.uniform(-0.2, 1.6, n), rng.uniform(-0.5, 1.0, n)
        if far is not None:
            (x, y)[far[1]][far[0]] = 9.0  # more than one period outside
        a, b = (x.copy(), y.copy()), (x.copy(), y.copy())
        with num_threads(2), dynamic_chunks(4096):
            got = FK.wrap(*b, lo, hi)
        with num_threads(1):
            assert got == FK.wrap(*a, lo, hi) == (-1 if far is None else far[0])
        wrapped = (x.copy(), y.copy())  # the wrap written out in numpy for the positions
        for d in range(2):
            w = wrapped[d]
            w[w < lo[d]] += hi[d] - lo[d]
            up = w >= hi[d]
            w[up] = np.maximum(w[up] - (hi[d] - lo[d]), lo[d])
        assert all(np.array_equal(u, w) for u, w in zip(a, wrapped))
        assert all(np.array_equal(u, w) for u, w in zip(a, b))
        box, hr = np.array([0.1, -0.2, 1.3, 0.7, 0.35]), np.array([0.01, -0.02, 0.3])
        st = [x.copy(), y.copy(), rng.normal(size=n), rng.normal(size=n)]
        pt = [c.copy() for c in st]
        with num_threads(2), dynamic_chunks(4096):
            gp = FK.wrap_tilted(*pt, box, hr, True)
        with num_threads(1):
            assert gp == FK.wrap_tilted(*st, box, hr, True)
        assert all(np.array_equal(u, w) for u, w in zip(st, pt))
