"""The constants of the papers gransim implements, with one statement of their units.

Meier, Steinmann & Kuhl, "Towards completeness, a multiscale approach of confined particulate
systems" (2007), Table 1 (the slope stability example), and the
RVE study of their section 4, which uses the same normal contact stiffness.

Units
-----
The seed's contact potential, eq. (4), Phi_ij = 1/2 E_n eps_ij^2 H(eps_ij), is written for a 2D
disk assembly: the overlap eps_ij is a length (m), so the contact force E_n eps_ij is a force per
unit out-of-plane thickness and Table 1 quotes E_n in N/m^2 = (N/m) per m of thickness. gransim's
2D codes (the Taylor and relaxed RVEs, the DEM) work per unit thickness throughout:

- a 2D contact stiffness ``kn`` is in N/m (force per m of thickness per m of overlap), and
  ``kn = E_n * THICKNESS``;
- a 2D stress (the RVE's Piola stress, the DEM's virial stress) is a force per length, N/m;
- the plane-strain FE code works in Pa; its stress is the 2D stress divided by the out-of-plane
  thickness: ``sigma_Pa = sigma_2D / THICKNESS`` (:func:`stress_2d_to_pa`), and its tangent
  likewise.

With THICKNESS = 1 m the numbers coincide; the conversion is still made explicitly at the rve -> fem
boundary (:func:`stress_2d_to_pa`, :func:`tangent_2d_to_pa`) so that a change of thickness or of
the unit convention cannot reinterpret units silently.
"""

from __future__ import annotations

import numpy as np

#: out-of-plane thickness of the plane-strain slope and of the 2D assemblies (m)
THICKNESS = 1.0

#: normal contact stiffness E_n of Table 1 (N/m^2: N/m of overlap per m of thickness)
E_N = 2.8e7

#: the 2D contact stiffness of the RVEs (N/m): E_n times the thickness
KN_2D = E_N * THICKNESS

#: mass density of the slope, Table 1 (kg/m^3)
DENSITY = 2.5e3

#: gravitational acceleration used with Table 1 (m/s^2)
GRAVITY = 9.81

#: footing load of Table 1: -4.0e7 N (per m of thickness, plane strain), the "paper" protocol
FOOTING_LOAD_PAPER = -4.0e7

#: footing load of the "service" protocol (N per m of thickness): a well-posed load level that runs
#: to the end with the Taylor RVE
FOOTING_LOAD_SERVICE = -5.0e6


def stress_2d_to_pa(p_2d, thickness: float = THICKNESS):
    """A 2D stress (N/m; any shape) as a plane-strain stress in Pa: ``p_2d / thickness``."""
    return np.asarray(p_2d, dtype=float) / float(thickness)


def tangent_2d_to_pa(a_2d, thickness: float = THICKNESS):
    """A 2D tangent dP/dF (N/m; any shape) as a plane-strain tangent in Pa: ``a_2d / thickness``."""
    return np.asarray(a_2d, dtype=float) / float(thickness)


__all__ = [
    "DENSITY",
    "E_N",
    "FOOTING_LOAD_PAPER",
    "FOOTING_LOAD_SERVICE",
    "GRAVITY",
    "KN_2D",
    "THICKNESS",
    "stress_2d_to_pa",
    "tangent_2d_to_pa",
]
