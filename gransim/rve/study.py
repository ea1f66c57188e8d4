"""RVE studies of Meier, Steinmann & Kuhl, Figs 3-5: fabric and stress paths of a set of RVEs.

For every RVE four affine load paths are followed (Taylor assumption, no relaxation):

=============  ====================================  ================
path           F(t), t = 0..1 in ``steps`` steps      driving value
=============  ====================================  ================
compression11  F11 = 1 - c t, all else identity       F11: 1 -> 0.9
compression22  F22 = 1 - c t                          F22: 1 -> 0.9
shear12        F12 = s t                              F12: 0 -> 0.1
shear21        F21 = s t                              F21: 0 -> 0.1
=============  ====================================  ================

(c = ``compression`` = 0.1, s = ``shear`` = 0.1). The Cauchy stress (tension positive,
N/m) of each state is computed by :class:`~gransim.rve.taylor.TaylorMaterial` in one
batched call; the RVEs are grouped by particle number and the mean and the sample
standard deviation (ddof = 1) over each group are reported, as the error bars of Figs 4-5.
The contact normal density (Fig. 3) of every RVE is computed in the reference state.
HDF5 layout: docs/schema_rve.md.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from .. import paper
from .._validate import as_positive_float
from ..errors import InputError, ResultFileError
from ..geometry import Packing
from ..io import atomic_h5, atomic_path, load_packing, open_result, read_packing_group, write_packing_group
from .fabric import DEFAULT_ANGLES_DEG, NormalDensity, contact_normal_density, most_uniform, plot_normal_densities
from .taylor import TaylorMaterial

PATHS = ("compression11", "compression22", "shear12", "shear21")
#: (row, column) of the driving component of F for each path
DRIVING = {"compression11": (0, 0), "compression22": (1, 1), "shear12": (0, 1), "shear21": (1, 0)}
#: paper's normal contact stiffness as the 2D RVE's kn (N/m): E_n of Table 1 times the thickness
#: (:mod:`gransim.paper`)
PAPER_NORMAL_STIFFNESS = paper.KN_2D


def load_path(name: str, steps: int = 50, compression: float = 0.1, shear: float = 0.1):
    """Deformation gradients of one load path: ``(drive (S+1,), F (S+1, 2, 2))``."""
    if name not in DRIVING:
        raise InputError(f"unknown load path {name!r}; choose one of: {', '.join(PATHS)}")
    steps = int(steps)
    if steps < 1:
        raise InputError(f"steps: must be >= 1, got {steps}")
    t = np.linspace(0.0, 1.0, steps + 1)
    F = np.tile(np.eye(2), (steps + 1, 1, 1))
    i, j = DRIVING[name]
    if i == j:
        if not 0 < compression < 1:
            raise InputError(f"compression: must lie in (0, 1), got {compression}")
        F[:, i, j] = 1.0 - compression * t
    else:
        F[:, i, j] = as_positive_float(shear, "shear") * t
    return F[:, i, j].copy(), F


def _sorted_names(packings: Mapping) -> list[str]:
    return sorted(packings, key=lambda k: (packings[k].n, str(k)))


@dataclass(frozen=True)
class StudyResult:
    """Stress paths and fabric of a set of RVEs.

    Attributes
    ----------
    names : tuple of str, RVE names (R,), ordered by size then name.
    sizes : (R,) int, particle numbers.
    paths : tuple of str, load path names (Q,).
    drive : (Q, S+1) driving component of F along each path.
    F : (Q, S+1, 2, 2) deformation gradients.
    cauchy, piola : (R, Q, S+1, 2, 2) stresses (N/m, tension positive).
    energy : (R, Q, S+1) W (J/m^2).  n_contacts : (R, Q, S+1) int.
    normal_stiffness : float (N/m).
    fabric : dict name -> :class:`~gransim.rve.fabric.NormalDensity` (reference state).
    packings : dict name -> Packing.
    """

    names: tuple
    sizes: np.ndarray
    paths: tuple
    drive: np.ndarray
    F: np.ndarray
    cauchy: np.ndarray
    piola: np.ndarray
    energy: np.ndarray
    n_contacts: np.ndarray
    normal_stiffness: float
    fabric: dict
    packings: dict

    def groups(self) -> dict:
        """Particle number -> indices of the RVEs of that size."""
        return {int(n): np.flatnonzero(self.sizes == n) for n in np.unique(self.sizes)}

    def summary(self) -> dict:
        """{size: (mean (Q, S+1, 2, 2), std (Q, S+1, 2, 2), count)} of the Cauchy stress.

        std is the sample standard deviation (ddof = 1); zero for a group of one.
        """
        out = {}
        for n, idx in self.groups().items():
            c = self.cauchy[idx]
            std = c.std(axis=0, ddof=1) if idx.size > 1 else np.zeros_like(c[0])
            out[n] = (c.mean(axis=0), std, int(idx.size))
        return out

    def most_uniform(self, size: int | None = None) -> str:
        """Name of the most uniform RVE (by U at 20 degrees), optionally among one size."""
        names = [k for k, n in zip(self.names, self.sizes) if size is None or n == size]
        if not names:
            raise InputError(f"no RVE with {size} particles (sizes: {sorted(set(self.sizes.tolist()))})")
        return min(names, key=lambda k: (self.fabric[k].ranking_uniformity, self.fabric[k].anisotropy))


class RVEStudy:
    """Compute object for Figs 3-5: ``RVEStudy(packings).run().result`` is a :class:`StudyResult`.

    Parameters
    ----------
    packings : mapping name -> Packing (or -> path of a packing HDF5 file)
    normal_stiffness : E_n (N/m); default the paper's 2.8e7.
    steps, compression, shear : load path resolution and end values (see module doc).
    angles_deg : angles of influence of the fabric densities (degrees).
    executor : :mod:`gransim.parallel` executor; None or in process: one batched kernel call for
        every state of every RVE; a Dask executor: one task per RVE (the same numbers, bit for bit:
        each RVE's candidate sets are built from its own states in the same order either way).
    """

    def __init__(
        self,
        packings: Mapping,
        normal_stiffness: float = PAPER_NORMAL_STIFFNESS,
        steps: int = 50,
        compression: float = 0.1,
        shear: float = 0.1,
        angles_deg=DEFAULT_ANGLES_DEG,
        executor=None,
    ):
        self.packings = load_packings(packings)
        self.executor = executor
        self.normal_stiffness = as_positive_float(normal_stiffness, "normal_stiffness")
        self.steps, self.compression, self.shear = int(steps), float(compression), float(shear)
        self.angles_deg = tuple(float(a) for a in angles_deg)
        self._paths = [load_path(p, self.steps, self.compression, self.shear) for p in PATHS]
        self._result = None

    @property
    def result(self) -> StudyResult:
        if self._result is None:
            raise InputError("RVEStudy: call run() first; no result exists yet")
        return self._result

    def run(self) -> RVEStudy:
        names = _sorted_names(self.packings)
        R, Q, S1 = len(names), len(PATHS), self.steps + 1
        drive = np.array([d for d, _ in self._paths])
        F = np.array([f for _, f in self._paths])  # (Q, S1, 2, 2)
        if self.executor is None or getattr(self.executor, "kind", "") == "in-process":
            mat = TaylorMaterial({k: self.packings[k] for k in names}, self.normal_stiffness)
            Fall = np.broadcast_to(F, (R, Q, S1, 2, 2)).reshape(-1, 2, 2)
            rve = np.repeat(np.arange(R), Q * S1)
            b = mat.evaluate(np.ascontiguousarray(Fall), rve)
            fabric = {k: contact_normal_density(self.packings[k], self.angles_deg) for k in names}
        else:
            Fr = np.ascontiguousarray(F.reshape(-1, 2, 2))
            parts = self.executor.map(
                _one_rve, [(self.packings[k], self.normal_stiffness, Fr, self.angles_deg) for k in names]
            )
            b = _Stacked(*(np.concatenate([p[i] for p in parts]) for i in range(4)))
            fabric = {k: p[4] for k, p in zip(names, parts)}
        self._result = StudyResult(
            names=tuple(names),
            sizes=np.array([self.packings[k].n for k in names]),
            paths=PATHS,
            drive=drive,
            F=F,
            cauchy=b.cauchy.reshape(R, Q, S1, 2, 2),
            piola=b.piola.reshape(R, Q, S1, 2, 2),
            energy=b.energy.reshape(R, Q, S1),
            n_contacts=b.n_contacts.reshape(R, Q, S1),
            normal_stiffness=self.normal_stiffness,
            fabric=fabric,
            packings={k: self.packings[k] for k in names},
        )
        return self


def _one_rve(task):
    """One RVE's states and fabric (a task of :meth:`RVEStudy.run` on an executor)."""
    packing, kn, F, angles = task
    b = TaylorMaterial(packing, kn).evaluate(F, np.zeros(len(F), np.int64))
    return (
        np.asarray(b.cauchy),
        np.asarray(b.piola),
        np.asarray(b.energy),
        np.asarray(b.n_contacts),
        contact_normal_density(packing, angles),
    )


@dataclass(frozen=True)
class _Stacked:
    cauchy: np.ndarray
    piola: np.ndarray
    energy: np.ndarray
    n_contacts: np.ndarray


def load_packings(packings) -> dict:
    """Mapping name -> Packing from a mapping whose values are Packings or packing-file paths."""
    if isinstance(packings, Packing):
        return {"rve": packings}
    if not isinstance(packings, Mapping) or not packings:
        raise InputError("packings: expected a non-empty mapping name -> Packing or file path")
    out = {}
    for k, v in packings.items():
        out[str(k)] = v if isinstance(v, Packing) else load_packing(v)
    return out


def write_study(path, result: StudyResult, parameters: dict | None = None) -> Path:
    """Write a :class:`StudyResult` to HDF5 (layout in docs/schema_rve.md), atomically."""
    params = {
        "normal_stiffness": result.normal_stiffness,
        "paths": list(result.paths),
        "steps": int(result.drive.shape[1] - 1),
        "rves": list(result.names),
        **(parameters or {}),
    }
    with atomic_h5(path, kind="rve-study", parameters=params) as f:
        f.attrs["sign_convention"] = "tension positive; stresses in N/m (2D), energy in J/m^2"
        g = f.create_group("rves")
        g.create_dataset("names", data=np.array(result.names, dtype="S"))
        g.create_dataset("sizes", data=result.sizes)
        for k in result.names:
            write_packing_group(g.create_group(k), result.packings[k])
        for q, p in enumerate(result.paths):
            h = f.create_group(f"paths/{p}")
            h.attrs["driving_component"] = "F{}{}".format(*(c + 1 for c in DRIVING[p]))
            h.create_dataset("drive", data=result.drive[q])
            h.create_dataset("F", data=result.F[q])
            h.create_dataset("cauchy", data=result.cauchy[:, q])
            h.create_dataset("piola", data=result.piola[:, q])
            h.create_dataset("energy", data=result.energy[:, q])
            h.create_dataset("n_contacts", data=result.n_contacts[:, q])
        for n, (mean, std, count) in result.summary().items():
            for q, p in enumerate(result.paths):
                h = f.create_group(f"summary/{p}/{n}")
                h.attrs["n_rves"] = count
                h.create_dataset("cauchy_mean", data=mean[q])
                h.create_dataset("cauchy_std", data=std[q])
        fb = f.create_group("fabric")
        d0 = result.fabric[result.names[0]]
        fb.create_dataset("angles_deg", data=np.degrees(d0.angles_of_influence))
        fb.create_dataset("theta", data=d0.theta)
        fb.create_dataset("density", data=np.array([result.fabric[k].density for k in result.names]))
        fb.create_dataset("uniformity", data=np.array([result.fabric[k].uniformity for k in result.names]))
        fb.create_dataset("anisotropy", data=np.array([result.fabric[k].anisotropy for k in result.names]))
        fb.create_dataset("n_contacts", data=np.array([result.fabric[k].n_contacts for k in result.names]))
        for n in result.groups():
            fb.attrs[f"most_uniform_{n}"] = result.most_uniform(n)
    return Path(path)


def study_rve_names(path) -> list[str]:
    """Names of the RVEs stored in a study file (the packing groups under ``/rves``)."""
    with open_result(path, kind="rve-study") as f:
        if "rves" not in f or not isinstance(f["rves"], h5py.Group):
            raise ResultFileError(f"{path}: rve-study file without a /rves group")
        return sorted(k for k, v in f["rves"].items() if isinstance(v, h5py.Group))


def read_study_packing(path, name: str) -> Packing:
    """The packing of RVE ``name`` stored in a study file."""
    names = study_rve_names(path)
    if name not in names:
        raise ResultFileError(f"{path}: no RVE {name!r} (has {', '.join(names) or 'none'})")
    with open_result(path, kind="rve-study") as f:
        return read_packing_group(f["rves"][name])


_COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple")


def plot_study(result: StudyResult, out_dir) -> list[Path]:
    """PNG figures: compression.png (Fig. 4), shear.png (Fig. 5), fabric.png (Fig. 3)."""
    import matplotlib  # noqa: PLC0415 - start-up: matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415 - start-up: matplotlib

    out_dir = Path(out_dir)
    summ = result.summary()
    written = []
    comps = {"11": ((0, 0), "-"), "22": ((1, 1), "--"), "12": ((0, 1), ":")}
    every = max(1, (result.drive.shape[1] - 1) // 10)
    for fname, pair, shown in (
        ("compression.png", ("compression11", "compression22"), ("11", "22")),
        ("shear.png", ("shear12", "shear21"), ("11", "22", "12")),
    ):
        fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
        for ax, p in zip(axes, pair):
            q = result.paths.index(p)
            for c, (n, (mean, std, count)) in enumerate(summ.items()):
                for comp in shown:
                    (i, j), ls = comps[comp]
                    ax.errorbar(
                        result.drive[q],
                        mean[q, :, i, j],
                        yerr=std[q, :, i, j],
                        ls=ls,
                        color=_COLOURS[c % len(_COLOURS)],
                        errorevery=every,
                        capsize=2,
                        lw=1.1,
                        label=f"N={n} ({count} RVEs) $\\sigma_{{{comp}}}$",
                    )
            ax.set_xlabel("F{}{}".format(*(k + 1 for k in DRIVING[p])))
            ax.set_ylabel("Cauchy stress (N/m, tension +)")
            ax.set_title(p)
            ax.grid(alpha=0.3)
        axes[0].legend(fontsize=7)
        fig.suptitle(
            f"Taylor RVE stress paths, mean ± std, E_n = {result.normal_stiffness:.3g} N/m",
            fontsize=10,
        )
        fig.tight_layout()
        with atomic_path(out_dir / fname, suffix=".png") as tmp:
            fig.savefig(tmp, dpi=110, format="png")
        plt.close(fig)
        written.append(out_dir / fname)
    written.append(
        Path(
            plot_normal_densities(
                result.fabric,
                out_dir / "fabric.png",
                ncols=5,
                title="Contact normal density (black 10°, blue 20°, red 30°)",
            )
        )
    )
    return written


def run_study(
    packings: Mapping,
    out_dir,
    normal_stiffness: float = PAPER_NORMAL_STIFFNESS,
    steps: int = 50,
    executor=None,
) -> tuple[StudyResult, Path, list[Path]]:
    """Run, write ``out_dir/rve_study.h5`` and the PNGs; returns (result, h5 path, png paths).
    ``executor``: see :class:`RVEStudy`."""
    result = RVEStudy(packings, normal_stiffness=normal_stiffness, steps=steps, executor=executor).run().result
    out_dir = Path(out_dir)
    h5 = write_study(out_dir / "rve_study.h5", result)
    pngs = plot_study(result, out_dir)
    return result, h5, pngs


__all__ = [
    "DRIVING",
    "PATHS",
    "NormalDensity",
    "RVEStudy",
    "StudyResult",
    "load_packings",
    "load_path",
    "most_uniform",
    "plot_study",
    "read_study_packing",
    "study_rve_names",
    "run_study",
    "write_study",
]
