"""YADE runs of the decks' periodic DEM cases (reference_runs.yade.dem): the biaxial test with its
stress servo and periodic simple shear, checked for physics on short runs.

What is checked, and why it can fail:

* the first step's stress is the independent numpy Love-Weber sum of the initial packing
  (reference_runs.taylor_numpy; at rest there is no damping or tangential force) and the stored
  LIGGGHTS one: YADE got the same disks, cell, contacts and stiffness;
* every dumped frame's contact rows give YADE's ``getStress`` back (reference_runs.yade.dem.
  contact_stress): the rows are YADE's whole stress, branch vectors and cellDist read right;
* the forces on all disks sum to zero (Newton's third law; YADE applies each contact force to both
  bodies) and, in a fixed cell, the momentum sum m v stays at its initial value (leapfrog: each kick
  adds dt times a zero sum);
* the cell follows the decks' loading: the rate axis L(n) = L0 + c n, the servo axis
  L(n+1) = L(n) (1 + dt gain (p_n - target)) at every step (the decks' ``fix deform`` map), the
  tilt of the sheared cell n dt erate Ly0; and with y fixed the servo brings the lateral stress to
  its target and holds it;
* the law of the runs (Cundall and Strack's) sees the velocity of a contact's periodic image, and
  YADE's linear spring-dashpot law adds it with the wrong sign (why the runs are undamped).

Tolerances are round-off: sums of ~150 contact or 120 particle terms (1e-13 relative); one step of
a cell recurrence rounds once (1e-15 of L), n steps of a prescribed side or tilt accumulate at most
about n eps of it (measured 1.5e-13 of L after 3000 steps, bound 6.7e-13).
"""

import shutil

import numpy as np
import pytest

from gransim.dem.settings import AxisControl, Loading
from reference_runs.decks.biaxial import read_thermo
from reference_runs.taylor_numpy import taylor_stress_numpy
from reference_runs.yade.dem import (
    biaxial_job,
    contact_stress,
    run_yade_dem,
    shear_job,
    short_biaxial,
    short_shear,
)

pytestmark = pytest.mark.skipif(
    shutil.which("yade") is None, reason="yade binary not installed (apt-get install yade; make engines)"
)
STORED = "reference_runs/stored/biaxial-short/log.liggghts"
EPS = np.finfo(float).eps


@pytest.fixture(scope="module")
def biaxial(tmp_path_factory):
    p, s, ld, n = short_biaxial()
    script, files = biaxial_job(p, s, ld, n, thermo_every=1, dump_every=500)
    out, manifest = run_yade_dem(tmp_path_factory.mktemp("yade-biaxial") / "job", script, files)
    return p, s, ld, n, out, manifest


def _frame_checks(out):
    for k, fr in out.frames.items():
        i = int(np.searchsorted(out.step, k))
        assert out.step[i] == k
        sig = out.stress[i]
        assert len(fr.ids) == out.n_contacts[i] > 0
        assert np.abs(contact_stress(fr, out.cell[i]) - sig).max() <= 1e-13 * np.abs(sig).max(), k
        assert np.abs(fr.forces.sum(axis=0)).max() <= 1e-14 * np.abs(fr.forces).sum(), k


def test_biaxial_short_is_complete_and_starts_from_the_decks_state(biaxial):
    p, s, ld, n, out, m = biaxial
    assert m["status"] == "ok" and m["engine_version"] == "YADE 2023.02a" and m["servers"] == "not started"
    assert list(out.step) == list(range(n + 1)) and sorted(out.frames) == list(range(0, n + 1, 500))
    assert all(len(fr.positions) == p.n == 120 for fr in out.frames.values())
    ref = taylor_stress_numpy(p, np.eye(2), s.kn)  # at rest: kn times the overlaps, no tangential force
    assert out.n_contacts[0] == ref.n_contacts
    assert np.abs(out.stress[0] - ref.cauchy).max() <= 1e-13 * np.abs(ref.cauchy).max()
    lig = read_thermo(STORED)  # LIGGGHTS' step 0 (compression positive)
    assert out.stress[0, 0, 0] == pytest.approx(-lig["sxx"][0], rel=1e-13)
    assert out.stress[0, 1, 1] == pytest.approx(-lig["syy"][0], rel=1e-13)


def test_biaxial_short_stress_forces_and_cell_follow_the_loading(biaxial):
    p, s, ld, n, out, _ = biaxial
    _frame_checks(out)
    L0x, L0y = p.cell[0, 0], p.cell[1, 1]
    c = ld.y.rate * L0y * s.dt  # the decks' literal: L(n) = L0 + c n
    drift = n * EPS * L0y  # YADE adds dt (c / (dt L)) L: a few roundings per step, accumulated
    assert np.abs(out.cell[:, 1, 1] - (L0y + c * out.step)).max() <= drift
    assert np.abs(out.cell[-1, 1, 1] - read_thermo(STORED)["ly"][-1]) <= drift  # LIGGGHTS' box
    k = s.dt * ld.x.gain
    p_xx = -out.stress[:, 0, 0]
    want = out.cell[:-1, 0, 0] * (1.0 + k * (p_xx[:-1] - ld.x.target))
    assert np.abs(out.cell[1:, 0, 0] - want).max() <= 1e-15 * L0x  # one rounding per step
    assert not out.cell[:, 0, 1].any() and not out.cell[:, 1, 0].any()
    # the run compresses: y shrinks, x follows its servo towards 100 N/m from 1585 N/m
    assert p_xx[-1] < 0.2 * p_xx[0] and out.cell[-1, 0, 0] > L0x


def test_servo_brings_the_lateral_stress_to_its_target_and_holds_it(tmp_path):
    p, s, _, _ = short_biaxial()
    target = 100.0
    ld = Loading(x=AxisControl("servo", target=target, gain=0.1), y=AxisControl("fixed"))
    script, files = biaxial_job(p, s, ld, 20000, thermo_every=10, dump_every=10000)
    out, _ = run_yade_dem(tmp_path / "job", script, files)
    p_xx = -out.stress[:, 0, 0]
    assert p_xx[0] > 15 * target  # starts far from it
    tail = p_xx[out.step >= 18000]  # the last tenth of the run
    assert abs(tail.mean() - target) < 0.03 * target and np.abs(tail - target).max() < 0.1 * target
    assert np.all(out.cell[:, 1, 1] == p.cell[1, 1])  # y fixed: exactly
    _frame_checks(out)


def test_momentum_is_conserved_in_a_fixed_cell(tmp_path):
    p, s, _, _ = short_biaxial()
    rng = np.random.default_rng(7)
    v0 = rng.normal(scale=0.05, size=(p.n, 2))  # m/s: contacts open, close and slide
    w0 = rng.normal(scale=50.0, size=p.n)
    ld = Loading(x=AxisControl("fixed"), y=AxisControl("fixed"))
    script, files = biaxial_job(p, s, ld, 2000, thermo_every=100, dump_every=100, velocities=v0, spins=w0)
    out, _ = run_yade_dem(tmp_path / "job", script, files)
    mass = out.frames[0].mass
    P = np.array([(fr.velocities * mass[:, None]).sum(axis=0) for _, fr in sorted(out.frames.items())])
    scale = (np.abs(v0) * mass[:, None]).sum()
    assert np.abs(P - (v0 * mass[:, None]).sum(axis=0)).max() <= 1e-13 * scale
    moved = max(np.abs(fr.velocities - out.frames[0].velocities).max() for fr in out.frames.values())
    assert moved > 0.1 * np.abs(v0).max()  # the velocities did change: the sum is not trivially constant
    _frame_checks(out)


@pytest.mark.parametrize("name", ["constant-volume", "servo"])
def test_periodic_simple_shear_tilts_the_cell_as_the_lammps_deck(name, tmp_path):
    p, s, ld, n = short_shear(name)
    script, files = shear_job(p, s, ld, n, thermo_every=1, dump_every=1000)
    out, _ = run_yade_dem(tmp_path / "job", script, files)
    Ly0 = p.cell[1, 1]
    tilt = out.step * s.dt * ld.erate * Ly0  # LAMMPS xy erate: d xy/dt = erate Ly0
    assert np.abs(out.cell[:, 0, 1] - tilt).max() <= n * EPS * tilt[-1]  # one rounding or so per step
    assert not out.cell[:, 1, 0].any() and np.all(out.cell[:, 0, 0] == p.cell[0, 0])
    p_yy = -out.stress[:, 1, 1]
    if name == "servo":
        k = s.dt * ld.gain
        want = out.cell[:-1, 1, 1] * (1.0 + k * (p_yy[:-1] - ld.target))
        assert np.abs(out.cell[1:, 1, 1] - want).max() <= 1e-15 * Ly0
        assert abs(p_yy[-1] - ld.target) < 0.05 * ld.target  # near its 1000 N/m after 1.5% shear
    else:
        assert np.all(out.cell[:, 1, 1] == Ly0)
    # sheared by a positive tilt rate the packing resists: sigma_xy grows from its initial 25 N/m
    # (LAMMPS: 25 -> 250 N/m at constant volume, 25 -> 208 N/m under the servo)
    assert out.stress[0, 0, 1] == pytest.approx(25.265261949933343, rel=1e-12)
    assert out.stress[-1, 0, 1] > 4 * out.stress[0, 0, 1]
    _frame_checks(out)


#: two pairs of disks in a periodic cell sheared at 1/s (homogeneous flow v = L x from step 0's
#: motion on): one pair across the y boundary (cellDist (0, -1)), one inside. At iteration 1 a
#: PyRunner between the interaction loop and the motion writes what the contact law used:
#: positions, velocities, spins, the cell before the step and every interaction's shear force
KINEMATICS_SCRIPT = r"""
import json, math
from yade import utils
rows = {}
for law in ("cundall", "viscel"):
    O.reset()
    O.periodic = True
    O.cell.hSize = Matrix3(0.02, 0, 0, 0, 0.02, 0, 0, 0, 0.008)
    if law == "cundall":
        mat = O.materials.append(FrictMat(young=1.0, poisson=0.0, frictionAngle=0.5, density=1.0))
        phys = Ip2_FrictMat_FrictMat_FrictPhys(kn=MatchMaker(algo="val", val=1e5), ks=MatchMaker(algo="val", val=1e5))
        law2 = Law2_ScGeom_FrictPhys_CundallStrack()
    else:
        mat = O.materials.append(ViscElMat(kn=2e5, ks=2e5, cn=0.0, cs=0.0, frictionAngle=0.5, density=1.0))
        phys, law2 = Ip2_ViscElMat_ViscElMat_ViscElPhys(), Law2_ScGeom_ViscElPhys_Basic()
    for x, y in ((0.005, 0.0009), (0.0052, 0.0191), (0.012, 0.010), (0.0122, 0.0119)):
        b = utils.sphere((x, y, 0), 0.001, material=mat)
        b.state.blockedDOFs = "zXY"
        m = 1000 * math.pi * 1e-6
        b.state.mass, b.state.inertia = m, (0.5 * m * 1e-6,) * 3
        O.bodies.append(b)
    out = []
    def dump():
        h0 = O.cell.prevHSize
        out.append({
            "h0": [[h0[i, j] for j in range(3)] for i in range(3)],
            "h": [[O.cell.hSize[i, j] for j in range(3)] for i in range(3)],
            "L": [[O.cell.velGrad[i, j] for j in range(3)] for i in range(3)],
            "bodies": [[list(b.state.pos), list(b.state.vel), list(b.state.angVel), b.shape.radius] for b in O.bodies],
            "contacts": [[i.id1, i.id2, list(i.cellDist), list(i.phys.shearForce), i.phys.ks]
                         for i in O.interactions if i.isReal],
        })
    O.engines = [ForceResetter(), InsertionSortCollider([Bo1_Sphere_Aabb()]),
                 InteractionLoop([Ig2_Sphere_Sphere_ScGeom(avoidGranularRatcheting=False)], [phys], [law2]),
                 PyRunner(command="dump() if O.iter == 1 else None", iterPeriod=1),
                 NewtonIntegrator(damping=0.0)]
    O.dt = 1e-6
    O.cell.velGrad = Matrix3(0, 1.0, 0, 0, 0, 0, 0, 0, 0)
    O.step(); O.step()
    rows[law] = out[0]
json.dump(rows, open("kinematics.json", "w"))
"""


def test_cundall_strack_sees_the_periodic_image_velocity_and_viscel_adds_it_with_the_wrong_sign(tmp_path):
    """Why the runs use Cundall and Strack's law and no contact damping (docs/yade.md): in homogeneous
    shear flow the shear force increment of each contact is -ks dt times the tangential velocity of
    body 2's image relative to body 1. YADE's ScGeom (Cundall-Strack) gets it for the pair across the
    boundary as for the inner pair; Law2_ScGeom_ViscElPhys_Basic (ViscoelasticPM.cpp:118) adds the
    image's velocity L h cellDist where it must subtract it: 2 ks dt L h cellDist off on that pair."""
    import json

    from reference_runs.yade.job import run_yade_job

    run_yade_job(tmp_path / "job", KINEMATICS_SCRIPT, outputs=["kinematics.json"])
    rows = json.loads((tmp_path / "job" / "kinematics.json").read_text())
    dt = 1e-6
    for law in ("cundall", "viscel"):
        st = rows[law]
        h0, h, L = np.array(st["h0"]), np.array(st["h"]), np.array(st["L"])
        B = [(np.array(b[0]), np.array(b[1]), np.array(b[2]), float(b[3])) for b in st["bodies"]]
        assert sorted(tuple(c[2][:2]) for c in st["contacts"]) == [(0, -1), (0, 0)]  # across, inside
        for id1, id2, cd, fs, ks in st["contacts"]:
            (x1, v1, w1, r1), (x2, v2, w2, r2) = B[id1], B[id2]
            shift = h @ np.array(cd, float)  # body 2's image is at x2 + h cellDist (the step's cell)
            image = L @ h0 @ np.array(cd, float)  # moving with L h cellDist (the cell before the step)
            d = x2 + shift - x1
            n = d / np.linalg.norm(d)
            cp = x1 + (r1 - 0.5 * (r1 + r2 - np.linalg.norm(d))) * n  # the contact point, mid-overlap
            v_rel = (v2 + image + np.cross(w2, cp - x2 - shift)) - (v1 + np.cross(w1, cp - x1))
            want = -ks * dt * (v_rel - (v_rel @ n) * n)  # both laws store it with this sign
            scale = ks * dt * 0.02  # ks dt times the speed of the cell's top (L 0.02 m)
            if law == "viscel" and any(cd):  # the image's velocity added where it must be subtracted
                want = want + 2.0 * ks * dt * (image - (image @ n) * n)
                assert np.abs(image).max() == pytest.approx(0.02)
            assert np.abs(np.array(fs) - want).max() <= 1e-9 * scale, (law, cd, fs, want)


def test_what_the_script_cannot_run_is_refused_naming_the_field():
    from gransim.dem.sheared import ShearLoading
    from gransim.errors import InputError
    from reference_runs.decks.biaxial import short_case

    p, damped, ld, _ = short_case()  # the decks' settings: gamma_n = gamma_t = 50 1/s
    with pytest.raises(InputError, match=r"settings.gamma_n, gamma_t: .*ViscoelasticPM.cpp:118"):
        biaxial_job(p, damped, ld, 10)
    _, s, _, _ = short_shear("servo")
    with pytest.raises(InputError, match="loading.xy: .*got xy 'vel'"):
        shear_job(p, s, ShearLoading(xy="vel", value=1e-3), 10)
    with pytest.raises(InputError, match="loading.every: .*every = 5"):
        shear_job(p, s, ShearLoading(erate=1.0, every=5), 10)
    with pytest.raises(InputError, match="nsteps: expected an integer >= 1"):
        biaxial_job(p, s, ld, 0)
