import os
import shutil

import numpy as np
import pytest

os.environ.setdefault("MPLBACKEND", "Agg")


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


def pytest_collection_modifyitems(config, items):
    """Tests marked ``lammps`` need the LAMMPS binary ``lmp``: skipped where it is absent (as the
    ``liggghts`` marker is in tests/reference_runs/conftest.py)."""
    if shutil.which("lmp") is None:
        skip = pytest.mark.skip(reason="LAMMPS binary lmp not installed (apt-get install lammps)")
        for item in items:
            if item.get_closest_marker("lammps") is not None:
                item.add_marker(skip)
