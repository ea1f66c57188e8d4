"""The YADE script of a Taylor job, its input file and the output format it writes.

The script (:data:`TAYLOR_SCRIPT`) is constant text run by ``yade -n -x -j1 -L MODULE SCRIPT``
(:mod:`reference_runs.yade.job`); everything that varies is in its input file ``input.json``,
written by gransim with Python's ``repr`` of every float (JSON round-trips float64 exactly):
the normal stiffness ``kn`` (N/m), the z size ``z`` of the periodic cell (m), the radii, the 2D
density, and per state its index, F, the deformed cell F C (columns = lattice vectors) and the
deformed centres x = F X as numpy computes them (the same numbers the LIGGGHTS and LAMMPS decks
print with ``%.17g``).

Per state the script builds a fresh periodic scene (``O.reset()``): ``O.cell.hSize`` = [[F C, 0],
[0, z]], one sphere per disk at (x, y, 0) with ``blockedDOFs = 'zXY'`` and the 2D mass and
inertia set by hand, ``Ip2_FrictMat_FrictMat_FrictPhys`` with ``kn = MatchMaker(algo='val',
val=kn)`` and ``ks = MatchMaker(algo='val', val=0)`` (the paper's elastic normal contact, no
tangential stiffness), ``Law2_ScGeom_FrictPhys_CundallStrack``, no integrator, and one
``O.step()`` (collider, then geometry, physics and law on the new contacts: the forces at the
given positions; nothing moves). It then writes, at full precision (``repr``):

``C index id1 id2 cd1 cd2 cd3 fn1 fn2 fn3 fs1 fs2 fs3 pen``
    one row per real interaction: body ids (0-based, the packing's order), ``cellDist`` (the
    image of body 2), ``phys.normalForce``, ``phys.shearForce`` (force on body 2, YADE's
    convention) and ``geom.penetrationDepth``;
``S index n_contacts volume stress(9) stress_t(9) tangent(36)``
    after its contact rows: the number of real interactions, ``O.cell.volume`` (the 3D volume,
    z included), ``utils.getStress()`` (Love-Weber, 3D volume), and the stress and 6x6 tangent of
    ``utils.getStressAndTangent()`` (row-major);
``END n_states``
    last line, when every state was written.

The first line is ``# gransim-yade-taylor 1 n_states N``. A reader
(:func:`reference_runs.yade.taylor.read_yade_taylor`) refuses a file without its ``END`` line, a
state missing or out of order, or a state whose contact rows do not number its ``n_contacts``.
"""

from __future__ import annotations

#: first token of the output's header line, and its format version
OUTPUT_MAGIC = "# gransim-yade-taylor"
OUTPUT_VERSION = 1

TAYLOR_SCRIPT = r"""# YADE script written by gransim (reference_runs.yade.script): Taylor (affine) RVE states.
# Input: input.json (kn, z, radii, density, states with F, the deformed cell F C and centres F X).
# Output: taylor.out (format in reference_runs/yade/script.py). Run: yade -n -x -j1 SCRIPT
import json
import math
import sys

from yade import utils

with open("input.json") as fh:
    job = json.load(fh)
kn = float(job["kn"])
z = float(job["z"])
radii = [float(r) for r in job["radii"]]
rho = float(job["density"])
out = open("taylor.out", "w")


def g(v):
    return repr(float(v))


def put(*fields):
    out.write(" ".join(str(f) for f in fields) + "\n")


put("# gransim-yade-taylor", 1, "n_states", len(job["states"]))
for st in job["states"]:
    O.reset()
    O.periodic = True
    (c11, c12), (c21, c22) = st["cell"]
    O.cell.hSize = Matrix3(c11, c12, 0.0, c21, c22, 0.0, 0.0, 0.0, z)
    mat = O.materials.append(FrictMat(young=1.0, poisson=0.0, frictionAngle=0.0, density=1.0))
    for (x, y), r in zip(st["positions"], radii):
        b = utils.sphere((x, y, 0.0), r, material=mat)
        b.state.blockedDOFs = "zXY"
        m = rho * math.pi * r * r
        b.state.mass = m
        b.state.inertia = (0.5 * m * r * r,) * 3
        O.bodies.append(b)
    O.engines = [
        ForceResetter(),
        InsertionSortCollider([Bo1_Sphere_Aabb()], verletDist=0.0),
        InteractionLoop(
            [Ig2_Sphere_Sphere_ScGeom(avoidGranularRatcheting=True)],
            [Ip2_FrictMat_FrictMat_FrictPhys(kn=MatchMaker(algo="val", val=kn), ks=MatchMaker(algo="val", val=0.0))],
            [Law2_ScGeom_FrictPhys_CundallStrack()],
        ),
    ]
    O.dt = 1.0
    O.step()
    n = 0
    for i in O.interactions:
        if not i.isReal:
            continue
        n += 1
        cd, fn, fs = i.cellDist, i.phys.normalForce, i.phys.shearForce
        put("C", st["index"], i.id1, i.id2, cd[0], cd[1], cd[2], g(fn[0]), g(fn[1]), g(fn[2]),
            g(fs[0]), g(fs[1]), g(fs[2]), g(i.geom.penetrationDepth))
    s = utils.getStress()
    st_t, tan = utils.getStressAndTangent()
    put("S", st["index"], n, g(O.cell.volume), *[g(s[a, b]) for a in range(3) for b in range(3)],
        *[g(st_t[a, b]) for a in range(3) for b in range(3)], *[g(tan[a, b]) for a in range(6) for b in range(6)])
    out.flush()
put("END", len(job["states"]))
out.close()
"""
