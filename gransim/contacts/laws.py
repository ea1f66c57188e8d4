"""The registry of contact laws: a law is one module that declares, and registers here, everything
about itself; this module names no concrete law.

A law module (``gransim/contacts/hooke.py``, ``hertz.py``, ``rolling.py``; a new law is one more
file, docs/laws.md "Adding a law") calls :func:`register_law` once per law with

* its **parameters**: a namedtuple class of floats (its numba type selects the law at compile
  time) and, for a law usable by name, ``name``, ``code`` (whose arithmetic: "liggghts" or
  "lammps"), ``required`` and ``optional`` parameter names and ``build`` (keywords -> the law
  object, values checked there: InputError naming the law and the parameter);
* its **time scale**: ``timescale(law, packing, overlap) -> (contact time (s), damping ratio)``
  of the two lightest disks at the largest overlap ``overlap`` (m) present, from which the engine's
  time-step check (:func:`gransim.dem.engine.stability_limit`) takes its limit;
* its **kernel**: the jitted ``pair`` function (below), the optional ``apart`` (an entry whose
  disks do not touch), the history ``width`` and ``flip`` signs, optionally ``select``: a
  branch-free twin of ``pair`` that the force loops run as SIMD code over blocks of list entries
  (:func:`pair_select`; the law *offers* it, the loops do not test for a class), and ``energy``;
* its **deck lines**: ``deck(law) -> list[str]``, the material / ``pair_style`` / ``pair_coeff``
  lines of its code's input deck (:func:`deck_lines`; reference_runs writes them as they are).

The force loops of :mod:`gransim.dem.kernels` call :func:`pair_force_split` and
:func:`pair_apart` with the law object as their first argument. Both are
``numba.extending.overload``-ed: numba types the call by the law's namedtuple class, looks the
class up in the registry and inlines that law's pair function. Each law therefore gets its own
specialised copy of the loop, compiled once and kept in numba's disk cache (the cache key is the
argument types, i.e. the law's class, which is pickled by reference: register laws from module
level of an importable module; a law defined in a test module or a script registers with
``cache=False``, :class:`LawSpec`).

The built-in laws register when their modules are imported; :func:`make_law`, :func:`law_names`,
:func:`law_code` and :func:`law_parameters` import the modules listed in
:data:`gransim.contacts.LAW_MODULES` first.

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

A ``select`` function (laws of width 2 only) takes ``(law, delx, dely, rsq, radi, radj, vix, viy,
vjx, vjy, wi, wj, mi, mj, dt, s0, s1, update)`` for *any* list entry, touching or not, and returns
``(touch, fx, fy, ti, tj, s0, s1, sliding, overlap)`` with touch and sliding as floats 1.0/0.0 and
the spring (s0, s1) as the entry keeps it (updated when touching; kept or zeroed as ``apart``
when not): the same floating-point operations as ``pair`` on the path ``pair`` takes, the branches
written as selects (gransim.contacts.hooke.hooke_select_liggghts).

**Energy**: ``energy(law, overlap, hist, radi, radj)`` (arrays over the K touching contacts) the
elastic energy (J) stored in them (:class:`LawSpec`, :func:`elastic_energy`; docs/laws.md).
"""

from __future__ import annotations

import importlib
import inspect
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numba.extending import overload

from .._numba import njit
from .._validate import as_positive_float
from ..errors import InputError

#: the codes whose arithmetic a law follows (its ``code``; the engine's ``flavour``): LIGGGHTS' and
#: LAMMPS' laws are pair functions of the engine's list loops (:data:`PAIR_CODES`); YADE's law runs
#: in YADE's own interaction loop, the yade cell's (gransim.contacts.yade_cundall_strack)
CODES = ("liggghts", "lammps", "yade")
#: the codes whose laws are pair functions (a ``pair`` registered): any cell of LIGGGHTS' and
#: LAMMPS' arithmetic runs them, and their decks are the codes' ``pair_style`` lines
PAIR_CODES = ("liggghts", "lammps")


@dataclass(frozen=True)
class LawSpec:
    """A registered law.

    Attributes
    ----------
    params : the namedtuple class of the law's parameters (its numba type selects the law).
    pair : jitted pair function (module docstring for its arguments and result); None for a law
        whose kernel is its code's own interaction loop (YADE's).
    width : columns of the per-contact history array (0: a law without history).
    apart : jitted ``apart(law, hist, e)`` for an entry that does not touch, or None (keep).
    flip : (width,) signs of the history seen from the other particle: a new list entry (a, b)
        that was stored as (b, a) before a rebuild takes ``flip * hist`` (-1 for vectors in the
        frame of i, as the tangential spring; +1 for scalars).
    energy : optional Python ``energy(law, overlap (K,), hist (K, width), radi (K,), radj (K,))
        -> float``: the elastic energy (J) stored in the K touching contacts with overlaps (m),
        histories and the radii of their two disks (m; R* = r_i r_j/(r_i + r_j) of a Hertz or a
        rolling law), for the engine's energy balance; None: 0.
    cache : the kernels compiled for this law go to numba's disk cache. Only for a class defined
        in a module every process can import (a ``gransim`` module): the cache index of a kernel
        lists the classes of all its compiled signatures and every process unpickles all of it,
        so a class from a test module or a script would break every other process sharing the
        cache (ModuleNotFoundError). Register such laws with ``cache=False``.
    split_torque : the pair function returns two more floats, (..., fn, tqa2, tqb2): torques the
        loop adds to a and b *after* ti and tj, each on its own (LAMMPS ``pair_style granular``
        adds the rolling torque to the particle's torque after the tangential one,
        pair_granular.cpp:664-686, 693-705; one sum ti would round differently). False: the
        loop adds -0.0 (folded away by the compiler: no work for the other laws).
    select : optional jitted branch-free twin of ``pair`` (module docstring): the force loops of
        the orthogonal cell run it over blocks of entries as SIMD code, bit for bit ``pair``.
    name, code, required, optional, build, description : a law usable by name (:func:`make_law`):
        its name, its code (:data:`CODES`), parameter names, defaults of the optional
        ones, ``build(**params) -> law`` (checks the values), one line of description.
    timescale : ``timescale(law, packing, overlap) -> (contact time (s), damping ratio)`` for the
        time-step check (:func:`stable_time_step`); None: the law sets no limit.
    deck : ``deck(law) -> list[str]``: the deck lines of the law in its code (:func:`deck_lines`).
    """

    params: type
    pair: Callable | None
    width: int
    apart: Callable | None
    flip: tuple
    energy: Callable | None
    cache: bool = True
    split_torque: bool = False
    select: Callable | None = None
    name: str | None = None
    code: str | None = None
    required: tuple = ()
    optional: dict = field(default_factory=dict)
    build: Callable | None = None
    description: str = ""
    timescale: Callable | None = None
    deck: Callable | None = None


_REGISTRY: dict[type, LawSpec] = {}
_NAMES: dict[str, LawSpec] = {}


def register_law(
    params: type,
    pair: Callable | None,
    width: int,
    *,
    apart: Callable | None = None,
    flip=None,
    energy: Callable | None = None,
    cache: bool = True,
    split_torque: bool = False,
    select: Callable | None = None,
    name: str | None = None,
    code: str | None = None,
    required=(),
    optional: dict | None = None,
    build: Callable | None = None,
    description: str = "",
    timescale: Callable | None = None,
    deck: Callable | None = None,
) -> LawSpec:
    """Register ``params`` (a namedtuple class of floats) with its jitted ``pair`` function and
    what else the law declares (:class:`LawSpec`; ``flip`` defaults to -1 for every column).

    A law with a ``name`` needs its ``code`` and ``build``. ``pair`` None: a law whose kernel is
    its code's own interaction loop, not a pair function (YADE's, :data:`CODES`); the engine runs
    it only in its code's arithmetic. Registering the same class (or name)
    again replaces its entry (a module reloaded); raises InputError for a class that is not a
    namedtuple, a bad width/flip, a ``select`` on a law whose history is not 2 wide, or a named
    law without code or build.
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
    if select is not None and width != 2:
        raise InputError(f"register_law: a select function needs a history of width 2 (the spring), got {width}")
    if pair is None and code in PAIR_CODES:
        raise InputError(f"register_law: a {code} law needs its pair function, got None")
    if name is not None and (code not in CODES or build is None):
        raise InputError(f"register_law: law {name!r} needs its code (one of {', '.join(CODES)}) and a build function")
    spec = LawSpec(
        params,
        pair,
        int(width),
        apart,
        flip,
        energy,
        bool(cache),
        bool(split_torque),
        select,
        name,
        code,
        tuple(required),
        dict(optional or {}),
        build,
        description,
        timescale,
        deck,
    )
    _REGISTRY[params] = spec
    if name is not None:
        _NAMES[name] = spec
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
    """The spec of a law's numba type, None for another type or a law without a pair function
    (the overloads below then do not apply)."""
    cls = getattr(ty, "instance_class", None)
    spec = _REGISTRY.get(cls)
    return spec if spec is not None and spec.pair is not None else None


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


def pair_select(law, delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, dt, s0, s1, update):
    """The branch-free pair function ``select`` that ``law``'s class offers (``LawSpec.select``):
    (touch, fx, fy, ti, tj, s0, s1, sliding, overlap) for any list entry (interpreted:
    NUMBA_DISABLE_JIT)."""
    return _REGISTRY[type(law)].select(
        law, delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, dt, s0, s1, update
    )


@overload(pair_select, inline="always")
def _ov_pair_select(law, delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, dt, s0, s1, update):
    spec = _spec_of_type(law)
    if spec is None or spec.select is None:
        return None
    fn = spec.select

    def impl(law, delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, dt, s0, s1, update):
        return fn(law, delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, dt, s0, s1, update)

    return impl


def spring_pair(core, n_params: int):
    """The pair function of a law whose one-pair arithmetic ``core`` keeps a tangential spring:
    ``core(delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, p_1 .. p_n, dt, s0, s1,
    update) -> (fx, fy, ti, tj, s0, s1, sliding, fn)`` with p the law's first ``n_params`` (5 or 6)
    fields, in the order of ``core``'s parameters. The pair function reads the entry's spring from
    ``hist[e, 0:2]`` and writes the updated one back: one adapter for every such law instead of a
    copy per law. (Two bodies, as numba inlines no closure that calls with ``*args``.)"""
    if n_params not in (5, 6):
        raise InputError(f"spring_pair: 5 or 6 law parameters before dt, got {n_params}")
    six = n_params == 6

    @njit(inline="always")
    def pair(law, hist, e, delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, dt, update):
        if six:
            fx, fy, ti, tj, s0, s1, sliding, fn = core(
                delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj,
                law[0], law[1], law[2], law[3], law[4], law[5], dt, hist[e, 0], hist[e, 1], update,
            )  # fmt: skip
        else:
            fx, fy, ti, tj, s0, s1, sliding, fn = core(
                delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj,
                law[0], law[1], law[2], law[3], law[4], dt, hist[e, 0], hist[e, 1], update,
            )  # fmt: skip
        hist[e, 0] = s0
        hist[e, 1] = s1
        return fx, fy, ti, tj, sliding, fn

    return pair


def spring_select(core):
    """The block path (``LawSpec.select``) of a law of 5 parameters whose branch-free one-pair
    arithmetic ``core`` takes the 13 pair arguments, the law's fields, dt, the spring s0, s1 and
    ``update`` (:func:`spring_pair`'s convention, the spring passed in and returned)."""

    @njit(inline="always")
    def select(law, delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, dt, s0, s1, update):
        return core(
            delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj,
            law[0], law[1], law[2], law[3], law[4], dt, s0, s1, update,
        )  # fmt: skip

    return select


def offers_select(law_type) -> bool:
    """Does the law of ``law_type`` (a law class or its numba type) offer a branch-free block
    path (``LawSpec.select``)? Read at compile time by the force loops' dispatch."""
    cls = getattr(law_type, "instance_class", law_type)
    spec = _REGISTRY.get(cls)
    return spec is not None and spec.select is not None


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


# ----------------------------------------------------------------------------- by name
def _load_builtin() -> None:
    """Import the law modules of the package (:data:`gransim.contacts.LAW_MODULES`): they register."""
    from . import LAW_MODULES  # noqa: PLC0415 - cycle: gransim.contacts (its __init__ imports this module)

    for mod in LAW_MODULES:
        importlib.import_module(f"{__package__}.{mod}")


def _named() -> dict[str, LawSpec]:
    """The named laws, those of :data:`gransim.contacts.LAW_MODULES` first in that module order
    (each module's laws as it registers them), then any other in the order they registered."""
    _load_builtin()
    from . import LAW_MODULES  # noqa: PLC0415 - cycle: gransim.contacts (see _load_builtin)

    mods = [f"{__package__}.{m}" for m in LAW_MODULES]
    order = list(_NAMES)

    def key(name):
        mod = _NAMES[name].params.__module__
        return (mods.index(mod) if mod in mods else len(mods), order.index(name))

    return {k: _NAMES[k] for k in sorted(_NAMES, key=key)}


def law_names(codes: tuple = PAIR_CODES) -> tuple[str, ...]:
    """Names :func:`make_law` knows of laws in the arithmetic of ``codes`` (default
    :data:`PAIR_CODES`: the pair laws of LIGGGHTS and LAMMPS, which the list loops, the decks and
    the biaxial laws' validation run; ``CODES`` adds YADE's), in the order their modules
    registered them."""
    return tuple(k for k, spec in _named().items() if spec.code in codes)


def _entry(name) -> LawSpec:
    named = _named()
    spec = named.get(name)
    if spec is None:
        raise InputError(f"law: expected one of {', '.join(named)}, got {name!r}")
    return spec


def law_code(name: str) -> str:
    """ "liggghts", "lammps" or "yade": whose arithmetic the law ``name`` follows (the engine's
    ``flavour``)."""
    return _entry(name).code


def law_parameters(name: str) -> tuple[tuple[str, ...], dict]:
    """(required parameter names, optional parameters with their defaults) of the law ``name``."""
    spec = _entry(name)
    return spec.required, dict(spec.optional)


def law_description(name: str) -> str:
    """One line on the law ``name`` (its code's pair style)."""
    return _entry(name).description


def make_law(name: str, **params):
    """The law object of ``name`` (:func:`law_names`) with checked parameters (SI): the law
    module's ``build`` with the optional parameters' defaults filled in. Raises InputError for an
    unknown name, a missing or unknown parameter (listing what the law expects) or a bad value
    (from ``build``, naming the law and the parameter). The parameters of each law: docs/laws.md.
    """
    spec = _entry(name)
    req, opt = spec.required, spec.optional
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
    return spec.build(**{**opt, **params})


def deck_lines(law, engine: str) -> list[str]:
    """The deck lines of ``law`` for ``engine`` ("liggghts" or "lammps"): material properties,
    ``pair_style`` and ``pair_coeff``, as the law module declares them (``LawSpec.deck``).
    InputError for a law of the other code or a law without deck lines."""
    spec = law_spec(law)
    cls = type(law).__name__
    if spec.deck is None or spec.code is None:
        raise InputError(f"law: no deck lines for {cls} (its module registers no deck function)")
    if spec.code != engine:
        raise InputError(
            f"law: {cls} is a {spec.code} law, the deck is for {engine} (use the {engine} variant of the law)"
        )
    return list(spec.deck(law))


def time_scale(law, packing, overlap: float = 0.0) -> tuple[float, float]:
    """(contact time (s), damping ratio) of ``law`` for the two lightest disks of ``packing`` at
    the largest overlap ``overlap`` (m) present: the law's ``timescale`` (``LawSpec``), (inf, 0)
    for a law without one (it sets no limit)."""
    fn = law_spec(law).timescale
    if fn is None:
        return float("inf"), 0.0
    tc, zeta = fn(law, packing, float(overlap))
    return float(tc), float(zeta)


def as_law_float(name: str, key: str, value, allow_zero: bool = True) -> float:
    """``value`` as a finite float >= 0 (> 0 unless ``allow_zero``); InputError naming the law
    ``name`` and its parameter ``key`` otherwise (the check of a law module's ``build``)."""
    return as_positive_float(value, f"law {name}: {key}", allow_zero=allow_zero)


def deck_float(v) -> str:
    """A number of a deck line: %.17g, the double read back exactly by either code."""
    return f"{float(v):.17g}"


def lightest_pair_mass(packing) -> float:
    """m* = m_1 m_2/(m_1 + m_2) (kg) of the two lightest disks of ``packing`` (the shortest
    contact time of a law whose stiffness does not depend on the disks' size)."""
    m = np.sort(packing.masses)
    return float(m[0] * m[1] / (m[0] + m[1]))


__all__ = [
    "CODES",
    "PAIR_CODES",
    "as_law_float",
    "LawSpec",
    "deck_float",
    "deck_lines",
    "effective_radius",
    "elastic_energy",
    "flip_signs",
    "law_code",
    "law_description",
    "law_names",
    "law_parameters",
    "law_spec",
    "lightest_pair_mass",
    "make_law",
    "pair_apart",
    "pair_force",
    "pair_force_split",
    "offers_select",
    "pair_select",
    "register_law",
    "time_scale",
]
