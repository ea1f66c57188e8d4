"""Load steps of a quasi-static problem with stateful Gauss points (updated Lagrangian, Newton).

Kinematics. Each load step n -> n+1 is solved on the last converged configuration x_n (the mesh's
nodes moved by every converged step so far): the unknown is the step's nodal displacement du, and
each Gauss point receives the step's relative deformation gradient f = 1 + grad_n du
(:mod:`gransim.fem.material_points`), whose point law returns the Cauchy stress sigma and
T = d sigma / d f. Equilibrium on x_{n+1}, pulled back to x_n (first Piola stress relative to x_n)::

    P = J sigma f^-T,   J = det f
    A_iJkL = dP_iJ / df_kL = J [ (f^-1)_Lk sigma_iM (f^-1)_JM + T_iMkL (f^-1)_JM - sigma_iM (f^-1)_Jk (f^-1)_LM ]
    r(du) = sum_e sum_g w_g P dN/dX_n - f_pressure(x_n + du),   K = dr/d du = sum_e sum_g w_g B^T A B - K_pressure

so the tangent is the exact derivative of the residual whenever T is (quadratic Newton; tested by
finite differences). This is Guo & Zhao's scheme (Int. J. Numer. Meth. Engng 99 (2014) 789-818;
``MultiScale.solve`` in yade/FEMxDEM/msFEM2D.py of Debian's yade 2023.02a, lines 204-244): stress
integrated on the current configuration (``setX(x_safe + u)``, line 225), strain increment
D = grad(u) measured on the configuration at the start of the step (line 235), the mesh moved after
every step (line 244); their tangent drops the geometric terms with sigma above (a small-strain
linearisation, exact for sigma = 0), gransim keeps them.

Confining pressure: a follower load p n da on the current boundary, as a fluid or membrane applies
it (Guo & Zhao apply a traction of fixed direction (+-p, 0) per unit current length, the same on
straight vertical sides). In 2D it is linear in the nodal positions (n ds = R dx/ds ds with R a
quarter turn), so its load stiffness is a constant matrix and the resultant on a side is exactly
p times its chord turned by a quarter (p times its length for a straight side): :class:`PressureLoad`.

Newton, as Guo & Zhao's ``solve``: a predictor with the committed stress and tangent and the
prescribed increments (no material call), then corrections K d = -r, each followed by a material
evaluation at the new du; converged when the correction's L2 norm over the configuration is below
``tol`` (1e-2 in their benchmark) times the step's displacement's (their ``err = d / l``, line
231). Unlike theirs (line 233), the material is evaluated after every correction, the last one
included, so the committed states belong to the committed displacement. Every evaluation starts each
point from its committed state; the trial states become committed only after convergence
(:meth:`GaussPoints.commit`), and are dropped on a failure.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import ConvergenceError, GransimError, InputError
from .assembly import Assembler
from .isoparametric import QuadGeometry, QuadMesh, edge_shape_functions
from .material_points import MaterialPointError
from .quadrature import gauss_legendre

#: a correction norm above this many times the step's displacement norm is divergence
DIVERGENCE = 1e2
_R = np.array([[0.0, 1.0], [-1.0, 0.0]])  # R x' = (y', -x'): the outward normal times ds, counter-clockwise


@dataclass(frozen=True, eq=False)
class PressureLoad:
    """A pressure p (Pa, compression positive: pushes into the body) on boundary edges, following the
    boundary.

    ``edges`` (k, m): node indices of each edge (m = 2 or 3), counter-clockwise around the body
    (:meth:`gransim.fem.isoparametric.QuadMesh.edges_on`). Nodal forces (N per m of thickness)::

        f_a = -p int N_a n ds = -p sum_b M_ab R x_b,   M_ab = int N_a dN_b/ds ds  (exact, 3 Gauss points)
    """

    edges: np.ndarray
    pressure: float
    M: np.ndarray = None

    def __post_init__(self):
        edges = np.asarray(self.edges, dtype=np.int64)
        if edges.ndim != 2 or edges.shape[1] not in (2, 3):
            raise InputError(f"edges: expected (k, 2) or (k, 3) node indices, got shape {edges.shape}")
        s, w = gauss_legendre(3)
        N, dN = edge_shape_functions(edges.shape[1], s)
        object.__setattr__(self, "edges", edges)
        object.__setattr__(self, "M", np.einsum("g,ga,gb->ab", w, N, dN))

    def forces(self, x: np.ndarray) -> np.ndarray:
        """Nodal forces (Nn, 2) on the configuration x (Nn, 2)."""
        xe = x[self.edges]  # (k, m, 2)
        fe = -self.pressure * np.einsum("ab,kbj,ij->kai", self.M, xe, _R)
        out = np.zeros_like(x, dtype=float)
        np.add.at(out, self.edges, fe)
        return out

    def stiffness(self, n_nodes: int) -> sp.csr_matrix:
        """d forces / dx (2 Nn, 2 Nn): constant (sparse)."""
        k, m = self.edges.shape
        a = np.repeat(np.arange(m), m)
        b = np.tile(np.arange(m), m)
        rows, cols, vals = [], [], []
        for i in range(2):
            for j in range(2):
                if _R[i, j] == 0:
                    continue
                rows.append((2 * self.edges[:, a] + i).ravel())
                cols.append((2 * self.edges[:, b] + j).ravel())
                vals.append(np.broadcast_to(-self.pressure * self.M[a, b] * _R[i, j], (k, m * m)).ravel())
        n = 2 * n_nodes
        return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))


def relative_piola(sigma: np.ndarray, T: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """P (G, 2, 2) and A = dP/df (G, 2, 2, 2, 2) relative to x_n from sigma, T = d sigma/df and f
    (module docstring)."""
    J = f[:, 0, 0] * f[:, 1, 1] - f[:, 0, 1] * f[:, 1, 0]
    fi = np.linalg.inv(f)  # fi[g, J, k] = (f^-1)_Jk
    P = J[:, None, None] * np.einsum("giM,gJM->giJ", sigma, fi)
    A = J[:, None, None, None, None] * (
        np.einsum("gLk,giM,gJM->giJkL", fi, sigma, fi)
        + np.einsum("giMkL,gJM->giJkL", T, fi)
        - np.einsum("giM,gJk,gLM->giJkL", sigma, fi, fi)
    )
    return P, A


class StepFailure(GransimError):
    """A load step's Newton solve failed (its trial states were dropped); ``errors`` its history."""

    def __init__(self, message: str, errors=(), point: int | None = None):
        super().__init__(message)
        self.errors = list(errors)
        self.point = point


@dataclass(frozen=True, eq=False)
class IncrementalProblem:
    """Mesh, Gauss rule, fixed dofs and pressure loads of a problem solved step by step.

    Attributes
    ----------
    mesh : QuadMesh (its nodes: the initial configuration)
    rule : int, Gauss points per direction
    fixed : (nfix,) int, full dof indices (2 node + i) with prescribed increments each step
    pressures : tuple of PressureLoad
    """

    mesh: QuadMesh
    rule: int
    fixed: np.ndarray
    pressures: tuple = ()
    assembler: Assembler = None
    free: np.ndarray = None
    K_pressure: sp.csr_matrix = None

    def __post_init__(self):
        asm = Assembler.from_elements(self.mesh.elements, self.mesh.n_nodes)
        fixed = np.unique(np.asarray(self.fixed, dtype=np.int64))
        if fixed.size and (fixed[0] < 0 or fixed[-1] >= asm.n_dofs):
            raise InputError(f"fixed: dof indices must lie in [0, {asm.n_dofs})")
        Kp = sp.csr_matrix((asm.n_dofs, asm.n_dofs))
        for p in self.pressures:
            Kp = Kp + p.stiffness(self.mesh.n_nodes)
        object.__setattr__(self, "fixed", fixed)
        object.__setattr__(self, "assembler", asm)
        object.__setattr__(self, "free", np.setdiff1d(np.arange(asm.n_dofs), fixed))
        object.__setattr__(self, "K_pressure", Kp.tocsr())

    @property
    def n_gauss(self) -> int:
        """Number of Gauss points E n^2."""
        return self.mesh.n_elements * self.rule**2

    def geometry(self, x: np.ndarray) -> QuadGeometry:
        """The element geometry on configuration x (Nn, 2) (InputError: an inverted element)."""
        return QuadGeometry.from_mesh(self.mesh.with_nodes(x), self.rule)

    def external(self, x: np.ndarray) -> np.ndarray:
        """Pressure forces (2 Nn,) on configuration x."""
        out = np.zeros(self.assembler.n_dofs)
        for p in self.pressures:
            out += p.forces(x).ravel()
        return out

    def residual(self, geom: QuadGeometry, x: np.ndarray, du: np.ndarray, sigma, T, f, tangent: bool = True):
        """(r (2 Nn,), K (CSC or None), |f_int| scale) at the step increment du (Nn, 2) with the Gauss
        responses sigma, T at f."""
        P, A = relative_piola(sigma, T, f)
        fe = geom.internal_forces(P)
        r = self.assembler.vector(fe) - self.external(x + du)
        K = None
        if tangent:
            K = (self.assembler.matrix(geom.stiffness(A)) - self.K_pressure).tocsc()
        scale = float(np.linalg.norm(self.assembler.vector(np.abs(fe))))
        return r, K, scale


@dataclass(frozen=True, eq=False)
class StepResult:
    """A converged load step.

    ``du`` (Nn, 2) the step's displacement, ``f`` (G, 2, 2) its relative deformation gradients,
    ``stress`` (G, 2, 2) and ``tangent`` the committed Cauchy stress and tangent, ``errors`` the
    relative correction norms (one per correction: the Newton iterations), ``residuals`` the free
    residual norms relative to the internal force scale (predictor, then one per evaluation),
    ``reaction`` (2 Nn,) the residual at the fixed dofs (the supports' forces on the body, N/m).
    """

    du: np.ndarray
    f: np.ndarray
    stress: np.ndarray
    tangent: np.ndarray
    errors: np.ndarray
    residuals: np.ndarray
    reaction: np.ndarray
    timing: dict = field(default_factory=dict)

    @property
    def iterations(self) -> int:
        """Newton corrections of the step."""
        return len(self.errors)


def _l2(geom: QuadGeometry, v: np.ndarray) -> float:
    """L2 norm over the configuration of a nodal vector field v (Nn, 2) (the element's Gauss rule)."""
    vg = geom.interpolate(v)
    return float(np.sqrt(geom.weight.ravel() @ np.sum(vg * vg, axis=1)))


def _solve(K, rhs, errors):
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            d = spla.splu(K).solve(rhs)
    except (RuntimeError, spla.MatrixRankWarning, RuntimeWarning) as exc:
        raise StepFailure(f"singular tangent ({exc})", errors) from None
    if not np.all(np.isfinite(d)):
        raise StepFailure("singular tangent (non-finite correction)", errors)
    return d


def newton_step(problem: IncrementalProblem, points, x: np.ndarray, du_fixed, tol: float = 1e-2, max_iter: int = 25):
    """Solve one load step from the converged configuration x (Nn, 2) with the prescribed increments
    ``du_fixed`` (nfix,) at ``problem.fixed``; the Gauss points' trial states are left to commit
    (the caller commits, after anything else it checks). Raises :class:`StepFailure` (trial
    states dropped) on a singular tangent, an inverted element, a point law's error (naming the
    Gauss point), divergence or ``max_iter`` corrections without convergence."""
    t_mat = 0.0
    t0 = time.perf_counter()
    errors, residuals = [], []
    fr, fx = problem.free, problem.fixed
    try:
        geom = problem.geometry(x)
        du = np.zeros(problem.assembler.n_dofs)
        du[fx] = np.asarray(du_fixed, dtype=float)
        # predictor: committed stress and tangent at f = 1 (Guo & Zhao's first solve), no material call
        t1 = time.perf_counter()
        sigma, T = points.committed_response()
        t_mat += time.perf_counter() - t1
        eye = np.broadcast_to(np.eye(2), (problem.n_gauss, 2, 2)).copy()
        r, K, scale = problem.residual(geom, x, np.zeros_like(x), sigma, T, eye)
        residuals.append(float(np.linalg.norm(r[fr])) / max(scale, 1e-300))
        rhs = -(r[fr] + K[fr][:, fx] @ du[fx])
        du[fr] = _solve(K[fr][:, fr].tocsc(), rhs, errors)
        for _ in range(max_iter + 1):
            u = du.reshape(-1, 2)
            f = geom.deformation_gradient(u)
            J = f[:, 0, 0] * f[:, 1, 1] - f[:, 0, 1] * f[:, 1, 0]
            if not np.all(J > 0):
                raise StepFailure(f"det f <= 0 at Gauss point {int(np.argmax(~(J > 0)))}", errors)
            t1 = time.perf_counter()
            sigma, T = points.evaluate(f)
            t_mat += time.perf_counter() - t1
            r, K, scale = problem.residual(geom, x, u, sigma, T, f)
            residuals.append(float(np.linalg.norm(r[fr])) / max(scale, 1e-300))
            if errors and errors[-1] < tol:
                break
            if len(errors) == max_iter:
                last = errors[-1]
                raise StepFailure(
                    f"no convergence in {max_iter} Newton iterations (relative correction {last:.3e} > {tol:.1e})",
                    errors,
                )
            d = _solve(K[fr][:, fr].tocsc(), -r[fr], errors)
            du[fr] += d
            dv = np.zeros_like(du)
            dv[fr] = d
            size = _l2(geom, du.reshape(-1, 2))
            corr = _l2(geom, dv.reshape(-1, 2))
            errors.append(corr / size if size > 0 else (0.0 if corr == 0 else np.inf))
            if not np.isfinite(errors[-1]) or errors[-1] > DIVERGENCE:
                raise StepFailure(f"diverged (relative correction {errors[-1]:.3e})", errors)
    except MaterialPointError as exc:
        points.revert()
        raise StepFailure(str(exc), errors, point=exc.point) from None
    except InputError as exc:  # an inverted element of the configuration
        points.revert()
        raise StepFailure(str(exc), errors) from None
    except (StepFailure, ConvergenceError):
        points.revert()
        raise
    reaction = np.zeros_like(r)
    reaction[fx] = r[fx]
    timing = {"material_s": t_mat, "fe_s": time.perf_counter() - t0 - t_mat}
    return StepResult(du.reshape(-1, 2), f, sigma, T, np.array(errors), np.array(residuals), reaction, timing)


__all__ = [
    "IncrementalProblem",
    "PressureLoad",
    "StepFailure",
    "StepResult",
    "newton_step",
    "relative_piola",
]
