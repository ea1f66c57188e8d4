"""Guo & Zhao's FEM x DEM biaxial test run by their own code, as Debian ships it (YADE 2023.02a and
escript 5.6), ported to Python 3 by ``port.patch``: the reference side of gransim's FEM x DEM.

Guo & Zhao, "A coupled FEM/DEM approach for hierarchical multiscale modelling of granular media",
Int. J. Numer. Meth. Engng 99 (2014) 789-818. How to run it and what was measured:
docs/femxdem_reference.md.
"""
