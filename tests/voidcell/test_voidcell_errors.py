"""Bad inputs give clear InputErrors; results cannot be read before compute()."""

import numpy as np
import pytest
from voidcell_fixtures import contacts, lattice_packing

from gransim.errors import InputError
from gransim.voidcell import NotComputedError, Snapshot, VoidCells


def base(lattice):
    x, r, cell = lattice
    i, j, s = contacts(x, r, cell)
    return x, r, cell, i, j, s


def test_contacts_refer_to_missing_particles(lattice):
    x, r, cell, i, j, s = base(lattice)
    j = j.copy()
    j[5] = len(x)
    with pytest.raises(InputError, match=r"contacts_j: contact 5 refers to missing particle 144"):
        Snapshot(x, cell, i, j, s, np.zeros_like(x))
    i = i.copy()
    i[0] = -1
    with pytest.raises(InputError, match="missing particle -1"):
        Snapshot(x, cell, i, j, s, np.zeros_like(x))


@pytest.mark.parametrize("check_crossings", [True, False])
def test_strongly_overlapping_particles_nonplanar(check_crossings):
    # radii 0.9 on a unit triangular lattice: second neighbours (distance sqrt 3) touch too and
    # their contact lines cross the first-neighbour ones
    x, r, cell = lattice_packing(8, 8, noise=0.02, seed=3)
    r = np.full(len(x), 0.9)
    i, j, s = contacts(x, r, cell)
    snap = Snapshot(x, cell, i, j, s, np.zeros_like(x))
    with pytest.raises(InputError, match="planar|non-planar|Euler"):
        VoidCells(check_crossings=check_crossings).compute(snap)


def test_empty_graph(lattice):
    x, r, cell = lattice
    none = np.zeros(0, int)
    snap = Snapshot(x, cell, none, none, np.zeros((0, 2), int), np.zeros_like(x))
    with pytest.raises(InputError, match="contact list is empty"):
        VoidCells().compute(snap)


def test_graph_that_does_not_span(lattice):
    x, r, cell, i, j, s = base(lattice)
    inside = np.all(s == 0, axis=1)  # drop every contact across the boundary
    snap = Snapshot(x, cell, i[inside], j[inside], s[inside], np.zeros_like(x))
    with pytest.raises(InputError, match="spans the periodic cell"):
        VoidCells().compute(snap)


def test_shape_and_value_errors(lattice):
    x, r, cell, i, j, s = base(lattice)
    v = np.zeros_like(x)
    with pytest.raises(InputError, match=r"velocities: expected shape \(144, 2\)"):
        Snapshot(x, cell, i, j, s, v[:-1])
    with pytest.raises(InputError, match="contacts_shift"):
        Snapshot(x, cell, i, j, s[:, :1], v)
    with pytest.raises(InputError, match="itself with zero image shift"):
        Snapshot(x, cell, np.r_[i, 3], np.r_[j, 3], np.vstack([s, [0, 0]]), v)
    with pytest.raises(InputError, match="degenerate"):
        Snapshot(x, np.zeros((2, 2)), i, j, s, v)
    with pytest.raises(InputError, match="motion"):
        Snapshot(x, cell, i, j, s, v, motion="speed")
    with pytest.raises(InputError, match="reference"):
        VoidCells(reference="box")
    with pytest.raises(InputError, match="Snapshot"):
        VoidCells().compute({"positions": x})


def test_results_before_compute():
    vc = VoidCells()
    for name in ("L", "alpha", "w", "face_area", "n_faces", "dcel", "graph", "v_rel"):
        with pytest.raises(NotComputedError, match="before compute"):
            getattr(vc, name)
    assert "not computed" in repr(vc)


def test_v_rel_needs_d50(lattice):
    x, r, cell, i, j, s = base(lattice)
    G = np.array([[0.1, 0.0], [0.0, -0.2]])
    vc = VoidCells().compute(Snapshot(x, cell, i, j, s, x @ G.T, cell_velocity=G @ cell))
    with pytest.raises(InputError, match="D50"):
        _ = vc.v_rel
    assert VoidCells(d50=1.0).compute(vc.snapshot).v_rel.shape == x.shape
