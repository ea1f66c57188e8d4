"""Outputs of ``gransim femxdem`` at chosen load steps: maps over the deformed quadratic mesh, the
RVE of chosen Gauss points, VTU for ParaView (every file written atomically).

Fields per Gauss point (G = E n^2, the element's points with xi fastest, row by row from the
bottom: :func:`gransim.fem.quadrature.square_rule`):

* ``deviatoric_strain``: Guo & Zhao's shear strain of the accumulated strain eps (the sum of the
  steps' sym(f - 1), msFEM2D.py:247): e = sym(eps) - tr(eps) 1 / 2, sqrt(2 e : e)
  (biaxialSmooth.py:102-104 of Debian's yade 2023.02a examples);
* ``void_ratio``: (cell area - sum pi r^2) / sum pi r^2 of the RVE (simDEM.getVoidRatio2D,
  simDEM.py:184-187); ``rotation``: the mean disk rotation since the initial RVE (rad,
  counter-clockwise; simDEM.avgRotation2D, simDEM.py:204-210), each disk's spin dt summed over every
  DEM step (:func:`gransim.dem.yade_arithmetic.rve_run_rotation`).
  Both exist for the DEM RVE only: a stand-in law has no grains (n/a); the LAMMPS RVE
  (``dem-lammps``) has a void ratio but no rotation (LAMMPS' spheres carry no orientation).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..io import atomic_path

#: the fields a map shows, with their labels (units)
MAP_FIELDS = {
    "deviatoric_strain": "deviatoric strain sqrt(2 e:e)",
    "void_ratio": "void ratio",
    "rotation": "mean particle rotation (rad)",
}
#: why a field is missing, by ``--rve`` (default: a stand-in)
NOT_AVAILABLE = {"dem-lammps": "LAMMPS' disks carry no orientation"}
NOT_AVAILABLE_STANDIN = "stand-in law: no grains"


def not_available(rve: str) -> str:
    """Why the fields a law does not report are n/a, for ``rve``."""
    return NOT_AVAILABLE.get(rve, NOT_AVAILABLE_STANDIN)


#: points per sub-cell edge drawn on a curved quadratic element
EDGE_SAMPLES = 4


def deviatoric_strain(strain: np.ndarray) -> np.ndarray:
    """sqrt(2 e : e) with e = sym(eps) - tr(eps) 1 / 2 (G,) of the accumulated strain (G, 2, 2)
    (biaxialSmooth.py:102-104)."""
    eps = 0.5 * (strain + np.swapaxes(strain, 1, 2))
    tr = eps[:, 0, 0] + eps[:, 1, 1]
    e = eps - 0.5 * tr[:, None, None] * np.eye(2)
    return np.sqrt(2.0 * np.einsum("gij,gij->g", e, e))


def gauss_cells(mesh, x: np.ndarray, gauss: int) -> np.ndarray:
    """Polygons (G, 4 EDGE_SAMPLES, 2): the sub-square of each Gauss point's parent cell mapped by
    the element's shape functions onto the configuration ``x`` (Nn, 2), curved edges included."""
    from .isoparametric import shape_functions  # noqa: PLC0415 - start-up: numpy

    t = np.linspace(0.0, 1.0, EDGE_SAMPLES, endpoint=False)
    unit = np.concatenate(
        [
            np.stack([t, 0 * t], 1),
            np.stack([1 + 0 * t, t], 1),
            np.stack([1 - t, 1 + 0 * t], 1),
            np.stack([0 * t, 1 - t], 1),
        ]
    )  # counter-clockwise around [0, 1]^2
    h = 2.0 / gauss
    polys = []
    for j in range(gauss):  # eta
        for i in range(gauss):  # xi fastest, as the rule's points
            xi = np.stack([-1 + h * (i + unit[:, 0]), -1 + h * (j + unit[:, 1])], 1)
            N, _ = shape_functions(mesh.element, xi)
            polys.append(N)
    N = np.stack(polys)  # (n^2, P, nodes)
    xe = x[mesh.elements]  # (E, nodes, 2)
    return np.einsum("kpa,eai->ekpi", N, xe).reshape(-1, N.shape[1], 2)


def gauss_positions(mesh, x: np.ndarray, gauss: int) -> np.ndarray:
    """Gauss point positions (G, 2) on the configuration ``x``."""
    from .isoparametric import shape_functions  # noqa: PLC0415 - start-up: numpy
    from .quadrature import square_rule  # noqa: PLC0415 - start-up: numpy

    N, _ = shape_functions(mesh.element, square_rule(gauss).points)
    return np.einsum("ga,eai->egi", N, x[mesh.elements]).reshape(-1, 2)


def plot_maps(path, mesh, x, gauss: int, fields: dict, title: str, na: str = NOT_AVAILABLE_STANDIN) -> Path:
    """One panel per :data:`MAP_FIELDS` entry over the deformed mesh ``x`` (true scale), each Gauss
    point's sub-cell coloured by its value; a field absent from ``fields`` is drawn as n/a, saying
    why (``na``)."""
    import matplotlib  # noqa: PLC0415 - start-up: matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415 - start-up: matplotlib
    from matplotlib.collections import PolyCollection  # noqa: PLC0415 - start-up: matplotlib
    from matplotlib.ticker import ScalarFormatter  # noqa: PLC0415 - start-up: matplotlib

    cells = gauss_cells(mesh, x, gauss)
    outline = gauss_cells(mesh, x, 1)
    fig, axes = plt.subplots(1, len(MAP_FIELDS), figsize=(3.3 * len(MAP_FIELDS), 5.2))
    for ax, (name, label) in zip(axes, MAP_FIELDS.items()):
        ax.set_aspect("equal")
        ax.set_axis_off()
        ax.add_collection(PolyCollection(outline, facecolors="none", edgecolors="k", linewidths=0.5))
        ax.autoscale()
        if name not in fields:
            ax.set_title(f"{label}\nn/a ({na})", fontsize=9)
            continue
        v = np.asarray(fields[name], float)
        cmap = "RdBu_r" if name == "rotation" else "viridis"
        pc = PolyCollection(cells, array=v, cmap=cmap, edgecolors="none")
        if name == "rotation":
            m = float(np.abs(v).max()) or 1.0
            pc.set_clim(-m, m)
        ax.add_collection(pc)
        ax.add_collection(PolyCollection(outline, facecolors="none", edgecolors="k", linewidths=0.5))
        cb = fig.colorbar(pc, ax=ax, shrink=0.7)
        cb.formatter = ScalarFormatter(useOffset=False)  # no offset text over the map: full values
        cb.update_ticks()
        ax.set_title(f"{label}\n{v.min():.6g} to {v.max():.6g}", fontsize=9)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=100)
    plt.close(fig)
    return Path(path)


def rve_snapshot(state) -> dict | None:
    """What an RVE picture needs from a DEM Gauss point's state (:class:`gransim.fem.dem_rve.DemState`):
    positions, radii, disk rotations, cell (hsize), contacts (ids, cell_dist, normal and shear
    forces); None for a stand-in's state (no grains)."""
    r = getattr(state, "rve", None)
    if r is None or not hasattr(r, "radii"):
        return None
    return {
        "positions": np.asarray(r.positions, float),
        "radii": np.asarray(r.radii, float),
        "rotation": np.asarray(state.disk_rotation(), float),
        "hsize": np.asarray(r.hsize, float),
        "ids": np.asarray(r.ids, np.int64).reshape(-1, 2),
        "cell_dist": np.asarray(r.cell_dist, np.int64).reshape(-1, 2),
        "normal_force": np.asarray(r.normal_force, float).reshape(-1, 2),
        "shear_force": np.asarray(r.shear_force, float).reshape(-1, 2),
    }


def contact_segments(snap: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(wrapped positions (N, 2), segments (M, 2, 2) from disk 1's wrapped centre along the branch to
    disk 2's image x2 + H cellDist - x1 (YADE's convention), normal force magnitudes (M,) N)."""
    H = snap["hsize"]
    x = snap["positions"]
    s = np.linalg.solve(H, x.T).T
    xw = (s - np.floor(s)) @ H.T
    i, j = snap["ids"][:, 0], snap["ids"][:, 1]
    branch = x[j] + snap["cell_dist"] @ H.T - x[i]
    seg = np.stack([xw[i], xw[i] + branch], axis=1)
    return xw, seg, np.linalg.norm(snap["normal_force"], axis=1)


def plot_rve(path, snap: dict, title: str) -> Path:
    """The RVE: disks coloured by their rotation (rad, one symmetric scale; in one colour when ``snap``
    has none: the LAMMPS RVE), the contact force chains as lines between centres with widths
    proportional to the normal force, the periodic cell."""
    import matplotlib  # noqa: PLC0415 - start-up: matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415 - start-up: matplotlib
    from matplotlib.collections import EllipseCollection, LineCollection  # noqa: PLC0415 - start-up: matplotlib

    xw, seg, fn = contact_segments(snap)
    rot = snap.get("rotation")
    fig, ax = plt.subplots(figsize=(6.2, 5.4))
    d = 2 * snap["radii"]
    ec = EllipseCollection(d, d, 0.0, units="xy", offsets=xw, offset_transform=ax.transData, cmap="RdBu_r",
                           edgecolors="0.4", linewidths=0.2)  # fmt: skip
    if rot is not None:
        m = float(np.abs(rot).max()) or 1.0
        ec.set_array(rot)
        ec.set_clim(-m, m)
    else:  # no rotation defined (the LAMMPS RVE): the disks in one colour
        ec.set_facecolor("0.85")
    ax.add_collection(ec)
    fmax = float(fn.max()) if len(fn) else 1.0
    ax.add_collection(LineCollection(seg, linewidths=3.0 * fn / fmax, colors="k"))
    H = snap["hsize"]
    c = np.array([[0, 0], H[:, 0], H[:, 0] + H[:, 1], H[:, 1], [0, 0]])
    ax.plot(c[:, 0], c[:, 1], "g-", lw=0.8)
    ax.set_aspect("equal")
    ax.autoscale()
    ax.set_xticks([])
    ax.set_yticks([])
    if rot is not None:
        fig.colorbar(ec, ax=ax, shrink=0.8, label="disk rotation (rad)", format="%.2g")
    na = "" if rot is not None else "; disk rotation n/a (no orientation)"
    ax.set_title(f"{title}\n{len(fn)} contacts; line width 3 pt x |f_n| / {fmax:.3g} N{na}", fontsize=9)
    fig.tight_layout()
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=100)
    plt.close(fig)
    return Path(path)


def write_vtu(path, mesh, X0: np.ndarray, x: np.ndarray, gauss: int, fields: dict, stress, strain) -> Path:
    """VTU of the quadratic mesh on the configuration ``x`` (``quad8`` or ``quad9`` cells, VTK's node
    order = finley's: corners counter-clockwise, midsides bottom, right, top, left, centre) and the
    Gauss points as ``vertex`` cells. Point data: ``displacement`` x - X0 (3 components; at the
    Gauss points interpolated) and every field as the mean of the elements around a node (at the
    Gauss points: the point's own value). Cell data: the element means (quads) and each Gauss
    point's values (vertices): the fields, ``stress`` and ``strain`` (xx, yy, zz, xy, yz, xz; zz 0)."""
    import meshio  # noqa: PLC0415 - start-up: meshio

    E, n = mesh.elements.shape
    k = gauss**2
    gp = gauss_positions(mesh, x, gauss)
    gp0 = gauss_positions(mesh, X0, gauss)
    Nn, G = len(x), len(gp)
    pts = np.zeros((Nn + G, 3))
    pts[:Nn, :2], pts[Nn:, :2] = x, gp
    disp = np.zeros_like(pts)
    disp[:Nn, :2], disp[Nn:, :2] = x - X0, gp - gp0

    def voigt(t):
        t = np.asarray(t, float)
        z = np.zeros(len(t))
        return np.stack([t[:, 0, 0], t[:, 1, 1], z, 0.5 * (t[:, 0, 1] + t[:, 1, 0]), z, z], axis=1)

    gfields = {name: np.asarray(v, float) for name, v in fields.items()}
    gfields["stress"] = voigt(stress)
    gfields["strain"] = voigt(strain)
    point_data = {"displacement": disp}
    cell_data = {}
    count = np.bincount(mesh.elements.ravel(), minlength=Nn).astype(float)
    for name, v in gfields.items():
        em = v.reshape(E, k, *v.shape[1:]).mean(axis=1)
        cell_data[name] = [em, v]
        nodal = np.zeros((Nn, *v.shape[1:]))
        np.add.at(nodal, mesh.elements.ravel(), np.repeat(em, n, axis=0))
        nodal /= count.reshape(-1, *([1] * (v.ndim - 1)))
        point_data[name] = np.concatenate([nodal, v])
    cell_type = {"Q8": "quad8", "Q9": "quad9"}[mesh.element]
    cells = [(cell_type, mesh.elements), ("vertex", (Nn + np.arange(G))[:, None])]
    m = meshio.Mesh(pts, cells, point_data=point_data, cell_data=cell_data)
    with atomic_path(path, suffix=".vtu") as tmp:
        meshio.write(tmp, m, file_format="vtu")
    return Path(path)


__all__ = [
    "MAP_FIELDS",
    "contact_segments",
    "deviatoric_strain",
    "gauss_cells",
    "gauss_positions",
    "plot_maps",
    "plot_rve",
    "rve_snapshot",
    "write_vtu",
]
