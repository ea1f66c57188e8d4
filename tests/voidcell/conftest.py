"""Session fixtures: dense periodic packings for the void-cell tests."""

import pytest
from voidcell_fixtures import lattice_packing, relaxed_packing


@pytest.fixture(scope="session")
def lattice():
    return lattice_packing()


@pytest.fixture(scope="session")
def relaxed():
    return relaxed_packing()
