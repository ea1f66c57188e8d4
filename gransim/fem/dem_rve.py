"""The DEM RVE as a Gauss-point law: Guo & Zhao's periodic disk RVE in YADE's arithmetic.

Guo & Zhao (*A coupled FEM/DEM approach for hierarchical multiscale modelling of granular media*,
Int. J. Numer. Meth. Engng 99 (2014) 789-818, section 3) give every Gauss point a periodic DEM
RVE: the FE strain increment D = grad u drives the RVE as a constant velocity gradient over
ns = max(1e5 max|D|, 2) steps, and the RVE returns its stress and its contact-stiffness tangent
(their eqs 9-10: sigma = (1/V) sum f (x) d, D = (1/V) sum (kn n n d d + kt t t d d)). Their code
(``simDEM.shear2D`` and ``getStressAndTangent2D`` of Debian's yade 2023.02a) runs YADE; here the
same calls run natively in YADE's arithmetic (:func:`gransim.dem.yade_arithmetic.rve_run`), which
equals YADE bit for bit, state after state (tests/fem/test_dem_rve.py; docs/femxdem.md).

:class:`DemRVE` is the point law of :mod:`gransim.fem.material_points`:

* ``update(f, state)`` runs ``rve_run(state.rve, f - 1)`` from the committed state (a new state;
  the committed one is never written) and returns simDEM's symmetrised stress 0.5 (s + s^T) and
  its tangent t[i, j, k, l] (the Voigt entries (0, 0), (0, 1), (0, 5), (1, 1), (1, 5), (5, 5) of
  ``getStressAndTangent`` spread over every minor symmetry, simDEM.py:137-149), used as
  d sigma / d f (the contact-stiffness tangent; its geometric and sliding terms are missing, so
  Newton converges linearly, as in Guo & Zhao's runs);
* stress unit: YADE's ``getStress()`` divides by det(hSize), the volume of the 3D cell whose z is
  the disks' thickness 0.1 m: the stress is in Pa, the 2D stress (N/m, gransim's convention
  elsewhere) divided by 0.1 m, the plane-strain stress the FE specimen carries (confining 1e5 Pa);
* the state (:class:`DemState`) is the scene as YADE serialises it between calls
  (:class:`gransim.dem.yade_arithmetic.YadeRVEState`: positions, velocities, spins, cell, the real
  interactions in YADE's container order with their shear forces, the collider's and the
  integrator's saved attributes), the number of updates that led to it, and each disk's rotation
  since the initial RVE: spin dt summed over every step of every call, as YADE turns the disks'
  orientation (:func:`gransim.dem.yade_arithmetic.rve_run_rotation`).

The initial RVE is the one ``prepareRVE.py`` prepares (400 disks, r_mean 5 mm +- 40 %, a periodic
0.24 m cell, 0.1-thick disks at 2650 kg/m^3, E 6e8 Pa with ks/kn 0.8, consolidated frictionless to
100 kPa by ``PeriTriaxController``, then friction angle 0.5 rad and damping 0.1), run in YADE
2023.02a and stored with its provenance in ``gransim/fem/data/guo_zhao_rve.h5``
(:func:`load_rve_state`; the consolidation itself is not reproduced natively: docs/femxdem.md).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError

#: the RVE prepared by prepareRVE.py in YADE 2023.02a (reference_runs/yade/rve.py)
PREPARED_RVE = Path(__file__).parent / "data" / "guo_zhao_rve.h5"
#: the disks' rotations in packed states (checkpoints): the step sums; the key of older checkpoints,
#: ``rotation``, held a trapezoidal estimate over each call and is refused
ROTATION_KEY = "rotation_sum"


def _fields():
    from ..dem.yade_arithmetic import RVE_STATE_FIELDS  # noqa: PLC0415 - start-up: numba

    return RVE_STATE_FIELDS


def save_rve_state(path, state, provenance: dict | None = None) -> Path:
    """Write a :class:`~gransim.dem.yade_arithmetic.YadeRVEState` (HDF5 group ``rve``, every field
    at full precision; ``provenance`` as JSON in the attribute ``provenance``), atomically."""
    from ..io.hdf5 import atomic_h5  # noqa: PLC0415 - start-up: h5py

    with atomic_h5(path, "yade-rve-state", parameters=provenance or {}) as f:
        g = f.create_group("rve")
        for name in _fields():
            v = getattr(state, name)
            if isinstance(v, np.ndarray):
                g.create_dataset(name, data=v, compression="gzip")
            else:
                g.attrs[name] = v
        g.attrs["provenance"] = json.dumps(provenance or {})
    return Path(path)


def load_rve_state(path=PREPARED_RVE):
    """(state, provenance dict) of a file of :func:`save_rve_state`."""
    import h5py  # noqa: PLC0415 - start-up: h5py

    from ..dem.yade_arithmetic import YadeRVEState  # noqa: PLC0415 - start-up: numba

    path = Path(path)
    try:
        with h5py.File(path, "r") as f:
            g = f["rve"]
            kw = {n: (np.array(g[n]) if n in g else g.attrs[n]) for n in _fields()}
            prov = json.loads(g.attrs["provenance"])
    except (OSError, KeyError) as exc:
        raise InputError(f"{path}: not a saved YADE RVE state ({exc})") from None
    for n in ("iteration",):
        kw[n] = int(kw[n])
    for n in ("dt", "z", "z_pos", "verlet", "damping", "young", "poisson", "friction_angle"):
        kw[n] = float(kw[n])
    kw["vel_grad_changed"] = bool(kw["vel_grad_changed"])
    return YadeRVEState(**kw), prov


@dataclass(frozen=True, eq=False)
class DemState:
    """State of a DEM Gauss point: the RVE's saved scene, the number of updates behind it, the
    strain increments D (updates, 2, 2) that led to it from the initial RVE (the point's strain
    history: replayed in YADE it gives the same scene, tests/fem/test_dem_rve.py) and each disk's
    rotation since the initial RVE (N,) rad, counter-clockwise: spin dt summed over every DEM step
    of every update (:func:`gransim.dem.yade_arithmetic.rve_run_rotation`; YADE's ``State::rot()``
    z to the round-off of its quaternions, docs/femxdem.md; None: zero, the initial RVE). The
    rotation is an output only: no force, position or velocity reads it."""

    rve: object
    updates: int = 0
    increments: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 2)))
    rotation: np.ndarray | None = None

    def disk_rotation(self) -> np.ndarray:
        """Each disk's rotation since the initial RVE (N,) rad."""
        return np.zeros(self.rve.n) if self.rotation is None else np.asarray(self.rotation)


@dataclass(frozen=True, eq=False)
class DemRVE:
    """Guo & Zhao's DEM RVE at every Gauss point (module docstring); ``initial``: the RVE every
    point starts from (default: the stored prepareRVE.py state)."""

    initial: object = None
    provenance: dict = field(default_factory=dict)

    @classmethod
    def prepared(cls, path=PREPARED_RVE) -> DemRVE:
        """The law with the stored RVE of ``path``."""
        state, prov = load_rve_state(path)
        return cls(state, prov)

    def initial_state(self, g: int) -> DemState:
        """Every Gauss point holds the same RVE (simDEM.initLoad loads one 0.yade.gz, simDEM.py:20-36)."""
        return DemState(self.initial, 0)

    def response(self, state: DemState):
        """(sigma (2, 2), t (2, 2, 2, 2)) of the state as it stands (Pa)."""
        from ..dem.yade_arithmetic import guo_zhao_stress_tangent  # noqa: PLC0415 - start-up: numba

        return guo_zhao_stress_tangent(state.rve)

    def update(self, f, state: DemState):
        """simDEM.shear2D with D = f - 1 from ``state`` (not modified), then the stress and tangent;
        the disks' rotations carried on by the call's steps."""
        from ..dem.yade_arithmetic import guo_zhao_stress_tangent, rve_run_rotation  # noqa: PLC0415 - start-up: numba

        D = np.asarray(f, dtype=float) - np.eye(2)
        new, rot = rve_run_rotation(state.rve, D, state.disk_rotation())
        sigma, t = guo_zhao_stress_tangent(new)
        return sigma, t, DemState(new, state.updates + 1, np.concatenate([state.increments, D[None]]), rot)

    def observables(self, state: DemState) -> dict:
        """Void ratio (cell area - sum pi r^2) / sum pi r^2 (Shop::getVoidRatio2D), the mean disk
        rotation since the initial RVE (rad, counter-clockwise; simDEM.avgRotation2D's quantity,
        simDEM.py:204-210: the mean of ``State::rot()`` z), the number of contacts and of updates."""
        r = state.rve
        h = np.asarray(r.hsize)
        area = float(h[0, 0] * h[1, 1] - h[0, 1] * h[1, 0])
        vs = float(np.sum(np.pi * np.asarray(r.radii) ** 2))
        return {
            "void_ratio": (area - vs) / vs,
            "rotation": float(np.mean(state.disk_rotation())),
            "contacts": float(len(r.kn)),
            "updates": float(state.updates),
        }

    @staticmethod
    def pack_states(states) -> dict:
        """{name: array} of a list of states (checkpoints): per-disk fields stacked (G, N, ...),
        the interactions concatenated with ``offsets`` (G + 1,)."""
        fields = _fields()
        out, counts = {}, [len(s.rve.kn) for s in states]
        out["offsets"] = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        out["updates"] = np.array([s.updates for s in states], dtype=np.int64)
        out["increments"] = np.concatenate([np.asarray(s.increments).reshape(-1, 2, 2) for s in states])
        out[ROTATION_KEY] = np.array([s.disk_rotation() for s in states])
        per_contact = ("ids", "cell_dist", "normal", "kn", "ks", "tan_phi", "normal_force", "shear_force")
        for name in fields:
            vals = [getattr(s.rve, name) for s in states]
            if name in per_contact:
                out[name] = np.concatenate([np.asarray(v) for v in vals])
            else:
                out[name] = np.array(vals)
        return out

    @staticmethod
    def unpack_states(arrays: dict) -> list:
        """The states of :meth:`pack_states`' arrays."""
        from ..dem.yade_arithmetic import YadeRVEState  # noqa: PLC0415 - start-up: numba

        a = arrays
        off = np.asarray(a["offsets"])
        per_contact = ("ids", "cell_dist", "normal", "kn", "ks", "tan_phi", "normal_force", "shear_force")
        scalars = {"iteration": int, "dt": float, "z": float, "z_pos": float, "verlet": float, "damping": float,
                   "young": float, "poisson": float, "friction_angle": float, "vel_grad_changed": bool}  # fmt: skip
        states = []
        upd = np.asarray(a["updates"])
        if ROTATION_KEY not in a:
            raise InputError(
                "the saved Gauss-point states hold no step-summed disk rotations (written by an older gransim, "
                "whose rotation was an estimate): rerun"
            )
        ioff = np.concatenate([[0], np.cumsum(upd)])
        for g in range(len(upd)):
            kw = {}
            for name in _fields():
                if name in per_contact:
                    kw[name] = np.array(a[name][off[g] : off[g + 1]])
                elif name in scalars:
                    kw[name] = scalars[name](a[name][g])
                else:
                    kw[name] = np.array(a[name][g])
            inc = np.array(a["increments"][ioff[g] : ioff[g + 1]]).reshape(-1, 2, 2)
            states.append(DemState(YadeRVEState(**kw), int(upd[g]), inc, np.array(a[ROTATION_KEY][g])))
        return states


__all__ = ["PREPARED_RVE", "ROTATION_KEY", "DemRVE", "DemState", "load_rve_state", "save_rve_state"]
