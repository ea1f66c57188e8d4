"""Grain size distributions and periodic disk packings generated from them.

Modules (imports flow one way: gsd, fire -> fire_shape, stats -> pack, compaction -> standard):

* :mod:`.gsd`: :class:`GrainSizeDistribution` (sieve curves, sampling by area fraction),
  :func:`get_distribution` for the shipped curves ``quartz-sand`` and ``kuhn-1002``.
* :mod:`.fire`: the FIRE 2.0 enthalpy minimiser (:class:`Minimiser`, :class:`FireParameters`).
* :mod:`.fire_shape`: its variant over the full cell shape (:class:`ShapeMinimiser`; the
  shear-stress-free packings of ``make_packing(..., cell="shape")``).
* :mod:`.stats`: :func:`packing_stats` and :func:`rattlers`.
* :mod:`.pack`: :func:`make_packing` (jammed periodic packings by pressure-controlled FIRE
  minimisation of the contact potential).
* :mod:`.compaction`: :func:`compact_packing` (looser, frictional assemblies by isotropic DEM
  compaction of a granular gas: the Kuhn assembly).
* :mod:`.standard`: the standard assemblies of the papers (:data:`STANDARD_PACKINGS`,
  :func:`standard_packings`).
* :mod:`.stiffness` (imported on its own, ``from gransim.generation.stiffness import ...``: it loads
  scipy.sparse.linalg, which ``import gransim.generation`` does not need): the enthalpy Hessian of a
  packing and the Newton step (stability analysis; docs/generation.md).
"""

from .compaction import compact_packing, compaction_run
from .fire import FireParameters, Minimiser
from .fire_shape import ShapeMinimiser
from .gsd import GrainSizeDistribution, distribution_names, get_distribution
from .pack import make_packing
from .standard import (
    RVE_MEAN_OVERLAP,
    SHIPPED_DIR,
    STANDARD_PACKINGS,
    build_standard,
    shipped_packing,
    standard_packings,
)
from .stats import packing_stats, rattlers

__all__ = [
    "RVE_MEAN_OVERLAP",
    "SHIPPED_DIR",
    "STANDARD_PACKINGS",
    "FireParameters",
    "GrainSizeDistribution",
    "Minimiser",
    "ShapeMinimiser",
    "build_standard",
    "compact_packing",
    "compaction_run",
    "distribution_names",
    "get_distribution",
    "make_packing",
    "packing_stats",
    "rattlers",
    "shipped_packing",
    "standard_packings",
]
