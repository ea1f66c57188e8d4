"""Static equilibrium by Newton-Raphson with the relative energy norm, and load stepping with cutting.

Residual in the reduced coordinates q (see :mod:`gransim.fem.constraints`) at load state
(gravity factor lam_g, footing factor lam_f)::

    r(q) = T^T (f_int(u(q)) - lam_g f_body - (1 - lam_g) f_int(0)) - lam_f Q_footing(q)

The term (1 - lam_g) f_int(0) releases the initial imbalance of a prestressed material (the Taylor
RVE has P(1) != 0, which free surfaces do not balance) together with the dead load: q = 0 solves
lam = (0, 0), step 1 is a continuous path that load cutting can follow, and at lam_g = 1 (every
later step) the term is zero, so the answer is unchanged. For P(1) = 0 it vanishes identically.

Newton: K_q dq = -r, q <- q + dq. Convergence measure (Meier et al. Table 2): the relative energy
norm e_k = |dq_k . r_k| / |dq_1 . r_1|, which falls quadratically (e_{k+1} ~ C e_k^2) near a regular
solution. A step that does not converge (iteration limit, divergence, a singular tangent, det F <= 0)
is cut in half, down to a minimum increment; then the solver stops and reports the limit.
No regularisation is added to the tangent.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import GransimError
from .assembly import Assembler
from .constraints import DofMap
from .element import Q1Geometry
from .materials import MaterialResult
from .mesh import Mesh

#: residual norm / force scale below which a state counts as converged (assembly round-off)
ROUNDOFF = 1e-14
#: (iterations, energy norm): a solve still above this energy norm after this many iterations is
#: abandoned as not converging (a quadratically converging step is many decades lower by then; this
#: only shortens the hopeless attempts of the limit search, it never rejects a converging step of
#: the slope runs, whose 4th energy norm is below 3e-5, while the failed attempts of the paper
#: protocol's limit search stand at 5e-2 or above)
STAGNATION = (4, 1e-2)
#: a relative energy norm above this is divergence
DIVERGENCE = 1e2


@dataclass
class Timer:
    """Wall time (s) spent in material evaluation, assembly and the linear solve."""

    material: float = 0.0
    assembly: float = 0.0
    solve: float = 0.0
    iterations: int = 0

    def as_dict(self) -> dict:
        """The split as a plain dict."""
        return {
            "material_s": self.material,
            "assembly_s": self.assembly,
            "solve_s": self.solve,
            "newton_iterations": self.iterations,
        }


class NewtonFailure(GransimError):
    """One Newton solve failed (the load stepper cuts the increment); ``energy_norms`` its history."""

    def __init__(self, message: str, energy_norms=()):
        super().__init__(message)
        self.energy_norms = list(energy_norms)


@dataclass(frozen=True, eq=False)
class Problem:
    """A static boundary value problem on a Q1 mesh.

    Attributes
    ----------
    mesh : Mesh
    material : object with ``evaluate(F) -> MaterialResult`` (batched over all Gauss points)
    dofs : DofMap
        Fixed dofs and the rigid footing.
    body_force : (2,) float
        Body force per reference volume at full dead load (N/m^3), e.g. (0, -rho g).
    footing_force : (2,) float
        Force on the rigid footing at full load (N per m of thickness), at its load point.
    release_prestress : bool
        Release the initial imbalance f_int(0) of a prestressed material with the dead load factor
        (see the module docstring); False applies it at once.
    """

    mesh: Mesh
    material: object
    dofs: DofMap
    body_force: np.ndarray = field(default_factory=lambda: np.zeros(2))
    footing_force: np.ndarray = field(default_factory=lambda: np.zeros(2))
    release_prestress: bool = True
    geometry: Q1Geometry = None
    assembler: Assembler = None
    f_body: np.ndarray = None
    f_int0: np.ndarray = None

    def __post_init__(self):
        geom = Q1Geometry.from_mesh(self.mesh)
        asm = Assembler.from_elements(self.mesh.elements, self.mesh.n_nodes)
        object.__setattr__(self, "geometry", geom)
        object.__setattr__(self, "assembler", asm)
        object.__setattr__(self, "body_force", np.asarray(self.body_force, dtype=float))
        object.__setattr__(self, "footing_force", np.asarray(self.footing_force, dtype=float))
        object.__setattr__(self, "f_body", asm.vector(geom.body_forces(self.body_force)))
        f0 = np.zeros(asm.n_dofs)
        if self.release_prestress:
            P0 = self.material.evaluate(np.broadcast_to(np.eye(2), (geom.n_gauss, 2, 2)).copy()).piola
            f0 = asm.vector(geom.internal_forces(np.asarray(P0)))
            # a material with Gauss-point history (the relaxed RVE) starts from its own state at
            # F = 1 (the relaxed reference RVE), not from the unrelaxed generated packing
            history(self.material, "commit")
        object.__setattr__(self, "f_int0", f0)

    # ------------------------------------------------------------------
    def evaluate(self, q: np.ndarray, load: tuple[float, float], tangent: bool = True, timer: Timer | None = None):
        """(r, K, material, u, F, scale) at q: residual r (n_red,), reduced tangent K_q (sparse CSC or
        None), the material result, nodal displacements (Nn, 2), F (G, 2, 2) and the force scale (N/m)."""
        timer = timer or Timer()
        u = self.dofs.displacement(q)
        F = self.geometry.deformation_gradient(u)
        t0 = time.perf_counter()
        mat: MaterialResult = self.material.evaluate(F)
        t1 = time.perf_counter()
        lam_g, lam_f = load
        fe = self.geometry.internal_forces(mat.piola)
        r_full = self.assembler.vector(fe) - lam_g * self.f_body - (1.0 - lam_g) * self.f_int0
        T = self.dofs.jacobian(q)
        r = T.T @ r_full
        K = None
        if self.dofs.body is not None:
            Q, dQ = self.dofs.point_load(q, self.footing_force)
            r -= lam_f * Q
        if tangent:
            K = T.T @ self.assembler.matrix(self.geometry.stiffness(mat.tangent)) @ T
            if self.dofs.body is not None:
                nth = self.dofs.n_reduced - 1
                extra = self.dofs.rotation_curvature(q, r_full) - lam_f * dQ[nth]
                K = (K + sp.csr_matrix(([extra], ([nth], [nth])), shape=K.shape)).tocsc()
            else:
                K = K.tocsc()
        timer.material += t1 - t0
        timer.assembly += time.perf_counter() - t1
        # size of the nodal forces (N/m): absolute element internal forces plus the applied loads;
        # a residual below ROUNDOFF times this is round-off
        scale = (
            float(np.linalg.norm(self.assembler.vector(np.abs(fe))))
            + abs(lam_g) * float(np.linalg.norm(self.f_body))
            + abs(lam_f) * float(np.linalg.norm(self.footing_force))
        )
        return r, K, mat, u, F, scale


@dataclass(frozen=True, eq=False)
class NewtonResult:
    """A converged Newton solve: state, the relative energy norms e_k (Table 2) and the residual norms.

    ``iterates`` holds the F (G, 2, 2) of every material evaluation of the solve, in order (the last
    is ``F``): a material whose trial history follows the iterates (the relaxed RVE warm-started
    from its previous trial) is restored exactly by evaluating them again before the commit
    (:func:`gransim.fem.checkpoint.replay_history`). Empty for a solve read back from a checkpoint.
    """

    q: np.ndarray
    u: np.ndarray
    F: np.ndarray
    material: MaterialResult
    energy_norms: np.ndarray
    residual_norms: np.ndarray
    iterates: tuple = ()


def _solve(K, r, timer: Timer, enorms=()):
    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            lu = spla.splu(K)
            dq = -lu.solve(r)
    except (RuntimeError, spla.MatrixRankWarning, RuntimeWarning) as exc:
        raise NewtonFailure(f"singular tangent ({exc})", enorms) from None
    finally:
        timer.solve += time.perf_counter() - t0
    if not np.all(np.isfinite(dq)):
        raise NewtonFailure("singular tangent (non-finite increment)", enorms)
    return dq


def newton(
    problem: Problem,
    q0: np.ndarray,
    load: tuple[float, float],
    tol: float = 1e-20,
    max_iter: int = 12,
    timer: Timer | None = None,
) -> NewtonResult:
    """Solve r(q) = 0 from q0; converged when the relative energy norm e_k <= tol.

    A state whose residual norm is at round-off level (``ROUNDOFF`` times the force scale) counts as
    converged: the energy norm of its (round-off sized) increment is still recorded for the table but
    not applied, and a step that starts in equilibrium returns at once (a relative measure would
    otherwise chase round-off).
    Raises :class:`NewtonFailure` on a singular tangent, det F <= 0 at a Gauss point, a diverging
    energy norm (e_k > ``DIVERGENCE``), stagnation (see ``STAGNATION``) or when ``max_iter`` iterations do not
    reach ``tol``.
    """
    timer = timer or Timer()
    q = np.array(q0, dtype=float)
    enorms, rnorms, iterates = [], [], []
    e0 = None
    for _ in range(max_iter):
        try:
            r, K, mat, u, F, scale = problem.evaluate(q, load, timer=timer)
        except (GransimError, RuntimeError) as exc:  # det F <= 0, or an RVE relaxation that fails
            raise NewtonFailure(f"material evaluation failed: {exc}", enorms) from None
        iterates.append(F)
        at_roundoff = np.linalg.norm(r) <= ROUNDOFF * scale
        if at_roundoff and e0 is None:  # already in equilibrium: nothing to record
            break
        dq = _solve(K, r, timer, enorms)
        timer.iterations += 1
        e = abs(float(dq @ r))
        if e0 is None:
            e0 = e if e > 0 else 1.0
        enorms.append(e / e0)
        rnorms.append(float(np.linalg.norm(r)))
        if not np.isfinite(enorms[-1]) or enorms[-1] > DIVERGENCE:
            raise NewtonFailure(f"diverged (relative energy norm {enorms[-1]:.3e})", enorms)
        if len(enorms) >= STAGNATION[0] and enorms[-1] > STAGNATION[1]:
            raise NewtonFailure(
                f"no quadratic convergence (relative energy norm {enorms[-1]:.3e} after {len(enorms)} iterations)",
                enorms,
            )
        if at_roundoff or enorms[-1] <= tol:
            # converged: the evaluated state q is returned; e_k measures its distance from equilibrium
            # (the remaining increment dq is below tolerance and is not applied)
            break
        q = q + dq
    else:
        raise NewtonFailure(
            f"no convergence in {max_iter} iterations (relative energy norm {enorms[-1]:.3e} > {tol:.1e})", enorms
        )
    return NewtonResult(q, u, F, mat, np.array(enorms), np.array(rnorms), tuple(iterates))


@dataclass(frozen=True, eq=False)
class StepRecord:
    """One converged load step: its target load, the converged state and the Newton history.

    ``energy_norms`` is the history of the step's last Newton solve (the whole step when ``cuts`` is
    0); ``substeps`` lists the load fractions of the step's converged sub-increments.
    """

    step: int
    load: tuple[float, float]
    solution: NewtonResult
    cuts: int
    substeps: tuple

    @property
    def energy_norms(self) -> np.ndarray:
        """Relative energy norms of the (last) Newton solve of this step."""
        return self.solution.energy_norms


@dataclass(frozen=True, eq=False)
class LoadPathResult:
    """Every converged step, and why the path stopped (``limit`` is None when it reached the end)."""

    steps: list
    limit: dict | None
    timer: Timer
    failures: list = field(default_factory=list)

    @property
    def completed(self) -> bool:
        """True when every load step converged."""
        return self.limit is None


def history(material, action: str) -> None:
    """``material.commit()`` or ``material.revert()`` when the material keeps Gauss-point history
    (see :func:`run_load_steps`); nothing for a history-free material."""
    fn = getattr(material, action, None)
    if callable(fn):
        fn()


@dataclass(frozen=True, eq=False)
class ResumeState:
    """Where a load path resumes (a checkpoint, :mod:`gransim.fem.checkpoint`): the converged steps
    so far (``steps``, StepRecords 1..k), the failed attempts so far (``failures``), and the
    Gauss-point history, already restored in the material. The next step is k + 1 from
    ``steps[-1].solution.q`` at load ``steps[-1].load``."""

    steps: list
    failures: list = field(default_factory=list)


def run_load_steps(
    problem: Problem,
    schedule,
    tol: float = 1e-20,
    max_iter: int = 12,
    min_fraction: float = 1.0 / 64,
    on_step=None,
    progress=None,
    start: ResumeState | None = None,
    on_commit=None,
    failures_out: list | None = None,
) -> LoadPathResult:
    """Follow ``schedule`` (a list of (lam_g, lam_f) targets, one per step) from the unloaded state.

    A step whose Newton solve fails is cut into halves (then quarters...) of its load increment;
    after a converged sub-increment the increment doubles again (up to the rest of the step). When
    the increment would fall below ``min_fraction`` of a step, the path stops: ``limit`` then holds
    the failed step, the last converged load and the reason. ``on_step(record)`` is called after each
    converged step (outputs are written there, so a stopped run keeps them).

    A material with Gauss-point history (``commit()`` / ``revert()``, e.g.
    :class:`gransim.rve.RelaxedMaterial`, whose converged fluctuations are the history) is committed
    after every converged (sub-)increment, i.e. at the state the Newton solve returned, and
    reverted after every failed attempt, so a rejected increment leaves the history as it was and
    the retry starts from the last converged state. Materials without these methods are unaffected.
    ``on_commit(solution)`` is called after every commit (the checkpoint records the solution's
    ``iterates``: the F of every evaluation since the last revert, the committed F last).

    ``start`` (:class:`ResumeState`) continues a path after its converged steps: the steps it holds
    are skipped and the path goes on from the last one's state, exactly as the uninterrupted run
    would (the material's history must already be the one committed at that step).
    ``failures_out`` (a list) receives the live list of failed attempts (for checkpoints).
    """
    timer = Timer()
    q = np.zeros(problem.dofs.n_reduced)
    prev = np.zeros(2)
    steps = []
    limit = None
    failures = []  # (step, fraction of the step tried, energy norms) of every failed attempt
    if start is not None and start.steps:
        steps = list(start.steps)
        failures = list(start.failures)
        q = np.array(steps[-1].solution.q, dtype=float)
        prev = np.asarray(steps[-1].load, dtype=float)
    if failures_out is not None:
        failures_out.append(failures)
    for k, target in enumerate(schedule, start=1):
        if k <= len(steps):
            if progress is not None:
                progress.update(1)
            continue
        target = np.asarray(target, dtype=float)
        done, h, cuts, sub = 0.0, 1.0, 0, []
        last_failure = ""
        sol = None
        while done < 1.0 - 1e-12:
            h = min(h, 1.0 - done)
            load = prev + (done + h) * (target - prev)
            try:
                sol = newton(problem, q, tuple(load), tol=tol, max_iter=max_iter, timer=timer)
            except NewtonFailure as exc:
                history(problem.material, "revert")
                last_failure = str(exc)
                failures.append((k, float(done + h), exc.energy_norms))
                h *= 0.5
                cuts += 1
                if h < min_fraction * (1 - 1e-12):
                    break
                continue
            history(problem.material, "commit")
            if on_commit is not None:
                on_commit(sol)
            q = sol.q
            done += h
            sub.append(done)
            h *= 2.0
        if done < 1.0 - 1e-12:
            last_load = prev + done * (target - prev)
            limit = {
                "step": k,
                "target": tuple(target),
                "last_converged_load": tuple(last_load),
                "fraction_of_step": done,
                "reason": last_failure,
                "min_fraction": min_fraction,
                "partial": sol if (sub and sol is not None) else None,
            }
            break
        rec = StepRecord(k, tuple(target), sol, cuts, tuple(sub))
        steps.append(rec)
        if on_step is not None:
            on_step(rec)
        if progress is not None:
            progress.update(1)
        prev = target
    return LoadPathResult(steps, limit, timer, failures)
