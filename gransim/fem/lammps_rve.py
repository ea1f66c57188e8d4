"""A DEM RVE in LAMMPS' arithmetic driven by a Gauss point's strain history.

Guo & Zhao (*A coupled FEM/DEM approach for hierarchical multiscale modelling of granular media*,
Int. J. Numer. Meth. Engng 99 (2014) 789-818, section 3) drive each Gauss point's periodic RVE by
its strain increment D (2, 2) (the increment of the displacement gradient), applied as a constant
velocity gradient over ns = max(1e5 max|D|, 2) steps (``simDEM.shear2D``, :func:`gransim.dem.
yade_arithmetic.n_steps_of`). :mod:`gransim.fem.dem_rve` does this in YADE's arithmetic; this module
does it in LAMMPS' (29 Sep 2021), so that a Gauss point's history can be replayed in LAMMPS too
(``reference_runs.femxdem.lammps_replay``).

The cell is LAMMPS' triclinic box (upper triangular, a1 = (Lx, 0)): one call is one LAMMPS ``run
ns`` under ``fix deform 1 x erate D00/T y erate D11/T xy erate (D01 + D10)/T remap x`` (T = ns dt),
:class:`gransim.dem.sheared.ShearLoading` with ``remap="x"``: Lx and Ly change by the engineering
increments D00 and D11, the tilt by (D01 + D10) Ly0, and every position follows the cell affinely.
The cell cannot rotate (LAMMPS keeps a1 along x), so the increment's rotation (D01 - D10)/2 is not
applied: a disk assembly with frictional Hooke contacts is frame indifferent, and the symmetric part
of D is applied exactly to first order. Each call starts with LAMMPS' run set-up (list build, the
springs handed over, forces without spring increment), as consecutive ``run`` commands do.

The RVE of Guo & Zhao's ``prepareRVE.py`` (:func:`gransim.fem.dem_rve.load_rve_state`: 400 disks
consolidated to 100 kPa in YADE) gives the disks and the cell; the contact law is LAMMPS'
``gran/hooke/history`` (a LAMMPS material, not YADE's Cundall-Strack law with its non-viscous
damping, which LAMMPS does not offer): kn the median of YADE's radius-dependent kn of the
prepared contacts, kt = (ks/kn) kn, friction tan of YADE's friction angle, viscous damping ratio
:data:`DAMPING_RATIO`, dt = contact time / :data:`STEPS_PER_CONTACT`. Mass per unit area:
YADE's disk mass over pi r^2 (2650 kg/m^3 times the 0.1 m thickness). Stresses: the Love stress of
the cell (N/m, tension positive) over the thickness :data:`THICKNESS`, in Pa as the FE specimen.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from ..dem.settings import DEMSettings
from ..errors import InputError
from ..geometry import Packing

#: the disks' thickness (m): YADE's 3D cell height of Guo & Zhao's RVE (stress in Pa)
THICKNESS = 0.1
#: viscous damping ratio of the LAMMPS law (Guo & Zhao's YADE damping is non-viscous, 0.1)
DAMPING_RATIO = 0.1
#: time step = contact time / this
STEPS_PER_CONTACT = 50.0


@dataclass(frozen=True)
class LammpsRVE:
    """The RVE (packing wrapped into its cell, orthogonal at the start) and its LAMMPS settings."""

    packing: Packing
    settings: DEMSettings

    def __reduce__(self):
        # a Packing's metadata is a read-only mappingproxy, which pickle refuses: rebuilt from a dict
        # (the law travels to the Dask workers of gransim femxdem --rve dem-lammps)
        p = self.packing
        args = (p.positions, p.radii, p.cell, p.density, dict(p.metadata), self.settings)
        return (_rebuild, args)

    def __post_init__(self):
        if self.settings.flavour != "lammps":
            raise InputError(
                f"settings.flavour: the LAMMPS RVE runs in LAMMPS' arithmetic, got {self.settings.flavour!r}"
            )

    @classmethod
    def guo_zhao(cls, state=None) -> LammpsRVE:
        """The RVE of ``prepareRVE.py`` (``state``: a :class:`gransim.dem.yade_arithmetic.
        YadeRVEState`, default the stored one) with the LAMMPS law of the module docstring."""
        from ..dem.biaxial import default_settings  # noqa: PLC0415 - start-up: numba
        from ..dem.kernels import pbc_wrap  # noqa: PLC0415 - start-up: numba
        from .dem_rve import load_rve_state  # noqa: PLC0415 - start-up: numba

        if state is None:
            state = load_rve_state()[0]
        H = np.asarray(state.hsize, np.float64)
        if H[0, 1] != 0.0 or H[1, 0] != 0.0:
            raise InputError(f"state.hsize: the LAMMPS RVE starts from an orthogonal cell, got {H.tolist()}")
        r = np.asarray(state.radii, np.float64)
        x = np.array(state.positions, np.float64)
        if pbc_wrap(x, np.zeros(2), np.array([H[0, 0], H[1, 1]])) >= 0:
            raise InputError("state.positions: a disk lies more than a cell outside the cell")
        rho = float(np.median(np.asarray(state.mass) / (np.pi * r * r)))
        packing = Packing(positions=x, radii=r, cell=H, density=rho, metadata={"source": "prepareRVE.py (YADE)"})
        kn = float(np.median(state.kn))
        ratio = float(np.median(np.asarray(state.ks) / np.asarray(state.kn)))
        mu = float(np.median(state.tan_phi))
        dem, _ = default_settings(
            packing, kn=kn, damping_ratio=DAMPING_RATIO, steps_per_contact=STEPS_PER_CONTACT, flavour="lammps",
            mu=mu, kt_ratio=ratio,
        )  # fmt: skip
        return cls(packing, dataclasses.replace(dem))

    def call(self, D):
        """(ShearLoading, ns) of the strain increment ``D`` (2, 2): the module's ``fix deform``."""
        from ..dem.sheared import ShearLoading  # noqa: PLC0415 - start-up: numba
        from ..dem.yade_arithmetic import n_steps_of  # noqa: PLC0415 - start-up: numba

        D = np.asarray(D, np.float64)
        if D.shape != (2, 2) or not np.all(np.isfinite(D)):
            raise InputError(f"D: expected a finite (2, 2) strain increment, got shape {D.shape}")
        ns = n_steps_of(D)
        T = ns * self.settings.dt
        ld = ShearLoading(
            erate=float((D[0, 1] + D[1, 0]) / T), x_erate=float(D[0, 0] / T), y="erate", y_erate=float(D[1, 1] / T),
            remap="x",
        )  # fmt: skip
        return ld, ns

    def engine(self):
        """A new engine of the RVE (the sheared cell in LAMMPS' arithmetic)."""
        from ..dem.sheared import ShearEngine  # noqa: PLC0415 - start-up: numba

        return ShearEngine(self.packing, self.settings, flavour="lammps")

    def engine_at(self, state: LammpsState):
        """The engine of the RVE at ``state`` (:meth:`gransim.dem.engine.Engine.from_checkpoint`:
        without the set-up of a new engine)."""
        from ..dem.engine import Engine  # noqa: PLC0415 - start-up: numba

        return Engine.from_checkpoint(
            self.packing, self.settings, state.arrays, state.step, cell="sheared", flavour="lammps"
        )

    def replay(self, increments) -> list[dict]:
        """Drive a new engine by ``increments`` (K, 2, 2), one call each; the set-up state and the
        state after each call (K + 1 dicts): ``positions`` (N, 2) m, ``velocities`` m/s, ``spins``
        rad/s, ``forces`` (N, 2) N, ``torques`` N m, ``box`` (5,) (lo_x, lo_y, hi_x, hi_y, xy; m),
        ``stress`` (2, 2) (Pa, tension positive), ``steps`` (the call's ns; 0 for the set-up)."""
        inc = np.asarray(increments, np.float64).reshape(-1, 2, 2)
        eng = self.engine()
        out = [_state(eng, 0)]
        for D in inc:
            ld, ns = self.call(D)
            eng.start_run(ld, ns)
            eng.advance(ns)
            out.append(_state(eng, ns))
        return out


def _rebuild(positions, radii, cell, density, metadata, settings) -> LammpsRVE:
    return LammpsRVE(Packing(positions=positions, radii=radii, cell=cell, density=density, metadata=metadata), settings)


def _state(eng, steps: int) -> dict:
    return {
        "positions": eng.x.copy(),
        "velocities": eng.v.copy(),
        "spins": eng.w.copy(),
        "forces": eng.f.copy(),
        "torques": eng.t.copy(),
        "box": eng.box.copy(),
        "stress": -eng.stress_tensor() / THICKNESS,
        "steps": steps,
    }


@dataclass(frozen=True, eq=False)
class LammpsState:
    """State of a Gauss point whose RVE runs in LAMMPS' arithmetic: the engine's checkpoint arrays
    (:meth:`gransim.dem.engine.Engine.state_arrays` without the run: each update begins its own),
    its step, the number of updates behind it and their strain increments (updates, 2, 2)."""

    arrays: dict
    step: int = 0
    updates: int = 0
    increments: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 2)))


#: the per-state arrays of a LammpsState of one length for every state (N particles), and those of
#: a length that varies (the list entries), packed with offsets by :meth:`LammpsPointLaw.pack_states`
_PER_PARTICLE = ("positions", "velocities", "spins", "forces", "torques", "x_hold", "lamda")
_PER_ENTRY = ("neighbours/a", "neighbours/b", "neighbours/shift", "neighbours/owned_both", "neighbours/xi",
              "neighbours/touch")  # fmt: skip
_PER_CELL = ("virial", "box", "box_hold", "h_rate", "corners_hold")


def _packed(name: str) -> str:
    """The name of an engine array in packed states: no "/" (an HDF5 checkpoint would read it as a group)."""
    return name.replace("/", ".")


@dataclass(frozen=True, eq=False)
class LammpsPointLaw:
    """The point law of a Gauss point whose RVE runs in LAMMPS' arithmetic (the interface of
    :mod:`gransim.fem.material_points`): every point starts from the same :class:`LammpsRVE`;
    ``update(f, state)`` restores an engine from ``state`` (never modified) and runs one call with
    D = f - 1 (:meth:`LammpsRVE.call`). Chained updates equal :meth:`LammpsRVE.replay` of the same
    increments bit for bit (tests/fem/test_lammps_gauss_point.py). Stress: the Love stress
    symmetrised, 0.5 (s + s^T), over the thickness (Pa, tension positive); tangent: the contact
    stiffness tangent of Guo & Zhao's eq. (10), t_ijkl = (1/V) sum_c (kn n_i n_k + kt t_i t_k) l_j l_l
    (l the branch vector, n = l/|l|, t its normal) with every minor symmetry, over the thickness."""

    rve: LammpsRVE

    def initial_state(self, g: int) -> LammpsState:
        eng = self.rve.engine()
        return LammpsState(self._arrays(eng), eng.step)

    @staticmethod
    def _arrays(eng) -> dict:
        # without the run (``run``, ``run_loading_json``: gransim.dem.sheared.run_arrays): each update begins its own
        out = {k: np.array(v) for k, v in eng.state_arrays().items() if k != "run" and not k.startswith("run_")}
        for v in out.values():
            v.flags.writeable = False
        return out

    def _engine(self, state: LammpsState):
        """The RVE's engine at ``state`` (no run set-up: the update begins its own run)."""
        return self.rve.engine_at(state)

    def response(self, state: LammpsState):
        """(sigma (2, 2), t (2, 2, 2, 2)) of the state as it stands (Pa)."""
        return self._response(self._engine(state))

    def _response(self, eng):
        s = self.rve.settings
        sig = -eng.stress_tensor() / THICKNESS
        c = eng.contacts()
        x = eng.x
        l = x[c["j"]] + c["shift"] @ eng.cell.T - x[c["i"]]  # noqa: E741 - the branch vector of the paper
        n = l / np.linalg.norm(l, axis=1)[:, None]
        t = np.stack([-n[:, 1], n[:, 0]], axis=1)
        C = s.kn * np.einsum("ci,cj,ck,cl->ijkl", n, l, n, l) + s.kt * np.einsum("ci,cj,ck,cl->ijkl", t, l, t, l)
        C = C / (eng.area * THICKNESS)
        C = 0.25 * (C + C.transpose(1, 0, 2, 3) + C.transpose(0, 1, 3, 2) + C.transpose(1, 0, 3, 2))
        return 0.5 * (sig + sig.T), C

    def update(self, f, state: LammpsState):
        """One call with D = f - 1 from ``state`` (not modified): (sigma, t, new state)."""
        D = np.asarray(f, np.float64) - np.eye(2)
        eng = self._engine(state)
        ld, ns = self.rve.call(D)
        eng.start_run(ld, ns)
        eng.advance(ns)
        sig, t = self._response(eng)
        new = LammpsState(self._arrays(eng), eng.step, state.updates + 1, np.concatenate([state.increments, D[None]]))
        return sig, t, new

    def observables(self, state: LammpsState) -> dict:
        """Void ratio (cell area - sum pi r^2) / sum pi r^2, the number of contacts (overlapping
        pairs) and of updates. (No disk rotation: LAMMPS' spheres carry no orientation.)"""
        b = np.asarray(state.arrays["box"])
        area = float((b[2] - b[0]) * (b[3] - b[1]))
        vs = float(np.sum(np.pi * self.rve.packing.radii**2))
        eng = self._engine(state)
        return {
            "void_ratio": (area - vs) / vs,
            "contacts": float(eng._touching()[0].size),
            "updates": float(state.updates),
        }

    def snapshot(self, state: LammpsState) -> dict:
        """What an RVE picture needs (:func:`gransim.fem.output_femxdem.plot_rve`): positions from
        the box's lower corner (N, 2), radii, the cell ``hsize`` (2, 2) (columns the lattice
        vectors), the touching pairs ``ids`` (M, 2) with their image shifts ``cell_dist`` (the
        branch x_j + H s - x_i, YADE's convention) and the force on j split along the branch
        (``normal_force``) and across it (``shear_force``), N, as LAMMPS' run set-up evaluates them
        (on a throw-away engine). No ``rotation``: LAMMPS' disks carry no orientation."""
        eng = self._engine(state)
        ld, ns = self.rve.call(np.zeros((2, 2)))
        eng.start_run(ld, ns)  # a run's set-up evaluates the contact forces (a restored engine holds none)
        c = eng.contacts()
        H = np.array(eng.cell, float)
        x = np.array(eng.x, float) - np.asarray(eng.box, float)[:2]
        l = eng.x[c["j"]] + c["shift"] @ H.T - eng.x[c["i"]]  # noqa: E741 - the branch vector of the paper
        n = l / np.linalg.norm(l, axis=1)[:, None]
        f = np.asarray(c["force"], float)
        fn = np.einsum("ci,ci->c", f, n)[:, None] * n
        return {
            "positions": x, "radii": np.array(self.rve.packing.radii, float), "hsize": H,
            "ids": np.stack([c["i"], c["j"]], axis=1).astype(np.int64), "cell_dist": np.asarray(c["shift"], np.int64),
            "normal_force": fn, "shear_force": f - fn,
        }  # fmt: skip

    @staticmethod
    def pack_states(states) -> dict:
        """{name: array} of a list of states (checkpoints): per-particle and per-cell arrays stacked
        (G, ...), the list entries concatenated with ``offsets`` (G + 1,); names without "/"
        (``neighbours.a``...: a dataset name of the checkpoint)."""
        counts = [len(s.arrays["neighbours/a"]) for s in states]
        out = {
            "offsets": np.concatenate([[0], np.cumsum(counts)]).astype(np.int64),
            "step": np.array([s.step for s in states], np.int64),
            "updates": np.array([s.updates for s in states], np.int64),
            "increments": np.concatenate([np.asarray(s.increments).reshape(-1, 2, 2) for s in states]),
        }
        for k in _PER_PARTICLE + _PER_CELL:
            out[k] = np.array([s.arrays[k] for s in states])
        for k in _PER_ENTRY:
            out[_packed(k)] = np.concatenate([np.asarray(s.arrays[k]) for s in states])
        return out

    @staticmethod
    def unpack_states(arrays: dict) -> list:
        """The states of :meth:`pack_states`' arrays."""
        off = np.asarray(arrays["offsets"])
        upd = np.asarray(arrays["updates"])
        inc = np.asarray(arrays["increments"]).reshape(-1, 2, 2)
        first = np.concatenate([[0], np.cumsum(upd)])
        states = []
        for g in range(len(off) - 1):
            a = {k: np.array(arrays[k][g]) for k in _PER_PARTICLE + _PER_CELL}
            a.update({k: np.array(arrays[_packed(k)][off[g] : off[g + 1]]) for k in _PER_ENTRY})
            for v in a.values():
                v.flags.writeable = False
            states.append(LammpsState(a, int(arrays["step"][g]), int(upd[g]), inc[first[g] : first[g + 1]].copy()))
        return states


__all__ = ["DAMPING_RATIO", "STEPS_PER_CONTACT", "THICKNESS", "LammpsPointLaw", "LammpsRVE", "LammpsState"]
