"""Contact normal density with an angle of influence, fabric tensor and uniformity of an RVE.

Section 4 and Fig. 3 of Meier, Steinmann & Kuhl select representative RVEs by a "contact
normal density function" with an "angle of influence" of 10, 20 or 30 degrees; the cited
definition is not available, so gransim defines it as follows.

Definition
----------
Let theta_c (c = 1..M) be the directions of the unit normals n_c of the M active contacts
(overlap eps > 0 in the configuration x = F X). A contact has no sense of direction, so
each contributes both n_c and -n_c: 2M directions {theta_c, theta_c + pi}. With the angle
of influence delta (the *half-width* of the window a normal influences), the density is
the top-hat kernel estimate

    rho_delta(theta) = 1 / (2M) * sum_{2M directions t} 1[|theta - t| < delta] / (2 delta),

angles compared modulo 2 pi. It is pi-periodic, non-negative and integrates to 1 over
[0, 2 pi); a perfectly uniform fabric has rho = 1/(2 pi). A narrow window gives a rough
curve, a wide one a smooth curve (as the paper's Fig. 3 describes).

Uniformity measure
------------------
    U_delta = sqrt( 1/(2 pi) * integral_0^{2 pi} (2 pi rho_delta(theta) - 1)^2 dtheta ),

the RMS relative deviation from the uniform density (0 = uniform), integrated *exactly*
(rho_delta is piecewise constant). Because a finite number of contacts gives a
sampling-noise floor ~ sqrt(pi / (2 M delta)), U also rewards larger RVEs, as the paper
observes. RVEs are ranked by U at delta = 20 degrees (:data:`RANKING_ANGLE_DEG`).

The fabric tensor Phi = 1/M sum n_c (x) n_c (trace 1) gives the second-order anisotropy
a = 2 (lambda_max - lambda_min): for rho = (1 + a cos 2(theta - theta_0)) / (2 pi) exactly a.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from .._validate import as_array
from ..contacts import find_neighbours
from ..errors import InputError
from ..geometry import Packing
from ..io import atomic_path
from .taylor import check_deformation_gradients

#: the paper's angles of influence (degrees)
DEFAULT_ANGLES_DEG = (10.0, 20.0, 30.0)
#: angle of influence used to rank RVEs by uniformity (degrees)
RANKING_ANGLE_DEG = 20.0
TWO_PI = 2.0 * np.pi


def contact_normal_angles(packing: Packing, F=None) -> np.ndarray:
    """Directions theta in [0, 2 pi) of the normals of the overlapping pairs at x = F X (M,)."""
    if not isinstance(packing, Packing):
        raise InputError(f"packing: expected a gransim.Packing, got {type(packing).__name__}")
    p = packing if F is None else packing.deformed(check_deformation_gradients(F)[0])
    nl = find_neighbours(p.positions, p.radii, p.cell, 0.0)
    return np.mod(np.arctan2(nl.branch[:, 1], nl.branch[:, 0]), TWO_PI)


def _directions(theta_c: np.ndarray) -> np.ndarray:
    return np.mod(np.concatenate([theta_c, theta_c + np.pi]), TWO_PI)


def normal_density(theta_c, delta: float, theta) -> np.ndarray:
    """rho_delta at angles ``theta`` for contact directions ``theta_c`` (rad); see module doc."""
    t = np.sort(_directions(np.asarray(theta_c, float)))
    th = np.mod(np.asarray(theta, float), TWO_PI)
    m = t.size
    if m == 0:
        raise InputError("contact normal density: no contacts (no overlapping pairs)")
    if not 0 < delta <= np.pi / 2:
        raise InputError(f"angle of influence: must lie in (0, 90] degrees, got {np.degrees(delta):.6g}")
    # count of t in the open window (th - delta, th + delta), modulo 2 pi, by sorted search
    tt = np.concatenate([t - TWO_PI, t, t + TWO_PI])
    lo = np.searchsorted(tt, th - delta, side="right")
    hi = np.searchsorted(tt, th + delta, side="left")
    return (hi - lo) / (m * 2.0 * delta)


def uniformity(theta_c, delta: float) -> float:
    """U_delta: exact RMS relative deviation of rho_delta from 1/(2 pi), see module doc."""
    t = _directions(np.asarray(theta_c, float))
    m = t.size
    if m == 0:
        raise InputError("uniformity: no contacts (no overlapping pairs)")
    # rho is constant between the breakpoints t +- delta; evaluate it at segment midpoints
    br = np.unique(np.mod(np.concatenate([t - delta, t + delta, [0.0]]), TWO_PI))
    ends = np.append(br[1:], TWO_PI)
    widths = ends - br
    rho = normal_density(theta_c, delta, 0.5 * (br + ends))
    return float(np.sqrt(np.sum(widths * (TWO_PI * rho - 1.0) ** 2) / TWO_PI))


def fabric_tensor(theta_c) -> np.ndarray:
    """Phi = 1/M sum n (x) n, (2, 2), trace 1."""
    t = np.asarray(theta_c, float)
    if t.size == 0:
        raise InputError("fabric tensor: no contacts (no overlapping pairs)")
    n = np.column_stack([np.cos(t), np.sin(t)])
    return n.T @ n / t.size


def anisotropy(theta_c) -> float:
    """a = 2 (lambda_max - lambda_min) of the fabric tensor (0 = isotropic)."""
    lam = np.linalg.eigvalsh(fabric_tensor(theta_c))
    return float(2.0 * (lam[1] - lam[0]))


@dataclass(frozen=True)
class NormalDensity:
    """Contact normal densities of one RVE for several angles of influence.

    Attributes
    ----------
    contact_angles : (M,) directions of the contact normals (rad, [0, 2 pi)).
    angles_of_influence : (K,) half-widths delta (rad).
    theta : (T,) evaluation grid (rad).
    density : (K, T) rho_delta(theta) (1/rad); integrates to 1 over [0, 2 pi).
    uniformity : (K,) U_delta (dimensionless, 0 = uniform).
    anisotropy : float, a = 2 (lambda_max - lambda_min) of the fabric tensor.
    fabric : (2, 2) fabric tensor.
    """

    contact_angles: np.ndarray
    angles_of_influence: np.ndarray
    theta: np.ndarray
    density: np.ndarray
    uniformity: np.ndarray
    anisotropy: float
    fabric: np.ndarray

    @property
    def n_contacts(self) -> int:
        return int(self.contact_angles.size)

    @property
    def ranking_uniformity(self) -> float:
        """U at the ranking angle (20 degrees); computed if not among the angles."""
        hit = np.isclose(np.degrees(self.angles_of_influence), RANKING_ANGLE_DEG)
        if hit.any():
            return float(self.uniformity[np.argmax(hit)])
        return uniformity(self.contact_angles, np.radians(RANKING_ANGLE_DEG))


def contact_normal_density(
    packing: Packing, angles_deg=DEFAULT_ANGLES_DEG, F=None, n_theta: int = 720
) -> NormalDensity:
    """Contact normal density, uniformity and fabric of ``packing`` (at x = F X, default F = I)."""
    deltas = np.radians(as_array(angles_deg, "angles_deg", (None,)))
    if deltas.size == 0 or np.any(deltas <= 0) or np.any(deltas > np.pi / 2):
        raise InputError(
            f"angles_deg: each angle of influence must lie in (0, 90] degrees, got {np.degrees(deltas).tolist()}"
        )
    if int(n_theta) < 8:
        raise InputError(f"n_theta: need at least 8 grid angles, got {n_theta}")
    tc = contact_normal_angles(packing, F)
    if tc.size == 0:
        raise InputError("contact normal density: the packing has no overlapping pairs")
    theta = np.linspace(0.0, TWO_PI, int(n_theta), endpoint=False)
    dens = np.array([normal_density(tc, d, theta) for d in deltas])
    U = np.array([uniformity(tc, d) for d in deltas])
    fab = fabric_tensor(tc)
    return NormalDensity(
        contact_angles=tc,
        angles_of_influence=deltas,
        theta=theta,
        density=dens,
        uniformity=U,
        anisotropy=anisotropy(tc),
        fabric=fab,
    )


def most_uniform(packings: Mapping, F=None) -> tuple[str, dict]:
    """Name of the most uniform RVE (smallest U at 20 degrees; ties: smallest anisotropy).

    Returns ``(name, scores)`` with ``scores[name] = (U_20, anisotropy)``.
    """
    if isinstance(packings, Packing):
        packings = {"rve": packings}
    if not isinstance(packings, Mapping) or not packings:
        raise InputError("packings: expected a non-empty mapping name -> Packing")
    scores = {}
    for name, p in packings.items():
        tc = contact_normal_angles(p, F)
        if tc.size == 0:
            scores[name] = (np.inf, np.inf)
            continue
        scores[name] = (uniformity(tc, np.radians(RANKING_ANGLE_DEG)), anisotropy(tc))
    best = min(scores, key=lambda k: scores[k])
    return best, scores


def plot_normal_densities(densities: Mapping, path, ncols: int = 5, title: str | None = None):
    """Polar plots like Fig. 3: one panel per RVE, one curve per angle of influence.

    Colours follow the paper: black 10 degrees, blue 20, red 30 (others from the colour cycle).
    The dashed circle is the uniform density 1/(2 pi). Writes a PNG atomically; returns the path.
    """
    import matplotlib  # noqa: PLC0415 - start-up: matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415 - start-up: matplotlib

    names = list(densities)
    n = len(names)
    ncols = max(1, min(ncols, n))
    nrows = int(np.ceil(n / ncols))
    fig, axes = plt.subplots(
        nrows,
        ncols,
        subplot_kw={"projection": "polar"},
        figsize=(2.6 * ncols, 2.8 * nrows),
        squeeze=False,
    )
    colours = {10: "black", 20: "tab:blue", 30: "tab:red"}
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    for ax, name in zip(axes.ravel(), names):
        d = densities[name]
        th = np.append(d.theta, d.theta[:1] + 2 * np.pi)
        for k, delta in enumerate(d.angles_of_influence):
            deg = int(round(np.degrees(delta)))
            ax.plot(
                th,
                np.append(d.density[k], d.density[k, :1]),
                lw=0.9,
                color=colours.get(deg),
                label=f"{deg}°",
            )
        ax.plot(th, np.full(th.shape, 1 / (2 * np.pi)), ls="--", lw=0.6, color="grey")
        ax.set_title(f"{name}\nU20={d.ranking_uniformity:.3f} a={d.anisotropy:.3f}", fontsize=8)
        ax.set_ylim(0.0, 1.05 * float(d.density.max()))
        ax.tick_params(labelsize=6)
        ax.set_yticklabels([])
    axes.ravel()[0].legend(fontsize=6, loc="lower left", bbox_to_anchor=(-0.35, -0.25))
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
    return path
