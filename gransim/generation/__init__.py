"""Grain size distributions and periodic disk packings generated from them.

* :mod:`.gsd`: :class:`GrainSizeDistribution` (sieve curves, sampling by area fraction),
  :func:`get_distribution` for the shipped curves ``quartz-sand`` and ``kuhn-1002``.
* :mod:`.pack`: :func:`make_packing` (jammed periodic packings by pressure-controlled FIRE
  minimisation of the contact potential), :func:`packing_stats`, :func:`standard_packings`.
* :mod:`.compaction`: :func:`compact_packing` (looser, frictional assemblies by isotropic DEM
  compaction of a granular gas: the Kuhn assembly).
"""

from .gsd import GrainSizeDistribution, distribution_names, get_distribution
from .compaction import compact_packing, compaction_run
from .pack import (STANDARD_PACKINGS, FireParameters, build_standard, make_packing, packing_stats, rattlers,
                   standard_packings)

__all__ = ["STANDARD_PACKINGS", "FireParameters", "build_standard", "compact_packing", "compaction_run", "GrainSizeDistribution", "distribution_names",
           "get_distribution", "make_packing", "packing_stats", "rattlers", "standard_packings"]
