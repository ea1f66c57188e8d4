"""Grain size distributions and periodic disk packings generated from them.

* :mod:`.gsd`: :class:`GrainSizeDistribution` (sieve curves, sampling by area fraction),
  :func:`get_distribution` for the shipped curves ``quartz-sand`` and ``kuhn-1002``.
* :mod:`.pack`: :func:`make_packing` (jammed periodic packings by pressure-controlled FIRE
  minimisation of the contact potential), :func:`packing_stats`, :func:`standard_packings`.
"""

from .gsd import GrainSizeDistribution, distribution_names, get_distribution

__all__ = ["GrainSizeDistribution", "distribution_names", "get_distribution"]
