"""The slope stability problem of Meier, Steinmann & Kuhl section 5 (their Fig. 6 did not survive the
text extraction: the slope's dimensions are gransim's reading of it, :class:`SlopeGeometry`).

Plane strain, unit thickness, units m, N, kg. 20 x 19 Q1 elements (1520 Gauss points); base fixed,
vertical sides on rollers; a rigid massless strip footing (x = 42.625 ... 65.875 m on the crest)
carries a vertical force acting 3.875 m from its centre towards the slope. Step 1 applies the dead
load rho g (rho = 2.5e3 kg/m^3, g = 9.81 m/s^2), steps 2 ... 21 the footing force in 20 equal steps.

Protocols: ``paper`` (footing force -4.0e7 N/m, the seed's Table 1) and ``service`` (-5.0e6 N/m, a
well-posed load level that runs to the end).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .. import paper
from .._validate import check_choice
from ..errors import InputError
from .constraints import DofMap, RigidBody
from .mesh import SlopeGeometry, slope_mesh
from .solver import LoadPathResult, Problem, run_load_steps

RHO = paper.DENSITY  # kg/m^3
G = paper.GRAVITY  # m/s^2
#: the 2D contact stiffness of the RVEs (N/m: force per m of thickness per m of overlap), E_n x thickness
NORMAL_STIFFNESS = paper.KN_2D
#: footing force, N per m of thickness
PROTOCOLS = {"paper": paper.FOOTING_LOAD_PAPER, "service": paper.FOOTING_LOAD_SERVICE}


@dataclass(frozen=True)
class SlopeSetup:
    """Footing and loading data of the slope problem (defaults: the problem of Meier, Steinmann & Kuhl,
    section 5, as gransim reads it without their Fig. 6: a footing 23.25 m wide on the crest, loaded
    3.875 m off its centre towards the slope)."""

    geometry: SlopeGeometry = field(default_factory=SlopeGeometry)
    footing_left: float = 42.625
    footing_right: float = 65.875
    eccentricity: float = 3.875  # load point offset from the footing centre towards the slope (m)
    footing_force: float = PROTOCOLS["service"]
    load_steps: int = 20
    density: float = RHO
    gravity: float = G
    dead_load_steps: int = 1  # the dead load in this many equal steps (the paper: 1)

    @property
    def footing_centre(self) -> np.ndarray:
        """Reference point of the footing on the crest surface (m)."""
        xc = 0.5 * (self.footing_left + self.footing_right)
        return np.array([xc, float(self.geometry.surface(xc))])

    @property
    def load_point(self) -> np.ndarray:
        """Where the footing force acts (m)."""
        x = self.footing_centre[0] - self.eccentricity
        return np.array([x, float(self.geometry.surface(x))])

    def schedule(self) -> list[tuple[float, float]]:
        """(gravity factor, footing factor) per step: the dead load (in ``dead_load_steps`` equal
        steps; Meier, Steinmann & Kuhl apply it in the first load step), then the footing in
        ``load_steps`` equal steps."""
        nd = self.dead_load_steps
        dead = [(k / nd, 0.0) for k in range(1, nd + 1)]
        return dead + [(1.0, k / self.load_steps) for k in range(1, self.load_steps + 1)]


def setup_for(
    protocol: str, geometry: SlopeGeometry | None = None, load_steps: int = 20, dead_load_steps: int = 1
) -> SlopeSetup:
    """The setup of a named protocol (``paper`` or ``service``)."""
    check_choice(protocol, "protocol", PROTOCOLS)
    for name, v in (("load_steps", load_steps), ("dead_load_steps", dead_load_steps)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            raise InputError(f"{name}: expected an integer >= 1, got {v!r}")
    return SlopeSetup(
        geometry=geometry or SlopeGeometry(),
        footing_force=PROTOCOLS[protocol],
        load_steps=int(load_steps),
        dead_load_steps=int(dead_load_steps),
    )


def slope_problem(material, setup: SlopeSetup) -> Problem:
    """Mesh, supports, rigid footing and loads of the slope as a :class:`Problem`."""
    mesh = slope_mesh(setup.geometry)
    X = mesh.nodes
    tol = 1e-9 * setup.geometry.length
    base = np.flatnonzero(np.abs(X[:, 1]) < tol)
    sides = np.flatnonzero((np.abs(X[:, 0]) < tol) | (np.abs(X[:, 0] - setup.geometry.length) < tol))
    fixed = np.unique(np.concatenate([2 * base, 2 * base + 1, 2 * sides]))
    surface = np.abs(X[:, 1] - setup.geometry.surface(X[:, 0])) < tol
    on_footing = surface & (X[:, 0] > setup.footing_left - tol) & (X[:, 0] < setup.footing_right + tol)
    body = RigidBody(np.flatnonzero(on_footing), setup.footing_centre, setup.load_point)
    dofs = DofMap.build(X, fixed, body)
    return Problem(
        mesh, material, dofs, body_force=(0.0, -setup.density * setup.gravity), footing_force=(0.0, setup.footing_force)
    )


def gauss_points_of_interest(problem: Problem, setup: SlopeSetup) -> dict[str, int]:
    """Four Gauss points for the RVE pictures (Fig. 7), nearest to fixed reference positions.

    below the footing centre near the surface; on the crest between slope edge and footing (where the
    RVEs lose their contacts under the paper's load); on the slope face; deep below the footing.
    """
    g = setup.geometry
    xc, yc = setup.footing_centre
    targets = {
        "under footing": (xc, yc - 1.5),
        "crest": (0.5 * (g.crest_x + setup.footing_left), g.crest_height - 1.0),
        "slope face": (0.5 * (g.toe_x + g.crest_x), 0.5 * (g.toe_height + g.crest_height) - 2.0),
        "deep": (xc, 0.25 * g.crest_height),
    }
    pts = problem.geometry.points.reshape(-1, 2)
    return {k: int(np.argmin(np.sum((pts - np.asarray(v)) ** 2, axis=1))) for k, v in targets.items()}


def describe_points(problem: Problem, gauss: np.ndarray, limit: int = 12) -> str:
    """Where Gauss points are: count, bounding box and (up to ``limit``) element/position list."""
    if gauss.size == 0:
        return "none"
    pts = problem.geometry.points.reshape(-1, 2)[gauss]
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    items = ", ".join(f"e{g // 4}/g{g % 4} ({x:.2f}, {y:.2f})" for g, (x, y) in zip(gauss[:limit], pts[:limit]))
    more = f", ... ({gauss.size - limit} more)" if gauss.size > limit else ""
    return (
        f"{gauss.size} Gauss points in x = {lo[0]:.2f} ... {hi[0]:.2f} m, y = {lo[1]:.2f} ... "
        f"{hi[1]:.2f} m: {items}{more}"
    )


def limit_message(problem: Problem, setup: SlopeSetup, result: LoadPathResult) -> str:
    """The clear stop message: failed step, last converged load fraction, contact-free Gauss points."""
    lim = result.limit
    lam_g, lam_f = lim["last_converged_load"]
    state = lim["partial"] if lim["partial"] is not None else (result.steps[-1].solution if result.steps else None)
    tgt_g, tgt = lim["target"]
    if state is not None:
        nc = np.asarray(state.material.n_contacts)
        free = np.flatnonzero(nc == 0)
        where = describe_points(problem, free)
    else:
        where = "no converged state"
    return (
        f"load limit: step {lim['step']} (dead load {tgt_g:.0%}, footing {tgt:.0%} of "
        f"{setup.footing_force:.3g} N/m) did not "
        f"converge with the increment cut to {lim['min_fraction']:.3g} of a step (last failure: "
        f"{lim['reason']}). Last converged load: dead load {lam_g:.0%}, footing {lam_f:.4f} of the "
        f"target = {lam_f * setup.footing_force:.4g} N/m. Gauss points without contacts (the Taylor "
        f"RVE carries no tension) at that state: {where}"
    )


def run_slope(
    material,
    setup: SlopeSetup,
    tol: float = 1e-20,
    max_iter: int = 12,
    min_fraction: float = 1.0 / 64,
    on_step=None,
    progress=None,
):
    """Build and solve the slope; returns (problem, LoadPathResult)."""
    problem = slope_problem(material, setup)
    result = run_load_steps(
        problem,
        setup.schedule(),
        tol=tol,
        max_iter=max_iter,
        min_fraction=min_fraction,
        on_step=on_step,
        progress=progress,
    )
    return problem, result
