"""Driver of a DEM run made of loading phases, with HDF5 output, progress bar, checkpoints and
resume (layout: docs/schema_dem.md)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._validate import as_positive_float
from ..errors import InputError, ResultFileError, SimulationError
from ..geometry import Packing
from ..progress import progress
from .engine import DEMEngine, fingerprint
from .output import OutputSettings, RunRecord, read_record, write_run
from .settings import DEMSettings, Loading, settings_json


@dataclass(frozen=True)
class Phase:
    """One loading phase.

    name : label. loading : Loading of both axes. max_steps : steps of the phase (exactly, when
    ``stop_tol`` is 0). stop_tol : > 0 ends the phase early once every servo axis holds its
    target within ``stop_tol`` relative (mean over a window of ``check_every`` steps) for
    ``settle_checks`` consecutive windows (isotropic consolidation).
    """

    name: str
    loading: Loading
    max_steps: int
    stop_tol: float = 0.0
    check_every: int = 1000
    settle_checks: int = 3

    def __post_init__(self):
        if int(self.max_steps) != self.max_steps or self.max_steps < 0:
            raise InputError(f"phase {self.name}: max_steps must be an integer >= 0, got {self.max_steps!r}")
        as_positive_float(self.stop_tol, "stop_tol", allow_zero=True)
        if self.check_every < 1:
            raise InputError(f"phase {self.name}: check_every must be >= 1")

    def to_dict(self) -> dict:
        return {"name": self.name, "loading": self.loading.to_dict(), "max_steps": int(self.max_steps),
                "stop_tol": self.stop_tol, "check_every": int(self.check_every),
                "settle_checks": int(self.settle_checks)}


def _settled(phase: Phase, mean_stress: np.ndarray) -> bool:
    ok = True
    for d, ctl in enumerate((phase.loading.x, phase.loading.y)):
        if ctl.mode == "servo":
            ok &= abs(mean_stress[d, d] - ctl.target) <= phase.stop_tol * abs(ctl.target)
    return bool(ok)


def _snapshot(eng: DEMEngine) -> dict:
    c = eng.contacts()
    return {"time": eng.step * eng.settings.dt, "cell": eng.cell, "positions": eng.x.copy(),
            "velocities": eng.v.copy(), "spins": eng.w.copy(), "contacts": c}


def run_phases(packing: Packing, settings: DEMSettings, phases, out_path, output: OutputSettings | None = None,
               resume: bool = False, velocities=None, threads: int | None = None, show_progress: bool = True,
               metadata: dict | None = None, stop_at_step: int | None = None) -> Path:
    """Run ``phases`` one after the other from ``packing``; write ``out_path`` (kind "dem-run").

    With ``resume`` and an existing ``out_path`` of the same run (same fingerprint: packing,
    DEM settings, phases), continue from its checkpoint bit for bit; a file of another run is
    refused (:class:`ResultFileError`). A :class:`SimulationError` (NaN, lost particle) writes
    the file with the snapshots so far and ``stop_reason`` before it propagates.
    ``stop_at_step`` ends this call at that step with a checkpoint (``complete`` False): a long
    run split into pieces, continued with ``resume``.
    """
    output = output or OutputSettings()
    phases = list(phases)
    text = settings_json(settings, None, phases=[p.to_dict() for p in phases], **(metadata or {}))
    fp = fingerprint(packing, text)
    out_path = Path(out_path)
    eng = DEMEngine(packing, settings, velocities=velocities, threads=threads)
    state = {"phase": 0, "phase_step0": 0, "lo0": eng.lo.tolist(), "hi0": eng.hi.tolist(), "settled": 0}
    if resume and out_path.exists():
        rec = read_record(out_path)
        if rec.fingerprint != fp:
            raise ResultFileError(f"{out_path}: belongs to another run (fingerprint {rec.fingerprint[:12]} != "
                                  f"{fp[:12]}: different packing, settings or phases); refusing to resume")
        if rec.complete:
            return out_path
        if rec.checkpoint is None:
            raise ResultFileError(f"{out_path}: no checkpoint to resume from; rerun without --resume")
        step = rec.checkpoint["step"]
        eng.restore(rec.checkpoint["arrays"], step)
        state = rec.checkpoint["protocol_state"]
        keep = [k for k, s in enumerate(rec.series["step"]) if s <= step]
        for k in rec.series:
            rec.series[k] = [rec.series[k][i] for i in keep]
        rec.snapshots = {s: v for s, v in rec.snapshots.items() if s <= step}
        rec.stop_reason = ""
    else:
        rec = RunRecord(packing=packing, settings_text=text, fingerprint=fp)
        _append(rec, eng, [0], eng.stress[None], eng.cell[None], [eng.n_contacts], [eng.mean_overlap],
                [eng.kinetic_energy()], 0)
        if output.snapshot_every:
            rec.snapshots[0] = _snapshot(eng)
    total = sum(p.max_steps for p in phases)
    bar = progress(total=total, desc="dem") if show_progress else None
    if bar is not None:
        bar.update(sum(p.max_steps for p in phases[:state["phase"]]) + eng.step - state["phase_step0"])
    try:
        while state["phase"] < len(phases):
            ph = phases[state["phase"]]
            lo0, hi0 = np.array(state["lo0"]), np.array(state["hi0"])
            end = state["phase_step0"] + ph.max_steps
            while eng.step < end:
                nxt = [end]
                for every in (output.snapshot_every, output.checkpoint_every):
                    if every:
                        nxt.append((eng.step // every + 1) * every)
                if ph.stop_tol > 0:
                    nxt.append(state["phase_step0"] + ((eng.step - state["phase_step0"]) // ph.check_every + 1)
                               * ph.check_every)
                if stop_at_step is not None and stop_at_step > eng.step:
                    nxt.append(int(stop_at_step))
                stop = min(nxt)
                out = eng.advance(ph.loading, stop - eng.step, phase_step0=state["phase_step0"], phase_box0=(lo0, hi0))
                sel = out["step"] % output.series_every == 0
                L = out["lengths"][sel]
                cells = np.zeros((len(L), 2, 2))
                cells[:, 0, 0], cells[:, 1, 1] = L[:, 0], L[:, 1]
                _append(rec, eng, out["step"][sel], out["stress"][sel], cells, out["n_contacts"][sel],
                        out["mean_overlap"][sel], out["kinetic_energy"][sel], min(state["phase"], 1))
                if bar is not None:
                    bar.update(len(out["step"]))
                if output.snapshot_every and eng.step % output.snapshot_every == 0:
                    rec.snapshots[eng.step] = _snapshot(eng)
                if ph.stop_tol > 0 and (eng.step - state["phase_step0"]) % ph.check_every == 0:
                    state["settled"] = state["settled"] + 1 if _settled(ph, out["stress"].mean(axis=0)) else 0
                    if state["settled"] >= ph.settle_checks:
                        break
                if output.checkpoint_every and eng.step % output.checkpoint_every == 0:
                    _checkpoint(rec, eng, state)
                    write_run(out_path, rec)
                if stop_at_step is not None and eng.step == stop_at_step:
                    _checkpoint(rec, eng, state)
                    write_run(out_path, rec)
                    return out_path
            state = {"phase": state["phase"] + 1, "phase_step0": eng.step, "lo0": eng.lo.tolist(),
                     "hi0": eng.hi.tolist(), "settled": 0}
    except SimulationError as exc:
        rec.stop_reason = str(exc)
        write_run(out_path, rec)
        raise
    finally:
        if bar is not None:
            bar.close()
    if eng.step not in rec.snapshots and output.snapshot_every:
        rec.snapshots[eng.step] = _snapshot(eng)
    rec.complete = True
    _checkpoint(rec, eng, state)
    write_run(out_path, rec)
    return out_path


def _checkpoint(rec: RunRecord, eng: DEMEngine, state: dict):
    rec.checkpoint = {"step": eng.step, "protocol_state": json.loads(json.dumps(state)),
                      "arrays": {k: np.array(v) for k, v in eng.state_arrays().items()}}


def _append(rec, eng, steps, stress, cells, nc, ov, ke, phase):
    dt = eng.settings.dt
    for k, s in enumerate(steps):
        rec.series["step"].append(int(s))
        rec.series["time"].append(float(s) * dt)
        rec.series["cell"].append(np.asarray(cells[k]))
        rec.series["stress"].append(np.asarray(stress[k]))
        rec.series["n_contacts"].append(int(nc[k]))
        rec.series["mean_overlap"].append(float(ov[k]))
        rec.series["kinetic_energy"].append(float(ke[k]))
        rec.series["phase"].append(int(phase))
