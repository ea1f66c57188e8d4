"""Packing data model, periodic helpers, HDF5 round trip with provenance, VTK export."""

import h5py
import numpy as np
import pytest

from gransim import Packing
from gransim.errors import InputError, ResultFileError
from gransim.geometry import minimum_image, wrap
from gransim.io import load_packing, read_provenance, save_packing
from gransim.io.hdf5 import atomic_h5


@pytest.fixture
def packing(rng):
    C = np.array([[3.0, 0.7], [0.2, 2.5]])
    return Packing(
        positions=rng.uniform(-1, 4, (30, 2)),
        radii=rng.uniform(0.05, 0.2, 30),
        cell=C,
        density=2650.0,
        metadata={"seed": 7, "distribution": "test"},
    )


def test_packing_is_immutable_and_validated(packing):
    with pytest.raises(ValueError):
        packing.positions[0, 0] = 1.0
    with pytest.raises(AttributeError):  # dataclasses.FrozenInstanceError
        packing.radii = np.ones(30)
    for kwargs, match in [
        (dict(positions=np.zeros((1, 2)), radii=[1.0]), "at least 2"),
        (dict(radii=-np.ones(30)), "radii"),
        (dict(cell=[[1.0, 1.0], [1.0, 1.0]]), "degenerate"),
        (dict(density=-1.0), "density"),
    ]:
        with pytest.raises(InputError, match=match):
            packing.replace(**kwargs)


def test_derived_quantities(packing):
    assert packing.area == pytest.approx(3.0 * 2.5 - 0.7 * 0.2)
    phi = np.pi * np.sum(packing.radii**2) / packing.area
    assert packing.solid_fraction == pytest.approx(phi)
    assert packing.void_ratio == pytest.approx((1 - phi) / phi)
    np.testing.assert_allclose(packing.masses, 2650.0 * np.pi * packing.radii**2)


def test_wrap_and_minimum_image_are_periodic_invariants(packing, rng):
    C = packing.cell
    xw, n = wrap(packing.positions, C)
    np.testing.assert_allclose(xw + n @ C.T, packing.positions, atol=1e-12)
    s = np.linalg.solve(C, xw.T).T
    assert np.all((s >= 0) & (s < 1))
    d = rng.uniform(-10, 10, (200, 2))
    m = minimum_image(d, C)
    # differs from d by a lattice vector, and is no longer than any neighbouring image
    k = np.linalg.solve(C, (d - m).T).T
    np.testing.assert_allclose(k, np.round(k), atol=1e-9)
    for n1 in (-1, 0, 1):
        for n2 in (-1, 0, 1):
            alt = m + C @ np.array([n1, n2])
            assert np.all(np.linalg.norm(m, axis=1) <= np.linalg.norm(alt, axis=1) + 1e-12)


def test_deformed_is_the_affine_map(packing):
    F = np.array([[1.1, 0.05], [0.0, 0.95]])
    p = packing.deformed(F)
    np.testing.assert_allclose(p.positions, packing.positions @ F.T)
    assert p.area == pytest.approx(np.linalg.det(F) * packing.area)
    with pytest.raises(InputError, match="det F"):
        packing.deformed([[1.0, 0.0], [0.0, -1.0]])


def test_hdf5_round_trip_and_provenance(packing, tmp_path):
    path = save_packing(tmp_path / "p.h5", packing)
    back = load_packing(path)
    np.testing.assert_array_equal(back.positions, packing.positions)
    np.testing.assert_array_equal(back.radii, packing.radii)
    np.testing.assert_array_equal(back.cell, packing.cell)
    assert back.density == packing.density
    assert dict(back.metadata) == dict(packing.metadata)
    prov = read_provenance(path)
    for key in ("gransim_version", "git_commit", "created", "parameters", "seed"):
        assert key in prov
    assert prov["seed"] == 7
    assert prov["kind"] == "packing"


def test_atomic_write_leaves_nothing_on_crash(tmp_path):
    target = tmp_path / "out.h5"
    with pytest.raises(RuntimeError):
        with atomic_h5(target, kind="test") as f:
            f.create_dataset("x", data=np.arange(3))
            raise RuntimeError("crash in the middle")
    assert not target.exists()
    assert list(tmp_path.iterdir()) == []


def test_foreign_and_unreadable_files_are_refused(tmp_path):
    junk = tmp_path / "junk.h5"
    junk.write_bytes(b"not hdf5 at all")
    with pytest.raises(ResultFileError, match="not a readable HDF5"):
        load_packing(junk)
    foreign = tmp_path / "foreign.h5"
    with h5py.File(foreign, "w") as f:
        f["positions"] = np.zeros((3, 2))
    with pytest.raises(ResultFileError, match="not a gransim"):
        load_packing(foreign)
    with pytest.raises(ResultFileError, match="no such file"):
        load_packing(tmp_path / "missing.h5")


def test_vtk_export(packing, tmp_path):
    import meshio

    from gransim.io import packing_to_vtu

    path = packing_to_vtu(tmp_path / "p.vtu", packing, point_data={"v": np.ones((30, 2))})
    mesh = meshio.read(path)
    assert mesh.points.shape == (30, 3)
    np.testing.assert_allclose(mesh.point_data["radius"], packing.radii)
    assert mesh.point_data["v"].shape == (30, 3)


def test_atomic_path_fsyncs_before_the_rename(tmp_path, monkeypatch):
    """The data reach the disk before the file appears under its name (temp, fsync, rename)."""
    import os

    from gransim.io import atomic_path

    events = []
    real_fsync, real_replace = os.fsync, os.replace
    monkeypatch.setattr(os, "fsync", lambda fd: (events.append("fsync"), real_fsync(fd))[1])
    monkeypatch.setattr(os, "replace", lambda a, b: (events.append("rename"), real_replace(a, b))[1])
    target = tmp_path / "out.txt"
    with atomic_path(target) as tmp:
        tmp.write_text("data")
        assert not target.exists()
    assert target.read_text() == "data"
    assert events[:2] == ["fsync", "rename"]
    assert not list(tmp_path.glob(".out.txt.*"))


def test_atomic_text_keeps_the_old_file_when_the_write_fails(tmp_path, monkeypatch):
    """The slope's markdown tables and reports (gransim.io.atomic_text): a write that fails part
    way (here after half the text) leaves the previous file whole and no temporary; a write that
    succeeds replaces it entirely."""
    from pathlib import Path

    from gransim.io import atomic_text

    target = tmp_path / "report.md"
    atomic_text(target, "old report\n")
    real = Path.write_text

    def half_then_fail(self, text, *a, **kw):
        real(self, text[: len(text) // 2], *a, **kw)
        raise OSError(5, "Input/output error")

    monkeypatch.setattr(Path, "write_text", half_then_fail)
    with pytest.raises(Exception, match="report.md"):
        atomic_text(target, "new report, much longer than the old one\n")
    monkeypatch.undo()
    assert target.read_text() == "old report\n"
    assert not list(tmp_path.glob(".report.md.*"))
    atomic_text(target, "new report\n")
    assert target.read_text() == "new report\n"
