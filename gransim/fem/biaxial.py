"""The biaxial specimen of Guo & Zhao's FEM x DEM benchmark (``biaxialSmooth.py`` of YADE's FEMxDEM
examples; Int. J. Numer. Meth. Engng 99 (2014) 789-818), solved step by step with stateful Gauss
points (:mod:`gransim.fem.incremental`, :mod:`gransim.fem.material_points`).

From biaxialSmooth.py (/usr/share/doc/yade/examples/FEMxDEM/biaxialSmooth.py of Debian's yade
2023.02a): a 50 x 100 mm specimen (``lx = 0.05``, ``ly = 0.1``, lines 37-38), 8 x 16 elements
(``nx``, ``ny``, lines 40-41) of order 2 with 2 x 2 Gauss points (``Rectangle(..., order=2,
integrationOrder=2)``, line 43: finley's 8-node Rec8, hence Q8 here by default), smooth platens
(bottom and top: vertical displacement prescribed, horizontal free) and the centre of the bottom
fixed (``Dbc``, ``Vbc``, lines 71 and 73), a confining pressure of 100 kPa on the sides
(``confining = -1.e5``, line 36; ``Nbc``, line 75), the top moved down by 1e-4 m per step
(``vel = -0.0001``, line 35) for 100 steps (line 78), Newton relative tolerance 1e-2
(``rtol=1e-2``, line 51).

Outputs per converged step (:class:`BiaxialStep`): the axial strain (compression positive, the top
platen's displacement over the initial height), the deviatoric stress q = sigma_1 - sigma_3
(compression positive: the top platen's force per current top width minus the confining pressure),
the volumetric strain (A - A_0) / A_0 (dilation positive) from the current area.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .._validate import as_int, as_positive_float, check_choice
from ..errors import InputError
from .incremental import IncrementalProblem, PressureLoad, StepFailure, newton_step
from .isoparametric import rectangle


@dataclass(frozen=True)
class BiaxialSpec:
    """Geometry, loading and Newton settings (SI units; defaults: Guo & Zhao's benchmark)."""

    width: float = 0.05
    height: float = 0.1
    nx: int = 8
    ny: int = 16
    element: str = "Q8"
    gauss: int = 2
    pressure: float = 1.0e5
    top_step: float = 1.0e-4
    steps: int = 100
    tol: float = 1e-2
    max_iter: int = 25

    def __post_init__(self):
        as_positive_float(self.width, "width")
        as_positive_float(self.height, "height")
        as_int(self.nx, "nx (elements across)", 1, 1000)
        as_int(self.ny, "ny (elements up)", 1, 1000)
        check_choice(self.element, "element", ("Q8", "Q9"))
        as_int(self.gauss, "gauss (points per direction)", 2, 5)
        if self.element == "Q9" and self.gauss < 3:
            raise InputError(
                "element Q9 needs gauss >= 3: with 2 x 2 points it has hourglass modes (singular stiffness)"
            )
        as_positive_float(self.pressure, "pressure", allow_zero=True)
        as_positive_float(self.top_step, "top_step")
        as_int(self.steps, "steps", 1)
        as_positive_float(self.tol, "tol")
        as_int(self.max_iter, "max_iter", 1)

    @property
    def n_gauss(self) -> int:
        """Number of Gauss points nx ny gauss^2 (512 by default)."""
        return self.nx * self.ny * self.gauss**2

    def as_dict(self) -> dict:
        """The parameters (provenance)."""
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


@dataclass(frozen=True, eq=False)
class BiaxialSetup:
    """The specimen's problem and the nodes the outputs need."""

    spec: BiaxialSpec
    problem: IncrementalProblem
    top: np.ndarray  # node indices of the top platen
    bottom: np.ndarray
    centre: int  # the bottom centre node (fixed horizontally)
    du_fixed: np.ndarray  # prescribed increments of problem.fixed per step (m)
    left: PressureLoad
    right: PressureLoad


def biaxial_setup(spec: BiaxialSpec | None = None) -> BiaxialSetup:
    """Mesh, supports and confining pressure of the specimen [0, width] x [0, height]."""
    spec = spec or BiaxialSpec()
    mesh = rectangle(spec.nx, spec.ny, spec.width, spec.height, spec.element)
    X = mesh.nodes
    tol = 1e-9 * max(spec.width, spec.height)
    bottom = np.flatnonzero(np.abs(X[:, 1]) < tol)
    top = np.flatnonzero(np.abs(X[:, 1] - spec.height) < tol)
    centre = np.flatnonzero((np.abs(X[:, 1]) < tol) & (np.abs(X[:, 0] - 0.5 * spec.width) < tol))
    if centre.size != 1:  # pragma: no cover - quadratic meshes always have a node there
        raise InputError("mesh: no node at the centre of the bottom")
    left = PressureLoad(mesh.edges_on(np.abs(X[:, 0]) < tol), spec.pressure)
    right = PressureLoad(mesh.edges_on(np.abs(X[:, 0] - spec.width) < tol), spec.pressure)
    fixed = np.concatenate([2 * bottom + 1, 2 * top + 1, 2 * centre])
    problem = IncrementalProblem(mesh, spec.gauss, fixed, (left, right))
    du = np.zeros(problem.fixed.size)
    du[np.isin(problem.fixed, 2 * top + 1)] = -spec.top_step
    return BiaxialSetup(spec, problem, top, bottom, int(centre[0]), du, left, right)


@dataclass(frozen=True, eq=False)
class BiaxialStep:
    """One converged step: configuration, Gauss-point fields, the curves' values and Newton's history.

    ``x`` (Nn, 2) nodes (m); ``stress`` (G, 2, 2) Cauchy (Pa, tension positive); ``F`` (G, 2, 2) the
    total deformation gradient (product of the steps' f); ``strain`` (G, 2, 2) the sum of the
    steps' sym(f - 1) (Guo & Zhao's accumulated strain); ``errors`` and ``residuals`` as
    :class:`gransim.fem.incremental.StepResult`.
    """

    step: int
    x: np.ndarray
    stress: np.ndarray
    F: np.ndarray
    strain: np.ndarray
    axial_strain: float
    deviatoric_stress: float
    volumetric_strain: float
    errors: np.ndarray
    residuals: np.ndarray
    wall_s: float
    material_s: float


def curves(setup: BiaxialSetup, x: np.ndarray, reaction: np.ndarray) -> tuple[float, float, float]:
    """(axial strain, q (Pa), volumetric strain) of configuration x with the supports' forces
    ``reaction`` (2 Nn,) (module docstring)."""
    s = setup.spec
    X0 = setup.problem.mesh.nodes
    h = float(np.mean(x[setup.top, 1]) - np.mean(x[setup.bottom, 1]))
    width = float(x[setup.top, 0].max() - x[setup.top, 0].min())
    sigma_1 = -float(reaction[2 * setup.top + 1].sum()) / width
    area = float(setup.problem.geometry(x).weight.sum())
    area0 = float(setup.problem.geometry(X0).weight.sum())
    return (s.height - h) / s.height, sigma_1 - s.pressure, (area - area0) / area0


def run_biaxial(setup: BiaxialSetup, points, start: BiaxialStep | None = None, on_step=None, progress=None) -> list:
    """Steps ``start.step + 1 .. spec.steps`` (from the initial configuration without ``start``).

    ``points`` (:mod:`gransim.fem.material_points`) must hold the states committed at ``start``.
    ``on_step(step_record, points)`` is called after each commit (checkpoints, outputs). A step that
    does not converge raises :class:`gransim.fem.incremental.StepFailure` naming the step (and the
    Gauss point, when a point law failed); its trial states are dropped.
    """
    spec, prob = setup.spec, setup.problem
    G = prob.n_gauss
    if start is None:
        x = prob.mesh.nodes.copy()
        F = np.broadcast_to(np.eye(2), (G, 2, 2)).copy()
        strain = np.zeros((G, 2, 2))
        k0 = 0
    else:
        x, F, strain, k0 = start.x.copy(), start.F.copy(), start.strain.copy(), start.step
    out = []
    for k in range(k0 + 1, spec.steps + 1):
        t0 = time.perf_counter()
        try:
            res = newton_step(prob, points, x, setup.du_fixed, tol=spec.tol, max_iter=spec.max_iter)
        except StepFailure as exc:
            raise StepFailure(f"load step {k}: {exc}", exc.errors, exc.point) from None
        tc = time.perf_counter()
        points.commit()  # a law's committed response may call its RVEs (the perturbation tangent)
        commit_s = time.perf_counter() - tc
        x = x + res.du
        F = np.einsum("gij,gjk->gik", res.f, F)
        strain = strain + 0.5 * (res.f + np.swapaxes(res.f, 1, 2)) - np.eye(2)
        ea, q, ev = curves(setup, x, res.reaction)
        rec = BiaxialStep(
            k, x, res.stress, F, strain, ea, q, ev, res.errors, res.residuals,
            time.perf_counter() - t0, res.timing["material_s"] + commit_s,
        )  # fmt: skip
        out.append(rec)
        if on_step is not None:
            on_step(rec, points)
        if progress is not None:
            progress.update(1)
    return out


__all__ = ["BiaxialSetup", "BiaxialSpec", "BiaxialStep", "biaxial_setup", "curves", "run_biaxial"]
