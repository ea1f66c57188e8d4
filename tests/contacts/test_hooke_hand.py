"""The Hooke history pair law alone, against cases computed by hand.

Two disks of radius 1 mm, masses 2 g (m_eff = 1 g), kn = kt = 1e5 N/m, gamma_n = gamma_t = 50 1/s,
mu = 0.5, dt = 1e-6 s; i sits at d = x_i - x_j = (1.9 mm, 0), so n = (1, 0), the overlap is
delta = 0.1 mm and the contact point lies c = r - delta/2 = 0.95 mm from each centre. Every expected
number below is worked out in the comment beside it from the law's definition (LIGGGHTS
hooke/stiffness + tangential history, docs/laws.md), not taken from the code.
"""

from __future__ import annotations

import pytest

from gransim.contacts.hooke import hooke_history, hooke_history_lammps

R, M, KN, KT, GN, GT, MU, DT = 1e-3, 2e-3, 1e5, 1e5, 50.0, 50.0, 0.5, 1e-6
DX = 1.9e-3
C = R - 0.5 * (2 * R - DX)  # 0.95 mm
#: the lever arm of each code (docs/lammps.md): LIGGGHTS r - delta/2, LAMMPS gran/hooke/history the radius r
LAWS = [pytest.param(hooke_history, C, id="liggghts"), pytest.param(hooke_history_lammps, R, id="lammps")]


def pair(law, vi=(0.0, 0.0), wi=0.0, s=(0.0, 0.0), update=False, mu=MU):
    return law(
        DX, 0.0, DX * DX, R, R, vi[0], vi[1], 0.0, 0.0, wi, 0.0, M, M, KN, KT, GN, GT, mu, DT, s[0], s[1], update
    )


@pytest.mark.parametrize("law, arm", LAWS)
def test_static_overlap_pushes_i_away_from_j(law, arm):
    fx, fy, ti, tj, s0, s1, sliding, fn = pair(law)
    # F_n = kn delta = 1e5 * 1e-4 = 10 N along +n; nothing tangential
    assert fn == pytest.approx(10.0, rel=1e-12)
    assert (fx, fy) == (pytest.approx(10.0, rel=1e-12), 0.0)
    assert (ti, tj, s0, s1, sliding) == (0.0, 0.0, 0.0, 0.0, False)


@pytest.mark.parametrize("law, arm", LAWS)
def test_normal_damping_resists_approach(law, arm):
    fx, fy, *_, fn = pair(law, vi=(-0.1, 0.0))
    # v_n = -0.1 m/s (approaching): F_n = 10 - m_eff gamma_n v_n = 10 + 1e-3 * 50 * 0.1 = 10.005 N
    assert fn == pytest.approx(10.005, rel=1e-12)
    assert fx == pytest.approx(10.005, rel=1e-12) and fy == 0.0


@pytest.mark.parametrize("law, arm", LAWS)
def test_tangential_spring_and_dashpot_in_one_step(law, arm):
    fx, fy, ti, tj, s0, s1, sliding, fn = pair(law, vi=(0.0, 0.2), update=True)
    # xi = v_t dt = (0, 2e-7 m); F_t = -kt xi - m_eff gamma_t v_t = -0.02 - 0.01 = -0.03 N (along y)
    assert (s0, s1) == (0.0, pytest.approx(2e-7, rel=1e-12))
    assert fy == pytest.approx(-0.03, rel=1e-12) and fx == pytest.approx(10.0, rel=1e-12)
    # torque on i: r_c x F_t with r_c = (-c, 0): (-c)(-0.03) = +c 0.03 N m; on j, (c, 0) x (+0.03): the same
    assert ti == pytest.approx(arm * 0.03, rel=1e-12) and tj == pytest.approx(arm * 0.03, rel=1e-12)
    assert not sliding


@pytest.mark.parametrize("law, arm", LAWS)
def test_spin_moves_the_contact_point(law, arm):
    fx, fy, ti, tj, s0, s1, sliding, fn = pair(law, wi=10.0)
    # the contact point of i moves with w x r_c = 10 z x (-c, 0) = (0, -10 c) m/s: the dashpot gives
    # F_t = -m_eff gamma_t v = +1e-3 * 50 * 10 c = 0.5 c N along y (LIGGGHTS 4.75e-4; no spring: update False)
    f = 0.5 * arm
    assert fy == pytest.approx(f, rel=1e-12)
    assert ti == pytest.approx(-arm * f, rel=1e-12) and tj == pytest.approx(-arm * f, rel=1e-12)


def test_coulomb_cap_scales_the_spring_back():
    # in a step (update): no relative motion, so no increment, and xi = (0, 1 mm) is already tangent
    fx, fy, ti, tj, s0, s1, sliding, fn = pair(hooke_history, s=(0.0, 1e-3), update=True)
    # kt |xi| = 100 N > mu |F_n| = 5 N: F_t = -kt xi * 5/100 = (0, -5) N, xi = -F_t / kt = 5e-5 m, no dashpot
    assert sliding
    assert fy == pytest.approx(-5.0, rel=1e-12)
    assert s1 == pytest.approx(5e-5, rel=1e-12) and s0 == 0.0
    assert ti == pytest.approx(C * 5.0, rel=1e-12)


def test_set_up_evaluation_caps_the_force_and_keeps_the_spring_in_liggghts_only():
    """A set-up evaluation (update False: a further ``run``'s set-up) caps the force in both codes;
    LIGGGHTS writes the capped spring back only in a step (tangential_model_history.h:195-200,
    ``if (update_history)``), LAMMPS in either case (pair_gran_hooke_history.cpp). Both native
    forms of the LIGGGHTS law (the code's branches and the branch-free block path) agree."""
    from gransim.contacts.hooke import hooke_liggghts

    fx, fy, ti, tj, s0, s1, sliding, fn = pair(hooke_history, s=(0.0, 1e-3))
    assert sliding and fy == pytest.approx(-5.0, rel=1e-12)
    assert (s0, s1) == (0.0, 1e-3)  # the stored spring, untouched
    out = pair(hooke_liggghts, s=(0.0, 1e-3))  # (touch, fx, fy, ti, tj, s0, s1, sliding, overlap, fn)
    assert out[0] == 1.0 and out[2] == fy and (out[5], out[6]) == (0.0, 1e-3)
    stepped = pair(hooke_liggghts, s=(0.0, 1e-3), update=True)
    assert stepped[6] == pytest.approx(5e-5, rel=1e-12)
    *_, l0, l1, lsliding, _ = pair(hooke_history_lammps, s=(0.0, 1e-3))
    assert lsliding and l1 == pytest.approx(5e-5, rel=1e-12)  # LAMMPS: written in the set-up too


def test_below_the_cap_the_spring_is_kept():
    *_, s0, s1, sliding, fn = pair(hooke_history, s=(0.0, 4.9e-5))
    # kt |xi| = 4.9 N < 5 N: no slip, the spring is unchanged
    assert not sliding and s1 == 4.9e-5


def test_lammps_caps_spring_plus_damping():
    # LAMMPS gran/hooke/history caps |F_spring + F_damp| (docs/lammps.md), LIGGGHTS the spring alone:
    # with xi = (0, 4.995e-5 m) and v_t = 0.2 m/s the spring gives 4.995 N < 5 N = mu F_n, the dashpot 0.01 N;
    # LIGGGHTS: no slip, F_t = -(4.995 + 0.01) = -5.005 N; LAMMPS: 5.005 > 5, slip, F_t = -5 N
    out_lig = pair(hooke_history, vi=(0.0, 0.2), s=(0.0, 4.995e-5))
    out_lmp = pair(hooke_history_lammps, vi=(0.0, 0.2), s=(0.0, 4.995e-5))
    assert out_lig[1] == pytest.approx(-5.005, rel=1e-12) and not out_lig[6]
    assert out_lmp[1] == pytest.approx(-5.0, rel=1e-12) and out_lmp[6]
