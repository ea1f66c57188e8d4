"""The curves of Guo & Zhao's biaxial test as their code computed them: q and eps_v against eps_a."""

from __future__ import annotations

from pathlib import Path

from gransim.io import atomic_path

from .output import read_h5


def _label(d: dict) -> str:
    p = d["attrs"].get("parameters", {})
    n = 4 * int(p.get("nx", 0)) * int(p.get("ny", 0))
    rves = f"{n} RVEs of {p.get('n_disks')} disks"
    return f"{p.get('nx')} x {p.get('ny')} elements ({rves}), {p.get('steps')} steps, {p.get('workers')} workers"


def plot_curves(paths, out) -> Path:
    """One PNG, two panels: the deviatoric stress q (kPa; from the volume-averaged Gauss-point
    stresses, solid, and from the top platen's resultant, dotted) and the volumetric strain eps_v
    (%, dilation positive), both against the axial strain eps_a (%, compression positive), one
    curve per results file. Returns the PNG path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = [read_h5(p) for p in paths]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
    for k, d in enumerate(runs):
        s = d["steps"]
        c = f"C{k}"
        ea = 100 * s["eps_a"]
        ax1.plot(ea, s["q"] / 1e3, "-o", ms=3, color=c, label=_label(d))
        ax1.plot(ea, s["q_top"] / 1e3, ":", color=c, label="from the top platen's force" if k == 0 else None)
        ax2.plot(ea, 100 * s["eps_v"], "-o", ms=3, color=c)
    ax1.set_xlabel("axial strain eps_a (%)")
    ax1.set_ylabel("deviatoric stress q = sigma_1 - sigma_3 (kPa)")
    ax2.set_xlabel("axial strain eps_a (%)")
    ax2.set_ylabel("volumetric strain eps_v (%, dilation > 0)")
    ax1.legend(fontsize=7)
    for ax in (ax1, ax2):
        ax.grid(alpha=0.3)
    v = runs[0]["attrs"]
    fig.suptitle(
        f"Guo & Zhao's FEM x DEM biaxial test, their code: {v.get('yade_version')}, "
        f"python3-escript {v.get('packages', {}).get('python3-escript', '?')}, 100 kPa confinement",
        fontsize=9,
    )
    fig.tight_layout()
    out = Path(out)
    with atomic_path(out, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=120, format="png")
    plt.close(fig)
    return out


__all__ = ["plot_curves"]
