"""The RVE's stress scale on the FE side, and shear-stabilised (sheared-cell) RVEs in the slope.

From docs/slope.md, "Pressure-scaled shear-stabilised RVEs": the FE2 slope sees the RVE's
Taylor stress at F = 1 as its prestress, in Pa at unit thickness (gransim.fem.materials.RVEMaterial).
These checks tie that stress to the packing's generation pressure and to its contacts, independently
of the RVE kernels, and check that a packing in a sheared cell (``make_packing(..., cell="shape")``)
is accepted by the slope's reference-state analysis (gransim.fem.stability) with a stable K(0).
"""

import numpy as np
import pytest

pytest.importorskip("gransim.rve")

from gransim import paper  # noqa: E402
from gransim.contacts import find_neighbours_bruteforce  # noqa: E402
from gransim.fem.materials import RVEMaterial  # noqa: E402
from gransim.fem.stability import mean_overlap_strain, reference_stability  # noqa: E402
from gransim.generation import make_packing  # noqa: E402
from gransim.rve import TaylorMaterial  # noqa: E402

KN = paper.KN_2D
OVERLAPS = (2.7e-4, 2.7e-3)


@pytest.fixture(scope="module")
def shape_packings():
    return {m: make_packing("quartz-sand", 60, seed=2, cell="shape", mean_overlap=m) for m in OVERLAPS}


def _virial_pressure(p):
    """p = 1/(2V) sum_c kn eps_c |l_c| (N/m): the contact virial (Meier et al. 2007 eq 10 at F = 1),
    from a brute-force O(N^2) periodic search."""
    nl = find_neighbours_bruteforce(p.positions, p.radii, p.cell, 0.0)
    eps = nl.overlaps(p.radii)
    return KN * np.sum(eps * nl.distance) / (2.0 * p.area)


def test_fe_prestress_is_the_generation_pressure_and_scales_with_the_overlap(shape_packings):
    pressures = {}
    for m, pk in shape_packings.items():
        assert not np.isclose(pk.cell[0, 1], 0.0)  # a sheared cell
        P = RVEMaterial(TaylorMaterial(pk, KN)).evaluate(np.eye(2)[None]).piola[0]  # Pa
        p = -0.5 * np.trace(P)
        # isotropic and shear free (the shape mode's stop criterion, force_tol 1e-5 p)
        assert abs(P[0, 1]) <= 2e-5 * p and abs(P[0, 0] - P[1, 1]) <= 4e-5 * p
        # the FE prestress in Pa is the packing's virial pressure / unit thickness ...
        assert p == pytest.approx(_virial_pressure(pk) / paper.THICKNESS, rel=1e-12)
        # ... and the generation's imposed pressure (reduced by kn)
        assert p == pytest.approx(KN * pk.metadata["pressure_reduced"] / paper.THICKNESS, rel=1e-4)
        # p = kn <eps/c> x z phi <c^2> / (4 pi <r^2>) ~ 1.1-1.3 kn <eps/c> for these packings
        assert 0.9 < p / (KN * mean_overlap_strain(pk)) < 1.5
        pressures[m] = p
    ratio = pressures[OVERLAPS[1]] / pressures[OVERLAPS[0]]
    # ten times the overlap: ten times the pressure, a little more as contacts are added
    assert 10.0 <= ratio < 13.0


def test_sheared_cell_rve_gives_a_stable_slope_tangent_and_smaller_relative_shear_at_higher_pressure(shape_packings):
    rel = {}
    for m, pk in shape_packings.items():
        for kind in ("taylor", "relaxed"):
            s = reference_stability(pk, kind)  # the 20 x 19 slope, 749 unknowns
            assert s["n_negative"] == 0, (m, kind, s)
        rel[m] = s["shear_median"] / mean_overlap_strain(pk)  # relaxed
    # the dead-load shear strains the relaxed RVEs are asked for, in units of their overlap strain,
    # fall when the RVE is generated at a higher pressure (its shear stiffness grows with p)
    assert rel[OVERLAPS[1]] < 0.3 * rel[OVERLAPS[0]]
