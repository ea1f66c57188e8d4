"""YADE's Cundall-Strack law as a registered contact law (gransim.contacts.yade_cundall_strack).

What is checked, and why it can fail:

* the registry knows the law by name, in YADE's code, apart from the pair laws of LIGGGHTS and
  LAMMPS (whose lists the decks and the biaxial laws' validation iterate); ``make_law`` checks its
  parameters, naming the law and the parameter;
* ``DEMSettings.hooke_law("yade")`` is the law the decks make (kn, ks = kt, friction angle
  atan(mu), no ratcheting correction): an engine given that law equals one given none, bit for bit
  over 300 steps of the biaxial short case (whose contacts change), and another law given to the
  yade arithmetic, or YADE's law to another arithmetic, is an InputError naming the law;
* the law's time scale: pi sqrt(m* / max(kn, ks)) with the constant stiffnesses (the Hooke law's,
  to the bit), pi sqrt(m* / (2 E r_1 r_2 / (r_1 + r_2))) with the radius-dependent ones of the two
  lightest disks, by hand.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from gransim.contacts.laws import CODES, law_code, law_names, law_spec, make_law, time_scale
from gransim.contacts.yade_cundall_strack import LAW_NAME, YadeCundallStrack, yade_law
from gransim.dem.engine import Engine
from gransim.dem.settings import DEMSettings
from gransim.errors import InputError
from gransim.geometry import Packing


def _case():
    from reference_runs.decks.shear import wrapped_packing
    from reference_runs.yade.dem import short_biaxial

    p, s, ld, _ = short_biaxial()
    return wrapped_packing(p), s, ld


def test_the_yade_law_is_registered_by_name_in_yades_code():
    assert LAW_NAME == "cundall-strack-yade"
    assert LAW_NAME in law_names(CODES) and LAW_NAME not in law_names()  # not a pair law of the decks
    assert law_code(LAW_NAME) == "yade"
    law = make_law(LAW_NAME, friction_angle=0.5, kn=1e5, ks=5e4)
    assert isinstance(law, YadeCundallStrack)
    assert law == YadeCundallStrack(1e5, 5e4, 0.5, 0.0, 0.0, True)
    spec = law_spec(law)
    assert spec.code == "yade" and spec.pair is None and spec.width == 0
    rve = make_law(LAW_NAME, friction_angle=0.5, young=6e8, poisson=0.8)
    assert (rve.kn, rve.ks, rve.young, rve.poisson) == (0.0, 0.0, 6e8, 0.8)


@pytest.mark.parametrize(
    "params, word",
    [
        ({"kn": 1e5}, "friction_angle"),  # required
        ({"friction_angle": 0.5}, "kn > 0"),  # no stiffness at all
        ({"friction_angle": 0.5, "kn": 1e5, "young": 6e8}, "either kn, ks"),  # both rules
        ({"friction_angle": 0.5, "kn": -1.0}, "kn"),
        ({"friction_angle": 2.0, "kn": 1e5}, "friction_angle"),  # >= pi/2
        ({"friction_angle": 0.5, "young": 6e8, "avoid_granular_ratcheting": 1}, "avoid_granular_ratcheting"),
        ({"friction_angle": 0.5, "kn": 1e5, "mu": 0.5}, "unknown mu"),
    ],
)
def test_bad_parameters_name_the_law_and_the_parameter(params, word):
    with pytest.raises(InputError, match=LAW_NAME) as exc:
        make_law(LAW_NAME, **params)
    assert word in str(exc.value)


def test_the_settings_yade_law_is_the_decks_law():
    s = DEMSettings(dt=1e-5, kn=2e5, kt=1.5e5, mu=0.5)
    law = s.hooke_law("yade")
    assert law == yade_law(math.atan(0.5), kn=2e5, ks=1.5e5, avoid_granular_ratcheting=False)
    # the contacts' tan(phi): YADE's tan(atan(mu)), not always mu to the bit (0.49999999999999994)
    assert math.tan(law.friction_angle) == math.tan(math.atan(0.5)) != 0.5


def test_an_explicit_yade_law_equals_the_default_bit_for_bit():
    p, s, ld = _case()
    runs = []
    for law in (None, s.hooke_law("yade")):
        eng = Engine(p, s, flavour="yade", law=law)
        eng.start_run(ld, 300)
        out = eng.advance(300)
        runs.append((out, eng.x.copy(), eng.contacts()))
    (a, xa, ca), (b, xb, cb) = runs
    for k in ("stress", "n_contacts", "kinetic_energy", "lengths"):
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)
    np.testing.assert_array_equal(xa, xb)
    np.testing.assert_array_equal(ca["force"], cb["force"])
    assert len(set(a["n_contacts"].tolist())) > 1  # contacts made and lost: the run has evidence


def test_a_law_of_another_arithmetic_is_refused_naming_the_law():
    p, s, _ = _case()
    with pytest.raises(InputError, match=r"law: .*HookeLiggghts"):
        Engine(p, s, flavour="yade", law=s.hooke_law("liggghts"))
    with pytest.raises(InputError, match=r"law: .*YadeCundallStrack.*flavour='yade'"):
        Engine(p, s, flavour="lammps", law=s.hooke_law("yade"))


def test_the_time_scale_is_the_contact_time_of_the_lightest_pair():
    p, s, _ = _case()
    undamped = DEMSettings(dt=s.dt, kn=s.kn, kt=s.kt, mu=s.mu)
    assert time_scale(s.hooke_law("yade"), p) == time_scale(undamped.hooke_law("lammps"), p)
    # radius-dependent stiffness: two small disks (0.5 and 0.6 mm) and a big one, density 2 kg/m^2
    q = Packing(np.array([[0.0, 0.0], [0.01, 0.0], [0.0, 0.01]]), np.array([6e-4, 5e-4, 2e-3]), np.eye(2) * 0.05, 2.0)
    law = yade_law(0.5, young=1e8, poisson=0.5)
    m1, m2 = 2.0 * math.pi * 5e-4**2, 2.0 * math.pi * 6e-4**2
    kn = 2 * 1e8 * 5e-4 * 6e-4 / (5e-4 + 6e-4)
    tc, zeta = time_scale(law, q)
    assert zeta == 0.0
    assert tc == pytest.approx(math.pi * math.sqrt(m1 * m2 / (m1 + m2) / kn), rel=1e-14)
    assert time_scale(yade_law(0.5, young=1e8, poisson=2.0), q)[0] == pytest.approx(tc / math.sqrt(2.0), rel=1e-14)
