"""Parameters, timing and outputs of one run of Guo & Zhao's FEM x DEM biaxial test, inside the job.

Imported by the ported ``biaxialSmooth.py`` and ``prepareRVE.py`` (``port.patch``) in the job
directory, where they run under Debian's ``/usr/bin/python3`` (3.11, numpy 1.24) with escript 5.6 and
YADE 2023.02a; written by gransim (``reference_runs/femxdem``) and copied into each job unchanged.
It computes no physics of its own: it reads the run's parameters, times the process pool's maps and
the Newton solves of Guo & Zhao's ``msFEM2D.MultiScale``, and writes what their code computed, every
float by ``repr`` (exact), each file ended by an ``END`` line so that a file cut short is seen.

Files (in the job directory's ``result/``; ``rve.txt`` beside ``0.yade.gz``):

- ``versions.txt``: ``key = value`` lines, the versions as YADE and escript report themselves.
- ``steps.txt``: one line per load step (0 = the state before loading), columns named in its header.
- ``newton.txt``: ``step iteration relative_error`` for every error msFEM2D printed.
- ``maps.txt``: ``step function n_items seconds worker_cpu_seconds`` for every ``Pool.map``.
- ``fields_<step>.txt``: per Gauss point its position, stress, strain, fabric, void ratio, rotation.
- ``rve.txt``: the consolidated RVE (prepareRVE.py's ``term()``).

Guo & Zhao, "A coupled FEM/DEM approach for hierarchical multiscale modelling of granular media",
Int. J. Numer. Meth. Engng 99 (2014) 789-818.
"""

import contextlib
import io
import json
import multiprocessing.pool
import os
import re
import sys
import time

PARAMS_NAME = "femxdem_params.json"
RESULT = "result"
#: msFEM2D.py prints this after every solve (msFEM2D.py:250), converged or not (the loop ends at iter_max)
_DONE = re.compile(r"Convergence reached after (\d+) iteration\(s\)! Relative error: (\S+)")
#: ... and this before every iteration (msFEM2D.py:223)
_ITER = re.compile(r"Not converged after (\d+) iteration\(s\)! Relative error: (\S+)")

STEP_COLUMNS = (
    "step",
    "axial_strain",  # t * vel / ly (biaxialSmooth.py:96), tension positive
    "force_top_x",
    "force_top_y",  # resultant traction on the top (biaxialSmooth.py:94), N/m
    "length_top",  # current length of the top (biaxialSmooth.py:95), m
    "area",  # current area of the domain, m^2
    "stress_xx",
    "stress_xy",
    "stress_yx",
    "stress_yy",  # volume average of the Gauss-point stresses, Pa
    "strain_xx",
    "strain_xy",
    "strain_yx",
    "strain_yy",  # volume average of the accumulated Gauss-point strains
    "iterations",  # Newton iterations msFEM2D reported (0 at step 0)
    "relative_error",  # its last relative error ||du|| / ||u|| (nan at step 0)
    "wall_step",  # s since the previous record (step 0: since the Recorder, i.e. the pool's start)
    "wall_solve",  # s in MultiScale.solve
    "wall_dem",  # s in the pool maps of shear2D and getStressAndTangent2D during the solve
    "n_dem_maps",  # number of those maps
    "load1",  # the machine's 1-minute load average at the record
    "cpu_main",  # CPU s used so far by the main process (FE, escript, pickling)
    "cpu_workers",  # CPU s used so far by the pool's worker processes (the RVEs)
)


_TICK = os.sysconf("SC_CLK_TCK")


def _cpu_of(pid):
    """User + system CPU seconds of process ``pid`` (``/proc/PID/stat`` fields 14 and 15), 0 when gone."""
    try:
        with open(f"/proc/{pid}/stat") as fh:
            fields = fh.read().rsplit(")", 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / _TICK


def workers_cpu(pool):
    """CPU seconds used so far by the worker processes of a ``multiprocessing`` pool."""
    return sum(_cpu_of(p.pid) for p in getattr(pool, "_pool", ()))


def parameters(path=PARAMS_NAME):
    """The run's parameters (a dict), from ``femxdem_params.json`` in the job directory."""
    with open(path) as fh:
        return json.load(fh)


def _write_atomic(name, text):
    tmp = name + ".part"
    with open(tmp, "w") as fh:
        fh.write(text)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, name)


class _MapClock:
    """Logs each ``multiprocessing.pool.Pool.map`` of this process (function, item count, wall
    time) once :meth:`install` has wrapped it (a class attribute, in this process only: the workers
    never call it)."""

    def __init__(self):
        self.step = 0
        self.log = []  # (step, name, n, seconds, worker CPU seconds)
        self.pool = None
        self.installed = False

    def install(self):
        if self.installed:
            return
        self.installed = True
        original = multiprocessing.pool.Pool.map
        clock = self

        def map(pool, func, iterable, chunksize=None):
            items = list(iterable)
            clock.pool = pool
            c0 = workers_cpu(pool)
            t0 = time.perf_counter()
            out = original(pool, func, items, chunksize)
            wall = time.perf_counter() - t0
            name = getattr(func, "__name__", str(func))
            clock.log.append((clock.step, name, len(items), wall, workers_cpu(pool) - c0))
            return out

        multiprocessing.pool.Pool.map = map


_CLOCK = _MapClock()  # installed by Recorder(), before msFEM2D.MultiScale starts its pool
DEM_MAPS = ("shear2D", "getStressAndTangent2D")


def write_versions(path):
    """``versions.txt``: YADE's and escript's versions as they report themselves, and the solver."""
    import esys.escript as escript
    import numpy
    import yade.config

    rows = {
        "yade_version": yade.config.version,
        "yade_revision": yade.config.revision,
        "yade_prefix": yade.config.prefix,
        "escript_getVersion": escript.getVersion(),
        "escript_module": escript.__file__,
        "python": sys.version.split()[0],
        "numpy": numpy.__version__,
    }
    buildvars = os.path.join(os.path.dirname(os.path.dirname(escript.__file__)), "..", "lib", "buildvars")
    with contextlib.suppress(OSError):
        with open(os.path.normpath(buildvars)) as fh:
            for line in fh:
                k, _, v = line.strip().partition("=")
                if k in ("umfpack", "mkl", "trilinos", "mumps", "openmp", "mpi", "svn_revision", "python_version"):
                    rows["escript_build_" + k] = v
    _write_atomic(path, "".join(f"{k} = {v}\n" for k, v in rows.items()) + "END\n")


class Recorder:
    """The records of one run of biaxialSmooth.py. Create it before ``MultiScale`` (so the pool's
    start counts in step 0), call :meth:`solve` instead of ``prob.solve``, :meth:`step` after each
    step's post-processing and :meth:`close` last."""

    def __init__(self, params):
        self.params = params
        self.field_steps = {int(s) for s in params["field_steps"]}
        _CLOCK.install()
        os.makedirs(RESULT, exist_ok=True)
        write_versions(os.path.join(RESULT, "versions.txt"))
        self._steps = open(os.path.join(RESULT, "steps.txt"), "w")
        self._steps.write("# " + " ".join(STEP_COLUMNS) + "\n")
        self._newton = open(os.path.join(RESULT, "newton.txt"), "w")
        self._newton.write("# step iteration relative_error\n")
        self._t_last = time.perf_counter()
        self._t_start = self._t_last
        self._solve = (0, float("nan"), 0.0, 0.0, 0)
        self._n_steps = 0

    def solve(self, prob, iter_max=100):
        """``prob.solve(iter_max)``, timed; msFEM2D's own report (printed, verbose=True) is kept and
        echoed; returns what ``prob.solve`` returns."""
        step = _CLOCK.step + 1
        _CLOCK.step = step
        first = len(_CLOCK.log)
        buf = io.StringIO()
        t0 = time.perf_counter()
        with contextlib.redirect_stdout(buf):
            u = prob.solve(iter_max=iter_max)
        wall = time.perf_counter() - t0
        text = buf.getvalue()
        sys.stdout.write(text)
        done = _DONE.findall(text)
        if len(done) != 1:
            raise RuntimeError(f"step {step}: msFEM2D printed {len(done)} convergence lines, expected 1")
        for it, err in _ITER.findall(text):
            self._newton.write(f"{step} {int(it)} {float(err)!r}\n")
        self._newton.write(f"{step} {int(done[0][0])} {float(done[0][1])!r}\n")
        self._newton.flush()
        dem = [r for r in _CLOCK.log[first:] if r[1] in DEM_MAPS]
        self._solve = (int(done[0][0]), float(done[0][1]), wall, sum(r[3] for r in dem), len(dem))
        return u

    def step(self, prob, t, force_top, length_top, void_ratio=None, fabric=None):
        """One line of ``steps.txt`` for step ``t`` and, at a field step, ``fields_<t>.txt``."""
        from esys.escript import Function, Scalar, integrate

        dom = prob.getDomain()
        area = float(integrate(Scalar(1.0, Function(dom))))
        stress = integrate(prob.getCurrentStress()) / area
        strain = integrate(prob.getCurrentStrain()) / area
        if t in self.field_steps:
            self._fields(prob, t, void_ratio, fabric)
        now = time.perf_counter()
        iters, err, wall_solve, wall_dem, n_dem = self._solve if t > 0 else (0, float("nan"), 0.0, 0.0, 0)
        row = [
            t,
            t * self.params["vel"] / self.params["ly"],
            float(force_top[0]),
            float(force_top[1]),
            float(length_top),
            area,
            *(float(v) for v in stress.ravel()),
            *(float(v) for v in strain.ravel()),
            iters,
            err,
            now - self._t_last,
            wall_solve,
            wall_dem,
            n_dem,
            os.getloadavg()[0],
            sum(os.times()[:2]),
            workers_cpu(_CLOCK.pool) if _CLOCK.pool is not None else 0.0,
        ]
        self._t_last = now
        self._steps.write(" ".join(repr(v) for v in row) + "\n")
        self._steps.flush()
        self._n_steps = t

    def _fields(self, prob, t, void_ratio, fabric):
        from esys.escript import Function

        dom = prob.getDomain()
        x = Function(dom).getX().toListOfTuples()
        stress = prob.getCurrentStress().toListOfTuples()
        strain = prob.getCurrentStrain().toListOfTuples()
        e = (void_ratio if void_ratio is not None else prob.getLocalVoidRatio()).toListOfTuples()
        fab = (fabric if fabric is not None else prob.getLocalFabric()).toListOfTuples()
        rot = prob.getLocalAvgRotation().toListOfTuples()
        cols = "x y stress_xx stress_xy stress_yx stress_yy strain_xx strain_xy strain_yx strain_yy"
        cols += " fabric_xx fabric_xy fabric_yx fabric_yy void_ratio rotation"
        lines = [f"# step {t} n_gauss {len(x)}", "# " + cols]
        for i in range(len(x)):
            row = [*x[i], *stress[i][0], *stress[i][1], *strain[i][0], *strain[i][1], *fab[i][0], *fab[i][1]]
            row += [e[i], rot[i]]
            lines.append(" ".join(repr(float(v)) for v in row))
        lines.append("END")
        _write_atomic(os.path.join(RESULT, f"fields_{t}.txt"), "\n".join(lines) + "\n")

    def close(self):
        """The end of the run: ``maps.txt`` and the ``END`` line of ``steps.txt`` (a run without it
        did not complete)."""
        rows = [f"{s} {name} {n} {sec!r} {cpu!r}" for s, name, n, sec, cpu in _CLOCK.log]
        _write_atomic(
            os.path.join(RESULT, "maps.txt"),
            "# step function n_items seconds worker_cpu_seconds\n" + "\n".join(rows) + "\nEND\n",
        )
        self._newton.write("END\n")
        self._newton.close()
        total = time.perf_counter() - self._t_start
        self._steps.write(f"END steps={self._n_steps} wall_total={total!r}\n")
        self._steps.close()


def rve_record(path="rve.txt"):
    """``rve.txt``: the consolidated RVE as prepareRVE.py's ``term()`` saves it (called there,
    after ``setContactFriction`` and ``O.save``): bodies, time step, iterations of the
    consolidation, the stress (``getStress``, Pa, 3D with the cell's z size), the cell, the
    unbalanced force, the contacts (radii of the two disks, kn, ks) and their friction, the engines
    saved with the scene (every RVE call runs them) and the NewtonIntegrator's damping."""
    from yade import utils
    from yade.wrapper import Omega

    O = Omega()  # noqa: N806 - YADE's name
    s = utils.getStress()
    h = O.cell.hSize
    real = [i for i in O.interactions if i.isReal]
    tans = sorted({float(i.phys.tangensOfFrictionAngle) for i in real})
    rows = {
        "n_bodies": len(O.bodies),
        "dt": repr(float(O.dt)),
        "iterations": O.iter,
        "stress": " ".join(repr(float(s[i, j])) for i in range(3) for j in range(3)),
        "hsize": " ".join(repr(float(h[i, j])) for i in range(3) for j in range(3)),
        "unbalanced": repr(float(utils.unbalancedForce())),
        "n_contacts": len(real),
        "tan_friction": " ".join(repr(t) for t in tans),
        "material_friction_angle": " ".join(repr(float(m.frictionAngle)) for m in O.materials),
        "engines": " ".join(type(e).__name__ for e in O.engines),
        "damping": " ".join(repr(float(e.damping)) for e in O.engines if type(e).__name__ == "NewtonIntegrator"),
        "contacts": " ".join(
            " ".join(
                repr(float(v))
                for v in (O.bodies[i.id1].shape.radius, O.bodies[i.id2].shape.radius, i.phys.kn, i.phys.ks)
            )
            for i in real
        ),
        "radii": " ".join(repr(float(b.shape.radius)) for b in O.bodies),
        "masses": " ".join(repr(float(b.state.mass)) for b in O.bodies),
    }
    _write_atomic(path, "".join(f"{k} = {v}\n" for k, v in rows.items()) + "END\n")
