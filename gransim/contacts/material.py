"""Material constants -> effective pair properties of the Hertz-Mindlin law, in each code's arithmetic.

The codes take per-type material constants and build per type-pair effective properties once
(at set-up); the jitted laws of :mod:`gransim.contacts.hertz` take those effective numbers.
Everything here runs at the Python boundary: inputs are checked once (:class:`InputError`
naming the option and the expected range), results are plain floats in the same floating-point
order as the code (``math.pow`` and ``math.log`` are the C library's ``pow`` and ``log``, the
ones the Debian builds call).

Symbols (SI): E Young's modulus (Pa), nu Poisson's ratio, e coefficient of restitution,
R* = r_i r_j/(r_i + r_j) effective radius (m), m* = m_i m_j/(m_i + m_j) effective mass (kg).

* Effective Young's modulus (Johnson, *Contact Mechanics*, 1985, eq (4.22)):
  1/Y* = (1 - nu_i^2)/E_i + (1 - nu_j^2)/E_j.
  LIGGGHTS 3.8.0 global_properties.cpp:432 ``1./((1.-pow(vi,2.))/Yi+(1.-pow(vj,2.))/Yj)``;
  LAMMPS 29Sep2021 GRANULAR/pair_granular.cpp:1780-1784 (``mix_stiffnessE``, nu*nu).
* Effective shear modulus (Mindlin 1949; Di Renzo & Di Maio, *Chem. Eng. Sci.* 59, 2004, eq (14)):
  1/G* = 2 (2 - nu_i)(1 + nu_i)/E_i + 2 (2 - nu_j)(1 + nu_j)/E_j  (= (2 - nu_i)/G_i + ...).
  LIGGGHTS global_properties.cpp:463; LAMMPS pair_granular.cpp:1790-1794 (``mix_stiffnessG``).
* LIGGGHTS damping constant from the restitution (global_properties.cpp:516, 539):
  beta = ln e / sqrt(ln^2 e + pi^2)  (< 0; 0 for e = 1), the linear spring-dashpot relation
  (e = exp(-pi zeta/sqrt(1 - zeta^2)) solved for zeta = -beta) carried over to Hertz with the
  factor 2 sqrt(5/6) of normal_model_hertz.h:236-238 (Tsuji, Tanaka & Ishida, *Powder Technol.*
  71, 1992, form of the damping). Measured (tests/contacts/test_hertz.py): the restitution
  of the resulting Hertz impact equals e to 1e-11 over e in [0.3, 0.95] (docs/laws.md).
  Accepted range 0.05 < e <= 1 (global_properties.cpp:488-489).
* LAMMPS ``damping tsuji`` takes e and maps it to alpha(e) with the polynomial of
  pair_granular.cpp:987-991 (a fit of Tsuji et al. 1992's alpha(e) curve); the restitution it
  gives is not e (0.44 for e = 0.3, 0.965 for e = 0.95: docs/laws.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..errors import InputError

#: LIGGGHTS' SI sanity limits on youngsModulus (global_properties.cpp:363-371): below needs
#: ``soft_particles yes``, above ``hard_particles yes`` in the deck
LIGGGHTS_YOUNGS_SI = (5e6, 1e9)


def _finite(value, name: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name}: expected a number, got {value!r}") from None
    if not math.isfinite(v):
        raise InputError(f"{name}: expected a finite number, got {value!r}")
    return v


def check_youngs(E, name: str = "youngs_modulus") -> float:
    """E > 0 (Pa)."""
    v = _finite(E, name)
    if v <= 0.0:
        raise InputError(f"{name}: expected a Young's modulus > 0 Pa, got {E!r}")
    return v


def check_poisson(nu, name: str = "poisson_ratio") -> float:
    """0 <= nu <= 0.5 (the range both codes accept: LIGGGHTS global_properties.cpp:399-400)."""
    v = _finite(nu, name)
    if not 0.0 <= v <= 0.5:
        raise InputError(f"{name}: expected a Poisson's ratio in [0, 0.5], got {nu!r}")
    return v


def check_restitution(e, name: str = "restitution") -> float:
    """0.05 < e <= 1 (LIGGGHTS global_properties.cpp:488-489)."""
    v = _finite(e, name)
    if not 0.05 < v <= 1.0:
        raise InputError(f"{name}: expected a coefficient of restitution in (0.05, 1], got {e!r}")
    return v


def check_friction(mu, name: str = "friction") -> float:
    """mu >= 0 (Coulomb coefficient)."""
    v = _finite(mu, name)
    if v < 0.0:
        raise InputError(f"{name}: expected a friction coefficient >= 0, got {mu!r}")
    return v


def effective_youngs(E_i, nu_i, E_j, nu_j) -> float:
    """Y* (Pa) = 1/((1 - nu_i^2)/E_i + (1 - nu_j^2)/E_j), LIGGGHTS' arithmetic
    (global_properties.cpp:432; ``pow(nu, 2.)``). LAMMPS' ``mix_stiffnessE`` writes nu*nu, the
    same double (pow(x, 2) is correctly rounded in glibc)."""
    E_i, E_j = check_youngs(E_i, "E_i"), check_youngs(E_j, "E_j")
    nu_i, nu_j = check_poisson(nu_i, "nu_i"), check_poisson(nu_j, "nu_j")
    return 1.0 / ((1.0 - math.pow(nu_i, 2.0)) / E_i + (1.0 - math.pow(nu_j, 2.0)) / E_j)


def effective_shear(E_i, nu_i, E_j, nu_j) -> float:
    """G* (Pa) = 1/(2(2 - nu_i)(1 + nu_i)/E_i + 2(2 - nu_j)(1 + nu_j)/E_j)
    (LIGGGHTS global_properties.cpp:463, LAMMPS pair_granular.cpp:1790-1794: same order)."""
    E_i, E_j = check_youngs(E_i, "E_i"), check_youngs(E_j, "E_j")
    nu_i, nu_j = check_poisson(nu_i, "nu_i"), check_poisson(nu_j, "nu_j")
    return 1.0 / (2.0 * (2.0 - nu_i) * (1.0 + nu_i) / E_i + 2.0 * (2.0 - nu_j) * (1.0 + nu_j) / E_j)


def beta_liggghts(e) -> float:
    """LIGGGHTS' ``betaeff`` = ln e / sqrt((ln e)^2 + pi^2) (global_properties.cpp:516, 539)."""
    e = check_restitution(e, "coefficientRestitution")
    le = math.log(e)
    return le / math.sqrt(math.pow(le, 2.0) + math.pow(math.pi, 2.0))


def tsuji_alpha_lammps(e) -> float:
    """LAMMPS ``damping tsuji``: alpha(e) = 1.2728 - 4.2783 e + 11.087 e^2 - 22.348 e^3
    + 27.467 e^4 - 18.022 e^5 + 4.8218 e^6 (pair_granular.cpp:987-991; ``square``, ``cube``,
    ``powint`` are repeated products: written the same way here)."""
    e = _finite(e, "damping tsuji coefficient of restitution")
    if not 0.0 <= e <= 1.0:
        raise InputError(f"damping tsuji: expected a coefficient of restitution in [0, 1], got {e!r}")
    e2 = e * e
    e3 = e2 * e
    return (
        1.2728
        - 4.2783 * e
        + 11.087 * e2
        - 22.348 * e3
        + 27.467 * _powint(e, 4)
        - 18.022 * _powint(e, 5)
        + 4.8218 * _powint(e, 6)
    )


def _powint(x: float, n: int) -> float:
    """LAMMPS ``MathSpecial::powint`` (math_special.h: square-and-multiply)."""
    yy = 1.0
    ww = x
    while n:
        if n & 1:
            yy *= ww
        n >>= 1
        ww *= ww
    return yy


@dataclass(frozen=True)
class HertzLiggghts:
    """LIGGGHTS 3.8.0 ``pair_style gran model hertz tangential history`` for one type pair.

    Deck: ``fix property/global youngsModulus peratomtype E``, ``poissonsRatio peratomtype nu``,
    ``coefficientRestitution peratomtypepair 1 e``, ``coefficientFriction peratomtypepair 1 mu``.
    :meth:`coefficients` gives the four law parameters of
    :func:`gransim.contacts.hertz.hertz_history_liggghts`.
    """

    youngs_modulus: float
    poisson_ratio: float
    restitution: float
    friction: float
    tangential_damping: bool = True

    def __post_init__(self):
        object.__setattr__(self, "youngs_modulus", check_youngs(self.youngs_modulus, "youngsModulus"))
        object.__setattr__(self, "poisson_ratio", check_poisson(self.poisson_ratio, "poissonsRatio"))
        e = check_restitution(self.restitution, "coefficientRestitution")
        object.__setattr__(self, "restitution", e)
        object.__setattr__(self, "friction", check_friction(self.friction, "coefficientFriction"))
        object.__setattr__(self, "tangential_damping", bool(self.tangential_damping))

    def coefficients(self) -> tuple[float, float, float, float, float]:
        """(Y*, G*, beta, tangential damping flag 1.0/0.0, mu) for one material on both sides."""
        E, nu = self.youngs_modulus, self.poisson_ratio
        return (
            effective_youngs(E, nu, E, nu),
            effective_shear(E, nu, E, nu),
            beta_liggghts(self.restitution),
            1.0 if self.tangential_damping else 0.0,
            self.friction,
        )


@dataclass(frozen=True)
class HertzMaterialLammps:
    """LAMMPS 29Sep2021 ``pair_style granular`` + ``pair_coeff * * hertz/material E DAMP NU
    damping MODEL tangential mindlin NULL GAMMAT_RATIO MU`` for one type pair.

    ``damping``: "tsuji" (DAMP is then a coefficient of restitution mapped by
    :func:`tsuji_alpha_lammps`), "viscoelastic" (the default of the build), "velocity" or
    "mass_velocity" (pair_granular.cpp:363-371, 849-866). :meth:`coefficients` gives the law
    parameters of :func:`gransim.contacts.hertz.hertz_mindlin_granular_lammps`.
    """

    youngs_modulus: float
    poisson_ratio: float
    damp: float
    friction: float
    gammat_ratio: float = 1.0
    damping: str = "tsuji"

    DAMPING_MODELS = ("velocity", "mass_velocity", "viscoelastic", "tsuji")

    def __post_init__(self):
        E = check_youngs(self.youngs_modulus, "hertz/material E")
        object.__setattr__(self, "youngs_modulus", E)
        object.__setattr__(self, "poisson_ratio", check_poisson(self.poisson_ratio, "hertz/material POISSON"))
        object.__setattr__(self, "friction", check_friction(self.friction, "tangential mindlin MU"))
        g = _finite(self.gammat_ratio, "tangential mindlin GAMMAT")
        if g < 0.0:
            raise InputError(f"tangential mindlin GAMMAT: expected a damping ratio >= 0, got {self.gammat_ratio!r}")
        object.__setattr__(self, "gammat_ratio", g)
        if self.damping not in self.DAMPING_MODELS:
            raise InputError(f"damping: expected one of {', '.join(self.DAMPING_MODELS)}, got {self.damping!r}")
        d = _finite(self.damp, "hertz/material DAMP")
        if self.damping == "tsuji" and not 0.0 <= d <= 1.0:
            raise InputError(
                f"hertz/material DAMP with damping tsuji: expected a coefficient of "
                f"restitution in [0, 1], got {self.damp!r}"
            )
        if d < 0.0:
            raise InputError(f"hertz/material DAMP: expected a damping coefficient >= 0, got {self.damp!r}")
        object.__setattr__(self, "damp", d)

    def coefficients(self) -> tuple[float, float, float, float, float, int]:
        """(E = 4/3 Y*, damping coefficient, kt0 = 8 G*, GAMMAT ratio, mu, damping model index)
        as pair_granular.cpp:986-1030 stores them (``FOURTHIRDS*mix_stiffnessE``: 4.0/3.0*Y*)."""
        E, nu = self.youngs_modulus, self.poisson_ratio
        damp = tsuji_alpha_lammps(self.damp) if self.damping == "tsuji" else self.damp
        return (
            4.0 / 3.0 * effective_youngs(E, nu, E, nu),
            damp,
            8 * effective_shear(E, nu, E, nu),
            self.gammat_ratio,
            self.friction,
            self.DAMPING_MODELS.index(self.damping),
        )
