"""The registered ``energy`` of every contact law against the law's own forces: the finite-difference
derivative of the energy with respect to the overlap is the law's elastic normal force, with respect
to the tangential spring xi minus its spring force, and with respect to the relative rotation
(advanced through the law's own rolling update) its rolling torque. Independent of how the energy
is written: the forces come from the jitted pair functions of :mod:`gransim.contacts` (hooke, hertz,
rolling), at rest (no damping) and below the Coulomb caps (mu large).

Tolerance: central differences with a step 1e-4 of the variable have a truncation error ~1e-8
relative (quadratic: exact) and round-off ~1e-12; 1e-7 relative (tangential force: from fx - F_n
n_x, cancellation ~1e-13 of F_n)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gransim.contacts import rolling
from gransim.contacts.granular import spring_dashpot_slider
from gransim.contacts.laws import law_spec, make_law, pair_force
from gransim.errors import InputError

RI, RJ = 1.0e-3, 0.6e-3  # m
MI, MJ = 2.0e-3, 0.8e-3  # kg
ANGLE = 0.3  # direction of the branch vector (rad)
DT = 1e-6  # s
TOL = 1e-7

_HOOKE = {"kn": 2e5, "kt": 1.5e5, "gamma_n": 30.0, "gamma_t": 10.0, "mu": 50.0}
#: name -> parameters (at rest the dampings do not act; mu large: below the caps)
LAWS = {
    "hooke-liggghts": _HOOKE,
    "hooke-lammps": _HOOKE,
    "hertz-liggghts": {"youngs_modulus": 5e8, "poisson_ratio": 0.3, "restitution": 0.5, "friction": 50.0},
    "hertz-lammps": {"kn": 6e8, "kt": 7e8, "gamma_n": 1e5, "gamma_t": 5e4, "mu": 50.0},
    "hertz-granular-lammps": {"youngs_modulus": 5e8, "poisson_ratio": 0.25, "damp": 0.4, "friction": 50.0},
    "hooke-epsd2-liggghts": {**_HOOKE, "mu_r": 0.3},
    "hooke-epsd-liggghts": {**_HOOKE, "mu_r": 0.3, "eta_r": 0.2},
    "hooke-cdt-liggghts": {**_HOOKE, "mu_r": 0.3},
    "hooke-sds-lammps": {
        "kn": 2e5,
        "damp": 20.0,
        "kt": 1.5e5,
        "xgammat": 0.5,
        "mu": 50.0,
        "kroll": 1e5,
        "gammaroll": 0.0,
        "muroll": 50.0,
    },
}


def _geometry(delta):
    """(delx, dely, rsq, overlap as the laws compute it, n) of the pair at overlap ``delta``."""
    dist = RI + RJ - delta
    delx, dely = dist * math.cos(ANGLE), dist * math.sin(ANGLE)
    rsq = delx * delx + dely * dely
    r = math.sqrt(rsq)
    return delx, dely, rsq, (RI + RJ) - r, np.array([delx / r, dely / r])


def _force(law, hist, delta):
    """(F_n, F_t (2,), torque on i) of the pair at rest at overlap ``delta`` with history ``hist``
    (no increment: update False)."""
    delx, dely, rsq, _, n = _geometry(delta)
    h = np.array(hist, np.float64).reshape(1, -1).copy()
    fx, fy, ti, _tj, sl, fn = pair_force(
        law, h, 0, delx, dely, rsq, RI, RJ, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, MI, MJ, DT, False
    )
    assert not sl
    return fn, np.array([fx, fy]) - fn * n, ti


def _energy(law, hist, delta):
    _, _, _, ov, _ = _geometry(delta)
    return law_spec(law).energy(
        law, np.array([ov]), np.array(hist, np.float64).reshape(1, -1), np.array([RI]), np.array([RJ])
    )


def _hist(law, xi=(0.0, 0.0), rest=()):
    w = law_spec(law).width
    h = np.zeros(w)
    h[:2] = xi
    h[2 : 2 + len(rest)] = rest
    return h


@pytest.mark.parametrize("name", list(LAWS))
@pytest.mark.parametrize("delta", [2e-6, 1.5e-5])
def test_energy_derivative_in_the_overlap_is_the_elastic_normal_force(name, delta):
    law = make_law(name, **LAWS[name])
    assert law_spec(law).energy is not None, f"{name} registers no energy"
    h = delta * 1e-4
    hist = _hist(law)
    fd = (_energy(law, hist, delta + h) - _energy(law, hist, delta - h)) / (2 * h)
    fn, _, _ = _force(law, hist, delta)
    assert fn > 0
    assert fd == pytest.approx(fn, rel=TOL)


@pytest.mark.parametrize("name", list(LAWS))
def test_energy_gradient_in_the_spring_is_minus_the_spring_force(name):
    """dU/dxi = -F_t at fixed overlap (xi in the tangent plane, F_t = -k_t(delta) xi)."""
    law = make_law(name, **LAWS[name])
    delta = 8e-6
    n = _geometry(delta)[4]
    t = np.array([-n[1], n[0]])
    fn0, _, _ = _force(law, _hist(law), delta)
    # a spring of a tenth of the normal force (below the cap): |xi| ~ 0.1 F_n / k_t
    _, ft1, _ = _force(law, _hist(law, 1e-9 * t), delta)
    xi = (0.1 * fn0 / np.linalg.norm(ft1) * 1e-9) * t
    _, ft, _ = _force(law, _hist(law, xi), delta)
    grad = np.empty(2)
    for c in range(2):
        step = np.zeros(2)
        step[c] = 1e-4 * np.linalg.norm(xi)
        up = _energy(law, _hist(law, xi + step), delta)
        dn = _energy(law, _hist(law, xi - step), delta)
        grad[c] = (up - dn) / (2 * step[c])
    np.testing.assert_allclose(grad, -ft, rtol=0, atol=TOL * np.linalg.norm(ft))


def _reff():
    return RI * RJ / (RI + RJ)


@pytest.mark.parametrize("name", ["hooke-epsd2-liggghts", "hooke-epsd-liggghts"])
def test_epsd_rolling_energy_derivative_in_the_rotation_is_the_rolling_torque(name):
    """U_r(theta) with M(theta) from the model's own update (M += k_r w dt, w dt = theta):
    dU/dtheta = M, the torque the pair applies (-M on i, xi = 0 and at rest: no other torque)."""
    law = make_law(name, **LAWS[name])
    delta = 8e-6
    fn, _, _ = _force(law, _hist(law), delta)
    m0 = 0.2 * law.mu_r * _reff() * fn  # below the cap mu_r R* |F_n|
    _, _, ti = _force(law, _hist(law, rest=(m0,)), delta)
    theta = 1e-4 * m0 / (law.kt * _reff() ** 2)

    def stored(w):
        if name == "hooke-epsd2-liggghts":
            return rolling.epsd2_torque(w, _reff(), law.kt, fn, law.mu_r, DT, m0, True)[1]
        return rolling.epsd_torque(w, _reff(), law.kn, fn, law.mu_r, law.eta_r, MI, MJ, RI, RJ, DT, m0, True)[1]

    up = _energy(law, _hist(law, rest=(stored(theta / DT),)), delta)
    dn = _energy(law, _hist(law, rest=(stored(-theta / DT),)), delta)
    assert (up - dn) / (2 * theta) == pytest.approx(-ti, rel=TOL)
    assert -ti == pytest.approx(m0, rel=1e-14)


def test_sds_rolling_energy_derivative_in_the_rotation_is_minus_the_rolling_torque():
    """psi(theta) from pair_granular's own update (frame update, psi += R* w dt t): dU/dtheta =
    -tr, tr = R* (n x F_r)_z the rolling torque on i (hooke_sds_granular_lammps' last result)."""
    law = make_law("hooke-sds-lammps", **LAWS["hooke-sds-lammps"])
    delta = 8e-6
    delx, dely, rsq, _, n = _geometry(delta)
    t = np.array([-n[1], n[0]])
    fn, _, _ = _force(law, _hist(law), delta)
    psi = (0.2 * law.muroll * fn / law.kroll / law.muroll) * t
    tr = rolling.hooke_sds_granular_lammps(
        delx,
        dely,
        rsq,
        RI,
        RJ,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        MI,
        MJ,
        law.kn,
        law.damp,
        law.damping,
        law.kt,
        law.xgammat,
        law.mu,
        law.kroll,
        law.gammaroll,
        law.muroll,
        DT,
        0.0,
        0.0,
        psi[0],
        psi[1],
        False,
    )[-1]
    theta = 1e-4 * np.linalg.norm(psi) / _reff()

    def rolled(th):
        vr = _reff() * (th / DT)
        p0, p1, *_ = spring_dashpot_slider(
            psi[0], psi[1], n[0], n[1], -vr * n[1], vr * n[0], law.kroll, law.gammaroll, law.muroll * fn, DT, True
        )
        return _energy(law, _hist(law, rest=(p0, p1)), delta) - _energy(law, _hist(law), delta)

    assert (rolled(theta) - rolled(-theta)) / (2 * theta) == pytest.approx(-tr, rel=TOL)


def test_cdt_stores_no_rolling_energy():
    law = make_law("hooke-cdt-liggghts", **LAWS["hooke-cdt-liggghts"])
    delta = 8e-6
    ov = _geometry(delta)[3]
    assert _energy(law, _hist(law), delta) == pytest.approx(0.5 * law.kn * ov * ov, rel=1e-14)


def test_energy_hook_of_three_arguments_still_registers():
    """A law registered with the former hook energy(law, overlap, hist) is called without radii."""
    from collections import namedtuple

    from gransim.contacts.hooke import hooke_pair_liggghts
    from gransim.contacts.laws import elastic_energy, register_law

    Old = namedtuple("Old", ["kn", "kt", "gamma_n", "gamma_t", "mu"])
    register_law(Old, hooke_pair_liggghts, 2, energy=lambda law, ov, h: float(np.sum(ov)), cache=False)
    assert elastic_energy(Old(1, 1, 0, 0, 0), np.array([1.0, 2.0]), np.zeros((2, 2)), np.ones(2), np.ones(2)) == 3.0
    with pytest.raises(InputError, match="law: expected an instance of a registered contact law"):
        elastic_energy(object(), np.zeros(1), np.zeros((1, 2)), np.ones(1), np.ones(1))


def test_split_rolling_torque_sums_to_the_whole_torque():
    """hooke-sds-lammps returns its rolling torque apart (split_torque: the loops add it after the
    tangential torque, as LAMMPS); pair_force, jitted and interpreted, still gives the whole
    torques of hooke_sds_granular_lammps, and pair_force_split the parts (tr on i, -tr on j)."""
    from gransim._numba import njit
    from gransim.contacts.laws import pair_force_split

    law = make_law("hooke-sds-lammps", **LAWS["hooke-sds-lammps"])
    assert law_spec(law).split_torque
    delx, dely, rsq, _, _ = _geometry(8e-6)
    args = (delx, dely, rsq, RI, RJ, 0.1, -0.2, 0.05, 0.3, 40.0, -25.0, MI, MJ, DT, True)
    hist0 = np.array([[1e-8, -2e-8, 3e-8, 1e-8]])

    @njit(cache=False)
    def jitted(law, hist):
        return pair_force(law, hist, 0, delx, dely, rsq, RI, RJ, 0.1, -0.2, 0.05, 0.3, 40.0, -25.0, MI, MJ, DT, True)

    ref = rolling.hooke_sds_granular_lammps(
        delx,
        dely,
        rsq,
        RI,
        RJ,
        *args[5:13],
        law.kn,
        law.damp,
        law.damping,
        law.kt,
        law.xgammat,
        law.mu,
        law.kroll,
        law.gammaroll,
        law.muroll,
        DT,
        *hist0[0],
        True,
    )
    for fn in (jitted, lambda law, h: pair_force(law, h, 0, *args)):
        fx, fy, ti, tj, _, _ = fn(law, hist0.copy())
        assert (fx, fy, ti, tj) == (ref[0], ref[1], ref[2], ref[3])
    out = pair_force_split(law, hist0.copy(), 0, *args)
    assert len(out) == 8 and out[6] == ref[-1] and out[7] == -ref[-1] and out[6] != 0.0
    hooke = make_law("hooke-lammps", **_HOOKE)
    tail = pair_force_split(hooke, np.zeros((1, 2)), 0, *args)[6:]
    assert tail == (0.0, 0.0) and all(math.copysign(1.0, z) == -1.0 for z in tail)  # -0.0: folded away
