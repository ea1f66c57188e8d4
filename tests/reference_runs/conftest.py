"""Collection rule of the reference-run tests: a test that needs a reference code says so with its
marker (``@pytest.mark.liggghts``: the ``liggghts`` binary), and is skipped, with the reason naming
the binary and how to install it, only when that binary is absent.

The rule reads the marker, never the test's keywords: a test's keywords also hold its name, its
module's name and its parameter ids, so ``test_x[liggghts]`` (a native test parametrised by the code
whose arithmetic it repeats, or a test of stored outputs) would be skipped with LIGGGHTS absent,
though it needs no binary. (``lammps`` is the same rule in tests/conftest.py; the YADE tests skip
with ``skipif`` on the ``yade`` binary.)
"""

import shutil

import pytest

from reference_runs.demo_packings import perturbed_lattice

#: marker -> (binary, install hint): a test carrying the marker needs the binary
CODE_MARKERS = {"liggghts": ("liggghts", "apt-get install liggghts")}


def code_skip_reason(item, which=shutil.which) -> str | None:
    """Why ``item`` cannot run here (a code its markers ask for is absent), or None."""
    for marker, (binary, hint) in CODE_MARKERS.items():
        if item.get_closest_marker(marker) is not None and which(binary) is None:
            return f"needs the {binary} binary (marker {marker}), which is not installed ({hint})"
    return None


def pytest_collection_modifyitems(config, items):
    for item in items:
        reason = code_skip_reason(item)
        if reason is not None:
            item.add_marker(pytest.mark.skip(reason=reason))


@pytest.fixture(scope="session")
def lattice_packing():
    """A dense 64-disk periodic packing (perturbed triangular lattice, overlapping radii)."""
    return perturbed_lattice(8, 8, seed=3)
