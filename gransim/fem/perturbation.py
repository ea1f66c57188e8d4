"""The consistent tangent of a Gauss point by perturbation: the central difference of its RVE calls.

Guo & Zhao (*A coupled FEM/DEM approach for hierarchical multiscale modelling of granular media*,
Int. J. Numer. Meth. Engng 99 (2014) 789-818, eq. 10) give the FE Newton the contact-stiffness
tangent D = (1/V) sum (kn n n d d + kt t t d d) of the RVE's state: it misses the sliding contacts
and the rearrangements of a call, so Newton converges linearly (the ratio of successive corrections
reaches 0.8-0.9 past the peak, docs/femxdem.md). A consistent tangent can instead be computed
numerically, by perturbing the material's update (Miehe, *Numerical computation of algorithmic
(consistent) tangent moduli in large-strain computational inelasticity*, Comput. Methods Appl.
Mech. Engrg. 134 (1996) 223-240), as Nitka, Combe, Dascalu & Desrues do for their DEM RVEs
(*Two-scale modeling of granular materials: a DEM-FEM approach*, Granular Matter 13 (2011)
277-281). Here, per Gauss point:

    T[:, :, k, l] = (sigma(D = +h e_k e_l) - sigma(D = -h e_k e_l)) / (2 h)        (1)

sigma(D) the stress of the point law's call ``update(1 + D, s_n)`` from the point's **committed**
state s_n (the last converged one), h the perturbation (``step``): 8 calls per point and load step,
each of ns = max(1e5 h, 2) DEM steps for the DEM RVEs (the strain rate of every call, 1e-5 a step,
is the load steps' own above h = 2e-5). (1) is the derivative at f = 1, the start of the step: the
same tangent serves the predictor (from the commit that made s_n, :meth:`commit_response`) and
every Newton iterate of the step (a modified Newton iteration with the tangent of the committed
state), so it is computed once per committed state and kept while the state lives. The
perturbation calls, like Newton's iterates, start from s_n and never write into it (its arrays are
read-only, :func:`gransim.fem.material_points.freeze`); their new states are dropped.

:class:`PerturbationTangent` wraps any point law of :mod:`gransim.fem.material_points` (the DEM
RVE in YADE's arithmetic, :class:`gransim.fem.dem_rve.DemRVE`, or in LAMMPS',
:class:`gransim.fem.lammps_rve.LammpsPointLaw`): stress, states, observables and checkpoints are
the wrapped law's, bit for bit; only the tangent differs. Stress and tangent in Pa.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from .material_points import is_frozen

#: the tangents a DEM Gauss point offers (``gransim femxdem --tangent``)
TANGENTS = ("contact", "perturbation")
#: bounds of ``--tangent-step``: below 2e-5 a DEM RVE call runs its floor of 2 steps (ns = max(1e5 h,
#: 2)), at a faster strain rate than the load steps' 1e-5 a step: the tangent of another, dynamic,
#: response (measured on a loaded RVE: 11 % from that of h = 3e-5 at h = 1e-5); above 1e-2 a call
#: runs over 1000 DEM steps and crosses many contacts' sliding thresholds (a secant, not a tangent)
MIN_STEP = 2.0e-5
MAX_STEP = 1.0e-2
#: the default h (``--tangent-step``): the fewest DEM steps over 40 load steps of the 1 x 1 specimen
#: among 1e-4, 3e-4 and 1e-3 (docs/femxdem.md, "The tangent")
DEFAULT_STEP = 3.0e-4


@dataclass(frozen=True, eq=False)
class PerturbationTangent:
    """``law`` with the tangent (1) of the module docstring, of perturbation ``step`` (h)."""

    law: object
    step: float
    _kept: weakref.WeakKeyDictionary = field(
        default_factory=weakref.WeakKeyDictionary, init=False, repr=False, compare=False
    )

    def __post_init__(self):
        h = float(self.step)
        if not (np.isfinite(h) and h > 0):  # the range of --tangent-step is checked at the command line
            raise InputError(f"--tangent-step: expected a positive perturbation, got {h:g}")
        object.__setattr__(self, "step", h)

    def __getstate__(self):  # the kept tangents stay where they were computed (a Dask worker's law is a copy)
        return {"law": self.law, "step": self.step}

    def __setstate__(self, d):
        object.__setattr__(self, "law", d["law"])
        object.__setattr__(self, "step", d["step"])
        object.__setattr__(self, "_kept", weakref.WeakKeyDictionary())

    @property
    def applied_step(self) -> float:
        """h as applied: rounded up to a multiple of 2^-52, so that f = 1 +- h is exact and the law's
        D = f - 1 is +-h exactly. Both calls then run the same number of steps ns = max(1e5 h, 2):
        with (1 + h) - 1 != h they can differ by one (measured on a loaded DEM RVE: the tangent 4e-4
        off at h = 1e-3, 1.2 % at h = 1e-4, against the difference of calls with D = +-h)."""
        ulp = np.finfo(float).eps
        return float(np.ceil(self.step / ulp) * ulp)

    def tangent(self, state) -> np.ndarray:
        """T (2, 2, 2, 2) of (1) at ``state`` (never modified): 8 calls of the wrapped law from it,
        with f = 1 +- h e_k e_l (h: :attr:`applied_step`). Kept for a frozen state (every array
        read-only: a committed state) while it lives."""
        t = self._kept.get(state) if is_frozen(state) else None
        if t is not None:
            return t.copy()
        h = self.applied_step
        t = np.empty((2, 2, 2, 2))
        for k in range(2):
            for m in range(2):
                e = np.zeros((2, 2))
                e[k, m] = h
                sp = np.asarray(self.law.update(np.eye(2) + e, state)[0], float)
                sm = np.asarray(self.law.update(np.eye(2) - e, state)[0], float)
                t[:, :, k, m] = (sp - sm) / (2.0 * h)
        if is_frozen(state):
            t.flags.writeable = False
            self._kept[state] = t
        return t.copy()

    def initial_state(self, g: int):
        return self.law.initial_state(g)

    def response(self, state):
        """(sigma (2, 2), T (2, 2, 2, 2)) of ``state``: the wrapped law's stress, the tangent (1)."""
        sigma, _ = self.law.response(state)
        return sigma, self.tangent(state)

    def update(self, f, state):
        """The wrapped law's update from ``state`` (stress and new state, bit for bit) with the
        tangent (1) of ``state``, the committed state every Newton iterate of a step starts from."""
        sigma, _, new = self.law.update(f, state)
        return sigma, self.tangent(state), new

    def commit_response(self, state, sigma, tangent):
        """The committed (stress, tangent) of a state just committed (:meth:`gransim.fem.
        material_points.GaussChunk.commit`): the last iterate's stress, and the tangent (1) of
        the state itself, for the next step's predictor and iterates."""
        return sigma, self.tangent(state)

    def observables(self, state) -> dict:
        fn = getattr(self.law, "observables", None)
        return fn(state) if callable(fn) else {}

    def snapshot(self, state):
        """The wrapped law's RVE picture data (:func:`gransim.fem.femxdem.field_record`)."""
        fn = getattr(self.law, "snapshot", None)
        if callable(fn):
            return fn(state)
        from .output_femxdem import rve_snapshot  # noqa: PLC0415 - start-up: numpy

        return rve_snapshot(state)

    def pack_states(self, states) -> dict:
        return self.law.pack_states(states)

    def unpack_states(self, arrays: dict) -> list:
        return self.law.unpack_states(arrays)


__all__ = ["DEFAULT_STEP", "MAX_STEP", "MIN_STEP", "TANGENTS", "PerturbationTangent"]
