"""Guo & Zhao's DEM RVE in YADE itself: ``prepareRVE.py`` and a Gauss point's strain history
replayed through ``simDEM.shear2D``, with every state dumped at full precision.

Guo & Zhao (*A coupled FEM/DEM approach for hierarchical multiscale modelling of granular media*,
Int. J. Numer. Meth. Engng 99 (2014) 789-818) prepare one periodic RVE (Debian yade 2023.02a,
``/usr/share/doc/yade/examples/FEMxDEM/prepareRVE.py``) and drive it at every Gauss point by
``simDEM.shear2D`` (``/usr/lib/x86_64-linux-gnu/yade-double/py/yade/FEMxDEM/simDEM.py``:53-62):
each call deserialises the committed scene (``Omega().stringToScene``), sets
``velGrad = D / (ns dt)`` with ns = int(max(1e5 max|D|, 2)), runs ns steps, sets ``velGrad`` to
zero and serialises the scene again. The constant script :data:`RVE_SCRIPT` does exactly that, with
the lines of both files copied (the recipe's numbers from ``input.json``), and writes ``rve.out``:
one JSON line per state (the prepared scene as ``simDEM.initLoad`` loads it, then the scene after
each increment, as the next call loads it), with everything the scene's serialisation keeps and
the native yade arithmetic needs (:class:`gransim.dem.yade_arithmetic.YadeRVEState`), YADE's
``getStress()`` and ``getStressAndTangent(symmetry=True)``, and ``END`` last. Each body also
carries its ``State::rot()`` (the rotation vector from refOri to ori, core/State.hpp:40-45, which
simDEM.avgRotation2D averages, simDEM.py:204-210) and its ``ori`` in minieigen's index order
(x, y, z, w): read by :func:`disk_rotations`, not part of the native state.

:func:`prepare_job` and :func:`replay_job` build the jobs; :func:`run_rve_job` runs one through
:func:`reference_runs.yade.job.run_yade_job` (the quiet module: YADE opens no TCP server) and reads
it (:func:`read_rve_out`, which refuses an output cut short). :func:`state_of` turns a dumped state
into the native :class:`~gransim.dem.yade_arithmetic.YadeRVEState`.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from gransim.errors import InputError

from ..errors import ReferenceRunError
from .job import run_yade_job

INPUT_NAME = "input.json"
OUTPUT_NAME = "rve.out"
OUTPUT_MAGIC = "# gransim-yade-rve 1"

#: prepareRVE.py's recipe (lines 5-19, 26-36): 400 disks, r_mean 5 mm +- 40 %, 0.24 m cell, seed 1
PREPARE_RVE = {"n": 400, "size": 0.24, "seed": 1, "r_mean": 0.005, "r_fuzz": 0.4}

RVE_SCRIPT = r"""# YADE script written by gransim (reference_runs.yade.rve): Guo & Zhao's RVE.
# prepareRVE.py and simDEM.shear2D of Debian's yade 2023.02a, copied; input.json, output rve.out.
import json
import re

import numpy
from yade import pack, utils

job = json.load(open("input.json"))
out = open("rve.out", "w")
out.write("# gransim-yade-rve 1\n")


def newton_prev_cell_size():
    # NewtonIntegrator.prevCellSize is Attr::hidden (not in Python) but saved: read it from an XML save
    O.save("state.xml")
    text = open("state.xml").read()
    m = re.search(r"<prevCellSize>\s*<x>([^<]+)</x>\s*<y>([^<]+)</y>\s*<z>([^<]+)</z>", text)
    return [float(m.group(i)) for i in (1, 2, 3)] if m else None


def mat(m):
    return [[float(m[i, j]) for j in range(3)] for i in range(3)]


def dump(kind, extra):
    c = O.cell
    newton = [e for e in O.engines if isinstance(e, NewtonIntegrator)][0]
    collider = [e for e in O.engines if isinstance(e, InsertionSortCollider)][0]
    bodies = []
    for b in O.bodies:
        s = b.state
        bodies.append([list(map(float, s.pos)), list(map(float, s.vel)), list(map(float, s.angVel)), float(s.mass),
                       list(map(float, s.inertia)), float(b.shape.radius), list(map(float, b.bound.refPos)),
                       float(b.bound.sweepLength), int(b.bound.lastUpdateIter), list(map(float, s.rot())),
                       [float(s.ori[i]) for i in range(4)]])
    intrs = []
    for i in O.interactions:
        if not i.isReal:
            intrs.append([i.id1, i.id2, list(i.cellDist), False])
            continue
        g, p = i.geom, i.phys
        intrs.append([i.id1, i.id2, list(i.cellDist), True, list(map(float, g.normal)), float(g.penetrationDepth),
                      float(p.kn), float(p.ks), float(p.tangensOfFrictionAngle), list(map(float, p.normalForce)),
                      list(map(float, p.shearForce))])
    st = utils.getStressAndTangent(symmetry=True)
    rec = {
        "kind": kind, "iter": O.iter, "dt": O.dt, "subStep": O.subStep,
        "hSize": mat(c.hSize), "trsf": mat(c.trsf), "velGrad": mat(c.velGrad), "nextVelGrad": mat(c.nextVelGrad),
        "cellPrevVelGrad": mat(c.prevVelGrad), "velGradChanged": bool(c.velGradChanged),
        "newtonPrevVelGrad": mat(newton.prevVelGrad), "maxVelocitySq": float(newton.maxVelocitySq),
        "prevCellSize": newton_prev_cell_size(), "damping": float(newton.damping),
        "verletDist": float(collider.verletDist), "young": float(O.materials[0].young),
        "poisson": float(O.materials[0].poisson), "frictionAngle": float(O.materials[0].frictionAngle),
        "engines": [type(e).__name__ for e in O.engines],
        "stress": mat(utils.getStress()), "stressT": mat(st[0]),
        "tangent": [[float(st[1][i, j]) for j in range(6)] for i in range(6)],
        "bodies": bodies, "interactions": intrs,
    }
    rec.update(extra)
    out.write(json.dumps(rec) + "\n")
    out.flush()


if job["mode"] == "prepare":
    # prepareRVE.py:5-54 (the cell size, number of disks and seed from input.json)
    O.materials.append(FrictMat(young=6.e8, poisson=.8, frictionAngle=.0))
    sp = pack.SpherePack()
    size = float(job["size"])
    sp.makeCloud(minCorner=(0, 0, .05), maxCorner=(size, size, .05), rMean=float(job["r_mean"]),
                 rRelFuzz=float(job["r_fuzz"]), num=int(job["n"]), periodic=True, seed=int(job["seed"]))
    sp.toSimulation()
    O.cell.hSize = Matrix3(size, 0, 0, 0, size, 0, 0, 0, .1)
    for p in O.bodies:
        p.state.blockedDOFs = 'zXY'
        p.state.mass = 2650 * 0.1 * pi * p.shape.radius**2  # 0.1 = thickness of cylindrical particle
        inertia = 0.5 * p.state.mass * p.shape.radius**2
        p.state.inertia = (.5 * inertia, .5 * inertia, inertia)
    O.dt = utils.PWaveTimeStep()
    O.engines = [
        ForceResetter(),
        InsertionSortCollider([Bo1_Sphere_Aabb()]),
        InteractionLoop([Ig2_Sphere_Sphere_ScGeom()], [Ip2_FrictMat_FrictMat_FrictPhys()],
                        [Law2_ScGeom_FrictPhys_CundallStrack()]),
        PeriTriaxController(dynCell=True, goal=(-1.e5, -1.e5, 0), stressMask=3, relStressTol=.001,
                            maxUnbalanced=.001, maxStrainRate=(.5, .5, .0), doneHook='term()', label='biax'),
        NewtonIntegrator(damping=.1)
    ]

    def term():
        O.engines = O.engines[:3] + O.engines[4:]
        setContactFriction(0.5)
        O.cell.trsf = Matrix3.Identity
        O.cell.velGrad = Matrix3.Zero
        for p in O.bodies:
            p.state.vel = Vector3.Zero
            p.state.angVel = Vector3.Zero
            p.state.refPos = p.state.pos
            p.state.refOri = p.state.ori
        O.save('0.yade.gz')
        O.pause()

    O.run()
    O.wait()
    O.load('0.yade.gz')  # simDEM.initLoad (simDEM.py:24): the scene term() saved
else:
    O.load(job["scene"])  # simDEM.initLoad (simDEM.py:24, 36)
scene = O.sceneToString()
O.stringToScene(scene)
dump("loaded", {"call": 0})
for k, D in enumerate(job.get("increments", []), 1):
    # simDEM.shear2D (simDEM.py:53-62), param = [scene, D]
    Omega().stringToScene(scene)
    ns = int(max(1e5 * numpy.max(numpy.abs(D)), 2))
    dstrain = utils.Matrix3(D[0], D[1], 0, D[2], D[3], 0, 0, 0, 0)
    Omega().cell.velGrad = dstrain / (ns * Omega().dt)
    Omega().run(ns, True)
    Omega().cell.velGrad = utils.Matrix3.Zero
    scene = Omega().sceneToString()
    O.stringToScene(scene)  # simDEM.getStressAndTangent2D loads the returned scene (simDEM.py:138)
    dump("call", {"call": k, "ns": ns})
out.write("END\n")
out.close()
"""


def prepare_job(n: int = 400, size: float = 0.24, seed: int = 1, increments=()):
    """``(script, files)`` of ``prepareRVE.py`` (n disks in a periodic ``size`` cell, makeCloud's
    ``seed``), then the strain increments ``increments`` (K, 4: D_xx, D_xy, D_yx, D_yy) replayed."""
    meta = dict(PREPARE_RVE, n=int(n), size=float(size), seed=int(seed), mode="prepare")
    meta["increments"] = _increments(increments)
    return RVE_SCRIPT, {INPUT_NAME: json.dumps(meta).encode()}


def replay_job(scene: Path, increments):
    """``(script, files)`` replaying ``increments`` (K, 4) from the saved scene ``scene``
    (``0.yade.gz`` of a prepare job): the file is copied into the job."""
    meta = {"mode": "replay", "scene": "scene.yade.gz", "increments": _increments(increments)}
    return RVE_SCRIPT, {INPUT_NAME: json.dumps(meta).encode(), "scene.yade.gz": Path(scene).read_bytes()}


def _increments(increments) -> list:
    a = np.asarray(increments, dtype=float).reshape(-1, 4)
    if not np.all(np.isfinite(a)):
        raise InputError("increments: every strain increment must be finite")
    return a.tolist()


def read_rve_out(path) -> list:
    """The dumped states of ``rve.out`` (list of dicts, call 0 the loaded scene). Raises
    :class:`ReferenceRunError` (``incomplete: ...``) for a file cut short or out of order."""
    path = Path(path)
    try:
        lines = path.read_text().split("\n")
    except OSError as exc:
        raise ReferenceRunError(f"incomplete: {path}: cannot read it ({exc})", job_dir=path.parent) from None
    if not lines or lines[0] != OUTPUT_MAGIC or len(lines) < 3 or lines[-2:] != ["END", ""]:
        raise ReferenceRunError(f"incomplete: {path}: no header or no END line", job_dir=path.parent)
    recs = [json.loads(s) for s in lines[1:-2]]
    if [r["call"] for r in recs] != list(range(len(recs))):
        raise ReferenceRunError(f"incomplete: {path}: a call is missing or out of order", job_dir=path.parent)
    return recs


def _check(job_dir) -> list:
    try:
        read_rve_out(Path(job_dir) / OUTPUT_NAME)
    except (ReferenceRunError, ValueError) as exc:
        return [str(exc)]
    return []


def run_rve_job(job_dir, script: str, files: dict, timeout: float | None = 1800.0, force: bool = False):
    """Run (or reuse) a job of :func:`prepare_job` / :func:`replay_job`: ``(records, manifest)``."""
    outputs = [OUTPUT_NAME] + (["0.yade.gz"] if json.loads(files[INPUT_NAME])["mode"] == "prepare" else [])
    res = run_yade_job(job_dir, script, files, timeout=timeout, outputs=outputs, force=force, check=_check)
    return read_rve_out(Path(job_dir) / OUTPUT_NAME), res.manifest


def disk_rotations(rec: dict) -> np.ndarray:
    """Each disk's ``State::rot()`` z (N,) rad of a dumped state: YADE's rotation since the prepared
    RVE (refOri = ori when prepareRVE.py's term() saved it). Raises :class:`ReferenceRunError` for a
    dump without it (written before the script recorded it) or a rotation off the z axis."""
    b = rec["bodies"]
    if not all(len(x) > 9 for x in b):
        raise ReferenceRunError("incomplete: the dumped state holds no State::rot() (an older rve.out)")
    rot = np.array([x[9] for x in b], float)
    if np.any(rot[:, :2] != 0.0):
        raise ReferenceRunError("a disk turned about x or y: its DOFs XY are not blocked")
    return rot[:, 2]


def state_of(rec: dict):
    """The native state of a dumped YADE state (every interaction must be real: a deserialised
    scene holds only the real ones, core/InteractionContainer.cpp:174-181)."""
    from gransim.dem.yade_arithmetic import YadeRVEState  # noqa: PLC0415 - numba at start-up

    b = rec["bodies"]
    it = rec["interactions"]
    if not all(i[3] for i in it):
        raise ReferenceRunError("a dumped scene holds a non-real interaction: not a deserialised scene")
    z = {float(x[0][2]) for x in b}
    if len(z) != 1:
        raise ReferenceRunError(f"the disks lie in several planes z = {sorted(z)[:3]}")

    def m2(key):
        return np.array(rec[key], float)[:2, :2]

    pcs = rec["prevCellSize"]
    return YadeRVEState(
        iteration=int(rec["iter"]),
        dt=float(rec["dt"]),
        z=float(rec["hSize"][2][2]),
        z_pos=z.pop(),
        radii=np.array([x[5] for x in b]),
        mass=np.array([x[3] for x in b]),
        inertia=np.array([x[4][2] for x in b]),
        positions=np.array([x[0][:2] for x in b]),
        velocities=np.array([x[1][:2] for x in b]),
        spins=np.array([x[2][2] for x in b]),
        bound_ref=np.array([x[6][:2] for x in b]),
        sweep=np.array([x[7] for x in b]),
        last_update=np.array([x[8] for x in b], np.int64),
        hsize=m2("hSize"),
        vel_grad=m2("velGrad"),
        next_vel_grad=m2("nextVelGrad"),
        vel_grad_changed=bool(rec["velGradChanged"]),
        newton_prev_vel_grad=m2("newtonPrevVelGrad"),
        prev_cell_size=np.array(pcs if pcs is not None else [np.nan] * 3, float),
        verlet=float(rec["verletDist"]),
        damping=float(rec["damping"]),
        young=float(rec["young"]),
        poisson=float(rec["poisson"]),
        friction_angle=float(rec["frictionAngle"]),
        ids=np.array([i[:2] for i in it], np.int64).reshape(-1, 2),
        cell_dist=np.array([i[2][:2] for i in it], np.int64).reshape(-1, 2),
        normal=np.array([i[4][:2] for i in it], float).reshape(-1, 2),
        kn=np.array([i[6] for i in it], float),
        ks=np.array([i[7] for i in it], float),
        tan_phi=np.array([i[8] for i in it], float),
        normal_force=np.array([i[9][:2] for i in it], float).reshape(-1, 2),
        shear_force=np.array([i[10][:2] for i in it], float).reshape(-1, 2),
    )


__all__ = [
    "PREPARE_RVE",
    "RVE_SCRIPT",
    "disk_rotations",
    "prepare_job",
    "read_rve_out",
    "replay_job",
    "run_rve_job",
    "state_of",
]
