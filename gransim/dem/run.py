"""Driver of a DEM run made of loading phases, with HDF5 output, progress bar, checkpoints and
resume (layout: docs/schema_dem.md)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._validate import as_int, as_positive_float, check_choice
from ..contacts.laws import law_spec
from ..errors import ConvergenceError, InputError, ResultFileError, SimulationError
from ..geometry import Packing
from ..progress import Interrupted, check_interrupt, deferred_interrupts, pending_interrupt, progress, result_written
from .engine import ORDERS, DEMEngine, Engine, fingerprint, make_engine
from .output import OutputSettings, RunRecord, read_record, remove_stale_run_temporaries, write_checkpoint, write_run
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
        return {
            "name": self.name,
            "loading": self.loading.to_dict(),
            "max_steps": int(self.max_steps),
            "stop_tol": self.stop_tol,
            "check_every": int(self.check_every),
            "settle_checks": int(self.settle_checks),
        }


def _settled(phase: Phase, mean_stress: np.ndarray) -> bool:
    ok = True
    for d, ctl in enumerate((phase.loading.x, phase.loading.y)):
        if ctl.mode == "servo":
            ok &= abs(mean_stress[d, d] - ctl.target) <= phase.stop_tol * abs(ctl.target)
    return bool(ok)


def _unsettled_reason(phase: Phase, mean_stress: np.ndarray | None, window: str = "the last window") -> str:
    """Why a phase with a stop criterion ended on its step cap: the stress ratios of its last window."""
    parts = []
    for d, ctl in enumerate((phase.loading.x, phase.loading.y)):
        if ctl.mode == "servo":
            ok = mean_stress is not None and ctl.target
            ratio = float(mean_stress[d, d] / ctl.target) if ok else float("nan")
            parts.append(f"sigma_{d + 1}{d + 1}/p = {ratio:.4g}")
    return (
        f"{phase.name} did not settle within {int(phase.max_steps)} steps: {', '.join(parts)} "
        f"(mean of {window}; tolerance {phase.stop_tol:g} relative, "
        f"{phase.settle_checks} windows of {phase.check_every} steps in a row)"
    )


def _snapshot(eng: DEMEngine) -> dict:
    c = eng.contacts()
    return {
        "time": eng.step * eng.settings.dt,
        "cell": eng.cell,
        "positions": eng.x.copy(),
        "velocities": eng.v.copy(),
        "spins": eng.w.copy(),
        "contacts": c,
    }


def run_phases(
    packing: Packing,
    settings: DEMSettings,
    phases,
    out_path,
    output: OutputSettings | None = None,
    resume: bool = False,
    velocities=None,
    threads: int | None = None,
    show_progress: bool = True,
    metadata: dict | None = None,
    stop_at_step: int | None = None,
    allow_unsettled: bool = False,
    law=None,
    order: str = "code",
) -> Path:
    """Run ``phases`` one after the other from ``packing``; write ``out_path`` (kind "dem-run").

    With ``resume`` and an existing ``out_path`` of the same run (same fingerprint: packing,
    DEM settings, phases), continue from its checkpoint bit for bit; a file of another run is
    refused (:class:`ResultFileError`), and so is another sampling of the series or snapshots
    (``output.series_every`` / ``snapshot_every`` differing from the file's, :class:`InputError`)
    or another ``settings.flavour`` (LIGGGHTS' or LAMMPS' arithmetic, :class:`InputError`).
    A :class:`SimulationError` (NaN, kinetic-energy blow-up, lost particle) writes the file with
    the snapshots so far and ``stop_reason`` before it propagates.

    A phase with a stop criterion (``stop_tol`` > 0) that reaches ``max_steps`` without meeting it
    stops the run: the file is written with ``complete`` False, ``stop_reason`` ("consolidation did
    not settle within N steps: sigma_11/p = ...") and a checkpoint at that step, and
    :class:`ConvergenceError` is raised. With ``allow_unsettled`` the run goes on; the file lists
    such phases in its ``unsettled_phases`` attribute (and ``allow_unsettled`` True).

    ``stop_at_step`` ends this call at that step with a checkpoint (``complete`` False): a long
    run split into pieces, continued with ``resume``.

    ``law``: a contact-law object (:mod:`gransim.contacts.laws`) instead of the Hooke law of
    ``settings``; its class name and parameters join the settings JSON (and so the fingerprint).

    ``order``: "code" (the code's order, bit for bit with it; ``threads`` those of mode
    "parallel") or "fast" (:mod:`gransim.dem.fast` on ``threads``), recorded in the
    settings JSON (and so the fingerprint: a resume keeps the ordering) when "fast".
    """
    output = output or OutputSettings()
    if stop_at_step is not None:
        stop_at_step = as_int(stop_at_step, "stop_at_step", minimum=1)
    phases = list(phases)
    extra = dict(metadata or {})
    if law is not None:
        law_spec(law)  # InputError for an unregistered law, before any file is touched
        extra["law"] = {"name": type(law).__name__, "params": {k: float(v) for k, v in law._asdict().items()}}
    check_choice(order, "order", ORDERS)
    if order != "code":
        extra["order"] = order
    text = settings_json(settings, None, phases=[p.to_dict() for p in phases], **extra)
    fp = fingerprint(packing, text)
    out_path = Path(out_path)
    remove_stale_run_temporaries(out_path)  # of a run of this file killed while it wrote a checkpoint
    if resume and out_path.exists():
        rec = read_record(out_path)
        _check_same_flavour(out_path, rec.settings_text, settings)
        if rec.fingerprint != fp:
            raise ResultFileError(
                f"{out_path}: belongs to another run (fingerprint {rec.fingerprint[:12]} != "
                f"{fp[:12]}: different packing, settings or phases); refusing to resume"
            )
        if rec.complete:
            return out_path
        if rec.checkpoint is None:
            raise ResultFileError(f"{out_path}: no checkpoint to resume from; rerun without --resume")
        _check_same_sampling(out_path, rec.output, output)
        step = rec.checkpoint["step"]
        # the engine straight from the checkpoint (no set-up of a new engine to overwrite)
        eng = Engine.from_checkpoint(packing, settings, rec.checkpoint["arrays"], step, threads, law=law, order=order)
        state = rec.checkpoint["protocol_state"]
        rec.truncate(step)
        rec.unsettled = [u for u in rec.unsettled if u["step"] <= step]
        rec.stop_reason = ""
    else:
        eng = make_engine(packing, settings, order=order, velocities=velocities, threads=threads, law=law)
        state = {"phase": 0, "phase_step0": 0, "lo0": eng.lo.tolist(), "hi0": eng.hi.tolist(), "settled": 0}
        rec = RunRecord(packing=packing, settings_text=text, fingerprint=fp)
        _append(
            rec,
            eng,
            [0],
            eng.stress[None],
            eng.cell[None],
            [eng.n_contacts],
            [eng.mean_overlap],
            [eng.kinetic_energy()],
            0,
        )
        if output.snapshot_every:
            rec.snapshots[0] = _snapshot(eng)
    rec.output = output.to_dict()
    rec.allow_unsettled = bool(allow_unsettled)
    total = sum(p.max_steps for p in phases)
    bar = progress(total=total, desc="dem") if show_progress else None
    if bar is not None:
        bar.update(sum(p.max_steps for p in phases[: state["phase"]]) + eng.step - state["phase_step0"])
    with deferred_interrupts():
        try:
            while state["phase"] < len(phases):
                ph = phases[state["phase"]]
                lo0, hi0 = np.array(state["lo0"]), np.array(state["hi0"])
                end = state["phase_step0"] + ph.max_steps
                settled = False
                last_mean = None
                tail = None
                while eng.step < end:
                    check_interrupt()
                    nxt = [end]
                    for every in (output.snapshot_every, output.checkpoint_every):
                        if every:
                            nxt.append((eng.step // every + 1) * every)
                    if ph.stop_tol > 0:
                        nxt.append(
                            state["phase_step0"]
                            + ((eng.step - state["phase_step0"]) // ph.check_every + 1) * ph.check_every
                        )
                    if stop_at_step is not None and stop_at_step > eng.step:
                        nxt.append(int(stop_at_step))
                    stop = min(nxt)
                    out = _advance(eng, ph.loading, stop - eng.step, state["phase_step0"], (lo0, hi0))
                    tail = out["stress"]  # the last steps of the phase, for the message of an unsettled end
                    sel = out["step"] % output.series_every == 0
                    L = out["lengths"][sel]
                    cells = np.zeros((len(L), 2, 2))
                    cells[:, 0, 0], cells[:, 1, 1] = L[:, 0], L[:, 1]
                    _append(
                        rec,
                        eng,
                        out["step"][sel],
                        out["stress"][sel],
                        cells,
                        out["n_contacts"][sel],
                        out["mean_overlap"][sel],
                        out["kinetic_energy"][sel],
                        min(state["phase"], 1),
                    )
                    if bar is not None:
                        bar.update(len(out["step"]))
                    if eng.step < stop:  # _advance stopped early: SIGINT or SIGTERM
                        check_interrupt()
                    if output.snapshot_every and eng.step % output.snapshot_every == 0:
                        rec.snapshots[eng.step] = _snapshot(eng)
                    if ph.stop_tol > 0 and (eng.step - state["phase_step0"]) % ph.check_every == 0:
                        last_mean = out["stress"].mean(axis=0)
                        state["last_mean_stress"] = last_mean.tolist()
                        state["settled"] = state["settled"] + 1 if _settled(ph, last_mean) else 0
                        if state["settled"] >= ph.settle_checks:
                            settled = True
                            break
                    if output.checkpoint_every and eng.step % output.checkpoint_every == 0:
                        _checkpoint(rec, eng, state)
                        rec.stop_reason = (
                            f"run in progress, or killed: last checkpoint at step {eng.step} (continue with "
                            "resume; later checkpoints, if any, are in the .part files beside this file)"
                        )
                        write_checkpoint(out_path, rec)
                    if stop_at_step is not None and eng.step == stop_at_step:
                        _checkpoint(rec, eng, state)
                        rec.stop_reason = (
                            f"stopped at step {eng.step} by stop_at_step (a piece of a longer run; "
                            "continue with resume)"
                        )
                        write_run(out_path, rec)
                        return out_path
                if ph.stop_tol > 0 and not settled:
                    if last_mean is None and state.get("last_mean_stress") is not None:
                        last_mean = np.array(state["last_mean_stress"])  # resumed right at the phase end
                    window = "the last window"
                    if last_mean is None and tail is not None and len(tail):
                        last_mean, window = tail.mean(axis=0), f"the last {len(tail)} steps"
                        if ph.max_steps < ph.check_every:
                            window += f"; no settle check ran: max_steps {ph.max_steps} < check_every {ph.check_every}"
                    reason = _unsettled_reason(ph, last_mean, window)
                    if not allow_unsettled:
                        _checkpoint(rec, eng, state)
                        rec.stop_reason = reason + ("; pass allow_unsettled=True (--allow-unsettled) to go on anyway")
                        write_run(out_path, rec)
                        raise ConvergenceError(f"{out_path}: {rec.stop_reason}")
                    if not any(u["phase"] == state["phase"] for u in rec.unsettled):
                        rec.unsettled.append(
                            {"phase": int(state["phase"]), "name": ph.name, "step": int(eng.step), "reason": reason}
                        )
                state = {
                    "phase": state["phase"] + 1,
                    "phase_step0": eng.step,
                    "lo0": eng.lo.tolist(),
                    "hi0": eng.hi.tolist(),
                    "settled": 0,
                }
                if stop_at_step is not None and eng.step == stop_at_step and state["phase"] < len(phases):
                    _checkpoint(rec, eng, state)  # the phase ended early right at stop_at_step
                    rec.stop_reason = (
                        f"stopped at step {eng.step} by stop_at_step (a piece of a longer run; continue with resume)"
                    )
                    write_run(out_path, rec)
                    return out_path
            check_interrupt()  # a signal during the last chunk
            if eng.step not in rec.snapshots and output.snapshot_every:
                rec.snapshots[eng.step] = _snapshot(eng)
            rec.complete = True
            rec.stop_reason = ""
            _checkpoint(rec, eng, state)
            write_run(out_path, rec)  # a signal during this write abandons it: the except below
            result_written(out_path)
        except SimulationError as exc:
            rec.stop_reason = str(exc)
            write_run(out_path, rec)
            raise
        except KeyboardInterrupt as exc:
            signum = getattr(exc, "signum", 2)  # a plain KeyboardInterrupt: SIGINT's default handler
            how = exc.signal_name if isinstance(exc, Interrupted) else "SIGINT"
            rec.complete = False
            if getattr(exc, "clean", False):
                # raised by check_interrupt between two chunks of steps: the engine's state is a
                # step's end, so it is the checkpoint a resume continues from, bit for bit
                _checkpoint(rec, eng, state)
            rec.stop_reason = f"interrupted by {how} at step {eng.step}" + (
                f"; resume continues from the checkpoint at step {rec.checkpoint['step']}"
                if rec.checkpoint is not None
                else "; no checkpoint: rerun it without resume"
            )
            write_run(out_path, rec)
            raise Interrupted(signum, f"{out_path}: {rec.stop_reason} (an incomplete run file)") from None
        finally:
            if bar is not None:
                bar.close()
    return out_path


#: particle-steps of the engine between two checks for SIGINT / SIGTERM (about 0.2 s): a run
#: stops within that time of the signal
CHECK_PARTICLE_STEPS = 2_000_000


def _advance(eng: DEMEngine, loading, nsteps: int, phase_step0: int, phase_box0) -> dict:
    """``eng.advance`` of ``nsteps`` steps in pieces of about :data:`CHECK_PARTICLE_STEPS`; stops
    early (fewer steps) when SIGINT or SIGTERM arrived. The pieces do not change the trajectory
    (the engine's state carries over from one ``advance`` to the next, bit for bit)."""
    cap = max(16, CHECK_PARTICLE_STEPS // max(len(eng.x), 1))
    parts = []
    done = 0
    while done < nsteps:
        k = min(cap, nsteps - done)
        parts.append(eng.advance(loading, k, phase_step0=phase_step0, phase_box0=phase_box0))
        done += k
        if pending_interrupt() is not None:
            break
    if len(parts) == 1:
        return parts[0]
    return {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}


def _check_same_flavour(path, settings_text: str, settings: DEMSettings):
    """A resume must keep the arithmetic (``DEMSettings.flavour``) of the file it continues: a run
    half in LIGGGHTS' and half in LAMMPS' arithmetic would match neither code. A file written
    before the option existed was computed in LIGGGHTS' arithmetic."""
    try:
        stored = json.loads(settings_text).get("dem", {}).get("flavour", "liggghts")
    except (ValueError, AttributeError):
        return  # an unreadable settings text: the fingerprint check refuses the file
    if stored != settings.flavour:
        raise InputError(
            f"flavour = {settings.flavour!r} differs from flavour = {stored!r} of the run in "
            f"{path}: a resume would mix the arithmetic of two DEM codes in one run; resume "
            f"with flavour {stored!r} (or start a new file)"
        )


def _check_same_sampling(path, stored: dict | None, output: OutputSettings):
    """A resume must keep the sampling of the series and snapshots of the file it continues."""
    if not stored:
        return  # a file written before the output settings were stored: nothing to compare
    for key, opt in (("series_every", "--series-every"), ("snapshot_every", "--snapshot-every")):
        if key in stored and int(stored[key]) != int(getattr(output, key)):
            raise InputError(
                f"{key} ({opt}) = {getattr(output, key)} differs from {key} = "
                f"{int(stored[key])} of the run "
                f"in {path}: a resume would mix two samplings in one file; resume with {opt} "
                f"{int(stored[key])} (or start a new file)"
            )


def _checkpoint(rec: RunRecord, eng: DEMEngine, state: dict):
    rec.checkpoint = {
        "step": eng.step,
        "protocol_state": json.loads(json.dumps(state)),
        "arrays": {k: np.array(v) for k, v in eng.state_arrays().items()},
        "ordering": eng.order,
    }


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
