"""Session fixtures: small dense periodic packings for the RVE tests."""

import pytest
from rve_fixtures import lattice_packing, random_packing


@pytest.fixture(scope="session")
def packings():
    return {
        "lattice": lattice_packing(),
        "sheared": lattice_packing(7, 6, seed=3, shear=0.4),
        "random": random_packing(),
    }
