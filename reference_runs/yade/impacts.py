"""Binary disk impacts in YADE (the scenes of validation case ``impacts``, docs/impacts.md): the script,
the reader of its output with its evidence accounting, the driver, and the answers of YADE's laws
where they differ from the LIGGGHTS and LAMMPS laws.

The scenes are those of :mod:`reference_runs.decks.impact` (pairs of disks side by side, each pair
meeting once; the caller gives the layout: packing, velocities, spins, number of steps). Every
pair stays far from the box's edges for the whole run (the disks move by ~1e-6 m), so YADE runs
them in an ordinary, non-periodic scene: no periodic image enters any contact.

YADE's laws (YADE 2023.02a, the tag ``2023.02a`` of the mirror ``Aoxi-git/Cementor``; docs/yade.md):

* the linear law with mass-scaled damping (:class:`reference_runs.decks.impact.HookeLaw`) is
  ``Law2_ScGeom_ViscElPhys_Basic`` with one ``ViscElMat`` per disk, kn_i = 2 kn, ks_i = 2 kt,
  cn_i = gamma_n m_i, cs_i = gamma_t m_i: the pair gets the series combinations 1/(1/a + 1/b)
  (pkg/dem/ViscoelasticPM.cpp:237-246, 297-300, 333-340), i.e. kn, kt, gamma_n m_eff, gamma_t
  m_eff. Its defect in periodic cells (the image velocity ``shiftVel`` added with the wrong sign,
  ViscoelasticPM.cpp:118) does not arise: ``shiftVel`` is zero in a non-periodic scene
  (ViscoelasticPM.cpp:113). Two differences from LIGGGHTS and LAMMPS change the answers:
  the normal force kn delta + cn v_n is set to 0 when negative (no attraction,
  ViscoelasticPM.cpp:129-139), so a damped impact ends its force at the inflection of delta(t)
  and the disks then coast apart (:func:`clipped_dashpot`); and the Coulomb cap mu |F_n| applies
  to the spring alone, the tangential dashpot only when it does not slide (153-165), so after
  the force has ended (|F_n| = 0) the spring is scaled to zero. The lever arm is r_i - delta/2
  (the contact point mid-overlap, Ig2_Sphere_Sphere_ScGeom.cpp:52; torques 166-167), as LIGGGHTS'.
* the Hertz-Mindlin laws (:class:`~reference_runs.decks.impact.HertzLiggghtsLaw`,
  :class:`~reference_runs.decks.impact.HertzHistoryLammpsLaw`,
  :class:`~reference_runs.decks.impact.HertzGranularLammpsLaw`, undamped) are
  ``Ip2_FrictMat_FrictMat_MindlinPhys`` + ``Law2_ScGeom_MindlinPhys_Mindlin``: kno = 4/3 E*
  sqrt(R*), E* = E_a E_b/((1 - nu_a^2) E_b + (1 - nu_b^2) E_a), kso = 8 sqrt(R*) G*,
  G* = 1/((2 - nu_a)/G_a + (2 - nu_b)/G_b) (pkg/dem/HertzMindlin.cpp:47-55), the same 4/3 Y*
  and 8 G* as the three laws; F_n = kno delta^(3/2) (312), k_t = kso sqrt(delta) (336), the shear
  force incremented by -k_t(delta) times the shear displacement increment (372-382: the
  *incremental* Mindlin form, where LIGGGHTS and LAMMPS keep the spring xi and set F_t = -k_t(delta)
  xi), capped at mu |F_n| (446-455); forces at the contact point (511-512). Gross sliding and the
  normal impact are therefore the same closed forms. A sticking contact leaves with the exit slip
  of the total form as long as it sticks (for a k_t symmetric in time the two forms' transfer
  matrices have equal diagonals), but YADE's force does not vanish with k_t at the end of the
  contact while mu F_n does, so it slides out there even at mu = 1e3
  (:func:`mindlin_incremental_stick`). YADE's Hertz damping (betan from a restitution by Thornton
  et al.'s fit, its dashpot clipped to repulsion, 344-417) is not the damping of any of the three
  laws: damped Hertz scenes are refused (:func:`yade_law`).

The script (:data:`IMPACT_SCRIPT`, constant; ``input.json`` carries everything that varies)
builds one sphere per disk with ``blockedDOFs = 'zXY'`` and the 2D mass and inertia m r^2/2 set
by hand, engines ``ForceResetter``, ``InsertionSortCollider``, ``InteractionLoop`` with
``Ig2_Sphere_Sphere_ScGeom(avoidGranularRatcheting=False)``, a ``PyRunner`` every iteration
(``initRun=True``) and ``NewtonIntegrator(damping=0)`` (leapfrog: docs/yade.md), and runs
``n_steps + 1`` iterations. Iteration k writes, at full precision (``repr``), every ``every``-th
step and the last, the state at step k: positions x_k, forces and torques at x_k, and the
velocities and spins YADE holds then, v_(k-1/2) and w_(k-1/2) (the leapfrog's half step).

Output ``impact.out``::

    # gransim-yade-impact 1 n_particles N n_steps S every E
    F k N                                   (a frame header)
    P id x y vx vy wz fx fy tz              (N rows, ids 0..N-1 in order)
    ...
    END S

:func:`read_yade_impact` refuses, as ``incomplete``, a file cut short (no ``END``, a partial last
line), a header that is not the job's, a frame missing or out of order, a frame whose particle
rows are not ids 0..N-1 in order, and NaN or inf anywhere; it is the job's evidence check, so such
an output makes the job ``failed``, never ``ok``. :func:`yade_impacts` gives the frames in the
form of the native engine's and the codes' (``{step: {"x", "v", "w", "f", "t"}}``) with the
velocities brought to the step: v_k = v_(k-1/2) + (dt/2) f_k/m, w_k = w_(k-1/2) + (dt/2) t_k/I
(velocity Verlet's on-step velocity; after a contact, where f = 0, the two are equal).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

from gransim.errors import InputError
from gransim.geometry import Packing

from ..errors import ReferenceRunError
from .dem import expected_steps
from .job import run_yade_job

OUTPUT_MAGIC = "# gransim-yade-impact"
OUTPUT_VERSION = 1
OUTPUT_NAME = "impact.out"
INPUT_NAME = "input.json"
_N_P = 10  # fields of a particle row

IMPACT_SCRIPT = r"""# YADE script written by gransim (reference_runs.yade.impacts): binary disk impacts, non-periodic.
# Input: input.json. Output: impact.out (format in reference_runs/yade/impacts.py).
# Run: yade -n -x -j1 SCRIPT
import json
import math

from yade import utils

with open("input.json") as fh:
    job = json.load(fh)
law = job["law"]
dt = float(job["dt"])
n_steps = int(job["n_steps"])
every = int(job["every"])
n = len(job["radii"])
phi = math.atan(float(law["mu"]))
mats = []
for i in range(n):
    m = float(job["mass"][i])
    if law["kind"] == "viscel":
        # series combination per pair (ViscoelasticPM.cpp:333-340): 2 kn, 2 kt; gamma m_i -> gamma m_eff
        mats.append(O.materials.append(ViscElMat(
            kn=2.0 * float(law["kn"]), ks=2.0 * float(law["kt"]), cn=float(law["gamma_n"]) * m,
            cs=float(law["gamma_t"]) * m, frictionAngle=phi, density=1.0)))
    else:
        mats.append(O.materials.append(FrictMat(
            young=float(law["youngs_modulus"]), poisson=float(law["poisson_ratio"]), frictionAngle=phi,
            density=1.0)))
for i, ((x, y), r, (vx, vy), w) in enumerate(zip(job["positions"], job["radii"], job["velocities"], job["spins"])):
    b = utils.sphere((x, y, 0.0), r, material=mats[i])
    b.state.blockedDOFs = "zXY"
    b.state.mass = float(job["mass"][i])
    b.state.inertia = (float(job["inertia"][i]),) * 3
    b.state.vel = Vector3(vx, vy, 0.0)
    b.state.angVel = Vector3(0.0, 0.0, w)
    O.bodies.append(b)

if law["kind"] == "viscel":
    phys, law2 = Ip2_ViscElMat_ViscElMat_ViscElPhys(), Law2_ScGeom_ViscElPhys_Basic()
else:
    phys, law2 = Ip2_FrictMat_FrictMat_MindlinPhys(), Law2_ScGeom_MindlinPhys_Mindlin()

out = open("impact.out", "w")


def g(v):
    return repr(float(v))


def put(*fields):
    out.write(" ".join(str(f) for f in fields) + "\n")


def dump():
    k = O.iter
    if k % every == 0 or k == n_steps:
        put("F", k, n)
        for b in O.bodies:
            st = b.state
            f, t = O.forces.f(b.id), O.forces.t(b.id)
            put("P", b.id, g(st.pos[0]), g(st.pos[1]), g(st.vel[0]), g(st.vel[1]), g(st.angVel[2]), g(f[0]),
                g(f[1]), g(t[2]))
        out.flush()


O.engines = [
    ForceResetter(),
    InsertionSortCollider([Bo1_Sphere_Aabb()]),
    InteractionLoop([Ig2_Sphere_Sphere_ScGeom(avoidGranularRatcheting=False)], [phys], [law2]),
    PyRunner(command="dump()", iterPeriod=1, initRun=True),
    NewtonIntegrator(damping=0.0, gravity=(0.0, 0.0, 0.0)),
]
O.dt = dt
put("# gransim-yade-impact", 1, "n_particles", n, "n_steps", n_steps, "every", every)
for _ in range(n_steps + 1):
    O.step()
put("END", n_steps)
out.close()
"""


# ----------------------------------------------------------------------------- the law
def yade_law(law) -> dict:
    """The YADE law of a scene's law (module doc): ``{"kind": "viscel", kn, kt, gamma_n, gamma_t,
    mu}`` for :class:`~reference_runs.decks.impact.HookeLaw`, ``{"kind": "mindlin",
    youngs_modulus, poisson_ratio, mu}`` for an undamped Hertz law whose 4/3 Y* and 8 G* are
    YADE's (``law.hertz()`` checked against HertzMindlin.cpp:47-55 to 1e-14).

    Raises InputError naming the law for a damped Hertz law (YADE's Hertz damping is another law)
    and for the rolling and flat-wall laws (no YADE script here)."""
    name = getattr(law, "name", type(law).__name__)
    if not hasattr(law, "hertz"):
        if not all(hasattr(law, k) for k in ("kn", "kt", "gamma_n", "gamma_t", "mu")) or hasattr(law, "params"):
            raise InputError(f"law {name!r}: the YADE impact script runs the Hooke and undamped Hertz laws only")
        if getattr(law, "engine", None) is not None:  # WallLaw: the codes' own flat walls
            raise InputError(f"law {name!r}: a flat granular wall of LIGGGHTS or LAMMPS has no YADE script here")
        return {
            "kind": "viscel",
            "kn": float(law.kn),
            "kt": float(law.kt),
            "gamma_n": float(law.gamma_n),
            "gamma_t": float(law.gamma_t),
            "mu": float(law.mu),
        }
    h = law.hertz()
    if h["damping"] != "none" or h["kt_damping"]:
        raise InputError(
            f"law {name!r}: damped ({h['damping']}); YADE's Hertz-Mindlin damping (betan from Thornton et al.'s "
            "fit, the dashpot clipped to repulsion, HertzMindlin.cpp:344-417) is another law: only undamped Hertz "
            "scenes run in YADE"
        )
    E, nu = float(law.youngs_modulus), float(law.poisson_ratio)
    G = E / (2.0 * (1.0 + nu))
    y43 = 4.0 / 3.0 * (E * E / ((1.0 - nu**2) * E + (1.0 - nu**2) * E))
    kt0 = 8.0 / ((2.0 - nu) / G + (2.0 - nu) / G)
    if abs(y43 / h["y43"] - 1.0) > 1e-14 or abs(kt0 / h["kt0"] - 1.0) > 1e-14:
        raise InputError(
            f"law {name!r}: 4/3 Y* = {h['y43']!r}, 8 G* = {h['kt0']!r} are not YADE's {y43!r}, {kt0!r} from "
            f"E = {E!r}, nu = {nu!r}"
        )
    return {"kind": "mindlin", "youngs_modulus": E, "poisson_ratio": nu, "mu": float(law.mu)}


# ----------------------------------------------------------------------------- job, reader, driver
def impact_job(packing: Packing, velocities, spins, law, dt: float, n_steps: int, every: int):
    """``(script, files)`` of the YADE run of an impact scene: the layout of
    ``validation.cases.impacts.layout`` (packing, (N, 2) velocities m/s, (N,) spins rad/s, steps),
    ``law`` as :func:`yade_law`, time step ``dt`` (s), a frame every ``every`` steps."""
    n_steps, every = int(n_steps), int(every)
    for nm, v in (("n_steps", n_steps), ("every", every)):
        if v < 1:
            raise InputError(f"{nm}: expected an integer >= 1, got {v}")
    if not (math.isfinite(dt) and dt > 0):
        raise InputError(f"dt: expected a time step > 0 s, got {dt!r}")
    n = packing.n
    v = np.asarray(velocities, float).reshape(n, 2)
    w = np.asarray(spins, float).reshape(n)
    r = np.asarray(packing.radii, float)
    m = float(packing.density) * math.pi * r * r
    meta = {
        "law": yade_law(law),
        "dt": float(dt),
        "n_steps": n_steps,
        "every": every,
        "radii": r.tolist(),
        "mass": m.tolist(),
        "inertia": (0.5 * m * r * r).tolist(),
        "positions": np.asarray(packing.positions, float).tolist(),
        "velocities": v.tolist(),
        "spins": w.tolist(),
    }
    return IMPACT_SCRIPT, {INPUT_NAME: json.dumps(meta).encode()}


@dataclass(frozen=True, eq=False)
class YadeImpactOutput:
    """A complete ``impact.out``.

    Attributes
    ----------
    n_particles, n_steps, every : from the header (checked against the job).
    steps : (T,) frame steps. x, v_half, f : (T, N, 2) positions x_k (m), velocities v_(k-1/2)
    (m/s), forces at x_k (N). w_half, t : (T, N) spins w_(k-1/2) (rad/s), torques (N m).
    """

    n_particles: int
    n_steps: int
    every: int
    steps: np.ndarray
    x: np.ndarray
    v_half: np.ndarray
    w_half: np.ndarray
    f: np.ndarray
    t: np.ndarray


def _incomplete(path, msg):
    return ReferenceRunError(f"incomplete: {path}: {msg}", job_dir=Path(path).parent, problems=[f"incomplete: {msg}"])


def read_yade_impact(path, expect: dict | None = None) -> YadeImpactOutput:
    """Read ``impact.out``; ``expect``: the job's ``n_particles``, ``n_steps``, ``every``.

    Raises :class:`~reference_runs.errors.ReferenceRunError` (``incomplete: ...``) for a file that
    is missing, unreadable, of another format or cut short (no ``END`` line, a partial line), a
    header that differs from the job, a frame missing or out of order, a frame whose particle rows
    are not ids 0..N-1 in order, and for a NaN or inf anywhere."""
    path = Path(path)
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise _incomplete(path, f"cannot read it ({exc})") from None
    lines = text.split("\n")
    if lines[-1] != "":
        raise _incomplete(path, "the last line is cut short (no newline at the end)")
    lines.pop()
    head = lines[0].split() if lines else []
    keys = ("n_particles", "n_steps", "every")
    if head[:2] != OUTPUT_MAGIC.split() or len(head) != 9 or tuple(head[3::2]) != keys:
        raise _incomplete(
            path, f"not a gransim YADE impact output (first line {lines[0][:80]!r})" if lines else "empty"
        )
    if head[2] != str(OUTPUT_VERSION):
        raise _incomplete(path, f"format version {head[2]}, this reader reads {OUTPUT_VERSION}")
    try:
        hdr = dict(zip(keys, (int(v) for v in head[4::2])))
    except ValueError:
        raise _incomplete(path, f"malformed header {lines[0][:80]!r}") from None
    for k, v in (expect or {}).items():
        if hdr[k] != int(v):
            raise _incomplete(path, f"the header has {k} = {hdr[k]}, the job {int(v)}")
    N = hdr["n_particles"]
    due = expected_steps(hdr["n_steps"], hdr["every"])
    frames, rows, ended, cur = [], [], False, None

    def close(where):
        if len(rows) != N:
            raise _incomplete(path, f"{where}: frame of step {cur} has {len(rows)} of {N} particles")
        P = np.array(rows, float)
        if not np.array_equal(P[:, 0], np.arange(N)):
            missing = sorted(set(range(N)) - {int(i) for i in P[:, 0]})
            raise _incomplete(
                path, f"frame of step {cur}: particle ids are not 0..{N - 1} in order (missing {missing[:5]})"
            )
        frames.append((cur, P[:, 1:]))

    for lineno, line in enumerate(lines[1:], 2):
        f = line.split()
        where = f"line {lineno}"
        if ended:
            raise _incomplete(path, f"{where}: text after the END line")
        try:
            if f and f[0] == "P":
                if cur is None or len(f) != _N_P:
                    raise _incomplete(path, f"{where}: malformed or stray particle row {line[:80]!r}")
                rows.append([float(v) for v in f[1:]])
                continue
            if cur is not None:
                close(where)
                cur, rows = None, []
            if f and f[0] == "F" and len(f) == 3:
                k, n_p = int(f[1]), int(f[2])
                want = due[len(frames)] if len(frames) < len(due) else None
                if k != want:
                    raise _incomplete(path, f"{where}: frame of step {k} where step {want} is due (one missing)")
                if n_p != N:
                    raise _incomplete(path, f"{where}: frame of step {k} announces {n_p} particles, the run has {N}")
                cur = k
            elif f and f[0] == "END" and len(f) == 2:
                if int(f[1]) != hdr["n_steps"]:
                    raise _incomplete(path, f"{where}: END {f[1]} for a run of {hdr['n_steps']} steps")
                ended = True
            else:
                raise _incomplete(path, f"{where}: malformed line {line[:80]!r}")
        except ValueError:
            raise _incomplete(path, f"{where}: a field is not a number: {line[:80]!r}") from None
    if cur is not None:
        close("at the end of the file")
    if not ended:
        raise _incomplete(path, f"cut short after {len(frames)} of {len(due)} frames (no END line)")
    if len(frames) != len(due):
        raise _incomplete(path, f"{len(frames)} of {len(due)} frames")
    A = np.stack([a for _, a in frames])  # (T, N, 9): x y vx vy wz fx fy tz
    if not np.all(np.isfinite(A)):
        T, i, _ = np.argwhere(~np.isfinite(A))[0]
        raise _incomplete(path, f"frame of step {frames[T][0]}, particle {i}: a value is NaN or inf")
    return YadeImpactOutput(
        N, hdr["n_steps"], hdr["every"], np.array([k for k, _ in frames], np.int64),
        A[:, :, 0:2], A[:, :, 2:4], A[:, :, 4], A[:, :, 5:7], A[:, :, 7],
    )  # fmt: skip


def _expect(job_dir: Path) -> dict:
    meta = json.loads((job_dir / INPUT_NAME).read_text())
    return {"n_particles": len(meta["radii"]), "n_steps": meta["n_steps"], "every": meta["every"]}


def check_output(job_dir) -> list:
    """Problems of a YADE impact job's output (empty: complete): the evidence check of the job."""
    job_dir = Path(job_dir)
    try:
        read_yade_impact(job_dir / OUTPUT_NAME, _expect(job_dir))
    except ReferenceRunError as exc:
        return [str(exc)]
    except (OSError, ValueError, KeyError) as exc:
        return [f"incomplete: {job_dir / INPUT_NAME}: cannot read the job's counts ({exc})"]
    return []


def run_yade_impact(job_dir, script: str, files: dict, timeout: float | None = 600.0, force: bool = False):
    """Run (or reuse) a YADE impact job in ``job_dir`` and read it: ``(output, manifest)``. Raises
    :class:`~reference_runs.errors.ReferenceRunError` when the job fails or its output is
    incomplete (the reader is the job's evidence check)."""
    res = run_yade_job(job_dir, script, files, timeout=timeout, outputs=[OUTPUT_NAME], force=force, check=check_output)
    return read_yade_impact(Path(job_dir) / OUTPUT_NAME, _expect(Path(job_dir))), res.manifest


def on_step_frames(out: YadeImpactOutput, files: dict) -> dict:
    """``{step: {"x", "v", "w", "f", "t"}}`` (the frames of the native engine and the codes) from a
    YADE output: v_k = v_(k-1/2) + (dt/2) f_k/m, w_k = w_(k-1/2) + (dt/2) t_k/I (module doc), with
    dt, m, I of the job's ``input.json`` (``files``)."""
    meta = json.loads(files[INPUT_NAME])
    dt = float(meta["dt"])
    m = np.asarray(meta["mass"], float)
    inertia = np.asarray(meta["inertia"], float)
    frames = {}
    for i, k in enumerate(out.steps):
        frames[int(k)] = {
            "x": out.x[i],
            "v": out.v_half[i] + (0.5 * dt) * out.f[i] / m[:, None],
            "w": out.w_half[i] + (0.5 * dt) * out.t[i] / inertia,
            "f": out.f[i],
            "t": out.t[i],
        }
    return frames


def yade_impacts(
    job_dir, packing: Packing, velocities, spins, law, dt: float, n_steps: int, every: int, timeout=600.0, force=False
) -> tuple[dict, dict]:
    """Run an impact scene in YADE (or reuse its complete job): ``(frames, manifest)`` with frames
    ``{step: {"x" (N, 2), "v" (N, 2), "w" (N,), "f" (N, 2), "t" (N,)}}`` at every ``every``-th step
    and the last, velocities on the step (:func:`on_step_frames`). The arguments are those of
    :func:`reference_runs.decks.impact.write_impact_deck`; ``law`` as :func:`yade_law`."""
    script, files = impact_job(packing, velocities, spins, law, dt, n_steps, every)
    out, manifest = run_yade_impact(job_dir, script, files, timeout=timeout, force=force)
    return on_step_frames(out, files), manifest


# ----------------------------------------------------------------------------- YADE's answers
def clipped_dashpot(meff: float, kn: float, gamma_n: float, vn: float) -> dict:
    """Normal impact of the linear spring-dashpot whose force is clipped to repulsion (YADE's
    ``Law2_ScGeom_ViscElPhys_Basic``, ViscoelasticPM.cpp:129-139): Schwager & Poeschel,
    "Coefficient of restitution and linear-dashpot model revisited", Granular Matter 9 (2007) 465,
    eqs (9)-(12) for a dashpot of m_eff gamma_n.

    Before the clip the motion is eq (1) of the impacts case, delta = (v_n/w_d) exp(-a t) sin(w_d t)
    (a = zeta w0); the force m_eff delta'' vanishes at w_d t* = pi - atan(2 a w_d/(w_d^2 - a^2))
    and the disks then coast at delta'(t*) until delta = 0.

    Parameters: meff (kg), kn (N/m), gamma_n (1/s), vn (m/s > 0); zeta < 1/sqrt(2).
    Returns: "release time" t* (s), "restitution" |delta'(t*)|/v_n, "contact time" t* + delta(t*)/
    |delta'(t*)| (s), "impulse factor" int |F_n| dt/(m_eff v_n) = 1 + e (the force never changes
    sign). The peak overlap is eq (4) unchanged (it comes before t*). Undamped: e = 1, t* = t_c = pi/w0.
    """
    w0 = math.sqrt(kn / meff)
    z = gamma_n / (2.0 * w0)
    if not 0.0 <= z < 1.0 / math.sqrt(2.0):
        raise ValueError(f"zeta = {z:.4g}: the clipped dashpot needs 0 <= zeta < 1/sqrt(2)")
    a, wd = z * w0, w0 * math.sqrt(1.0 - z * z)
    ts = (math.pi - math.atan2(2.0 * a * wd, wd * wd - a * a)) / wd
    d = vn / wd * math.exp(-a * ts) * math.sin(wd * ts)
    u = -vn * math.exp(-a * ts) * (math.cos(wd * ts) - a / wd * math.sin(wd * ts))
    e = u / vn
    return {"release time": ts, "restitution": e, "contact time": ts + d / u, "impulse factor": 1.0 + e}


def mindlin_incremental_stick(
    meff: float, reff: float, y43: float, kt0: float, vn: float, s0: float, mu: float, rtol: float = 1e-12
) -> float:
    """s'/s0 of an undamped Hertz-Mindlin impact at a large mu in YADE's incremental form
    (HertzMindlin.cpp:336, 372-382, cap 446-455): m* delta'' = -K delta^(3/2), K = y43 sqrt(R*);
    the tangential force F (on body 1, along t) changes as F' = -k_t(delta) s, k_t = kt0 sqrt(R*
    delta), the slip as s' = 3 F/m* (disks: 1/m1 + 1/m2 + r1^2/I1 + r2^2/I2 = 3/m*); F(0) = 0,
    s(0) = s0 (m/s), released at the return to delta = 0.

    LIGGGHTS and LAMMPS keep the spring xi, F = -k_t(delta) xi (eq H5 of the impacts case), which
    vanishes with k_t at the end of the contact. Without the cap both give the same s'/s0 (s'' =
    -(3/m*) k_t s from s'(0) = 0 here, xi'' = -(3/m*) k_t xi from xi(0) = 0 there: the diagonal
    entries of one transfer matrix, equal for a k_t symmetric in time); YADE's F does not vanish,
    while F_n = K delta^(3/2) does, so near the end |F| reaches mu F_n even for mu = 1e3. YADE then
    scales F to the cap keeping its sign (446-455): on the cap F = sign(F) mu K delta^(3/2) while
    the cap shrinks faster than the spring would unload, sign(F) (-k_t s) >= d(mu F_n)/dt, and the
    spring law again after that.
    Not linear in s0 (the cap is not). Integrated by DOP853 (scipy) phase by phase, each switch
    located by an event (at most 20 switches)."""
    if s0 == 0.0:
        raise ValueError("s0: the initial slip must not be 0 (s'/s0 is returned)")
    K = y43 * math.sqrt(reff)
    tc = 2.9432 * (5.0 * meff * vn * vn / (4.0 * K)) ** 0.4 / vn
    opts = {"method": "DOP853", "rtol": rtol, "atol": 1e-16}

    def fn(y):
        return K * max(y[0], 0.0) ** 1.5

    def kt(y):
        return kt0 * math.sqrt(reff * max(y[0], 0.0))

    def dcap(y):  # d(mu F_n)/dt
        return 1.5 * mu * K * math.sqrt(max(y[0], 0.0)) * y[1]

    def back(t, y):
        return y[0]

    back.terminal, back.direction = True, -1
    t, y, sign = 0.0, [0.0, vn, 0.0, float(s0)], 0.0
    for _ in range(21):
        if sign == 0.0:  # sticking: the spring law

            def rhs(t, y):
                return [y[1], -fn(y) / meff, -kt(y) * y[3], 3.0 * y[2] / meff]

            def switch(t, y):
                return mu * fn(y) - abs(y[2])

        else:  # on the cap, F = sign mu F_n

            def rhs(t, y, sign=sign):
                return [y[1], -fn(y) / meff, sign * dcap(y), 3.0 * y[2] / meff]

            def switch(t, y, sign=sign):
                return sign * (-kt(y) * y[3]) - dcap(y)

        switch.terminal, switch.direction = True, -1
        first = {"first_step": tc * 1e-6} if t == 0.0 else {}
        sol = solve_ivp(rhs, (t, 2.0 * tc), y, events=(back, switch), **opts, **first)
        if len(sol.t_events[0]):
            return float(sol.y_events[0][0][3]) / s0
        if not len(sol.t_events[1]):
            raise RuntimeError("mindlin_incremental_stick: the contact did not end within twice the Hertz contact time")
        t, y = float(sol.t_events[1][0]), list(sol.y_events[1][0])
        sign = math.copysign(1.0, y[2]) if sign == 0.0 else 0.0
    raise RuntimeError("mindlin_incremental_stick: more than 20 stick-slip switches")


__all__ = [
    "IMPACT_SCRIPT",
    "YadeImpactOutput",
    "check_output",
    "clipped_dashpot",
    "impact_job",
    "mindlin_incremental_stick",
    "on_step_frames",
    "read_yade_impact",
    "run_yade_impact",
    "yade_impacts",
    "yade_law",
]
