"""A Gauss point's strain history in LAMMPS' arithmetic: the RVE of Guo & Zhao's prepareRVE.py
driven call after call by strain increments (gransim.fem.lammps_rve), natively and in LAMMPS
(reference_runs.femxdem.lammps_replay): the cell equal bit for bit, stresses and positions to
round-off after every call."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from gransim.errors import InputError
from gransim.fem.lammps_rve import THICKNESS, LammpsRVE

#: three increments of a biaxial Gauss point: axial compression, lateral expansion, some shear
INCREMENTS = np.array(
    [
        [[4.0e-4, 1.5e-4], [0.5e-4, -1.0e-3]],
        [[6.0e-4, -2.0e-4], [1.0e-4, -1.0e-3]],
        [[5.0e-4, 3.0e-4], [-1.0e-4, -8.0e-4]],
    ]
)


@pytest.fixture(scope="module")
def rve():
    return LammpsRVE.guo_zhao()


def test_the_rve_is_guo_zhaos_with_a_lammps_law(rve):
    p, s = rve.packing, rve.settings
    assert p.n == 400 and s.flavour == "lammps"
    assert np.all((p.positions >= 0) & (p.positions < np.diag(p.cell)))  # wrapped for the data file
    # 0.1-thick disks at 2650 kg/m^3: 265 kg/m^2; ks/kn 0.8; friction tan 0.5
    assert p.density == pytest.approx(265.0, rel=1e-12)
    assert s.kt == pytest.approx(0.8 * s.kn, rel=1e-12) and s.mu == pytest.approx(np.tan(0.5), rel=1e-12)


def test_a_call_applies_the_engineering_increments(rve):
    # Lx, Ly change by D00 and D11, the tilt by (D01 + D10) Ly0, over ns = max(1e5 max|D|, 2) steps
    D = INCREMENTS[0]
    ld, ns = rve.call(D)
    assert ns == 100 and ld.remap == "x"
    setup, state = rve.replay(D[None])
    assert setup["steps"] == 0 and state["steps"] == 100
    lx0, ly0 = np.diag(rve.packing.cell)
    b = state["box"]
    assert b[2] - b[0] == pytest.approx(lx0 * (1 + D[0, 0]), rel=1e-12)
    assert b[3] - b[1] == pytest.approx(ly0 * (1 + D[1, 1]), rel=1e-12)
    assert b[4] == pytest.approx((D[0, 1] + D[1, 0]) * ly0, rel=1e-10)
    # compressed along y: the RVE pushes back (tension positive: sigma_yy < 0), in Pa
    assert state["stress"][1, 1] < 0 and abs(state["stress"][1, 1]) > 1e3
    with pytest.raises(InputError, match="strain increment"):
        rve.call(np.zeros(3))


@pytest.mark.lammps
def test_replay_in_lammps_equals_the_native_calls(rve, tmp_path):
    if shutil.which("lmp") is None:
        pytest.skip("lmp (LAMMPS) binary not installed")
    from reference_runs.femxdem.lammps_replay import replay_in_lammps

    native = rve.replay(INCREMENTS)
    lammps = replay_in_lammps(tmp_path, rve, INCREMENTS)
    assert len(lammps) == len(native) == len(INCREMENTS) + 1  # the set-up, then every call
    d50 = 2 * float(np.median(rve.packing.radii))
    for k, (a, b) in enumerate(zip(native, lammps, strict=True)):
        box = a["box"]
        np.testing.assert_array_equal(
            [box[2] - box[0], box[3] - box[1], box[4]], b["lx_ly_xy"], err_msg=f"call {k}: the cell"
        )
        cell = np.array([[box[2] - box[0], box[4]], [0.0, box[3] - box[1]]])
        d = a["positions"] - b["positions"]
        lam = np.linalg.solve(cell, d.T).T
        assert np.abs(d - np.round(lam) @ cell.T).max() < 1e-10 * d50, f"call {k}: positions"
        for i, j in ((0, 0), (1, 1), (0, 1)):
            ref = b["stress"][i, j]
            assert abs(a["stress"][i, j] - ref) < 1e-8 * np.abs(b["stress"]).max(), f"call {k}: stress {i}{j}"
        for key in ("velocities", "forces"):
            big = np.abs(b[key]).max()
            assert big > 0 or k == 0, key
            assert np.abs(a[key] - b[key]).max() <= 1e-8 * big, f"call {k}: {key}"
    # the replay really loads the RVE: its stress after the calls is of the order of the confinement
    assert np.abs(native[-1]["stress"]).max() > 1e3 / THICKNESS / 10


def test_point_law_updates_chain_to_the_replay_bit_for_bit(rve):
    # each update restores an engine from the committed state and runs one call: chained, they
    # equal one engine driven through the calls (restore + run set-up repeat LAMMPS' consecutive runs)
    from gransim.fem.lammps_rve import LammpsPointLaw

    law = LammpsPointLaw(rve)
    fs = np.eye(2) + INCREMENTS
    replay = rve.replay(fs - np.eye(2))  # D = f - 1 as the point law forms it ((1 + D) - 1 is not D)
    state = law.initial_state(0)
    np.testing.assert_array_equal(state.arrays["positions"], replay[0]["positions"])
    for k, f in enumerate(fs, 1):
        before = {n: v.copy() for n, v in state.arrays.items()}
        sig, t, new = law.update(f, state)
        for n, v in state.arrays.items():  # the committed state is never written
            np.testing.assert_array_equal(v, before[n])
        np.testing.assert_array_equal(new.arrays["positions"], replay[k]["positions"])
        np.testing.assert_array_equal(new.arrays["velocities"], replay[k]["velocities"])
        np.testing.assert_array_equal(new.arrays["box"], replay[k]["box"])
        s = replay[k]["stress"]
        np.testing.assert_array_equal(sig, 0.5 * (s + s.T))
        assert new.updates == k and np.array_equal(new.increments[-1], f - np.eye(2))
        state = new
    # the tangent has every minor symmetry and the order of the contact stiffness
    assert np.allclose(t, t.transpose(1, 0, 2, 3)) and np.allclose(t, t.transpose(0, 1, 3, 2))
    assert t[1, 1, 1, 1] > 0 and t[0, 0, 0, 0] > 0
    # pack / unpack round trip (checkpoints)
    packed = law.pack_states([law.initial_state(0), state])
    back = law.unpack_states(packed)
    assert back[1].updates == state.updates and back[1].step == state.step
    for n, v in state.arrays.items():
        np.testing.assert_array_equal(back[1].arrays[n], v)
    obs = law.observables(state)
    assert 0.1 < obs["void_ratio"] < 1.0 and obs["contacts"] > 100


def test_contact_stiffness_tangent_predicts_a_small_elastic_increment(rve):
    # a small increment from the loaded state: the stress change is of the order the tangent predicts
    # (the contact-stiffness tangent misses the geometric and sliding terms: same sign, same order)
    from gransim.fem.lammps_rve import LammpsPointLaw

    law = LammpsPointLaw(rve)
    s0, t0, st = law.update(np.eye(2) + INCREMENTS[0], law.initial_state(0))
    dF = np.array([[0.0, 0.0], [0.0, -2e-5]])
    s1, _, _ = law.update(np.eye(2) + dF, st)
    pred = np.einsum("ijkl,kl->ij", t0, dF)
    assert np.sign(s1[1, 1] - s0[1, 1]) == np.sign(pred[1, 1])
    assert 0.1 < (s1[1, 1] - s0[1, 1]) / pred[1, 1] < 10


# ---------------------------------------------------------------------------------------------------
# gransim femxdem --rve dem-lammps: the LAMMPS RVE at every Gauss point


@pytest.fixture(scope="module")
def lammps_run(tmp_path_factory):
    """A 1 x 1 Q8 specimen (4 Gauss points), 2 steps, --rve dem-lammps, checkpointed."""
    from gransim.fem.biaxial import BiaxialSpec
    from gransim.fem.femxdem import run_femxdem

    out = tmp_path_factory.mktemp("fxl") / "run"
    summary = run_femxdem(BiaxialSpec(nx=1, ny=1, steps=2), rve="dem-lammps", out=out)
    return out, summary


def _committed(out, step):
    import h5py

    from gransim.fem.lammps_rve import LammpsPointLaw

    with h5py.File(out / "checkpoint" / f"states_{step:03d}.h5", "r") as f:
        arrays = {k: np.array(v) for k, v in f["states"].items()}
        return LammpsPointLaw.unpack_states(arrays), f["stress"][()]


def test_a_lammps_gauss_point_equals_a_single_rve_driven_by_its_strain_path(lammps_run, rve):
    """(a) for --rve dem-lammps: every Gauss point of the uniform specimen holds the RVE that one
    LAMMPS RVE driven from the prepared state by the point's own strain increments reaches, bit
    for bit (positions, velocities, spins, forces, torques, the cell), with its stress."""
    out, summary = lammps_run
    states, stress = _committed(out, 2)
    assert len(states) == 4 and all(s.updates == 2 for s in states)
    for g, s in enumerate(states):
        replay = rve.replay(s.increments)[-1]
        for key in ("positions", "velocities", "spins", "forces", "torques", "box"):
            np.testing.assert_array_equal(s.arrays[key], replay[key], err_msg=f"Gauss point {g}: {key}")
        sig = replay["stress"]
        np.testing.assert_array_equal(stress[g], 0.5 * (sig + sig.T), err_msg=f"Gauss point {g}: stress")
    assert np.abs(states[0].increments).max() > 5e-4  # the points were strained: the comparison has a scale
    q = [r.deviatoric_stress for r in summary["steps"]]
    assert 0 < q[0] < q[1]  # the specimen hardens under compression


def test_lammps_run_resumes_bit_for_bit_and_says_what_it_lacks(lammps_run, tmp_path):
    import h5py

    from gransim.fem.biaxial import BiaxialSpec
    from gransim.fem.femxdem import FemxdemInterrupted, run_femxdem

    out, summary = lammps_run
    cut = tmp_path / "cut"
    with pytest.raises(FemxdemInterrupted):
        run_femxdem(BiaxialSpec(nx=1, ny=1, steps=2), rve="dem-lammps", out=cut, stop_after=1)
    resumed = run_femxdem(BiaxialSpec(nx=1, ny=1, steps=2), rve="dem-lammps", out=cut, resume=True)
    assert resumed["resumed_after"] == 1
    for a, b in zip(summary["steps"], resumed["steps"], strict=True):
        for key in ("x", "stress", "F", "errors"):
            np.testing.assert_array_equal(getattr(a, key), getattr(b, key))
    a, _ = _committed(out, 2)
    b, _ = _committed(cut, 2)
    for sa, sb in zip(a, b, strict=True):
        for key, v in sa.arrays.items():
            np.testing.assert_array_equal(v, sb.arrays[key], err_msg=key)
    # its observables: the void ratio; the rotation is not defined (LAMMPS' disks carry no angle)
    with h5py.File(out / "femxdem.h5", "r") as f:
        obs = f["final/observables"]
        assert 0.1 < obs["void_ratio"][()].min() and obs["void_ratio"][()].max() < 0.3
        assert "rotation" not in obs and obs["contacts"][()].min() > 100
        assert f["fields"].attrs["not_available"] == "rotation"
        assert "orientation" in f["fields"].attrs["not_available_reason"]
        assert "LammpsPointLaw" in f.attrs["parameters"]
    report = (out / "report.md").read_text()
    assert "LAMMPS' arithmetic" in report and "rotation n/a (LAMMPS' disks carry no orientation)" in report
    assert (out / "maps_002.png").exists() and (out / "mesh_002.vtu").exists()
    assert len(list(out.glob("rve_002_g*.png"))) == 1  # the most strained point's RVE, drawn without rotation


def test_the_lammps_rve_picture_shows_its_touching_pairs(lammps_run):
    """The picture's data (LammpsPointLaw.snapshot): every contact's branch x_j + H s - x_i joins two
    touching disks (shorter than the sum of the radii, longer than 0.9 of it: a wrong image shift
    gives a branch of a cell's length), the force splits into its parts along and across it."""
    import h5py

    from gransim.fem.output_femxdem import contact_segments

    out, _ = lammps_run
    with h5py.File(out / "femxdem.h5", "r") as f:
        (name,) = list(f["fields/step_002/pictures"])
        snap = {k: v[()] for k, v in f["fields/step_002/pictures"][name].items()}
    assert "rotation" not in snap and len(snap["ids"]) > 100
    _, seg, fn = contact_segments(snap)
    branch = np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1)
    rsum = snap["radii"][snap["ids"][:, 0]] + snap["radii"][snap["ids"][:, 1]]
    assert np.all(branch < rsum) and np.all(branch > 0.9 * rsum)
    b = (seg[:, 1] - seg[:, 0]) / branch[:, None]
    assert np.allclose(np.einsum("ci,ci->c", snap["shear_force"], b), 0, atol=1e-12 * fn.max())
    assert fn.min() > 0 and np.any(np.abs(snap["shear_force"]) > 1e-6 * fn.max())  # friction carried


def test_lammps_rve_options_are_checked_at_the_boundary(tmp_path):
    import argparse

    from gransim.cli.cmd_femxdem import check_options

    base = dict(rve="dem-lammps", full=False, mesh=None, steps=None, element="Q8", gauss=None, pressure=1e5,
                top_step=1e-4, tol=1e-2, max_iter=None, packing=None, packing_dir=None, out=str(tmp_path / "o"),
                resume=False, stop_after=None, workers=None, scheduler=None, field_steps=None, rve_pictures=None,
                tangent=None, tangent_step=None)  # fmt: skip
    assert check_options(argparse.Namespace(**base))["spec"]["nx"] == 2
    assert check_options(argparse.Namespace(**{**base, "rve_pictures": "3,0"}))["rve_pictures"] == (0, 3)
    for kw, msg in [
        ({"pressure": 2e5}, "--pressure: --rve dem-lammps's RVE was consolidated to 1e5 Pa"),
        ({"rve_pictures": "32"}, "--rve-pictures"),
        ({"rve": "j2", "rve_pictures": "0"}, "--rve-pictures: applies to the DEM RVEs"),
    ]:
        with pytest.raises(InputError, match=msg):
            check_options(argparse.Namespace(**{**base, **kw}))
    assert check_options(argparse.Namespace(**{**base, "tangent": "perturbation"}))["spec"]["nx"] == 2


def test_the_lammps_point_law_travels_to_a_worker_unchanged(rve):
    """The law is pickled to each Dask worker (--workers): the copy updates to the same bits."""
    import pickle

    from gransim.fem.lammps_rve import LammpsPointLaw

    law = LammpsPointLaw(rve)
    copy = pickle.loads(pickle.dumps(law))
    assert dict(copy.rve.packing.metadata) == dict(rve.packing.metadata) and copy.rve.settings == rve.settings
    f = np.eye(2) + INCREMENTS[0]
    a, b = law.update(f, law.initial_state(0)), copy.update(f, copy.initial_state(0))
    np.testing.assert_array_equal(a[0], b[0])
    for key, v in a[2].arrays.items():
        np.testing.assert_array_equal(v, b[2].arrays[key], err_msg=key)
