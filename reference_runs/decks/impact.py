"""LIGGGHTS 3.8.0 / LAMMPS 29Sep2021 deck of a scene of binary disk impacts (validation case ``impacts``).

A *scene* is a set of independent two-disk impacts laid side by side in one orthogonal periodic
box, far enough apart that no disk of one impact ever comes within the neighbour cut-off of a
disk of another, and each pair only a few steps from touching, so that every pair meets exactly
once during the run (the box is many contact-durations of travel wide). All impacts of a scene
share one contact law with one set of parameters (the law is a parameter of the deck:
:class:`HookeLaw` for both codes, and the Hertz-Mindlin laws of one code each:
:class:`HertzLiggghtsLaw`, :class:`HertzHistoryLammpsLaw`, :class:`HertzGranularLammpsLaw`).

Every law class has ``engines`` (the codes that have it), ``mu``, ``dem_settings(dt, skin,
flavour)`` (the native engine's settings: the integration; the Hooke law's with it),
``native_law(flavour)`` (the plug-in law object of
:mod:`gransim.contacts.laws`, or None: the Hooke law of the settings), ``deck_lines(engine)``
and ``describe()``. The Hertz classes add ``hertz()``: the constants of the closed forms
(``y43`` = 4/3 Y* in Pa, ``kt0`` = 8 G* in Pa, the damping form and its dimensionless
coefficient; validation/cases/impacts.py).

The deck mirrors :class:`gransim.dem.DEMEngine` step for step (as
:mod:`reference_runs.decks.biaxial`: ``newton off``, no atom sorting, ``neigh_modify delay 0
every 1 check yes``, ``fix nve/sphere`` with 2D inertia m r^2/2, ``fix enforce2d``, no box
deformation). Output: ``dump.atoms`` (``dump custom`` every ``dump_every`` steps, %.17g: id x y
vx vy omegaz fx fy tqz) and a thermo line (step, atoms) every ``thermo_every`` steps.

LAMMPS form (``engine="lammps"``, docs/lammps.md): ``set group all density/disc RHO`` after
``read_data`` (m = pi r^2 rho), ``fix nve/sphere disc``, ``comm_modify mode single vel yes``,
``dump_modify ... format line``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gransim.contacts.laws import deck_lines, law_code, make_law
from gransim.contacts.material import (
    HertzLiggghts,
    HertzMaterialLammps,
    check_friction,
    effective_shear,
    effective_youngs,
)
from gransim.dem.settings import DEMSettings, Integration
from gransim.errors import InputError
from gransim.geometry import Packing
from gransim.io import atomic_path
from reference_runs.datafile import write_data_file
from reference_runs.parsers import parse_dump_custom

ENGINES = ("liggghts", "lammps")
#: deck file name written by :func:`write_impact_deck` (run_job copies it to its own deck name)
DECK_NAMES = {"liggghts": "in.liggghts", "lammps": "in.lammps"}
DATA_NAME = "data.impact"
DUMP_NAME = "dump.atoms"
DUMP_COLUMNS = ("id", "x", "y", "vx", "vy", "omegaz", "fx", "fy", "tqz")


def _g(v: float) -> str:
    return f"{float(v):.17g}"


@dataclass(frozen=True)
class HookeLaw:
    """Linear spring-dashpot law with tangential history (today's native law, docs/dem.md).

    F_n = kn delta - m_eff gamma_n v_n; spring xi += v_t,rel dt, F_t = -kt xi - m_eff gamma_t
    v_t,rel, Coulomb cap mu |F_n| (each code's own cap: docs/lammps.md, items A-B).

    Attributes
    ----------
    kn, kt : normal, tangential stiffness (N/m; 2D: per unit thickness reads the same).
    gamma_n, gamma_t : mass-scaled damping rates (1/s): damping coefficient m_eff gamma.
    mu : Coulomb friction coefficient (-).

    LIGGGHTS: ``pair_style gran model hooke/stiffness tangential history`` with ``fix
    property/global`` kn, kt, gamman, gammat, coefficientFriction. LAMMPS: ``pair_style
    gran/hooke/history KN KT GAMMAN GAMMAT MU 1`` (the trailing 1: tangential damping on; no
    ``limit_damping``, so a damped normal force may turn attractive before the pair opens, as in
    LIGGGHTS, whose ``limitForce`` is off).
    """

    kn: float
    kt: float
    gamma_n: float = 0.0
    gamma_t: float = 0.0
    mu: float = 0.5
    name: str = "hooke"
    engines = ENGINES

    def __post_init__(self):
        for k in ("kn", "kt", "gamma_n", "gamma_t", "mu"):
            v = getattr(self, k)
            if not (isinstance(v, int | float | np.floating) and np.isfinite(v) and v >= 0):
                raise InputError(f"HookeLaw.{k}: expected a finite number >= 0, got {v!r}")
        if self.kn <= 0:
            raise InputError(f"HookeLaw.kn: expected > 0 N/m, got {self.kn!r}")

    def dem_settings(self, dt: float, skin: float, flavour: str = "liggghts") -> DEMSettings:
        """The native engine's settings of this law (serial mode, the mode compared step for step)."""
        return DEMSettings(
            kn=self.kn,
            kt=self.kt,
            gamma_n=self.gamma_n,
            gamma_t=self.gamma_t,
            mu=self.mu,
            dt=dt,
            skin=skin,
            mode="serial",
            flavour=flavour,
        )

    def native_law(self, flavour: str = "liggghts"):
        """None: the engine builds the Hooke law of :meth:`dem_settings` in ``flavour``."""
        return

    def deck_lines(self, engine: str) -> list[str]:
        """The pair-style lines of the deck for ``engine`` ("liggghts" or "lammps"): those of the
        Hooke law of that code (:func:`gransim.contacts.laws.deck_lines`)."""
        return deck_lines(self.dem_settings(1.0, 1.0).hooke_law(engine), engine)

    def describe(self) -> str:
        return (
            f"Hooke + tangential history: kn {self.kn:g} N/m, kt {self.kt:g} N/m, gamma_n {self.gamma_n:.6g} 1/s, "
            f"gamma_t {self.gamma_t:.6g} 1/s, mu {self.mu:g}"
        )


def _one_code(law, engine: str) -> None:
    if engine not in law.engines:
        raise InputError(
            f"law {law.name}: only {', '.join(law.engines)} has it, not {engine!r} (a deck for "
            f"{engine} needs another law)"
        )


def _hertz_settings(dt: float, skin: float, flavour: str) -> Integration:
    """The integration of a Hertz law's run (dt, skin, serial, ``flavour``): the time-step check
    asks the law itself (:func:`gransim.dem.engine.check_time_step`)."""
    return Integration(dt=dt, skin=skin, mode="serial", flavour=flavour)


@dataclass(frozen=True)
class HertzLiggghtsLaw:
    """LIGGGHTS 3.8.0 ``pair_style gran model hertz tangential history`` (docs/laws.md).

    F_n = 4/3 Y* sqrt(R*) delta^(3/2) + damping -2 sqrt(5/6) beta sqrt(2 Y* a m*) v_n with
    beta = ln e/sqrt(ln^2 e + pi^2); Mindlin k_t = 8 G* a, tangential damping with 8 G* a in place
    of 2 Y* a (below the cap), cap mu |F_n| (normal_model_hertz.h:211-255,
    tangential_model_history.h:147-227; :func:`gransim.contacts.hertz.hertz_history_liggghts`).

    Attributes: youngs_modulus E (Pa, 5e6 <= E <= 1e9: LIGGGHTS' SI limits without
    ``soft_particles``/``hard_particles``), poisson_ratio nu, restitution e (0.05 < e <= 1),
    mu (coefficientFriction). Deck: ``fix property/global youngsModulus``, ``poissonsRatio``,
    ``coefficientRestitution``, ``coefficientFriction``.
    """

    youngs_modulus: float
    poisson_ratio: float
    restitution: float = 1.0
    mu: float = 0.3
    name: str = "hertz-liggghts"
    engines = ("liggghts",)

    def __post_init__(self):
        m = self.material()  # InputError naming the LIGGGHTS property
        lo, hi = 5e6, 1e9
        if not lo <= m.youngs_modulus <= hi:
            raise InputError(
                f"HertzLiggghtsLaw.youngs_modulus: expected {lo:g} <= E <= {hi:g} Pa "
                f"(LIGGGHTS' SI limits), got {self.youngs_modulus!r}"
            )

    def material(self) -> HertzLiggghts:
        return HertzLiggghts(self.youngs_modulus, self.poisson_ratio, self.restitution, self.mu)

    def hertz(self) -> dict:
        """y43 = 4/3 Y*, kt0 = 8 G* (Pa); damping "tsuji" with alpha = -sqrt(5) beta(e): the damping
        coefficient alpha sqrt(m* y43 a) (2 sqrt(5/6) sqrt(2 Y* a m*) = sqrt(5) sqrt(4/3 Y* a m*))."""
        Y, G, beta, _, _ = self.material().coefficients()
        return {
            "y43": 4.0 / 3.0 * Y,
            "kt0": 8.0 * G,
            "damping": "tsuji" if beta != 0.0 else "none",
            "alpha": -(5.0**0.5) * beta,
            "kt_damping": beta != 0.0,
        }

    def native_law(self, flavour: str = "liggghts"):
        return make_law(
            "hertz-liggghts",
            youngs_modulus=self.youngs_modulus,
            poisson_ratio=self.poisson_ratio,
            restitution=self.restitution,
            friction=self.mu,
        )

    def dem_settings(self, dt: float, skin: float, flavour: str = "liggghts") -> Integration:
        return _hertz_settings(dt, skin, flavour)

    def deck_lines(self, engine: str) -> list[str]:
        _one_code(self, engine)
        return deck_lines(self.native_law(), engine)

    def describe(self) -> str:
        return (
            f"LIGGGHTS hertz + tangential history: E {self.youngs_modulus:g} Pa, "
            f"nu {self.poisson_ratio:g}, e {self.restitution:g}, mu {self.mu:g}"
        )


@dataclass(frozen=True)
class HertzHistoryLammpsLaw:
    """LAMMPS 29Sep2021 ``pair_style gran/hertz/history KN KT GAMMAN GAMMAT MU 1`` built from
    material constants: KN = 4/3 Y* (Hertz' elastic force), KT = 8 G* (Mindlin's 8 G* a), the
    damping m* GAMMAN a v_n (1/(s m); pair_gran_hertz_history.cpp:181-221;
    :func:`gransim.contacts.hertz.hertz_history_lammps`). ``gamma_n`` = ``gamma_t`` = 0 here
    (undamped: the damping ~ m* a has no speed-free restitution, docs/laws.md).
    """

    youngs_modulus: float
    poisson_ratio: float
    mu: float = 0.3
    gamma_n: float = 0.0
    gamma_t: float = 0.0
    name: str = "hertz-lammps"
    engines = ("lammps",)

    def __post_init__(self):
        effective_youngs(self.youngs_modulus, self.poisson_ratio, self.youngs_modulus, self.poisson_ratio)
        check_friction(self.mu, "gran/hertz/history MU")
        for k in ("gamma_n", "gamma_t"):
            v = getattr(self, k)
            if not (isinstance(v, int | float) and np.isfinite(v) and v >= 0):
                raise InputError(f"HertzHistoryLammpsLaw.{k}: expected a damping >= 0 1/(s m), got {v!r}")

    def _kk(self):
        E, nu = self.youngs_modulus, self.poisson_ratio
        return 4.0 / 3.0 * effective_youngs(E, nu, E, nu), 8.0 * effective_shear(E, nu, E, nu)

    def hertz(self) -> dict:
        kn, kt = self._kk()
        return {
            "y43": kn,
            "kt0": kt,
            "damping": "none" if self.gamma_n == 0 else "gran",
            "alpha": 0.0,
            "kt_damping": self.gamma_t != 0.0,
        }

    def native_law(self, flavour: str = "lammps"):
        kn, kt = self._kk()
        return make_law("hertz-lammps", kn=kn, kt=kt, gamma_n=self.gamma_n, gamma_t=self.gamma_t, mu=self.mu)

    def dem_settings(self, dt: float, skin: float, flavour: str = "lammps") -> Integration:
        return _hertz_settings(dt, skin, flavour)

    def deck_lines(self, engine: str) -> list[str]:
        _one_code(self, engine)
        return deck_lines(self.native_law(), engine)

    def describe(self) -> str:
        kn, kt = self._kk()
        return (
            f"LAMMPS gran/hertz/history: KN = 4/3 Y* = {kn:.6g} Pa, KT = 8 G* = {kt:.6g} Pa (E "
            f"{self.youngs_modulus:g} Pa, nu {self.poisson_ratio:g}), GAMMAN {self.gamma_n:g}, GAMMAT "
            f"{self.gamma_t:g}, mu {self.mu:g}"
        )


@dataclass(frozen=True)
class HertzGranularLammpsLaw:
    """LAMMPS 29Sep2021 ``pair_style granular`` + ``pair_coeff * * hertz/material E DAMP NU damping
    MODEL tangential mindlin NULL GAMMAT MU`` (:func:`gransim.contacts.hertz.
    hertz_mindlin_granular_lammps`; :class:`gransim.contacts.material.HertzMaterialLammps`).

    damping "tsuji": DAMP a restitution mapped to alpha(DAMP) by the build's polynomial
    (pair_granular.cpp:987-991), damping coefficient alpha sqrt(m* 4/3 Y* a); "mass_velocity"
    with DAMP = 0: undamped. gammat_ratio: tangential damping = GAMMAT times the normal one.
    """

    youngs_modulus: float
    poisson_ratio: float
    damp: float = 0.0
    mu: float = 0.3
    gammat_ratio: float = 0.0
    damping: str = "mass_velocity"
    name: str = "hertz-granular-lammps"
    engines = ("lammps",)

    def __post_init__(self):
        self.material()

    def material(self) -> HertzMaterialLammps:
        return HertzMaterialLammps(
            self.youngs_modulus,
            self.poisson_ratio,
            self.damp,
            self.mu,
            gammat_ratio=self.gammat_ratio,
            damping=self.damping,
        )

    def hertz(self) -> dict:
        E43, damp, kt0, _, _, _ = self.material().coefficients()
        if self.damping == "tsuji":
            kind = "tsuji"
        elif damp == 0.0:
            kind = "none"
        else:
            kind = self.damping
        return {
            "y43": E43,
            "kt0": kt0,
            "damping": kind,
            "alpha": damp if kind == "tsuji" else 0.0,
            "kt_damping": kind != "none" and self.gammat_ratio != 0.0,
        }

    def native_law(self, flavour: str = "lammps"):
        return make_law(
            "hertz-granular-lammps",
            youngs_modulus=self.youngs_modulus,
            poisson_ratio=self.poisson_ratio,
            damp=self.damp,
            friction=self.mu,
            gammat_ratio=self.gammat_ratio,
            damping=self.damping,
        )

    def dem_settings(self, dt: float, skin: float, flavour: str = "lammps") -> Integration:
        return _hertz_settings(dt, skin, flavour)

    def deck_lines(self, engine: str) -> list[str]:
        _one_code(self, engine)
        return deck_lines(self.native_law(), engine)

    def describe(self) -> str:
        return (
            f"LAMMPS granular hertz/material: E {self.youngs_modulus:g} Pa, DAMP {self.damp:g} "
            f"(damping {self.damping}), nu {self.poisson_ratio:g}, tangential mindlin NULL, "
            f"GAMMAT {self.gammat_ratio:g}, mu {self.mu:g}"
        )


def write_impact_deck(
    job_dir,
    packing: Packing,
    law,
    dt: float,
    skin: float,
    nsteps: int,
    velocities,
    spins,
    engine: str = "liggghts",
    dump_every: int = 1,
    thermo_every: int = 10,
) -> Path:
    """Write the deck (``in.liggghts`` or ``in.lammps``) and ``data.impact`` into ``job_dir``.

    Parameters
    ----------
    packing : the scene (orthogonal cell, box [0, Lx] x [0, Ly]; every centre inside the box).
    law : the contact law (an object with ``deck_lines(engine)``, e.g. :class:`HookeLaw`).
    dt, skin : time step (s) and neighbour skin (m). nsteps : steps of the single ``run``.
    velocities : (N, 2) m/s; spins : (N,) rad/s.
    engine : "liggghts" or "lammps" (ValueError otherwise).

    Returns the deck path. Run it with ``reference_runs.runner.run_job(job_dir, deck_text,
    files={"data.impact": ...}, outputs=("dump.atoms",), engine=engine)``.
    """
    if engine not in ENGINES:
        raise ValueError(f"engine: expected one of {', '.join(ENGINES)}, got {engine!r}")
    if engine not in getattr(law, "engines", ENGINES):
        raise InputError(
            f"law {getattr(law, 'name', law)!r}: {engine} does not have it (only {', '.join(law.engines)})"
        )
    x = np.asarray(packing.positions)
    L = np.array([packing.cell[0, 0], packing.cell[1, 1]])
    if np.any(x < 0) or np.any(x >= L):
        raise ValueError("packing: every centre must lie inside the box [0, Lx) x [0, Ly) (the scene is not wrapped)")
    job = Path(job_dir)
    job.mkdir(parents=True, exist_ok=True)
    write_data_file(job / DATA_NAME, packing, velocities=velocities, omegas=spins, wrap=False)
    head = [
        "units si",
        "dimension 2",
        "atom_style sphere",
        "atom_modify map array sort 0 0.0",
        "boundary p p p",
        "newton off",
    ]
    if engine == "lammps":
        lines = [
            "# gransim impact scene, LAMMPS form (reference_runs/decks/impact.py)",
            *head,
            "comm_modify mode single vel yes",
            f"read_data {DATA_NAME}",
            f"set group all density/disc {_g(packing.density)}",
        ]
        integ = "fix integr all nve/sphere disc"
        fmt = "line "
    else:
        lines = [
            "# gransim impact scene (reference_runs/decks/impact.py)",
            *head,
            "communicate single vel yes",
            f"read_data {DATA_NAME}",
        ]
        integ = "fix integr all nve/sphere"
        fmt = ""
    lines += [
        f"neighbor {_g(skin)} bin",
        "neigh_modify delay 0 every 1 check yes",
        f"timestep {_g(dt)}",
        *law.deck_lines(engine),
        integ,
        "fix e2d all enforce2d",
        "thermo_style custom step atoms",
        f"thermo {int(thermo_every)}",
        f"dump d1 all custom {int(dump_every)} {DUMP_NAME} " + " ".join(DUMP_COLUMNS),
        f'dump_modify d1 sort id format {fmt}"%d' + " %.17g" * (len(DUMP_COLUMNS) - 1) + '"',
        f"run {int(nsteps)}",
    ]
    deck = job / DECK_NAMES[engine]
    with atomic_path(deck) as tmp:
        Path(tmp).write_text("\n".join(lines) + "\n")
    return deck


def read_frames(dump_path) -> dict:
    """``dump.atoms`` as {step: {"x": (N, 2), "v": (N, 2), "w": (N,), "f": (N, 2), "t": (N,)}}
    (rows sorted by id; :func:`reference_runs.parsers.parse_dump_custom`)."""
    out = {}
    for fr in parse_dump_custom(Path(dump_path)):
        out[int(fr.step)] = {
            "x": fr.array("x", "y"),
            "v": fr.array("vx", "vy"),
            "w": np.array(fr["omegaz"], float),
            "f": fr.array("fx", "fy"),
            "t": np.array(fr["tqz"], float),
        }
    return out


# ----------------------------------------------------------------------------- rolling resistance
#: rolling-law name (:func:`gransim.contacts.laws.make_law`) -> its model in the codes
ROLLING_MODELS = {
    "hooke-epsd2-liggghts": "epsd2",
    "hooke-epsd-liggghts": "epsd",
    "hooke-cdt-liggghts": "cdt",
    "hooke-sds-lammps": "sds",
}


@dataclass(frozen=True)
class RollingLaw:
    """A Hooke law with rolling resistance, by its :func:`gransim.contacts.laws.make_law` name
    (one code each: LIGGGHTS ``hooke/stiffness tangential history rolling_friction epsd2|epsd|cdt``,
    LAMMPS ``granular hooke ... tangential linear_history ... rolling sds``; docs/laws.md).

    ``params``: the make_law parameters as a tuple of (name, value) pairs (a frozen dataclass
    must hash), SI. The deck lines are those of the biaxial decks
    (the law's own, :func:`gransim.contacts.laws.deck_lines`), so the two cases share one law block.
    :meth:`rolling` gives the constants of the closed forms of validation/cases/impacts.py.
    """

    name: str
    params: tuple

    def __post_init__(self):
        if self.name not in ROLLING_MODELS:
            raise InputError(f"RollingLaw.name: expected one of {', '.join(ROLLING_MODELS)}, got {self.name!r}")
        self.law()  # InputError naming a bad parameter

    @property
    def engines(self) -> tuple:
        return (law_code(self.name),)

    @property
    def p(self) -> dict:
        return dict(self.params)

    @property
    def mu(self) -> float:
        return float(self.p["mu"])

    def law(self):
        return make_law(self.name, **self.p)

    def native_law(self, flavour: str = ""):
        return self.law()

    def rolling(self) -> dict:
        """{"model": epsd2|epsd|cdt|sds, "kn" (N/m), "kt" (N/m), "mu_r" (-), "eta_r" (-), "kroll"
        (N/m), "gammaroll" (kg/s)}: what the rolling torque depends on (zeros where absent)."""
        p = self.p
        out = {
            "model": ROLLING_MODELS[self.name],
            "kn": float(p["kn"]),
            "kt": float(p["kt"]),
            "mu_r": float(p.get("mu_r", p.get("muroll", 0.0))),
            "eta_r": float(p.get("eta_r", 0.0)),
            "kroll": float(p.get("kroll", 0.0)),
            "gammaroll": float(p.get("gammaroll", 0.0)),
        }
        return out

    def dem_settings(self, dt: float, skin: float, flavour: str = "") -> DEMSettings:
        """Settings for the engine: kn, kt, the normal damping and mu of the law (its time-step
        check), dt, skin, serial, the law's code as flavour (its neighbour-rebuild rule)."""
        p = self.p
        return DEMSettings(
            kn=p["kn"],
            kt=p["kt"],
            gamma_n=p.get("gamma_n", p.get("damp", 0.0)),
            gamma_t=p.get("gamma_t", 0.0),
            mu=p["mu"],
            dt=dt,
            skin=skin,
            mode="serial",
            flavour=self.engines[0],
        )

    def deck_lines(self, engine: str) -> list[str]:
        _one_code(self, engine)
        return deck_lines(self.law(), engine)

    def describe(self) -> str:
        return f"{self.name}: " + ", ".join(
            f"{k} {v:g}" if isinstance(v, float) else f"{k} {v}" for k, v in self.params
        )


# ----------------------------------------------------------------------------- flat granular walls
@dataclass(frozen=True)
class WallLaw:
    """Each code's own flat granular wall ``y = 0`` with the linear Hooke law with tangential
    history, for the oblique impacts of validation/cases/impacts.py (scene ``wall-<code>``).

    LAMMPS 29Sep2021: ``fix wall/gran hooke/history KN KT GAMMAN GAMMAT MU 1 yplane 0.0 NULL``
    (GRANULAR/fix_wall_gran.cpp:847-967: the pair law of ``gran/hooke/history`` with the wall as
    an infinitely heavy body of radius 0, meff = m_i, lever arm r_i), with the pair style
    ``gran/hooke/history`` of the same constants (no pair ever touches). LIGGGHTS 3.8.0: ``fix
    wall/gran model hooke/stiffness tangential history primitive type 1 yplane 0.0`` (the mesh-less
    primitive wall, fix_wall_gran.cpp; it runs in 2D with ``enforce2d``) with the properties of
    :class:`HookeLaw`. Both need ``boundary p f p`` (a wall in a periodic dimension is an error).
    """

    kn: float
    kt: float
    mu: float = 0.5
    engine: str = "lammps"
    name: str = "wall"

    def __post_init__(self):
        HookeLaw(self.kn, self.kt, 0.0, 0.0, self.mu)  # the checks
        if self.engine not in ENGINES:
            raise InputError(f"WallLaw.engine: expected one of {', '.join(ENGINES)}, got {self.engine!r}")

    @property
    def engines(self) -> tuple:
        return (self.engine,)

    def deck_lines(self, engine: str) -> list[str]:
        _one_code(self, engine)
        pair = HookeLaw(self.kn, self.kt, 0.0, 0.0, self.mu).deck_lines(engine)
        if engine == "lammps":
            return pair + [
                (
                    f"fix wall all wall/gran hooke/history {_g(self.kn)} {_g(self.kt)} 0 0 {_g(self.mu)} 1 "
                    "yplane 0.0 NULL"
                )
            ]
        return pair + ["fix wall all wall/gran model hooke/stiffness tangential history primitive type 1 yplane 0.0"]

    def describe(self) -> str:
        what = (
            "LAMMPS fix wall/gran hooke/history yplane"
            if self.engine == "lammps"
            else "LIGGGHTS fix wall/gran primitive yplane, hooke/stiffness tangential history"
        )
        return f"{what}: kn {self.kn:g} N/m, kt {self.kt:g} N/m, no damping, mu {self.mu:g}"


def write_wall_deck(
    job_dir,
    packing: Packing,
    law: WallLaw,
    dt: float,
    skin: float,
    nsteps: int,
    velocities,
    spins,
    dump_every: int = 1,
    thermo_every: int = 10,
) -> Path:
    """The deck of disks impacting the flat wall ``y = 0`` of ``law`` (its code), as
    :func:`write_impact_deck` but ``boundary p f p`` (the box spans y in [0, Ly])."""
    deck = write_impact_deck(
        job_dir,
        packing,
        law,
        dt,
        skin,
        nsteps,
        velocities,
        spins,
        engine=law.engine,
        dump_every=dump_every,
        thermo_every=thermo_every,
    )
    text = deck.read_text().replace("boundary p p p", "boundary p f p")
    with atomic_path(deck) as tmp:
        Path(tmp).write_text(text)
    return deck


# ----------------------------------------------------------------------------- Chung & Ooi test 5
#: tolerances of test 5 (quantity -> (tolerance, reason)): errors against the closed forms of the
#: impacts case (H1-H3 for the normal impact, eq (6) with P = 2 m* v_n for gross sliding), measured
#: with v_n = 0.01 m/s, mu 0.3, E 5e8 Pa, nu 0.3, dt 5e-6 s (docs/impacts.md, "Chung & Ooi test 5")
TEST5_TOL = {
    "contact time": (
        2.0e-3,
        "geometric, dt-independent (the same at dt/2): the rotation of the normal, "
        "v_t t_c/(r1 + r2) <= 1.1e-3 rad at Psi1 20; measured 7.2e-4",
    ),
    "restitution": (6.0e-4, "geometric as the contact time; measured 1.9e-4 (undamped: e = 1)"),
    "peak overlap": (5.0e-3, "geometric (the curved path shortens the approach); measured 1.9e-3 at Psi1 20"),
    "peak force": (8.0e-3, "geometric, F ~ delta^(3/2); measured 2.8e-3 at Psi1 20"),
    "friction impulse": (1.0e-2, "gross sliding, P = 2 m* v_n along the rotating normal; measured 3.3e-3 at Psi1 20"),
    "exit slip": (
        3.0e-3,
        "|s' - s'_rigid|/|s0|: lever arm r - delta/2 and the rotation of the normal; measured 1.2e-3",
    ),
    "exit spin": (2.5e-3, "r1 |w1' - w1'_rigid|/|s0|: as the exit slip; measured 7.9e-4"),
    "sliding force": (
        1.0e-9,
        "gross sliding: |F_t| = mu |F_n| at every contact frame (the cap of each code, exact); measured 6.7e-16",
    ),
    "coulomb bound": (1.0e-9, "max |F_t|/(mu |F_n|) - 1 at every contact frame: the cap is exact; measured 6.7e-16"),
    "energy gain": (1.0e-6, "KE'/KE - 1 (positive part): no source of energy in an undamped spring-slider; measured 0"),
}
#: Psi1 = 2 v_t/(mu (1 + e) v_n) of the sweep: microslip below 6 (the disk rule, docs/impacts.md),
#: gross sliding from 6 on
TEST5_PSI1 = (1.0, 2.0, 4.0, 6.5, 8.0, 12.0, 20.0)


def chung_ooi_test5_impacts(
    v_n: float, mu: float, r: float, r_wall: float, psi1=TEST5_PSI1, e: float = 1.0
) -> list[dict]:
    """Chung & Ooi's test 5 (Granular Matter 13, 2011, 643-656: oblique impact on a wall at a
    constant normal and a varying tangential speed) for disks: a disk of radius ``r`` (m) hits the
    wall disk of radius ``r_wall`` (at rest) at the normal speed ``v_n`` (m/s) with the tangential
    speed v_t = Psi1 mu (1 + e) v_n/2 for each Psi1 of ``psi1`` (so the impact angle atan(v_t/v_n)
    is swept while the normal answers stay those of one normal impact).

    Returns one dict per impact: ``label`` (``psi<Psi1>``), ``kind`` (``sliding`` for Psi1 >= 6,
    the rigid-body limit of eq (6) of the impacts case; ``microslip`` below, judged by the Coulomb
    bound and the energy bound only), ``r1``, ``r2``, ``v1`` (v_n, v_t), ``v2`` (0, 0), ``w1``,
    ``w2`` (0), ``psi1``, ``angle`` (deg) and ``note``. Raises InputError for a non-positive
    speed, radius or mu, or an empty sweep."""
    for nm, v in (("v_n", v_n), ("mu", mu), ("r", r), ("r_wall", r_wall)):
        if not (isinstance(v, int | float) and np.isfinite(v) and v > 0):
            raise InputError(f"chung_ooi_test5_impacts: {nm} must be a finite number > 0, got {v!r}")
    psi1 = tuple(float(p) for p in psi1)
    if not psi1 or any(not (np.isfinite(p) and p > 0) for p in psi1):
        raise InputError(f"chung_ooi_test5_impacts: psi1 must be a non-empty sequence of numbers > 0, got {psi1!r}")
    out = []
    for p in psi1:
        vt = p * mu * (1.0 + e) * v_n / 2.0
        angle = float(np.degrees(np.arctan2(vt, v_n)))
        out.append(
            {
                "label": f"psi{p:g}",
                "kind": "sliding" if p >= 6.0 else "microslip",
                "r1": r,
                "r2": r_wall,
                "v1": (v_n, vt),
                "v2": (0.0, 0.0),
                "w1": 0.0,
                "w2": 0.0,
                "psi1": p,
                "angle": angle,
                "note": f"Chung & Ooi test 5: v_n = {v_n:g} m/s, v_t = {vt:.6g} m/s ({angle:.4g} deg, Psi1 = {p:g})",
            }
        )
    return out


def sliding_force_deviation(frames: dict, pairs, radii, mu: float) -> list[float]:
    """Per pair (i, j) of ``pairs``, the largest | |F_t|/(mu |F_n|) - 1 | over the frames in which
    the pair overlaps and F_n != 0 (F on disk i, n from i to j, t = z x n): 0 where the tangential
    force is mu |F_n| throughout (gross sliding, the closed form of the tangential force); NaN for
    a pair that never overlapped. ``frames``: {step: {"x" (N, 2), "f" (N, 2), ...}}; ``radii``
    (N,) m."""
    r = np.asarray(radii, float)
    out = []
    for i, j in pairs:
        dev, seen = 0.0, False
        for k in sorted(frames):
            x, f = frames[k]["x"], frames[k]["f"]
            d = x[j] - x[i]
            dist = float(np.hypot(d[0], d[1]))
            if r[i] + r[j] - dist <= 0:
                continue
            n = d / dist
            fn = float(f[i] @ n)
            if fn == 0.0:
                continue
            seen = True
            ft = float(f[i, 1] * n[0] - f[i, 0] * n[1])
            dev = max(dev, abs(abs(ft) / (mu * abs(fn)) - 1.0))
        out.append(dev if seen else float("nan"))
    return out
