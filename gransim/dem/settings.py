"""Settings of a DEM run (frozen dataclasses, checked once): the integration (:class:`Integration`:
time step, skin, threads mode, whose arithmetic), apart from the contact law (a law object of
:mod:`gransim.contacts.laws`: stiffness, damping, friction, rolling), and the loading.
:class:`DEMSettings` is the integration together with the parameters of the Hooke law of Kuhn's
protocol (its :meth:`~DEMSettings.hooke_law`), the law of a run that is given no other."""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field

import numpy as np

from .._validate import as_positive_float, check_choice
from ..errors import InputError
from ..geometry import Packing

#: the established DEM codes whose arithmetic the engine can follow (DEMSettings.flavour)
FLAVOURS = ("liggghts", "lammps")


@dataclass(frozen=True)
class Integration:
    """How a DEM run integrates, whatever its contact law (SI).

    Attributes
    ----------
    dt : time step (s). Must be below the law's stability limit
        (:func:`gransim.dem.engine.stability_limit`, which asks the law for its time scale).
    skin : neighbour-list skin (m). Part of the contact bookkeeping (history hand-over at rebuilds).
    mode : "serial" (half list, the code's order: the mode that is compared step for step) or
        "parallel" (the same half list over numba threads: each pair once, then a per-particle
        gather of the partner forces; deterministic, summation order differs).
    flavour : whose arithmetic the engine reproduces bit for bit: "liggghts" (LIGGGHTS-PUBLIC
        3.8.0; the default) or "lammps" (LAMMPS 29 Sep 2021: its rebuild rule, docs/lammps.md).
        The law's own arithmetic is the law's (``gransim.contacts.laws.law_code``).
    """

    dt: float = 1.0e-6
    skin: float = 1.0e-4
    mode: str = "serial"
    flavour: str = "liggghts"

    def __post_init__(self):
        for name in ("dt", "skin"):
            object.__setattr__(self, name, as_positive_float(getattr(self, name), name))
        check_choice(self.mode, "mode", ("serial", "parallel"))
        check_choice(self.flavour, "flavour", FLAVOURS)

    @property
    def integration(self) -> Integration:
        return self

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class DEMSettings:
    """Contact law and integration settings (SI units; 2D forces per unit thickness read the same).

    Attributes
    ----------
    kn, kt : normal and tangential spring stiffness (N/m). Kuhn (002) uses kt = kn.
    gamma_n, gamma_t : mass-scaled viscous damping rates (1/s); the damping coefficient of a
        contact is m_eff gamma with m_eff = m_i m_j/(m_i + m_j) (LIGGGHTS ``gamman``, ``gammat``).
    mu : Coulomb friction coefficient (0.5 in the biaxial test of 002).
    dt : time step (s). Must be below the stability limit (see :func:`stability_limit`).
    skin : neighbour-list skin (m). Part of the contact law (history hand-over at rebuilds).
    mode : "serial" (half list, LIGGGHTS' order: the mode that is compared step for step) or
        "parallel" (the same half list over numba threads: each pair once, then a per-particle
        gather of the partner forces; deterministic, summation order differs).
    flavour : whose arithmetic the engine reproduces bit for bit: "liggghts" (LIGGGHTS-PUBLIC
        3.8.0, ``hooke/stiffness`` + ``tangential history``; the default) or "lammps" (LAMMPS
        29 Sep 2021, ``gran/hooke/history``: full radii as lever arms, damping inside the Coulomb
        cap, springs reset when a pair stops touching; docs/lammps.md). Same physics otherwise.
    """

    kn: float = 1.0e5
    kt: float = 1.0e5
    gamma_n: float = 0.0
    gamma_t: float = 0.0
    mu: float = 0.5
    dt: float = 1.0e-6
    skin: float = 1.0e-4
    mode: str = "serial"
    flavour: str = "liggghts"

    def __post_init__(self):
        for name in ("kn", "dt", "skin"):
            object.__setattr__(self, name, as_positive_float(getattr(self, name), name))
        for name in ("kt", "gamma_n", "gamma_t", "mu"):
            object.__setattr__(self, name, as_positive_float(getattr(self, name), name, allow_zero=True))
        check_choice(self.mode, "mode", ("serial", "parallel"))
        check_choice(self.flavour, "flavour", FLAVOURS)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @property
    def integration(self) -> Integration:
        """The integration part (dt, skin, mode, flavour)."""
        return Integration(self.dt, self.skin, self.mode, self.flavour)

    def hooke_law(self, flavour: str | None = None):
        """The Hooke law of these stiffnesses, dampings and friction in the arithmetic of
        ``flavour`` (default: :attr:`flavour`): the law ``hooke-liggghts`` or ``hooke-lammps``; for
        "yade", YADE's Cundall-Strack law ``cundall-strack-yade`` with kn, ks = kt of
        ``MatchMaker(algo='val')``, the friction angle atan(mu) and no ratcheting correction, as
        YADE's decks make it (reference_runs/yade/dem_script.py; undamped: the yade cell refuses
        gamma_n, gamma_t)."""
        from ..contacts.laws import make_law  # noqa: PLC0415 - start-up: the laws' numba kernels, on demand

        f = self.flavour if flavour is None else flavour
        if f == "yade":
            return make_law(
                "cundall-strack-yade", kn=self.kn, ks=self.kt, friction_angle=math.atan(self.mu),
                avoid_granular_ratcheting=False,
            )  # fmt: skip
        return make_law(f"hooke-{f}", kn=self.kn, kt=self.kt, gamma_n=self.gamma_n, gamma_t=self.gamma_t, mu=self.mu)

    @classmethod
    def for_packing(
        cls,
        packing,
        kn: float,
        *,
        kt: float | None = None,
        mu: float = 0.5,
        damping_ratio: float = 0.3,
        steps_per_contact: float = 50.0,
        skin_d50: float = 0.05,
        mode: str = "serial",
        flavour: str = "liggghts",
    ) -> DEMSettings:
        """Settings derived from a packing's disks and the contact stiffness alone (no test protocol).

        Parameters
        ----------
        packing : gransim.Packing
            Its masses (density pi r^2, kg) and D50 (m) set the time step, damping and skin.
        kn : float
            Normal spring stiffness (N/m); ``kt`` defaults to kn (Kuhn's law).
        mu : float
            Coulomb friction coefficient.
        damping_ratio : float
            zeta of the normal contact of two median disks: gamma_n = gamma_t = 2 zeta sqrt(kn/m_eff),
            m_eff = m_median/2 (1/s, mass-scaled as LIGGGHTS' ``gamman``).
        steps_per_contact : float
            dt = t_c / steps_per_contact, with t_c = pi sqrt(m_eff/kn) the undamped contact time of
            the two lightest disks (:func:`gransim.dem.engine.contact_time`).
        skin_d50 : float
            Neighbour skin in D50.

        With the defaults these are the contact settings of the biaxial protocol's
        :func:`gransim.dem.biaxial.default_settings` (the same arithmetic, so the same bits).
        """
        if not isinstance(packing, Packing):
            raise InputError(f"packing: expected a gransim.Packing, got {type(packing).__name__}")
        kn = as_positive_float(kn, "kn")
        kt = kn if kt is None else kt
        damping_ratio = as_positive_float(damping_ratio, "damping_ratio", allow_zero=True)
        steps_per_contact = as_positive_float(steps_per_contact, "steps_per_contact")
        skin_d50 = as_positive_float(skin_d50, "skin_d50")
        if packing.n < 2:
            raise InputError("packing: the time step needs at least two disks")
        gamma = 2.0 * damping_ratio * np.sqrt(kn / (0.5 * np.median(packing.masses)))
        m = np.sort(packing.masses)
        meff = m[0] * m[1] / (m[0] + m[1])
        dt = float(np.pi * np.sqrt(meff / kn)) / steps_per_contact
        return cls(
            kn=kn,
            kt=kt,
            gamma_n=gamma,
            gamma_t=gamma,
            mu=mu,
            dt=dt,
            skin=skin_d50 * packing.d50,
            mode=mode,
            flavour=flavour,
        )


@dataclass(frozen=True)
class AxisControl:
    """Loading of one axis of the orthogonal periodic cell (applied at the end of each step).

    mode "fixed": the side length stays. mode "rate": L(n) = L_0 + c n with c = rate L_0 dt
    (``rate`` in 1/s, negative = compression; engineering rate, as the LIGGGHTS variable deck
    ``del = c*step``). mode "servo": proportional control of the normal stress of that axis,
    L(n) = L(n-1) + dt gain (sigma - target) L(n-1), sigma the Love stress of the step
    (compression positive, N/m in 2D), ``gain`` in 1/(Pa s): more stress than the target
    expands the cell.
    """

    mode: str = "fixed"
    rate: float = 0.0
    target: float = 0.0
    gain: float = 0.0

    def __post_init__(self):
        check_choice(self.mode, "axis mode", ("fixed", "rate", "servo"))
        for name in ("rate", "target", "gain"):
            try:
                v = float(getattr(self, name))
            except (TypeError, ValueError):
                raise InputError(f"{name}: expected a number, got {getattr(self, name)!r}") from None
            object.__setattr__(self, name, v)
        if self.mode == "servo" and self.gain <= 0:
            raise InputError(f"servo gain: must be > 0, got {self.gain!r}")


@dataclass(frozen=True)
class Loading:
    """Control of both axes (x = 1, y = 2)."""

    x: AxisControl = field(default_factory=AxisControl)
    y: AxisControl = field(default_factory=AxisControl)

    def to_dict(self) -> dict:
        return {"x": dataclasses.asdict(self.x), "y": dataclasses.asdict(self.y)}

    @classmethod
    def from_dict(cls, d: dict) -> Loading:
        return cls(x=AxisControl(**d["x"]), y=AxisControl(**d["y"]))


@dataclass(frozen=True, eq=False)
class PrescribedBox:
    """Loading that takes the box of every step from a table (e.g. a ``fix deform`` of a replayed
    deck, :func:`reference_runs.replay.deform.box_table`), evaluated inside the engine's step.

    Attributes
    ----------
    lo, hi : (T, 2) float64 box corners (m): row k is the box after step ``step0 + k`` (row 0,
        the box at ``step0``, is not used by the stepping).
    remap : (T,) bool: step ``step0 + k`` is a box step (``fix deform`` with ``ntimestep % N ==
        0``): the box becomes row k and the positions are mapped affinely from the old box
        (``remap x``, even when the box is unchanged, as the codes do). On the other steps the
        box stays. Default: every row.
    step0 : the step of row 0.

    Raises InputError for arrays of the wrong shape, non-finite values or a box with hi <= lo.
    """

    lo: np.ndarray
    hi: np.ndarray
    remap: np.ndarray | None = None
    step0: int = 0

    def __post_init__(self):
        lo = np.array(self.lo, np.float64)
        hi = np.array(self.hi, np.float64)
        if lo.ndim != 2 or lo.shape[1] != 2 or lo.shape != hi.shape or lo.shape[0] < 1:
            raise InputError(
                f"prescribed box: lo and hi must both be (T, 2) arrays, got shapes {lo.shape} and {hi.shape}"
            )
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            raise InputError("prescribed box: lo and hi must be finite")
        bad = np.flatnonzero(np.any(hi <= lo, axis=1))
        if bad.size:
            k = int(bad[0])
            raise InputError(f"prescribed box: row {k} has hi <= lo ({lo[k].tolist()}, {hi[k].tolist()})")
        if self.remap is None:
            remap = np.ones(lo.shape[0], np.bool_)
        else:
            remap = np.array(self.remap, np.bool_).reshape(-1)
            if remap.shape[0] != lo.shape[0]:
                raise InputError(
                    f"prescribed box: remap must have {lo.shape[0]} rows (one per box row), got {remap.shape[0]}"
                )
        try:
            step0 = int(self.step0)
        except (TypeError, ValueError):
            raise InputError(f"prescribed box: step0 must be an integer, got {self.step0!r}") from None
        for name, a in (("lo", lo), ("hi", hi), ("remap", remap)):
            a.setflags(write=False)
            object.__setattr__(self, name, a)
        object.__setattr__(self, "step0", step0)

    @property
    def last_step(self) -> int:
        """The last step the table covers."""
        return self.step0 + self.lo.shape[0] - 1


def settings_json(settings: DEMSettings, loading: Loading | None = None, **extra) -> str:
    """Canonical JSON of the settings (stored in result files, hashed into the fingerprint)."""
    d = {"dem": settings.to_dict()}
    if loading is not None:
        d["loading"] = loading.to_dict()
    d.update(extra)
    return json.dumps(d, sort_keys=True)
