"""Exact cases of the DEM engine: restitution, energy, momentum, Coulomb slip, stress, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from gransim import Packing
from gransim.contacts.hooke import hooke_history
from gransim.contacts.law import potential
from gransim.dem import AxisControl, DEMEngine, DEMSettings, Loading, contact_time, stability_limit
from gransim.dem.lattice import lattice_packing
from gransim.errors import InputError, SimulationError

FIXED = Loading()


def two_disks(r1=1e-3, r2=1.5e-3, gap=1e-5, offset=0.0):
    """Two disks in a large cell, touching after a short approach along x."""
    L = 0.02
    x = np.array(
        [[0.5 * L - r1 - 0.5 * gap, 0.5 * L - 0.5 * offset], [0.5 * L + r2 + 0.5 * gap, 0.5 * L + 0.5 * offset]]
    )
    return Packing(positions=x, radii=[r1, r2], cell=np.diag([L, L]), density=2650.0)


def collide(p, settings, v0, w=None, nmax=200000):
    eng = DEMEngine(p, settings, velocities=v0, spins=w)
    touched = False
    for _ in range(nmax):
        eng.advance(FIXED, 1)
        d = np.linalg.norm(eng.x[1] - eng.x[0])
        if d < p.radii.sum():
            touched = True
        elif touched:
            return eng
    raise AssertionError("the disks did not separate")


@pytest.mark.parametrize("gamma", [0.0, 200.0, 2000.0])
def test_head_on_restitution_matches_damped_spring(gamma):
    # m_eff d'' + m_eff gamma d' + kn d = 0 from d = 0 to d = 0 again (no force limit):
    # e = exp(-zeta pi / sqrt(1 - zeta^2)), zeta = gamma / (2 omega_0), omega_0 = sqrt(kn/m_eff)
    p = two_disks()
    m = np.pi * p.radii**2 * p.density
    meff = m[0] * m[1] / m.sum()
    kn = 1e5
    w0 = np.sqrt(kn / meff)
    zeta = gamma / (2 * w0)
    e_exact = np.exp(-zeta * np.pi / np.sqrt(1 - zeta**2))
    tc = contact_time(p, kn)
    errs = []
    for steps_per_contact in (100, 400):
        s = DEMSettings(kn=kn, kt=0.0, gamma_n=gamma, gamma_t=0.0, mu=0.0, dt=tc / steps_per_contact, skin=1e-5)
        v0 = np.array([[0.05, 0.0], [-0.05 * m[0] / m[1], 0.0]])
        eng = collide(p, s, v0)
        vrel_in = v0[0, 0] - v0[1, 0]
        vrel_out = eng.v[0, 0] - eng.v[1, 0]
        errs.append(abs(-vrel_out / vrel_in - e_exact))
    # discretisation error of velocity Verlet plus the contact-detection phase error: O(dt)
    assert errs[1] < 2e-2 * (1 - e_exact + 0.05)
    assert errs[1] < errs[0] or errs[1] < 1e-9


def test_energy_conserved_without_damping_and_friction():
    p = lattice_packing(8, 8, seed=3, spread=0.1, compression=0.03)
    s = DEMSettings(kn=1e5, kt=1e5, gamma_n=0.0, gamma_t=0.0, mu=0.0, dt=contact_time(p, 1e5) / 60, skin=2e-5)
    rng = np.random.default_rng(0)
    eng = DEMEngine(p, s, velocities=rng.normal(0, 0.01, (p.n, 2)))

    def energy():
        L = eng.box_lengths
        d = eng.x[eng.ea] - (eng.x[eng.eb] + eng.eshift * L)
        ov = eng.r[eng.ea] + eng.r[eng.eb] - np.linalg.norm(d, axis=1)
        w = np.where(eng.both, 1.0, 0.5)  # boundary pairs are listed once per owner
        return eng.kinetic_energy() + sum(wi * potential(o, s.kn) for wi, o in zip(w, ov))

    E0 = energy()
    E = []
    for _ in range(40):
        eng.advance(FIXED, 50)
        E.append(energy())
    E = np.array(E)
    # velocity Verlet: bounded O(dt^2) fluctuation, no drift (kinetic energy is at half steps
    # mismatch-free here because it is evaluated at full steps)
    assert np.abs(E / E0 - 1).max() < 5e-3
    assert abs(E[20:].mean() - E[:20].mean()) / E0 < 1e-3


def test_momentum_conserved_with_friction_and_damping():
    p = lattice_packing(8, 8, seed=4, spread=0.1, compression=0.04)
    s = DEMSettings(kn=1e5, kt=1e5, gamma_n=100.0, gamma_t=100.0, mu=0.5, dt=2e-6, skin=2e-5)
    rng = np.random.default_rng(1)
    v = rng.normal(0, 0.02, (p.n, 2))
    eng = DEMEngine(p, s, velocities=v, spins=rng.normal(0, 10, p.n))
    P0 = (eng.m[:, None] * eng.v).sum(0)
    scale = (eng.m[:, None] * np.abs(eng.v)).sum()
    eng.advance(FIXED, 1000)
    assert eng.slide.any()  # some contacts slide
    P1 = (eng.m[:, None] * eng.v).sum(0)
    assert np.abs(P1 - P0).max() < 1e-12 * scale


def test_angular_momentum_conserved_in_oblique_collision_with_friction():
    p = two_disks(offset=1.2e-3)
    s = DEMSettings(kn=1e5, kt=1e5, gamma_n=100.0, gamma_t=100.0, mu=0.3, dt=contact_time(p, 1e5) / 200, skin=1e-5)
    m = np.pi * p.radii**2 * p.density
    v0 = np.array([[0.05, 0.0], [-0.05 * m[0] / m[1], 0.0]])
    w0 = np.array([30.0, -10.0])
    I = 0.5 * m * p.radii**2

    def L_of(x, v, w):
        return np.sum(m * (x[:, 0] * v[:, 1] - x[:, 1] * v[:, 0])) + np.sum(I * w)

    # full-step angular momentum about the origin: orbital + spin
    L0 = L_of(p.positions, v0, w0)
    eng = collide(p, s, v0, w0)
    assert abs(eng.w - w0).max() > 1.0  # friction did change the spins
    L1 = L_of(eng.x, eng.v, eng.w)
    scale = np.sum(m * np.abs(p.positions[:, 0] * v0[:, 1] - p.positions[:, 1] * v0[:, 0])) + np.sum(I * abs(w0))
    assert abs(L1 - L0) < 1e-10 * scale + 1e-3 * np.sum(m * np.abs(v0).sum(1) * p.radii)


def test_tangential_slip_follows_coulomb_cap():
    # pressed pair (fixed overlap) sheared at constant tangential velocity u: the spring force
    # grows as kt u t until it reaches mu F_n, then stays there; spring reset to the cap
    kn, kt, mu, dt, u = 1e5, 8e4, 0.4, 1e-6, 0.02
    ri = rj = 1e-3
    delta = 2e-5
    d = ri + rj - delta
    s0 = s1 = 0.0
    Ft = []
    for k in range(1, 1001):
        fx, fy, ti, tj, s0, s1, sl, fn = hooke_history(
            0.0, d, d * d, ri, rj, u, 0.0, 0.0, 0.0, 0.0, 0.0, 1e-3, 1e-3, kn, kt, 0.0, 0.0, mu, dt, s0, s1, True
        )
        assert fn == pytest.approx(kn * delta, rel=1e-12)
        assert fy == pytest.approx(fn, rel=1e-12)
        expect = min(kt * u * k * dt, mu * fn)
        assert -fx == pytest.approx(expect, rel=1e-9)
        assert sl == (kt * u * k * dt > mu * fn * (1 + 1e-12))
        # torques: same sign on both disks, lever arm r - delta/2; i sits above j (n = +y) and is
        # dragged back (fx < 0) at its lowest point: clockwise, T_i = (r_i - delta/2) fx < 0
        assert ti == pytest.approx(tj) and ti == pytest.approx((ri - delta / 2) * fx, rel=1e-12)
        Ft.append(-fx)
    assert Ft[-1] == pytest.approx(mu * kn * delta)
    assert abs(s0) == pytest.approx(mu * kn * delta / kt)


def test_cap_is_strict_and_uses_damped_normal_force():
    # kt |xi| exactly mu |F_n|: no cap (strictly greater); damping included in |F_n|.
    # kt = 1 N/m makes kt |xi| == mu |F_n| exact in floating point.
    kn, kt, mu = 1e5, 1.0, 0.5
    ri = rj = 1e-3
    delta = 1e-5
    d = ri + rj - delta
    vn = -0.01  # approaching: damping adds to the normal force
    gamman = 1000.0
    meff = 0.5e-3
    fn = kn * delta - meff * gamman * vn
    xi = mu * abs(fn) / kt
    out = hooke_history(
        d, 0.0, d * d, ri, rj, vn, 0.0, 0.0, 0.0, 0.0, 0.0, 1e-3, 1e-3, kn, kt, gamman, 0.0, mu, 1e-6, 0.0, -xi, False
    )
    assert out[7] == pytest.approx(fn)
    assert not out[6]
    out = hooke_history(
        d,
        0.0,
        d * d,
        ri,
        rj,
        vn,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        1e-3,
        1e-3,
        kn,
        kt,
        gamman,
        0.0,
        mu,
        1e-6,
        0.0,
        -1.01 * xi,
        False,
    )
    assert out[6] and out[1] == pytest.approx(mu * abs(fn))


def test_stress_equals_love_sum_of_snapshot_contacts():
    p = lattice_packing(8, 8, seed=5, spread=0.1, compression=0.04)
    s = DEMSettings(kn=1e5, kt=1e5, gamma_n=50.0, gamma_t=50.0, mu=0.5, dt=2e-6, skin=2e-5)
    eng = DEMEngine(p, s)
    ld = Loading(x=AxisControl("servo", target=50.0, gain=1e-2), y=AxisControl("rate", rate=-0.5))
    eng.advance(ld, 300)
    # one step without box change: the snapshot branch vectors are those the forces used
    out = eng.advance(FIXED, 1)
    c = eng.contacts()
    L = eng.box_lengths
    assert len(c["i"]) == out["n_contacts"][-1] > 0
    assert np.any(np.abs(c["shift"]).sum(1) > 0)  # contacts across the boundary are included
    lvec = eng.x[c["j"]] + c["shift"] * L - eng.x[c["i"]]
    ov = eng.r[c["i"]] + eng.r[c["j"]] - np.linalg.norm(lvec, axis=1)
    np.testing.assert_allclose(ov, c["overlap"], rtol=0, atol=1e-15)
    assert np.all(c["overlap"] > 0)
    # Love stress (eq 17 of Kuhn 002), compression positive: (1/A) sum_c l_ij (x) f_j
    sig = np.einsum("ca,cb->ab", lvec, c["force"]) / (L[0] * L[1])
    np.testing.assert_allclose(sig, out["stress"][-1], rtol=1e-12, atol=1e-12 * np.abs(sig).max())
    assert np.trace(sig) > 0


def test_rejects_unstable_time_step():
    p = lattice_packing(6, 6, seed=0)
    lim = stability_limit(p, DEMSettings(kn=1e5, kt=1e5))
    with pytest.raises(InputError, match="stability limit"):
        DEMEngine(p, DEMSettings(kn=1e5, kt=1e5, dt=1.01 * lim))
    DEMEngine(p, DEMSettings(kn=1e5, kt=1e5, dt=0.99 * lim, skin=2e-5))


def test_nan_stops_with_step_and_particle():
    p = lattice_packing(6, 6, seed=0)
    s = DEMSettings(kn=1e5, kt=1e5, dt=2e-6, skin=2e-5)
    v = np.zeros((p.n, 2))
    v[7, 1] = np.nan
    with pytest.raises(InputError, match="velocities: expected finite numbers"):
        DEMEngine(p, s, velocities=v)  # checked at the boundary
    eng = DEMEngine(p, s)
    eng.v[7, 1] = np.nan  # a state that went non-finite: the run stops naming the step and particle
    with pytest.raises(SimulationError, match=r"step 1: particle 7"):
        eng.advance(FIXED, 10)


def test_bad_settings_and_cells():
    with pytest.raises(InputError, match="kn"):
        DEMSettings(kn=-1.0)
    with pytest.raises(InputError, match="mode"):
        DEMSettings(mode="gpu")
    with pytest.raises(InputError, match="gain"):
        AxisControl("servo", target=1.0, gain=0.0)
    p = lattice_packing(6, 6, seed=0)
    sheared = p.replace(cell=p.cell + np.array([[0.0, 1e-3], [0.0, 0.0]]))
    with pytest.raises(InputError, match="orthogonal"):
        DEMEngine(sheared, DEMSettings(dt=2e-6))


def test_parallel_mode_matches_serial_to_round_off():
    # threaded loop over the same list: same law and step, only the summation order differs
    p = lattice_packing(8, 8, seed=6, spread=0.1, compression=0.04)
    s = DEMSettings(kn=1e5, kt=1e5, gamma_n=50.0, gamma_t=50.0, mu=0.5, dt=2e-6, skin=2e-5)
    ld = Loading(x=AxisControl("servo", target=100.0, gain=1e-2), y=AxisControl("rate", rate=-1.0))
    a = DEMEngine(p, s)
    b = DEMEngine(p, DEMSettings(**{**s.to_dict(), "mode": "parallel"}), threads=2)
    ra = a.advance(ld, 300)
    rb = b.advance(ld, 300)
    assert a.n_rebuilds == b.n_rebuilds
    assert np.abs(a.x - b.x).max() < 1e-10 * p.d50
    np.testing.assert_allclose(rb["stress"], ra["stress"], rtol=0, atol=1e-9 * np.abs(ra["stress"]).max())
    np.testing.assert_array_equal(ra["n_contacts"], rb["n_contacts"])


def test_parallel_mode_is_deterministic():
    p = lattice_packing(6, 6, seed=7, spread=0.1, compression=0.04)
    s = DEMSettings(kn=1e5, kt=1e5, gamma_n=50.0, gamma_t=50.0, mu=0.5, dt=2e-6, skin=2e-5, mode="parallel")
    runs = []
    for _ in range(2):
        eng = DEMEngine(p, s, threads=2)
        eng.advance(Loading(y=AxisControl("rate", rate=-1.0)), 200)
        runs.append(eng.x.copy())
    np.testing.assert_array_equal(runs[0], runs[1])


def test_parallel_engine_leaves_the_process_thread_count_alone():
    import numba

    from gransim.errors import InputError

    p = lattice_packing(6, 6, seed=7, spread=0.1, compression=0.04)
    s = DEMSettings(kn=1e5, kt=1e5, gamma_n=50.0, gamma_t=50.0, mu=0.5, dt=2e-6, skin=2e-5, mode="parallel")
    before = numba.get_num_threads()
    eng = DEMEngine(p, s, threads=1)
    eng.advance(Loading(), 50)
    assert numba.get_num_threads() == before
    one = eng.x.copy()
    eng2 = DEMEngine(p, s, threads=numba.config.NUMBA_NUM_THREADS)
    eng2.advance(Loading(), 50)
    np.testing.assert_array_equal(one, eng2.x)  # the thread count does not change the result
    for bad in (0, 1.5, numba.config.NUMBA_NUM_THREADS + 1):
        with pytest.raises(InputError, match="threads"):
            DEMEngine(p, s, threads=bad)


def test_lost_particle_stops_with_step_and_particle():
    p = lattice_packing(6, 6, seed=0)
    s = DEMSettings(kn=1e5, kt=1e5, dt=2e-6, skin=2e-5)
    v = np.zeros((p.n, 2))
    v[11, 0] = 3.0 * p.cell[0, 0] / s.dt  # three box lengths in one step: beyond one periodic wrap
    eng = DEMEngine(p, s, velocities=v)
    with pytest.raises(SimulationError, match=r"step 1: particle 11 lost"):
        eng.advance(FIXED, 5)
