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

    register_law(HertzLiggghts, hertz_pair, width=2, energy=hertz_energy)

A law defined in a test module or a script registers with ``cache=False`` (:class:`LawSpec`).

Arguments of a pair function (all SI): ``law`` the parameters; ``hist`` (M, width) float64, the
history of every list entry, row ``e`` the entry's (frame of i; update in place); d = (delx, dely)
= x_i - x_j (j's periodic image, m), ``rsq`` = |d|^2 < (r_i + r_j)^2 (the caller tested contact);
radii (m), velocities (m/s), spins (rad/s), masses (kg) of i and j; ``dt`` (s); ``update`` False
in the set-up evaluation of a run (no history increment, as both codes' ``run`` set-up). Returns
(fx, fy) the force on i (N; j gets minus it), ti and tj the torques on i and j (N m), ``sliding``
(bool) and F_n (N). The optional ``apart(law, hist, e)`` runs for an entry whose disks do not
touch (LAMMPS' ``gran/*/history`` zeroes the spring there; LIGGGHTS keeps it).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numba.extending import overload

from ..errors import InputError


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
    energy : optional Python ``energy(law, overlap (K,), hist (K, width)) -> float``: the elastic
        energy (J) stored in the touching contacts, for the engine's energy balance; None: 0.
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


_REGISTRY: dict[type, LawSpec] = {}


def register_law(params: type, pair: Callable, width: int, *, apart: Callable | None = None,
                 flip=None, energy: Callable | None = None, cache: bool = True) -> LawSpec:
    """Register ``params`` (a namedtuple class of floats) with its jitted ``pair`` function.

    ``width`` >= 0 history columns; ``apart``, ``flip`` (default -1 for every column), ``energy``
    and ``cache`` (False for a law defined outside an importable package module): :class:`LawSpec`. Registering the same class again replaces its entry (a module
    reloaded); raises InputError for a class that is not a namedtuple or a bad width/flip.
    """
    if not (isinstance(params, type) and issubclass(params, tuple) and hasattr(params, "_fields")):
        raise InputError(f"register_law: params must be a namedtuple class, got {params!r}")
    if int(width) != width or width < 0:
        raise InputError(f"register_law: width must be an integer >= 0 (history columns), got {width!r}")
    flip = (-1.0,) * int(width) if flip is None else tuple(float(s) for s in flip)
    if len(flip) != width or any(s not in (-1.0, 1.0) for s in flip):
        raise InputError(f"register_law: flip must hold {width} signs (+1 or -1), got {flip!r}")
    spec = LawSpec(params, pair, int(width), apart, flip, energy, bool(cache))
    _REGISTRY[params] = spec
    return spec


def law_spec(law) -> LawSpec:
    """The :class:`LawSpec` of a law object (an instance of a registered class)."""
    spec = _REGISTRY.get(type(law))
    if spec is None:
        known = ", ".join(sorted(c.__name__ for c in _REGISTRY)) or "none"
        raise InputError(f"law: expected an instance of a registered contact law ({known}), got "
                         f"{type(law).__name__} (gransim.contacts.laws.register_law)")
    return spec


def _spec_of_type(ty) -> LawSpec | None:
    cls = getattr(ty, "instance_class", None)
    return _REGISTRY.get(cls)


def pair_force(law, hist, e, delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, dt, update):
    """The pair function of ``law``'s registered class (interpreted: NUMBA_DISABLE_JIT)."""
    return _REGISTRY[type(law)].pair(law, hist, e, delx, dely, rsq, radi, radj, vix, viy, vjx, vjy,
                                     wi, wj, mi, mj, dt, update)


def pair_apart(law, hist, e):
    """The ``apart`` function of ``law``'s class, if any (interpreted: NUMBA_DISABLE_JIT)."""
    fn = _REGISTRY[type(law)].apart
    if fn is not None:
        fn(law, hist, e)


@overload(pair_force, inline="always")
def _ov_pair_force(law, hist, e, delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, dt,
                   update):
    spec = _spec_of_type(law)
    if spec is None:
        return None
    fn = spec.pair

    def impl(law, hist, e, delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, dt, update):
        return fn(law, hist, e, delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, dt, update)

    return impl


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


def elastic_energy(law, overlap: np.ndarray, hist: np.ndarray) -> float:
    """Elastic energy (J) of the touching contacts with ``overlap`` (K,) and history (K, width)."""
    fn = law_spec(law).energy
    return 0.0 if fn is None else float(fn(law, overlap, hist))


__all__ = ["LawSpec", "elastic_energy", "flip_signs", "law_spec", "pair_apart", "pair_force", "register_law"]
