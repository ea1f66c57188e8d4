"""Results files of DEM runs (layout: docs/schema_dem.md), reading, VTK export and the
stress-strain plot (Fig. 7b of Kuhn 002)."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError, ResultFileError
from ..geometry import Packing
from ..io import atomic_h5, open_result, read_packing_group, write_packing_group

KIND = "dem-run"
SERIES_KEYS = ("step", "time", "cell", "stress", "n_contacts", "mean_overlap", "kinetic_energy", "phase")
_GZ = {"compression": "gzip", "compression_opts": 4}


@dataclass(frozen=True)
class OutputSettings:
    """How often to write: series rows, snapshots, checkpoints (in steps; 0 = never)."""

    series_every: int = 1
    snapshot_every: int = 1000
    checkpoint_every: int = 20000

    def __post_init__(self):
        for k in ("series_every", "snapshot_every", "checkpoint_every"):
            v = getattr(self, k)
            if int(v) != v or v < 0:
                raise InputError(f"{k}: expected an integer >= 0, got {v!r}")
        if self.series_every == 0:
            raise InputError("series_every: must be >= 1")


@dataclass
class RunRecord:
    """In-memory content of a run file (what :func:`write_run` writes)."""

    packing: Packing
    settings_text: str
    fingerprint: str
    series: dict = field(default_factory=lambda: {k: [] for k in SERIES_KEYS})
    snapshots: dict = field(default_factory=dict)  # step -> dict of arrays
    checkpoint: dict | None = None  # arrays + "step" + "protocol_state"
    complete: bool = False
    stop_reason: str = ""

    def series_arrays(self) -> dict:
        out = {}
        for k in SERIES_KEYS:
            v = self.series[k]
            if k in ("cell", "stress"):
                out[k] = np.array(v, np.float64).reshape(-1, 2, 2)
            elif k in ("step", "n_contacts"):
                out[k] = np.array(v, np.int64)
            elif k == "phase":
                out[k] = np.array(v, np.int8)
            else:
                out[k] = np.array(v, np.float64)
        return out


def write_run(path, rec: RunRecord, parameters: dict | None = None, seed=None) -> Path:
    """Write the whole record atomically (a crash never leaves a half-written file)."""
    with atomic_h5(path, kind=KIND, parameters=parameters or json.loads(rec.settings_text), seed=seed) as f:
        f.attrs["fingerprint"] = rec.fingerprint
        f.attrs["settings"] = rec.settings_text
        f.attrs["n_particles"] = rec.packing.n
        f.attrs["complete"] = bool(rec.complete)
        f.attrs["stop_reason"] = rec.stop_reason
        write_packing_group(f.create_group("packing"), rec.packing)
        g = f.create_group("series")
        g.attrs["stress_sign"] = "tension positive (gransim convention; = -LIGGGHTS compute pressure)"
        for k, v in rec.series_arrays().items():
            if k == "stress":
                v = -v  # the engine works in LIGGGHTS' compression-positive virial; files are tension positive
            chunks = (min(max(len(v), 1), 4096),) + v.shape[1:]
            g.create_dataset(k, data=v, chunks=chunks if len(v) else None, maxshape=(None,) + v.shape[1:],
                             **(_GZ if len(v) else {}))
        sg = f.create_group("snapshots")
        for step in sorted(rec.snapshots):
            snap = rec.snapshots[step]
            h = sg.create_group(f"s{step:010d}")
            h.attrs["step"] = step
            h.attrs["time"] = snap["time"]
            for k in ("cell", "positions", "velocities", "spins"):
                h.create_dataset(k, data=snap[k], **(_GZ if np.ndim(snap[k]) and len(snap[k]) > 1 else {}))
            c = h.create_group("contacts")
            for k, v in snap["contacts"].items():
                v = np.asarray(v)
                c.create_dataset(k, data=v, chunks=(min(max(len(v), 1), 65536),) + v.shape[1:] if len(v) else None,
                                 **(_GZ if len(v) else {}))
        if rec.checkpoint is not None:
            ck = f.create_group("checkpoint")
            ck.attrs["step"] = int(rec.checkpoint["step"])
            ck.attrs["protocol_state"] = json.dumps(rec.checkpoint["protocol_state"])
            for k, v in rec.checkpoint["arrays"].items():
                ck.create_dataset(k, data=np.asarray(v))
    return Path(path)


def read_record(path) -> RunRecord:
    """Read a run file back into a :class:`RunRecord` (used to resume)."""
    with open_result(path, kind=KIND) as f:
        rec = RunRecord(packing=read_packing_group(f["packing"]), settings_text=str(f.attrs["settings"]),
                        fingerprint=str(f.attrs["fingerprint"]), complete=bool(f.attrs["complete"]),
                        stop_reason=str(f.attrs["stop_reason"]))
        for k in SERIES_KEYS:
            v = f["series"][k][()]
            rec.series[k] = list(-v if k == "stress" else v)  # back to the engine's compression-positive virial
        for h in f["snapshots"].values():
            step = int(h.attrs["step"])
            rec.snapshots[step] = {"time": float(h.attrs["time"]),
                                   **{k: h[k][()] for k in ("cell", "positions", "velocities", "spins")},
                                   "contacts": {k: v[()] for k, v in h["contacts"].items()}}
        if "checkpoint" in f:
            ck = f["checkpoint"]
            arrays = {}
            ck.visititems(lambda name, obj: arrays.__setitem__(name, obj[()]) if hasattr(obj, "shape") else None)
            rec.checkpoint = {"step": int(ck.attrs["step"]), "protocol_state": json.loads(ck.attrs["protocol_state"]),
                              "arrays": arrays}
    return rec


@dataclass(frozen=True)
class RunResult:
    """A finished (or stopped) DEM run as read from its file."""

    path: Path
    packing: Packing
    settings: dict
    series: dict
    snapshot_steps: tuple
    complete: bool
    stop_reason: str

    def strain(self) -> np.ndarray:
        """Logarithmic strains ln(L/L0) of the two axes, (T, 2) (compression negative)."""
        L = np.stack([self.series["cell"][:, 0, 0], self.series["cell"][:, 1, 1]], axis=1)
        L0 = np.array([self.packing.cell[0, 0], self.packing.cell[1, 1]])
        return np.log(L / L0)


def read_run(path) -> RunResult:
    """Series, packing and settings of a run file (``series["stress"]`` tension positive, N/m)."""
    with open_result(path, kind=KIND) as f:
        series = {k: f["series"][k][()] for k in SERIES_KEYS}
        return RunResult(path=Path(path), packing=read_packing_group(f["packing"]),
                         settings=json.loads(f.attrs["settings"]), series=series,
                         snapshot_steps=tuple(int(h.attrs["step"]) for h in f["snapshots"].values()),
                         complete=bool(f.attrs["complete"]), stop_reason=str(f.attrs["stop_reason"]))


@dataclass(frozen=True)
class Snapshot:
    """One snapshot: positions (N,2), velocities (N,2), spins (N,), cell (2,2), contacts dict
    (i, j, shift, force (on j), overlap, tangential_spring, sliding)."""

    step: int
    time: float
    cell: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    spins: np.ndarray
    radii: np.ndarray
    contacts: dict


def read_snapshot(path, step: int | None = None) -> Snapshot:
    """The snapshot at ``step`` (None = the last one)."""
    with open_result(path, kind=KIND) as f:
        g = f["snapshots"]
        names = sorted(g.keys())
        if not names:
            raise ResultFileError(f"{path}: no snapshots")
        if step is None:
            name = names[-1]
        else:
            name = f"s{int(step):010d}"
            if name not in g:
                have = [int(n[1:]) for n in names]
                raise ResultFileError(f"{path}: no snapshot at step {step} (have {have[:5]}...{have[-3:]})")
        h = g[name]
        return Snapshot(step=int(h.attrs["step"]), time=float(h.attrs["time"]), cell=h["cell"][()],
                        positions=h["positions"][()], velocities=h["velocities"][()], spins=h["spins"][()],
                        radii=f["packing/radii"][()], contacts={k: v[()] for k, v in h["contacts"].items()})


def snapshot_to_vtu(path, step: int | None, out) -> Path:
    """Write one snapshot as a ParaView .vtu (points with radius, velocity, spin, contact count)."""
    from ..io import particles_to_vtu

    s = read_snapshot(path, step)
    z = np.bincount(s.contacts["i"], minlength=len(s.radii)) + np.bincount(s.contacts["j"], minlength=len(s.radii))
    return particles_to_vtu(out, s.positions, s.radii, point_data={"velocity": s.velocities, "spin": s.spins,
                                                                 "contacts": z.astype(float)}, cell=s.cell)


def plot_stress_strain(path, out) -> Path:
    """Fig. 7b of Kuhn (002): stress ratio sigma_22/sigma_11 and deviator (sigma_22 - sigma_11)/2
    against the axial strain -eps_22 (compression phase; compression-positive stresses)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..io import atomic_path

    run = read_run(path)
    sel = run.series["phase"] == 1
    if not np.any(sel):
        sel = np.ones_like(run.series["phase"], bool)
    eps = run.strain()[sel]
    e22 = -(eps[:, 1] - eps[0, 1])
    st = -run.series["stress"][sel]  # plotted compression positive, as in the paper
    s11, s22 = st[:, 0, 0], st[:, 1, 1]
    fig, ax = plt.subplots(1, 2, figsize=(9, 3.6))
    ax[0].plot(e22 * 100, s22 / s11)
    ax[0].set_xlabel(r"axial strain $-\varepsilon_{22}$ (%)")
    ax[0].set_ylabel(r"$\bar\sigma_{22}/\bar\sigma_{11}$")
    ax[1].plot(e22 * 100, 0.5 * (s22 - s11), label="deviator")
    ax[1].plot(e22 * 100, s11, label=r"$\bar\sigma_{11}$")
    ax[1].set_xlabel(r"axial strain $-\varepsilon_{22}$ (%)")
    ax[1].set_ylabel("stress (N/m)")
    ax[1].legend()
    fig.suptitle(f"biaxial compression, {run.packing.n} disks ({Path(path).name})")
    fig.tight_layout()
    out = Path(out)
    with atomic_path(out, suffix=out.suffix) as tmp:
        fig.savefig(tmp, dpi=120, format=out.suffix.lstrip(".") or "png")
    plt.close(fig)
    return out
