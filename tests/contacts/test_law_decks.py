"""A law is one module: what it declares agrees with itself.

* Deck lines: every law usable by name writes deck lines (gransim.contacts.laws.deck_lines) that,
  read back by an independent reader written from the codes' documented syntax (LIGGGHTS 3.8.0
  ``fix property/global`` + ``pair_style gran model``; LAMMPS 29 Sep 2021 ``pair_style
  gran/*/history`` and ``pair_style granular`` + ``pair_coeff``), rebuild the same native law
  object bit for bit: the deck gives the code exactly the parameters the native law runs with.
  That the code then computes what the native law computes is the stored-run tests'
  (tests/dem/test_law_runs.py, tests/contacts/test_hertz.py, test_rolling.py).
* Time scale: the contact time and damping ratio a law declares for the time-step check follow
  from its own pair function (the tangent stiffness by finite differences of the force it
  computes), and the engine refuses a time step above the limit of the law it runs.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from gransim.contacts import hertz
from gransim.contacts.laws import deck_lines, law_code, law_names, law_spec, make_law, time_scale
from gransim.dem import DEMEngine, Loading
from gransim.dem.settings import Integration
from gransim.errors import InputError
from gransim.geometry import Packing

#: parameters of every named law (SI), values that print with many digits
PARAMS = {
    "hooke-liggghts": {"kn": 1.2345678e5, "kt": 9.87654321e4, "gamma_n": 51.3, "gamma_t": 17.1, "mu": 0.4321},
    "hooke-lammps": {"kn": 1.2345678e5, "kt": 9.87654321e4, "gamma_n": 51.3, "gamma_t": 17.1, "mu": 0.4321},
    "hertz-liggghts": {"youngs_modulus": 6.1e8, "poisson_ratio": 0.31, "restitution": 0.73, "friction": 0.45},
    "hertz-lammps": {"kn": 3.3e8, "kt": 2.9e8, "gamma_n": 3.5e5, "gamma_t": 1.7e5, "mu": 0.35},
    "hertz-granular-lammps": {
        "youngs_modulus": 6.1e8,
        "poisson_ratio": 0.29,
        "damp": 0.81,
        "friction": 0.52,
        "gammat_ratio": 0.7071,
    },
    "hooke-epsd2-liggghts": {"kn": 1e5, "kt": 8.1e4, "gamma_n": 50.5, "gamma_t": 25.25, "mu": 0.5, "mu_r": 0.13},
    "hooke-epsd-liggghts": {
        "kn": 1e5,
        "kt": 8.1e4,
        "gamma_n": 50.5,
        "gamma_t": 25.25,
        "mu": 0.5,
        "mu_r": 0.13,
        "eta_r": 0.31,
    },
    "hooke-cdt-liggghts": {"kn": 1e5, "kt": 8.1e4, "gamma_n": 50.5, "gamma_t": 25.25, "mu": 0.5, "mu_r": 0.13},
    "hooke-sds-lammps": {
        "kn": 1e5,
        "damp": 47.0,
        "kt": 8.3e4,
        "xgammat": 0.61,
        "mu": 0.45,
        "kroll": 7.7e4,
        "gammaroll": 0.19,
        "muroll": 0.11,
        "damping": "velocity",
    },
}

#: LIGGGHTS property name -> make_law parameter, per pair-style model (LIGGGHTS 3.8.0 manual:
#: pair_gran, gran_model_hooke_stiffness, gran_model_hertz, gran_rolling_friction_*)
LIGGGHTS_PROPERTIES = {
    "hooke/stiffness": {
        "kn": "kn",
        "kt": "kt",
        "gamman": "gamma_n",
        "gammat": "gamma_t",
        "coefficientFriction": "mu",
        "coefficientRollingFriction": "mu_r",
        "coefficientRollingViscousDamping": "eta_r",
    },
    "hertz": {
        "youngsModulus": "youngs_modulus",
        "poissonsRatio": "poisson_ratio",
        "coefficientRestitution": "restitution",
        "coefficientFriction": "friction",
    },
}


def read_liggghts(lines):
    """(law name, parameters) of LIGGGHTS deck lines."""
    props = {}
    style = None
    for ln in lines:
        w = ln.split()
        if w[:3] == ["fix", w[1], "all"] and w[3] == "property/global":
            props[w[4]] = float(w[-1])
        elif w[0] == "pair_style":
            style = w
    assert style[:3] == ["pair_style", "gran", "model"] and style[4:6] == ["tangential", "history"], style
    model = style[3]
    params = {LIGGGHTS_PROPERTIES[model][k]: v for k, v in props.items()}
    rest = style[6:]
    if model == "hertz":
        if rest == ["tangential_damping", "off"]:
            params["tangential_damping"] = False
        else:
            assert rest == []
        return "hertz-liggghts", params
    if rest:
        assert rest[0] == "rolling_friction" and len(rest) == 2
        return f"hooke-{rest[1]}-liggghts", params
    return "hooke-liggghts", params


def read_lammps(lines):
    """(law name, parameters) of LAMMPS deck lines."""
    style = next(ln.split() for ln in lines if ln.startswith("pair_style"))
    coeff = next(ln.split() for ln in lines if ln.startswith("pair_coeff"))
    if style[1] in ("gran/hooke/history", "gran/hertz/history"):
        assert style[7] == "1" and coeff == ["pair_coeff", "*", "*"]
        vals = dict(zip(("kn", "kt", "gamma_n", "gamma_t", "mu"), map(float, style[2:7]), strict=True))
        return ("hooke-lammps" if style[1] == "gran/hooke/history" else "hertz-lammps"), vals
    assert style == ["pair_style", "granular"] and coeff[:3] == ["pair_coeff", "*", "*"]
    w = coeff[3:]
    if w[0] == "hertz/material":
        assert w[4] == "damping" and w[6:9] == ["tangential", "mindlin", "NULL"] and len(w) == 11
        return "hertz-granular-lammps", {
            "youngs_modulus": float(w[1]),
            "damp": float(w[2]),
            "poisson_ratio": float(w[3]),
            "damping": w[5],
            "gammat_ratio": float(w[9]),
            "friction": float(w[10]),
        }
    assert w[0] == "hooke" and w[3] == "damping" and w[5:7] == ["tangential", "linear_history"]
    assert w[10:12] == ["rolling", "sds"] and len(w) == 15
    return "hooke-sds-lammps", {
        "kn": float(w[1]),
        "damp": float(w[2]),
        "damping": w[4],
        "kt": float(w[7]),
        "xgammat": float(w[8]),
        "mu": float(w[9]),
        "kroll": float(w[12]),
        "gammaroll": float(w[13]),
        "muroll": float(w[14]),
    }


def _bits(law):
    return np.array(law, np.float64).view(np.uint64)


@pytest.mark.parametrize("name", law_names())
def test_deck_lines_rebuild_the_native_law(name):
    assert set(PARAMS) == set(law_names()), "a law without parameters here is not checked"
    law = make_law(name, **PARAMS[name])
    code = law_code(name)
    lines = deck_lines(law, code)
    got_name, params = (read_liggghts if code == "liggghts" else read_lammps)(lines)
    assert got_name == name
    again = make_law(got_name, **params)
    assert type(again) is type(law) and np.array_equal(_bits(again), _bits(law)), (law, again)
    other = "lammps" if code == "liggghts" else "liggghts"
    with pytest.raises(InputError, match=f"is a {code} law, the deck is for {other}"):
        deck_lines(law, other)


def test_a_deck_wrong_in_one_digit_is_caught():
    # the reader is not blind: one parameter changed in the last printed digit gives another law
    law = make_law("hooke-lammps", **PARAMS["hooke-lammps"])
    lines = deck_lines(law, "lammps")
    lines[0] = lines[0].replace("0.43209999999999998", "0.43210000000000004")
    _, params = read_lammps(lines)
    assert not np.array_equal(_bits(make_law("hooke-lammps", **params)), _bits(law))


def test_hertz_without_material_constants_has_no_deck():
    law = make_law("hertz-liggghts", **PARAMS["hertz-liggghts"])
    bare = type(law)(*law[:5])  # the coefficients alone
    with pytest.raises(InputError, match="needs its material constants"):
        deck_lines(bare, "liggghts")


def _pair_packing():
    r = np.array([1.0e-3, 0.8e-3, 1.2e-3])
    return Packing(
        positions=np.array([[0.01, 0.01], [0.02, 0.01], [0.01, 0.02]]),
        radii=r,
        cell=np.diag([0.03, 0.03]),
        density=25.0,
    )


@pytest.mark.parametrize("name", ["hertz-liggghts", "hertz-lammps", "hertz-granular-lammps"])
def test_hertz_time_scale_is_the_tangent_stiffness_of_its_own_force(name):
    """k_n = dF_n/d delta of the law's pair function (central difference, no velocity, no history),
    at the overlap given, of the two lightest disks: contact time pi sqrt(m*/max(k_n, k_t))."""
    law = make_law(name, **PARAMS[name])
    spec = law_spec(law)
    p = _pair_packing()
    r = np.sort(p.radii)[:2]
    m = np.pi * r * r * p.density
    meff = m[0] * m[1] / (m[0] + m[1])
    delta = 3.0e-6

    def fn(d):
        dist = r[0] + r[1] - d
        hist = np.zeros((1, 2))
        pair = getattr(spec.pair, "py_func", spec.pair)
        out = pair(
            law, hist, 0, dist, 0.0, dist * dist, r[0], r[1], 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, m[0], m[1], 1e-7, False
        )
        return out[0]  # force on i along +x = F_n

    h = 1e-3 * delta
    kn = (fn(delta + h) - fn(delta - h)) / (2 * h)
    reff = r[0] * r[1] / (r[0] + r[1])
    kt = hertz.hertz_coefficients(law)[1] * math.sqrt(reff * delta)
    tc, zeta = time_scale(law, p, delta)
    assert tc == pytest.approx(math.pi * math.sqrt(meff / max(kn, kt)), rel=1e-6)
    assert 0.0 < zeta < 1.0
    assert time_scale(law, p, 0.0) == (math.inf, 0.0)  # no contact: no stiffness to bound dt


def test_hooke_time_scale():
    law = make_law("hooke-liggghts", **PARAMS["hooke-liggghts"])
    p = _pair_packing()
    r = np.sort(p.radii)[:2]
    m = np.pi * r * r * p.density
    meff = m[0] * m[1] / (m[0] + m[1])
    tc, zeta = time_scale(law, p)
    assert tc == pytest.approx(math.pi * math.sqrt(meff / law.kn), rel=1e-14)
    assert zeta == pytest.approx(law.gamma_n / (2 * math.sqrt(law.kn / meff)), rel=1e-14)


def test_engine_checks_the_time_step_of_its_law():
    """A compressed Hertz pair: the engine's check asks the law at the overlap present (no kn of
    a settings object involved) and refuses a time step above it; the same run below passes."""
    p = Packing(
        positions=np.array([[0.010, 0.010], [0.010 + 1.8e-3 - 2e-5, 0.010]]),
        radii=np.array([1.0e-3, 0.8e-3]),
        cell=np.diag([0.03, 0.03]),
        density=25.0,
    )
    law = make_law("hertz-liggghts", **PARAMS["hertz-liggghts"])
    tc, zeta = time_scale(law, p, 2e-5)
    lim = tc / 5.0 * (math.sqrt(1 + zeta * zeta) - zeta)
    with pytest.raises(InputError, match="stability limit.*largest overlap"):
        DEMEngine(p, Integration(dt=1.01 * lim, skin=1e-4), law=law)
    eng = DEMEngine(p, Integration(dt=0.99 * lim, skin=1e-4), law=law)
    eng.advance(Loading(), 3)
    with pytest.raises(InputError, match="needs its contact law"):
        DEMEngine(p, Integration(dt=1e-7, skin=1e-4))
