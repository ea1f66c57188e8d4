"""The YADE script of a periodic DEM run (biaxial test with its stress servo, periodic simple shear),
its input and the output format it writes.

The script (:data:`DEM_SCRIPT`) is constant text run by ``yade -n -x -j1 -L MODULE SCRIPT``
(:mod:`reference_runs.yade.job`); everything that varies is in ``input.json`` (floats by Python's
``repr``, exact), written by :mod:`reference_runs.yade.dem`: the 2D disks (centres wrapped into the
cell, radii, density, initial velocities and spins), the cell (2 x 2, lattice vectors as columns)
and its z size ``z``, the contact law, ``dt``, the number of steps and the output periods, and the
loading of the cell: per diagonal component ``xx``, ``yy`` one of

* ``fixed``: velGrad 0;
* ``rate`` (``c`` = rate L0 dt, m per step): velGrad = c / (dt L), so that the side grows by c per
  step, L(n) = L0 + c n as the LIGGGHTS and LAMMPS decks' ``del = c*step``;
* ``servo`` (``k`` = dt gain, ``target``): velGrad = k (p - target) / dt with p = -sigma of that axis
  (compression positive, N/m), sigma the 2D stress z ``utils.getStress()`` of the step: L(n+1) =
  L(n) (1 + k (p - target)), the decks' ``del = (l - L0) + k (p - target) l``;

and for the shear component ``xy`` either nothing or ``erate`` R: velGrad = R Ly0 / Ly, so that the
tilt grows by dt R Ly0 per step (LAMMPS ``fix deform 1 xy erate R``).

The scene: ``O.periodic``, ``O.cell.hSize`` = [[cell, 0], [0, z]], one sphere per disk with
``blockedDOFs = 'zXY'``, the 2D mass rho pi r^2 and inertia m r^2 / 2 set by hand, the linear
elastic-frictional law of Cundall and Strack: ``Ip2_FrictMat_FrictMat_FrictPhys`` with
``kn = MatchMaker(algo='val', val=kn)``, ``ks = MatchMaker(algo='val', val=kt)``, friction angle
atan(mu), ``Law2_ScGeom_FrictPhys_CundallStrack``, and ``Ig2_Sphere_Sphere_ScGeom(
avoidGranularRatcheting=False)`` (relative velocity at the contact point); no contact damping
(YADE 2023.02a's linear spring-dashpot law adds the periodic image's velocity with the wrong sign,
docs/yade.md, so the runs are undamped: gamma_n = gamma_t = 0); engines ``ForceResetter``,
``InsertionSortCollider``, ``InteractionLoop``, a
``PyRunner`` every step (the loading and the output: after the forces, before the motion) and
``NewtonIntegrator(damping=0)``. It runs ``n_steps + 1`` iterations: iteration k writes the state
at step k (positions x_k, the forces and stress at x_k, the cell of step k, and the velocity
v_(k-1/2), which YADE's leapfrog holds at that point); the last iteration's motion is not written.

Output ``dem.out``, every value at full precision (``repr``):

``# gransim-yade-dem 1 n_particles N n_steps S thermo_every T dump_every D``
    first line;
``T k h00 h01 h10 h11 s00 s01 s10 s11 g00 g01 g10 g11 n_contacts``
    every T-th step (and the last): the cell (lattice vectors as columns, m), the 2D stress z
    ``getStress()`` (N/m, tension positive, not symmetrised), the velocity gradient the loading
    set for the step (1/s) and the number of real interactions;
``F k n_particles n_contacts``
    every D-th step (and the last), followed by ``n_particles`` rows
    ``P id x y vx vy wz fx fy tz mass radius`` (``state.pos``, not wrapped; ``state.vel``, which
    includes the mean field velGrad x; ``O.forces``) and ``n_contacts`` rows
    ``C id1 id2 cd0 cd1 fn0 fn1 fs0 fs1 pen`` (``cellDist`` of body 2, ``phys.normalForce``,
    ``phys.shearForce`` on body 2, ``geom.penetrationDepth``);
``END n_steps``
    last line, when every step was run.

The reader (:func:`reference_runs.yade.dem.read_yade_dem`) refuses, as ``incomplete``, a file
without its ``END`` line or with a partial last line, a step or frame missing or out of order, a
frame whose particle rows are not the ids 0..N-1 or whose contact rows do not number its
``n_contacts``, and a header that differs from the job's.
"""

from __future__ import annotations

#: first tokens of the output's header line, and its format version
OUTPUT_MAGIC = "# gransim-yade-dem"
OUTPUT_VERSION = 1
OUTPUT_NAME = "dem.out"
INPUT_NAME = "input.json"

DEM_SCRIPT = r"""# YADE script written by gransim (reference_runs.yade.dem_script): a periodic 2D DEM run.
# Input: input.json. Output: dem.out (format in reference_runs/yade/dem_script.py).
# Run: yade -n -x -j1 SCRIPT
import json
import math

from yade import utils

with open("input.json") as fh:
    job = json.load(fh)
law = job["law"]
z = float(job["z"])
dt = float(job["dt"])
n_steps = int(job["n_steps"])
thermo_every = int(job["thermo_every"])
dump_every = int(job["dump_every"])
load = job["loading"]
rho = float(job["density"])
radii = [float(r) for r in job["radii"]]
n = len(radii)

O.periodic = True
(c00, c01), (c10, c11) = job["cell"]
O.cell.hSize = Matrix3(c00, c01, 0.0, c10, c11, 0.0, 0.0, 0.0, z)
L0 = (c00, c11)
mat = O.materials.append(FrictMat(young=1.0, poisson=0.0, frictionAngle=math.atan(float(law["mu"])), density=1.0))
for (x, y), r, (vx, vy), w in zip(job["positions"], radii, job["velocities"], job["spins"]):
    m = rho * math.pi * r * r
    b = utils.sphere((x, y, 0.0), r, material=mat)
    b.state.blockedDOFs = "zXY"
    b.state.mass = m
    b.state.inertia = (0.5 * m * r * r,) * 3
    b.state.vel = Vector3(vx, vy, 0.0)
    b.state.angVel = Vector3(0.0, 0.0, w)
    O.bodies.append(b)

out = open("dem.out", "w")


def g(v):
    return repr(float(v))


def put(*fields):
    out.write(" ".join(str(f) for f in fields) + "\n")


def axis_rate(a, ctl, h, p):
    # velGrad of a diagonal component: fixed, engineering rate, or the stress servo
    if ctl["mode"] == "fixed":
        return 0.0
    if ctl["mode"] == "rate":
        return float(ctl["c"]) / (dt * h[a, a])
    return float(ctl["k"]) * (p[a] - float(ctl["target"])) / dt


def control():
    k = O.iter
    h = O.cell.hSize
    s = utils.getStress()
    s2 = [[z * s[0, 0], z * s[0, 1]], [z * s[1, 0], z * s[1, 1]]]
    p = (-s2[0][0], -s2[1][1])
    gxx = axis_rate(0, load["xx"], h, p)
    gyy = axis_rate(1, load["yy"], h, p)
    gxy = float(load["xy_erate"]) * L0[1] / h[1, 1] if load["xy_erate"] else 0.0
    O.cell.velGrad = Matrix3(gxx, gxy, 0.0, 0.0, gyy, 0.0, 0.0, 0.0, 0.0)
    if k % thermo_every == 0 or k == n_steps:
        put("T", k, g(h[0, 0]), g(h[0, 1]), g(h[1, 0]), g(h[1, 1]), g(s2[0][0]), g(s2[0][1]), g(s2[1][0]),
            g(s2[1][1]), g(gxx), g(gxy), g(0.0), g(gyy), O.interactions.countReal())
    if k % dump_every == 0 or k == n_steps:
        real = [i for i in O.interactions if i.isReal]
        put("F", k, n, len(real))
        for b in O.bodies:
            st = b.state
            f, t = O.forces.f(b.id), O.forces.t(b.id)
            put("P", b.id, g(st.pos[0]), g(st.pos[1]), g(st.vel[0]), g(st.vel[1]), g(st.angVel[2]), g(f[0]), g(f[1]),
                g(t[2]), g(st.mass), g(b.shape.radius))
        for i in real:
            cd, fn, fs = i.cellDist, i.phys.normalForce, i.phys.shearForce
            put("C", i.id1, i.id2, cd[0], cd[1], g(fn[0]), g(fn[1]), g(fs[0]), g(fs[1]), g(i.geom.penetrationDepth))
    if k % 100 == 0:
        out.flush()


O.engines = [
    ForceResetter(),
    InsertionSortCollider([Bo1_Sphere_Aabb()]),
    InteractionLoop(
        [Ig2_Sphere_Sphere_ScGeom(avoidGranularRatcheting=False)],
        [Ip2_FrictMat_FrictMat_FrictPhys(kn=MatchMaker(algo="val", val=float(law["kn"])),
                                         ks=MatchMaker(algo="val", val=float(law["kt"])))],
        [Law2_ScGeom_FrictPhys_CundallStrack()],
    ),
    PyRunner(command="control()", iterPeriod=1, initRun=True),
    NewtonIntegrator(damping=0.0, gravity=(0.0, 0.0, 0.0)),
]
O.dt = dt
put("# gransim-yade-dem", 1, "n_particles", n, "n_steps", n_steps, "thermo_every", thermo_every, "dump_every",
    dump_every)
for _ in range(n_steps + 1):
    O.step()
put("END", n_steps)
out.close()
"""
