"""Contact laws as plug-ins of the DEM loop: a law = its parameters (a namedtuple class, one numba
type per law) + a jitted pair function + the width of its per-contact history.

The force loops of :mod:`gransim.dem.kernels` call :func:`pair_force` and :func:`pair_apart` with
the law object as their first argument. Both are ``numba.extending.overload``-ed: numba types the
call by the law's namedtuple class, looks the class up in the registry below and inlines that
law's pair function. Each law therefore gets its own specialised copy of the loop, compiled once
and kept in numba's disk cache (the cache key is the argument types, i.e. the law's class, which
is pickled by reference: register laws from module level of an importable module). No closure is
created at run time; the integrator and the neighbour list never name a law.

Registering a law (e.g. in ``gransim/contacts/hertz.py``)::

    HertzLiggghts = namedtuple("HertzLiggghts", ["E", "nu", "e", "mu"])   # floats only

    @njit(inline="always")
    def hertz_pair(law, hist, e, delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj,
                   mi, mj, dt, update):
        s0 = hist[e, 0]; ...                     # read the entry's history row
        ...                                      # the scalar law
        hist[e, 0] = s0; ...                     # write it back (in place)
        return fx, fy, ti, tj, sliding, fn       # force on i, torques on i and j, cap flag, F_n

    def hertz_energy(law, overlap, hist, radi, radj):   # (K,) arrays -> J
        ...

    register_law(HertzLiggghts, hertz_pair, width=2, energy=hertz_energy)

A law defined in a test module or a script registers with ``cache=False`` (:class:`LawSpec`).

**By name**: :func:`make_law` builds a law object of the package from a name of :func:`law_names`
and its parameters as keywords (checked once: InputError naming the law, the parameter and what
was expected); :func:`law_code` says whose arithmetic a name follows ("liggghts" or "lammps",
the ``DEMSettings.flavour`` to run it with: the rebuild rule belongs to the code).

Arguments of a pair function (all SI): ``law`` the parameters; ``hist`` (M, width) float64, the
history of every list entry, row ``e`` the entry's (frame of i; update in place); d = (delx, dely)
= x_i - x_j (j's periodic image, m), ``rsq`` = |d|^2 < (r_i + r_j)^2 (the caller tested contact);
radii (m), velocities (m/s), spins (rad/s), masses (kg) of i and j; ``dt`` (s); ``update`` False
in the set-up evaluation of a run (no history increment, as both codes' ``run`` set-up). Returns
(fx, fy) the force on i (N; j gets minus it), ti and tj the torques on i and j (N m), ``sliding``
(bool) and F_n (N). The optional ``apart(law, hist, e)`` runs for an entry whose disks do not
touch (LAMMPS' ``gran/*/history`` zeroes the spring there; LIGGGHTS keeps it). A law registered
with ``split_torque=True`` returns two more floats, ``(..., fn, ti2, tj2)``: torques the loops add
to i and j after ti and tj, each on its own (LAMMPS' ``granular`` rolling torque,
:func:`gransim.contacts.rolling.sds_pair`); :func:`pair_force` still returns the six values
(torques summed), :func:`pair_force_split` (the loops) always eight (-0.0 for the other laws, an
addition the compiler removes).

**Energy**: ``energy(law, overlap, hist, radi, radj)`` (arrays over the K touching contacts) the
elastic energy (J) stored in them (:class:`LawSpec`, :func:`elastic_energy`; docs/laws.md).
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numba.extending import overload

from .._validate import as_positive_float
from ..errors import InputError
from .material import HertzLiggghts, HertzMaterialLammps


@dataclass(frozen=True)
class LawSpec:
    """A registered law.

    Attributes
    ----------
    params : the namedtuple class of the law's parameters (its numba type selects the law).
    pair : jitted pair function (module docstring for its arguments and result).
    width : columns of the per-contact history array (0: a law without history).
    apart : jitted ``apart(law, hist, e)`` for an entry that does not touch, or None (keep).
    flip : (width,) signs of the history seen from the other particle: a new list entry (a, b)
        that was stored as (b, a) before a rebuild takes ``flip * hist`` (-1 for vectors in the
        frame of i, as the tangential spring; +1 for scalars).
    energy : optional Python ``energy(law, overlap (K,), hist (K, width), radi (K,), radj (K,))
        -> float``: the elastic energy (J) stored in the K touching contacts with overlaps (m),
        histories and the radii of their two disks (m; R* = r_i r_j/(r_i + r_j) of a Hertz or a
        rolling law), for the engine's energy balance; None: 0. A function of the first three
        arguments only (the former hook) is accepted by :func:`register_law` and called without
        the radii.
    split_torque : the pair function returns two more floats, (..., fn, tqa2, tqb2): torques the
        loop adds to a and b *after* ti and tj, each on its own (LAMMPS ``pair_style granular``
        adds the rolling torque to the particle's torque after the tangential one,
        pair_granular.cpp:664-686, 693-705; one sum ti would round differently). False: the
        loop adds -0.0 (folded away by the compiler: no work for the other laws).
    cache : the kernels compiled for this law go to numba's disk cache. Only for a class defined
        in a module every process can import (a ``gransim`` module): the cache index of a kernel
        lists the classes of all its compiled signatures and every process unpickles all of it,
        so a class from a test module or a script would break every other process sharing the
        cache (ModuleNotFoundError). Register such laws with ``cache=False``.
    """

    params: type
    pair: Callable
    width: int
    apart: Callable | None
    flip: tuple
    energy: Callable | None
    cache: bool = True
    split_torque: bool = False


_REGISTRY: dict[type, LawSpec] = {}


def register_law(
    params: type,
    pair: Callable,
    width: int,
    *,
    apart: Callable | None = None,
    flip=None,
    energy: Callable | None = None,
    cache: bool = True,
    split_torque: bool = False,
) -> LawSpec:
    """Register ``params`` (a namedtuple class of floats) with its jitted ``pair`` function.

    ``width`` >= 0 history columns; ``apart``, ``flip`` (default -1 for every column), ``energy``
    and ``cache`` (False for a law defined outside an importable package module): :class:`LawSpec`.
    Registering the same class again replaces its entry (a module
    reloaded); raises InputError for a class that is not a namedtuple or a bad width/flip.
    """
    if not (isinstance(params, type) and issubclass(params, tuple) and hasattr(params, "_fields")):
        raise InputError(f"register_law: params must be a namedtuple class, got {params!r}")
    if int(width) != width or width < 0:
        raise InputError(f"register_law: width must be an integer >= 0 (history columns), got {width!r}")
    flip = (-1.0,) * int(width) if flip is None else tuple(float(s) for s in flip)
    if energy is not None:
        energy = _energy_hook(energy)
    if len(flip) != width or any(s not in (-1.0, 1.0) for s in flip):
        raise InputError(f"register_law: flip must hold {width} signs (+1 or -1), got {flip!r}")
    spec = LawSpec(params, pair, int(width), apart, flip, energy, bool(cache), bool(split_torque))
    _REGISTRY[params] = spec
    return spec


def _energy_hook(fn):
    """``fn`` as a hook of five arguments (law, overlap, hist, radi, radj): a function that takes
    three positional arguments only (the hook before the radii were passed) is wrapped."""
    try:
        params = list(inspect.signature(fn).parameters.values())
    except (TypeError, ValueError):
        return fn
    if any(p.kind is p.VAR_POSITIONAL for p in params):
        return fn
    if len([p for p in params if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]) >= 5:
        return fn

    def three(law, overlap, hist, radi, radj):
        return fn(law, overlap, hist)

    three.__wrapped__ = fn
    return three


def law_spec(law) -> LawSpec:
    """The :class:`LawSpec` of a law object (an instance of a registered class)."""
    spec = _REGISTRY.get(type(law))
    if spec is None:
        known = ", ".join(sorted(c.__name__ for c in _REGISTRY)) or "none"
        raise InputError(
            f"law: expected an instance of a registered contact law ({known}), got "
            f"{type(law).__name__} (gransim.contacts.laws.register_law)"
        )
    return spec


def _spec_of_type(ty) -> LawSpec | None:
    cls = getattr(ty, "instance_class", None)
    return _REGISTRY.get(cls)


def pair_force(law, hist, e, delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, dt, update):
    """The pair function of ``law``'s registered class: (fx, fy, ti, tj, sliding, fn), ti and tj
    the whole torques on i and j (interpreted: NUMBA_DISABLE_JIT)."""
    out = _REGISTRY[type(law)].pair(
        law, hist, e, delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, dt, update
    )
    if len(out) == 8:
        fx, fy, ti, tj, sl, fn, ti2, tj2 = out
        return fx, fy, ti + ti2, tj + tj2, sl, fn
    return out


def pair_force_split(law, hist, e, delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, dt, update):
    """The pair function of ``law`` as the force loops call it: (fx, fy, ti, tj, sliding, fn, ti2,
    tj2), ti2 and tj2 added to the particles after ti and tj (``LawSpec.split_torque``; -0.0 for a
    law that returns its torques whole). Interpreted: NUMBA_DISABLE_JIT."""
    out = _REGISTRY[type(law)].pair(
        law, hist, e, delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, dt, update
    )
    if len(out) == 8:
        return out
    return (*out, -0.0, -0.0)


def pair_apart(law, hist, e):
    """The ``apart`` function of ``law``'s class, if any (interpreted: NUMBA_DISABLE_JIT)."""
    fn = _REGISTRY[type(law)].apart
    if fn is not None:
        fn(law, hist, e)


@overload(pair_force, inline="always")
def _ov_pair_force(law, hist, e, delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, dt, update):
    spec = _spec_of_type(law)
    if spec is None:
        return None
    fn = spec.pair

    if spec.split_torque:

        def joined(law, hist, e, delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, dt, update):
            fx, fy, ti, tj, sl, fnorm, ti2, tj2 = fn(
                law, hist, e, delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, dt, update
            )
            return fx, fy, ti + ti2, tj + tj2, sl, fnorm

        return joined

    def impl(law, hist, e, delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, dt, update):
        return fn(law, hist, e, delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, dt, update)

    return impl


@overload(pair_force_split, inline="always")
def _ov_pair_force_split(law, hist, e, delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, dt, update):
    spec = _spec_of_type(law)
    if spec is None:
        return None
    fn = spec.pair
    if spec.split_torque:

        def split(law, hist, e, delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, dt, update):
            return fn(law, hist, e, delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, dt, update)

        return split

    def whole(law, hist, e, delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, dt, update):
        fx, fy, ti, tj, sl, fnorm = fn(
            law, hist, e, delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, dt, update
        )
        return fx, fy, ti, tj, sl, fnorm, -0.0, -0.0

    return whole


@overload(pair_apart, inline="always")
def _ov_pair_apart(law, hist, e):
    spec = _spec_of_type(law)
    if spec is None:
        return None
    fn = spec.apart
    if fn is None:

        def keep(law, hist, e):
            return None

        return keep

    def impl(law, hist, e):
        fn(law, hist, e)

    return impl


def flip_signs(law) -> np.ndarray:
    """(width,) float64 signs of the history of ``law`` seen from the other particle."""
    return np.array(law_spec(law).flip, np.float64).reshape(-1)


def elastic_energy(law, overlap: np.ndarray, hist: np.ndarray, radi: np.ndarray, radj: np.ndarray) -> float:
    """Elastic energy (J) of the K touching contacts with ``overlap`` (K,) m, history (K, width)
    and the radii ``radi``, ``radj`` (K,) m of their two disks: the law's registered ``energy``
    (:class:`LawSpec`), 0 for a law without one."""
    fn = law_spec(law).energy
    if fn is None:
        return 0.0
    return float(
        fn(
            law,
            np.asarray(overlap, np.float64),
            np.asarray(hist, np.float64),
            np.asarray(radi, np.float64),
            np.asarray(radj, np.float64),
        )
    )


def effective_radius(radi, radj) -> np.ndarray:
    """R* = r_i r_j/(r_i + r_j) (m), in the codes' order (radi * radj / (radi + radj))."""
    radi = np.asarray(radi, np.float64)
    radj = np.asarray(radj, np.float64)
    return radi * radj / (radi + radj)


# ----------------------------------------------------------------------------- factory
_HOOKE = ("kn", "kt", "gamma_n", "gamma_t", "mu")
_DAMPING = ("velocity", "mass_velocity", "viscoelastic", "tsuji")

#: name -> (code, required parameters, optional parameters with defaults, one-line description)
LAWS = {
    "hooke-liggghts": ("liggghts", _HOOKE, {}, "hooke/stiffness tangential history"),
    "hooke-lammps": ("lammps", _HOOKE, {}, "gran/hooke/history"),
    "hertz-liggghts": (
        "liggghts",
        ("youngs_modulus", "poisson_ratio", "restitution", "friction"),
        {"tangential_damping": True},
        "gran model hertz tangential history",
    ),
    "hertz-lammps": ("lammps", _HOOKE, {}, "gran/hertz/history KN KT GAMMAN GAMMAT MU 1"),
    "hertz-granular-lammps": (
        "lammps",
        ("youngs_modulus", "poisson_ratio", "damp", "friction"),
        {"gammat_ratio": 1.0, "damping": "tsuji"},
        "granular hertz/material E DAMP NU damping MODEL tangential mindlin NULL",
    ),
    "hooke-epsd2-liggghts": ("liggghts", _HOOKE + ("mu_r",), {}, "hooke/stiffness ... rolling_friction epsd2"),
    "hooke-epsd-liggghts": ("liggghts", _HOOKE + ("mu_r", "eta_r"), {}, "hooke/stiffness ... rolling_friction epsd"),
    "hooke-cdt-liggghts": ("liggghts", _HOOKE + ("mu_r",), {}, "hooke/stiffness ... rolling_friction cdt"),
    "hooke-sds-lammps": (
        "lammps",
        ("kn", "damp", "kt", "xgammat", "mu", "kroll", "gammaroll", "muroll"),
        {"damping": "mass_velocity"},
        "granular hooke ... tangential linear_history ... rolling sds",
    ),
}


def law_names() -> tuple[str, ...]:
    """Names :func:`make_law` knows."""
    return tuple(LAWS)


def law_code(name: str) -> str:
    """ "liggghts" or "lammps": whose arithmetic the law ``name`` follows (its DEMSettings.flavour)."""
    return _entry(name)[0]


def _entry(name):
    ent = LAWS.get(name)
    if ent is None:
        raise InputError(f"law: expected one of {', '.join(LAWS)}, got {name!r}")
    return ent


def _pos(name, key, v, zero=True):
    return as_positive_float(v, f"law {name}: {key}", allow_zero=zero)


def make_law(name: str, **params):
    """The law object of ``name`` (:func:`law_names`) with checked parameters (SI).

    hooke-liggghts, hooke-lammps, hertz-lammps: kn, kt, gamma_n, gamma_t, mu (hertz-lammps: kn, kt
    in Pa, dampings in 1/(s m)); hooke-epsd2/cdt-liggghts: those + mu_r; hooke-epsd-liggghts:
    + mu_r, eta_r; hertz-liggghts: youngs_modulus, poisson_ratio, restitution, friction
    [tangential_damping=True] (material constants, :class:`gransim.contacts.material.HertzLiggghts`);
    hertz-granular-lammps: youngs_modulus, poisson_ratio, damp, friction [gammat_ratio=1,
    damping="tsuji"] (:class:`~gransim.contacts.material.HertzMaterialLammps`); hooke-sds-lammps:
    kn, damp, kt, xgammat, mu, kroll, gammaroll, muroll [damping="mass_velocity"]. Raises
    InputError for an unknown name, a missing or unknown parameter or a bad value.
    """
    code, req, opt, _ = _entry(name)
    unknown = sorted(set(params) - set(req) - set(opt))
    missing = [k for k in req if k not in params]
    if unknown or missing:
        what = (
            (f"unknown {', '.join(unknown)}" if unknown else "")
            + ("; " if unknown and missing else "")
            + (f"missing {', '.join(missing)}" if missing else "")
        )
        raise InputError(
            f"law {name}: expected parameters {', '.join(req)}"
            + (f" [optional {', '.join(opt)}]" if opt else "")
            + f", got {what}"
        )
    p = {**opt, **params}
    if name in ("hooke-liggghts", "hooke-lammps"):
        from .hooke import hooke_law  # noqa: PLC0415 - cycle: .hooke imports this module

        return hooke_law(*(p[k] for k in _HOOKE), flavour=code)
    if name == "hertz-liggghts":
        from .hertz import HertzHistoryLiggghts  # noqa: PLC0415 - cycle: .hertz imports this module

        m = HertzLiggghts(
            p["youngs_modulus"],
            p["poisson_ratio"],
            p["restitution"],
            p["friction"],
            tangential_damping=p["tangential_damping"],
        )
        return HertzHistoryLiggghts(*m.coefficients())
    if name == "hertz-granular-lammps":
        from .hertz import HertzGranularLammps  # noqa: PLC0415 - cycle: .hertz imports this module

        m = HertzMaterialLammps(
            p["youngs_modulus"],
            p["poisson_ratio"],
            p["damp"],
            p["friction"],
            gammat_ratio=p["gammat_ratio"],
            damping=p["damping"],
        )
        E, damp, kt0, g, mu, idx = m.coefficients()
        return HertzGranularLammps(E, damp, kt0, g, mu, float(idx))
    if name == "hooke-sds-lammps":
        from .rolling import HookeSdsLammps  # noqa: PLC0415 - cycle: .rolling imports this module

        if p["damping"] not in _DAMPING:
            raise InputError(f"law {name}: damping: expected one of {', '.join(_DAMPING)}, got {p['damping']!r}")
        vals = {k: _pos(name, k, p[k], zero=k != "kn") for k in req}
        for k in ("kt", "kroll"):
            if vals[k] == 0.0:
                raise InputError(f"law {name}: {k}: expected a stiffness > 0 N/m (the cap divides by it), got 0")
        return HookeSdsLammps(
            vals["kn"],
            vals["damp"],
            float(_DAMPING.index(p["damping"])),
            vals["kt"],
            vals["xgammat"],
            vals["mu"],
            vals["kroll"],
            vals["gammaroll"],
            vals["muroll"],
        )
    vals = [_pos(name, k, p[k], zero=k != "kn") for k in req]
    if name == "hertz-lammps":
        from .hertz import HertzHistoryLammps as cls  # noqa: PLC0415 - cycle: .hertz imports this module
    elif name == "hooke-epsd2-liggghts":
        from .rolling import HookeEpsd2Liggghts as cls  # noqa: PLC0415 - cycle: .rolling imports this module
    elif name == "hooke-epsd-liggghts":
        from .rolling import HookeEpsdLiggghts as cls  # noqa: PLC0415 - cycle: .rolling imports this module
    else:
        from .rolling import HookeCdtLiggghts as cls  # noqa: PLC0415 - cycle: .rolling imports this module
    return cls(*vals)


__all__ = [
    "LAWS",
    "LawSpec",
    "effective_radius",
    "elastic_energy",
    "flip_signs",
    "law_code",
    "law_names",
    "law_spec",
    "make_law",
    "pair_apart",
    "pair_force",
    "pair_force_split",
    "register_law",
]
