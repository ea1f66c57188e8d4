import shutil

import pytest

from reference_runs.demo_packings import perturbed_lattice


def pytest_collection_modifyitems(config, items):
    if shutil.which("liggghts") is None:
        skip = pytest.mark.skip(reason="liggghts binary not installed (apt-get install liggghts)")
        for item in items:
            if "liggghts" in item.keywords:
                item.add_marker(skip)


@pytest.fixture(scope="session")
def lattice_packing():
    """A dense 64-disk periodic packing (perturbed triangular lattice, overlapping radii)."""
    return perturbed_lattice(8, 8, seed=3)
