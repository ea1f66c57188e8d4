"""Outputs of a slope run: VTU per step, PNG pictures (Fig. 7), Table 2, load-settlement curve, HDF5.

HDF5 layout: docs/schema_fem.md. Von Mises stress of the 2D (plane) Cauchy stress, sigma_33 = 0
(the disk assembly has no out-of-plane stress):
sigma_vM = sqrt(s11^2 + s22^2 - s11 s22 + 3 s12^2).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..contacts import find_neighbours
from ..io import atomic_h5, atomic_path, atomic_text
from .solver import LoadPathResult, NewtonResult, Problem

TABLE2_STEPS = (2, 6, 10, 15, 18)
#: line width (points) of the strongest contact in the RVE pictures; widths are proportional to force
BRANCH_WIDTH = 3.0


def von_mises(cauchy: np.ndarray) -> np.ndarray:
    """2D von Mises stress (G,) from the Cauchy stress (G, 2, 2) (Pa), sigma_33 = 0."""
    s11, s22, s12 = cauchy[:, 0, 0], cauchy[:, 1, 1], 0.5 * (cauchy[:, 0, 1] + cauchy[:, 1, 0])
    return np.sqrt(np.maximum(s11**2 + s22**2 - s11 * s22 + 3 * s12**2, 0.0))


def nodal_average(problem: Problem, values: np.ndarray) -> np.ndarray:
    """Gauss point values (G, ...) averaged to the nodes with the quadrature weights (Nn, ...)."""
    geom = problem.geometry
    w = geom.weight.ravel()
    v = values.reshape(len(w), -1)
    idx = geom.elements.ravel()  # Gauss point g of an element sits next to its node g
    num = np.zeros((problem.mesh.n_nodes, v.shape[1]))
    np.add.at(num, idx, w[:, None] * v)
    den = np.bincount(idx, weights=w, minlength=problem.mesh.n_nodes)
    return (num / den[:, None]).reshape((problem.mesh.n_nodes,) + values.shape[1:])


def gauss_fields(solution: NewtonResult) -> dict[str, np.ndarray]:
    """Per Gauss point: Cauchy (G,2,2), von Mises, det F, n_contacts, contact-free flag."""
    F = solution.F
    mat = solution.material
    return {
        "cauchy": mat.cauchy,
        "von_mises": von_mises(mat.cauchy),
        "det_F": F[:, 0, 0] * F[:, 1, 1] - F[:, 0, 1] * F[:, 1, 0],
        "n_contacts": np.asarray(mat.n_contacts),
        "contact_free": (np.asarray(mat.n_contacts) == 0),
    }


def write_vtu(path, problem: Problem, solution: NewtonResult) -> Path:
    """One VTU: the Q1 mesh (cell block 0) and the Gauss points as vertices (cell block 1).

    Point data: ``displacement`` (3 comp.; at Gauss points interpolated); cell data per block: for the
    quads the element means, for the vertices the Gauss point values: ``cauchy`` (xx, yy, zz, xy, yz,
    xz; zz = 0), ``von_mises``, ``det_F``, ``n_contacts``, ``contact_free``.
    """
    import meshio  # noqa: PLC0415 - start-up: meshio (~0.1 s)

    geom = problem.geometry
    fields = gauss_fields(solution)
    X = problem.mesh.nodes
    G = geom.n_gauss
    gp = geom.points.reshape(-1, 2)
    u_gp = np.einsum("ga,eai->egi", geom.N, solution.u[geom.elements]).reshape(-1, 2)
    pts = np.zeros((len(X) + G, 3))
    pts[: len(X), :2] = X
    pts[len(X) :, :2] = gp
    disp = np.zeros_like(pts)
    disp[: len(X), :2] = solution.u
    disp[len(X) :, :2] = u_gp
    s = fields["cauchy"]
    voigt = np.stack([s[:, 0, 0], s[:, 1, 1], np.zeros(G), s[:, 0, 1], np.zeros(G), np.zeros(G)], axis=1)
    cells = [("quad", problem.mesh.elements), ("vertex", (len(X) + np.arange(G))[:, None])]

    def both(v):
        v = np.asarray(v, dtype=float)
        return [v.reshape(-1, 4, *v.shape[1:]).mean(axis=1), v]

    cell_data = {
        "cauchy": both(voigt),
        "von_mises": both(fields["von_mises"]),
        "det_F": both(fields["det_F"]),
        "n_contacts": [
            fields["n_contacts"].reshape(-1, 4).min(axis=1).astype(float),
            fields["n_contacts"].astype(float),
        ],
        "contact_free": [
            fields["contact_free"].reshape(-1, 4).sum(axis=1).astype(float),
            fields["contact_free"].astype(float),
        ],
    }
    mesh = meshio.Mesh(pts, cells, point_data={"displacement": disp}, cell_data=cell_data)
    with atomic_path(path, suffix=".vtu") as tmp:
        meshio.write(tmp, mesh, file_format="vtu")
    return Path(path)


def rve_network(material, F: np.ndarray, gauss: int = 0):
    """Deformed contact network of the RVE at Gauss point ``gauss`` under F: (segments (M,2,2),
    forces (M,), cell).

    The relaxed material's centres are F X + w with the Gauss point's committed fluctuation w.
    Needs ``material.packings`` (the Taylor or relaxed material, optionally wrapped by
    :class:`gransim.fem.materials.AssignedRVEs`) and ``material.normal_stiffness``; returns None for
    a continuum material. Forces f = E_n eps (N/m), eq (5).
    """
    packings = getattr(material, "packings", None)
    kn = getattr(material, "normal_stiffness", None)
    if packings is None or kn is None:
        return None
    index = getattr(material, "rve_index", None)
    packing = packings[int(index[gauss]) if index is not None else 0]

    p = packing.deformed(F)
    pos = p.positions
    fluct = getattr(material, "committed_fluctuation", None)
    w = fluct(gauss) if callable(fluct) else None
    if w is not None:  # the relaxed RVE: x = F X + w with its committed fluctuation
        pos = pos + w
    nl = find_neighbours(pos, p.radii, p.cell, 0.0)
    eps = p.radii[nl.i] + p.radii[nl.j] - np.linalg.norm(nl.branch, axis=1)
    on = eps > 0
    xi = pos[nl.i[on]]
    seg = np.stack([xi, xi + nl.branch[on]], axis=1)
    return seg, kn * eps[on], p.cell


def render_png(
    path,
    problem: Problem,
    solution: NewtonResult,
    title: str,
    material=None,
    interest: dict | None = None,
    magnify: float | None = None,
) -> tuple[Path, str]:
    """Von Mises contour on the deformed mesh with four deformed RVEs (Fig. 7), drawn by matplotlib
    (Agg, no pyplot state kept).

    The contour interpolates the nodal averages of the Gauss-point von Mises stress over each quad
    (two Gouraud-shaded triangles per element, the element edges drawn on top). Contact-free Gauss
    points are drawn as red crosses, the four RVE Gauss points are numbered. The RVE branches have a
    width proportional to the contact force, with one scale for all four panels; the RVEs are drawn
    at the Gauss point's F. Returns (path, renderer), renderer "matplotlib". (An earlier version
    rendered the contour with pyvista/VTK off-screen: about 0.4 s of CPU to import pyvista and as
    much to render, for the same picture.)
    """
    import matplotlib  # noqa: PLC0415 - start-up: matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415 - start-up: matplotlib
    from matplotlib.collections import LineCollection, PolyCollection  # noqa: PLC0415 - start-up: matplotlib

    fields = gauss_fields(solution)
    vm_nodes = nodal_average(problem, fields["von_mises"])
    X = problem.mesh.nodes
    umax = float(np.abs(solution.u).max()) or 1.0
    if magnify is None:
        magnify = max(1.0, round(0.03 * np.ptp(X[:, 0]) / umax))
    x = X + magnify * solution.u
    gp = problem.geometry.points.reshape(-1, 2)
    u_gp = np.einsum("ga,eai->egi", problem.geometry.N, solution.u[problem.geometry.elements]).reshape(-1, 2)
    free = fields["contact_free"]
    renderer = "matplotlib"

    fig = plt.figure(figsize=(16, 9))
    ax = fig.add_axes([0.03, 0.37, 0.85, 0.56])
    cax = fig.add_axes([0.9, 0.42, 0.012, 0.46])
    el = problem.mesh.elements
    triangles = np.concatenate([el[:, [0, 1, 2]], el[:, [0, 2, 3]]])
    tpc = ax.tripcolor(x[:, 0], x[:, 1], triangles, vm_nodes, shading="gouraud", cmap="jet")
    ax.add_collection(PolyCollection(x[el], facecolors="none", edgecolors="k", linewidths=0.4))
    fig.colorbar(tpc, cax=cax, label="von Mises (Pa)", format="%.2e")
    if free.any():
        fxy = (gp + magnify * u_gp)[free]
        ax.plot(fxy[:, 0], fxy[:, 1], "x", color="red", ms=7, mew=2)
    if interest:
        for k, g in enumerate(interest.values()):
            px, py = gp[g] + magnify * u_gp[g]
            ax.plot([px], [py], "o", color="black", ms=5)
            ax.annotate(
                str(k + 1),
                (px, py),
                xytext=(6, 6),
                textcoords="offset points",
                fontsize=14,
                bbox={"boxstyle": "round,pad=0.2", "fc": "white", "alpha": 0.6},
            )
    ax.set_aspect("equal")
    ax.autoscale()
    ax.set_axis_off()
    ax.set_title(f"{title}; displacements x{magnify:g}; red: Gauss points without contacts ({int(free.sum())})")
    if interest:
        nets = [rve_network(material, solution.F[g], g) if material is not None else None for g in interest.values()]
        fmax = max([n[1].max() for n in nets if n is not None and len(n[1])] or [1.0])
        for k, ((name, g), net) in enumerate(zip(interest.items(), nets)):
            a = fig.add_axes([0.02 + 0.245 * k, 0.02, 0.22, 0.3])
            a.set_xticks([])
            a.set_yticks([])
            F = solution.F[g]
            a.set_title(
                f"{k + 1}: {name} (x={gp[g, 0]:.1f}, y={gp[g, 1]:.1f})\n"
                f"det F={np.linalg.det(F):.4f}, contacts {int(fields['n_contacts'][g])}",
                fontsize=9,
            )
            if net is None:
                a.text(0.5, 0.5, "continuum material\n(no RVE)", ha="center", va="center")
                continue
            seg, f, cell = net
            a.add_collection(LineCollection(seg, linewidths=BRANCH_WIDTH * f / fmax, colors="k"))
            corners = np.array([[0, 0], cell[:, 0], cell[:, 0] + cell[:, 1], cell[:, 1], [0, 0]])
            a.plot(corners[:, 0], corners[:, 1], "b-", lw=0.5)
            a.set_aspect("equal")
            a.autoscale()
        fig.text(
            0.5,
            0.005,
            f"RVEs at the Gauss point's F (true scale); branch width {BRANCH_WIDTH:g} pt x f / "
            f"{fmax:.3g} N/m, one scale for all four",
            ha="center",
            fontsize=9,
        )
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=80, format="png")
    plt.close(fig)
    return Path(path), renderer


def convergence_table(result: LoadPathResult, steps=TABLE2_STEPS) -> str:
    """Table 2: relative energy norm per Newton iteration for the given steps (markdown)."""
    recs = {s.step: s for s in result.steps}
    cols = [k for k in steps if k in recs]
    n = max([len(recs[k].energy_norms) for k in cols] or [0])
    head = "| iter | " + " | ".join(f"step {k}" + (" (cut)" if recs[k].cuts else "") for k in cols) + " |"
    lines = [head, "|" + "---|" * (len(cols) + 1)]
    for it in range(n):
        row = [f"{recs[k].energy_norms[it]:.3E}" if it < len(recs[k].energy_norms) else "" for k in cols]
        lines.append(f"| {it + 1} | " + " | ".join(row) + " |")
    missing = [k for k in steps if k not in recs]
    if missing:
        lines.append(f"\n(steps {missing} did not converge)")
    return "\n".join(lines)


def observed_orders(energy_norms: np.ndarray) -> np.ndarray:
    """Observed convergence orders p_k = log(e_{k+1}/e_k) / log(e_k/e_{k-1})."""
    e = np.log(np.asarray(energy_norms, dtype=float))
    return (e[2:] - e[1:-1]) / (e[1:-1] - e[:-2])


def load_settlement(problem: Problem, setup, result: LoadPathResult):
    """(footing force N/m, settlement m, rotation rad) per converged state, including a partial step."""
    nf = problem.dofs.free.size
    rows = [(0.0, 0.0, 0.0)]
    sols = [(s.load, s.solution) for s in result.steps]
    if result.limit and result.limit["partial"] is not None:
        sols.append((result.limit["last_converged_load"], result.limit["partial"]))
    for load, sol in sols:
        rows.append((load[1] * setup.footing_force, -sol.q[nf + 1], sol.q[nf + 2]))
    return np.array(rows)


def plot_load_settlement(path, problem: Problem, setup, result: LoadPathResult) -> Path:
    """PNG of footing force against settlement of the footing centre."""
    import matplotlib  # noqa: PLC0415 - start-up: matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415 - start-up: matplotlib

    d = load_settlement(problem, setup, result)[1:]  # from the dead-load state on
    if len(d) == 0:
        d = np.zeros((1, 3))
    fig, ax = plt.subplots(figsize=(6, 4.5))
    ax.plot(d[:, 1] - d[0, 1], -d[:, 0], "o-")
    ax.set_xlabel("settlement of the footing centre under the footing load (m)")
    ax.set_ylabel("footing force (N per m)")
    status = (
        "complete"
        if result.completed
        else (f"stopped: limit at {result.limit['last_converged_load'][1]:.3f} of the target")
    )
    ax.set_title(f"load-settlement (target {setup.footing_force:.3g} N/m; {status})", fontsize=9)
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=100, format="png")
    plt.close(fig)
    return Path(path)


def write_h5(path, problem: Problem, setup, result: LoadPathResult, parameters: dict, message: str = "") -> Path:
    """All converged steps in one HDF5 file (schema: docs/schema_fem.md)."""
    with atomic_h5(path, kind="fem-slope", parameters=parameters) as f:
        m = f.create_group("mesh")
        m.create_dataset("nodes", data=problem.mesh.nodes)
        m.create_dataset("elements", data=problem.mesh.elements)
        m.create_dataset("gauss_points", data=problem.geometry.points.reshape(-1, 2))
        m.create_dataset("gauss_weights", data=problem.geometry.weight.ravel())
        f.attrs["completed"] = result.completed
        f.attrs["message"] = message
        f.attrs["timing"] = json.dumps(result.timer.as_dict())
        f.create_dataset("load_settlement", data=load_settlement(problem, setup, result))
        sols = [(s.step, s.load, s.solution, s.cuts) for s in result.steps]
        if result.limit and result.limit["partial"] is not None:
            sols.append((result.limit["step"], result.limit["last_converged_load"], result.limit["partial"], -1))
        for step, load, sol, cuts in sols:
            g = f.create_group(f"steps/{step:03d}" + ("_partial" if cuts < 0 else ""))
            g.attrs["load"] = np.asarray(load, dtype=float)
            g.attrs["cuts"] = cuts
            fields = gauss_fields(sol)
            g.create_dataset("q", data=sol.q)
            g.create_dataset("u", data=sol.u)
            g.create_dataset("F", data=sol.F)
            g.create_dataset("piola", data=sol.material.piola)
            for k in ("cauchy", "von_mises", "det_F", "n_contacts"):
                g.create_dataset(k, data=fields[k])
            g.create_dataset("energy_norms", data=sol.energy_norms)
            g.create_dataset("residual_norms", data=sol.residual_norms)
    return Path(path)


def _final_state(summary):
    res = summary["result"]
    if res.limit and res.limit["partial"] is not None:
        return res.limit["partial"]
    return res.steps[-1].solution if res.steps else None


def plot_compare(out, summaries: dict, n_worst: int = 3) -> dict:
    """Taylor vs relaxed: ``compare_load_settlement.png`` (both load-settlement curves),
    ``compare_map.png`` (relative Cauchy stress difference per Gauss point at each run's last
    converged state, the ``n_worst`` largest marked, with the Taylor and the relaxed RVE of each
    drawn at its own F) and ``compare.md``. Returns {"worst": [(g, difference)], "paths": [...]}."""
    import matplotlib  # noqa: PLC0415 - start-up: matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415 - start-up: matplotlib
    from matplotlib.collections import LineCollection  # noqa: PLC0415 - start-up: matplotlib

    out = Path(out)
    fig, ax = plt.subplots(figsize=(7, 5))
    for kind, s in summaries.items():
        ls = s["load_settlement"]
        ax.plot(-ls[:, 1], -ls[:, 0], "o-", ms=3, label=f"{kind} RVE" + ("" if s["completed"] else " (limit)"))
    ax.set_xlabel("settlement of the footing (m)")
    ax.set_ylabel("footing force (N/m)")
    ax.legend()
    ax.grid(alpha=0.3)
    p1 = out / "compare_load_settlement.png"
    with atomic_path(p1, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=100, format="png")
    plt.close(fig)
    st = {k: _final_state(s) for k, s in summaries.items()}
    lines = ["# Slope: Taylor vs relaxed RVE", ""]
    for k, s in summaries.items():
        lam = s["result"].limit["last_converged_load"][1] if s["result"].limit else 1.0
        lines.append(
            f"- {k}: {'completed' if s['completed'] else 'stopped'}, last converged footing fraction "
            f"{lam:.4f}, wall {s['timing']['wall_s']:.1f} s, {s['timing']['newton_iterations']} Newton "
            f"iterations"
        )
    worst = []
    if all(v is not None for v in st.values()):
        t, r = st["taylor"], st["relaxed"]
        d = np.linalg.norm((r.material.cauchy - t.material.cauchy).reshape(len(t.F), -1), axis=1)
        d = d / max(float(np.abs(t.material.cauchy).max()), 1e-300)
        worst = [(int(g), float(d[g])) for g in np.argsort(-d)[:n_worst]]
        prob = summaries["taylor"]["problem"]
        gp = prob.geometry.points.reshape(-1, 2)
        fig = plt.figure(figsize=(15, 4 + 3 * len(worst)))
        a = fig.add_axes([0.05, 1 - 4 / (4 + 3 * len(worst)) + 0.02, 0.9, 4 / (4 + 3 * len(worst)) - 0.06])
        sc = a.scatter(gp[:, 0], gp[:, 1], c=d, s=12, cmap="viridis")
        fig.colorbar(sc, ax=a, label="|sigma_relaxed - sigma_Taylor| / max|sigma_Taylor|")
        for k, (g, _) in enumerate(worst):
            a.annotate(str(k + 1), gp[g], color="red", fontsize=12, weight="bold")
        a.set_aspect("equal")
        a.set_title("Gauss points where the relaxed and the Taylor RVE differ most (last converged states)")
        h = 3 / (4 + 3 * len(worst))
        for k, (g, dg) in enumerate(worst):
            for c, kind in enumerate(("taylor", "relaxed")):
                s, sol = summaries[kind], st[kind]
                net = rve_network(s["material"], sol.F[g], g)
                ax2 = fig.add_axes([0.1 + 0.45 * c, 1 - 4 / (4 + 3 * len(worst)) - (k + 1) * h + 0.01, 0.35, h - 0.04])
                ax2.set_xticks([])
                ax2.set_yticks([])
                ax2.set_title(
                    f"{k + 1}: Gauss point {g} ({gp[g, 0]:.1f}, {gp[g, 1]:.1f}) m, {kind}: det F "
                    f"{np.linalg.det(sol.F[g]):.4f}, contacts {int(sol.material.n_contacts[g])}, "
                    f"difference {dg:.3g}",
                    fontsize=8,
                )
                if net is None:
                    continue
                seg, f, cell = net
                fm = float(f.max()) if len(f) else 1.0
                ax2.add_collection(LineCollection(seg, linewidths=BRANCH_WIDTH * f / fm, colors="k"))
                cn = np.array([[0, 0], cell[:, 0], cell[:, 0] + cell[:, 1], cell[:, 1], [0, 0]])
                ax2.plot(cn[:, 0], cn[:, 1], "b-", lw=0.5)
                ax2.set_aspect("equal")
                ax2.autoscale()
        p2 = out / "compare_map.png"
        with atomic_path(p2, suffix=".png") as tmp:
            fig.savefig(tmp, dpi=70, format="png")
        plt.close(fig)
        lines += [
            "",
            "Largest relative Cauchy stress differences (Gauss point, difference): "
            + ", ".join(f"{g}: {v:.3g}" for g, v in worst),
        ]
    atomic_text(out / "compare.md", "\n".join(lines) + "\n")
    return {"worst": worst, "paths": [p1]}
