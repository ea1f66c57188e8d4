"""Maps and histograms of the void-cell measures (Kuhn 002, Figs 6b, 8, 9, 10).

Faces are drawn as the lifted polygons of the DCEL, moved by a lattice vector so that their
centroid lies in the primary cell; faces that stick out are drawn again at the neighbouring
images and everything is clipped to the cell parallelogram, so cells across the periodic
boundary appear on both sides. matplotlib is imported inside the functions.
"""

from __future__ import annotations

import numpy as np

from ..geometry.cell import wrap
from ..io.hdf5 import atomic_path
from .core import VoidCells
from .graph import REMOVAL_NAMES


def wrapped_face_polygons(vc: VoidCells) -> tuple[list, np.ndarray]:
    """Polygons (list of (m, 2) arrays) and the face index of each, including periodic copies."""
    d = vc.dcel
    C = vc.snapshot.cell
    x = vc.snapshot.positions
    Cinv = np.linalg.inv(C)
    fh = d.face_halfedges
    ptr = d.face_ptr
    fv = d.vec[fh]
    csum = np.cumsum(fv, axis=0) - fv
    start = np.repeat(csum[ptr[:-1]], np.diff(ptr), axis=0)
    pts = x[d.origin[fh]][np.repeat(ptr[:-1], np.diff(ptr))] + csum - start
    # (pts: every face's vertices lifted from its first vertex)
    fid = np.repeat(np.arange(d.n_faces), np.diff(ptr))
    k = np.floor(d.face_centroid @ Cinv.T)
    pts = pts - k[fid] @ C.T
    s = pts @ Cinv.T
    smin = np.minimum.reduceat(s, ptr[:-1], axis=0)
    smax = np.maximum.reduceat(s, ptr[:-1], axis=0)
    polys, owner = [], []
    for a in (-1, 0, 1):
        for b in (-1, 0, 1):
            t = np.array([a, b])
            lo, hi = smin + t, smax + t
            show = np.all((hi > 0) & (lo < 1), axis=1)
            off = C @ t
            for f in np.flatnonzero(show):
                polys.append(pts[ptr[f] : ptr[f + 1]] + off)
                owner.append(f)
    return polys, np.asarray(owner, dtype=np.int64)


def _cell_axes(ax, C):
    from matplotlib.patches import Polygon  # noqa: PLC0415 - start-up: matplotlib

    corners = np.array([[0, 0], C[:, 0], C[:, 0] + C[:, 1], C[:, 1]])
    clip = Polygon(corners, closed=True, facecolor="none", edgecolor="k", lw=0.8, zorder=5)
    ax.add_patch(clip)
    ax.set_xlim(corners[:, 0].min(), corners[:, 0].max())
    ax.set_ylim(corners[:, 1].min(), corners[:, 1].max())
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])
    return clip


def plot_cells(
    vc: VoidCells,
    values=None,
    ax=None,
    cmap="Greys",
    vmin=None,
    vmax=None,
    edgecolor="0.3",
    linewidth=0.3,
    colorbar_label=None,
):
    """Void cells coloured by a per-face value (F,) (or outlined only when ``values`` is None)."""
    import matplotlib.pyplot as plt  # noqa: PLC0415 - start-up: matplotlib
    from matplotlib.collections import PolyCollection  # noqa: PLC0415 - start-up: matplotlib

    if ax is None:
        _, ax = plt.subplots(figsize=(6, 6))
    C = vc.snapshot.cell
    clip = _cell_axes(ax, C)
    polys, owner = wrapped_face_polygons(vc)
    pc = PolyCollection(
        polys, edgecolors=edgecolor, linewidths=linewidth, facecolors="none" if values is None else None, cmap=cmap
    )
    if values is not None:
        pc.set_array(np.asarray(values, float)[owner])
        pc.set_clim(vmin, vmax)
    pc.set_clip_path(clip)
    ax.add_collection(pc)
    if values is not None and colorbar_label:
        ax.figure.colorbar(pc, ax=ax, shrink=0.8, label=colorbar_label)
    return ax


def plot_graph(vc: VoidCells, ax=None, title=None):
    """Fig. 6b: the particle graph (void-cell outlines) with the removed particles of Fig. 4
    marked by class (isolated, pendant, island, peninsular)."""
    ax = plot_cells(vc, None, ax=ax, edgecolor="k", linewidth=0.5)
    removed = vc.graph.removed
    colours = {1: "tab:blue", 2: "tab:orange", 3: "tab:green", 4: "tab:red"}
    for code, colour in colours.items():
        idx = np.flatnonzero(removed == code)
        if idx.size:
            xw, _ = wrap(vc.snapshot.positions[idx], vc.snapshot.cell)
            ax.plot(xw[:, 0], xw[:, 1], "o", ms=3, color=colour, label=f"{REMOVAL_NAMES[code]} ({idx.size})")
    if np.any(removed > 0):
        ax.legend(loc="upper right", fontsize=7, framealpha=0.8)
    ax.set_title(title or f"particle graph: {vc.n_faces} faces, {vc.n_edges} edges, {vc.n_vertices} vertices")
    return ax


def plot_alignment(vc: VoidCells, ax=None, title=None):
    """Fig. 8: cells shaded by alignment alpha (eq 18), white for alpha <= 0, black for 1."""
    ax = plot_cells(vc, vc.alpha, ax=ax, cmap="Greys", vmin=0.0, vmax=1.0, colorbar_label="alignment alpha (eq 18)")
    ax.set_title(
        title or f"alignment: mean {vc.mean_alpha:.2f}, {100 * vc.fraction_nonpositive_alpha:.0f}% with alpha <= 0"
    )
    return ax


def plot_vorticity(vc: VoidCells, ax=None, title=None):
    """Fig. 9: cells coloured by the normalised vorticity w (eq 20); the scale tanh(w / median|w|)
    accentuates direction and de-emphasises magnitude (red counter-clockwise, blue clockwise)."""
    w = vc.w
    scale = float(np.nanmedian(np.abs(w))) or 1.0
    ax = plot_cells(
        vc,
        np.tanh(w / scale),
        ax=ax,
        cmap="RdBu_r",
        vmin=-1,
        vmax=1,
        colorbar_label=f"tanh(w / {scale:.2g}), w of eq (20)",
    )
    ax.set_title(title or "normalised vorticity w (red: counter-clockwise)")
    return ax


def plot_relative_motion(vc: VoidCells, ax=None, title=None, scale=None):
    """Fig. 10: arrows of v_rel (eq 21) at the (wrapped) particle centres over the cells; where the
    loading leaves eq (21) undefined (:attr:`VoidCells.v_rel_undefined`) the cells carry that text
    instead of arrows."""
    ax = plot_cells(vc, None, ax=ax, edgecolor="0.75")
    if vc.v_rel_undefined is not None:
        ax.text(
            0.5,
            0.5,
            f"relative motion (eq 21)\n{vc.v_rel_undefined}",
            transform=ax.transAxes,
            ha="center",
            va="center",
            fontsize=10,
            bbox={"facecolor": "white", "edgecolor": "k"},
        )
        ax.set_title(title or "relative particle motion v_rel (eq 21): undefined")
        return ax
    keep = vc.graph.vertices
    xw, _ = wrap(vc.snapshot.positions[keep], vc.snapshot.cell)
    u = vc.v_rel[keep]
    d50 = vc._get("d50")
    ax.quiver(
        xw[:, 0],
        xw[:, 1],
        u[:, 0] * d50,
        u[:, 1] * d50,
        angles="xy",
        scale_units="xy",
        scale=scale or 1.0,
        width=0.002,
        color="k",
    )
    ax.set_title(title or "relative particle motion v_rel (eq 21), arrow = D50 x v_rel")
    return ax


def plot_alpha_histogram(vc: VoidCells, ax=None, bins=40, label=None):
    """Histogram of alpha over the cells with the mean and the alpha <= 0 fraction."""
    import matplotlib.pyplot as plt  # noqa: PLC0415 - start-up: matplotlib

    if ax is None:
        _, ax = plt.subplots(figsize=(5, 3.5))
    a = vc.alpha[np.isfinite(vc.alpha)]
    ax.hist(
        a,
        bins=bins,
        range=(-1, 1),
        histtype="step",
        lw=1.5,
        label=label or f"mean {a.mean():.2f}, {100 * np.mean(a <= 0):.0f}% <= 0",
    )
    ax.axvline(0, color="0.5", lw=0.8)
    ax.set_xlabel("alignment alpha (eq 18)")
    ax.set_ylabel("void cells")
    ax.legend(frameon=False)
    return ax


def save_figures(vc: VoidCells, prefix, label: str = "") -> list:
    """Write the figures of one snapshot: ``{prefix}_{graph,alpha,w,hist,vrel}.png`` (the vrel map
    says so when eq (21) is undefined for the loading)."""
    import matplotlib  # noqa: PLC0415 - start-up: matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt  # noqa: PLC0415 - start-up: matplotlib

    out = []
    makers = [
        ("graph", plot_graph),
        ("alpha", plot_alignment),
        ("w", plot_vorticity),
        ("hist", plot_alpha_histogram),
        ("vrel", plot_relative_motion),
    ]
    for name, fn in makers:
        fig, ax = plt.subplots(figsize=(6.5, 6) if name != "hist" else (5, 3.5))
        fn(vc, ax=ax)
        if label:
            ax.set_title(f"{label}: {ax.get_title()}", fontsize=9)
        fig.tight_layout()
        path = f"{prefix}_{name}.png"
        with atomic_path(path, suffix=".png") as tmp:
            fig.savefig(tmp, dpi=130, format="png")
        plt.close(fig)
        out.append(path)
    return out
