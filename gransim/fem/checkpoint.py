"""Checkpoint and resume of a slope run at each converged load step.

The checkpoint (``OUT/checkpoint/step_NNN.h5``, kind ``fem-slope-checkpoint``, one file per step) is
written atomically after every converged load step (temporary file, fsync, rename:
:func:`gransim.io.atomic_h5`), with the run's parameters as provenance. Together the files hold what
the rest of the path depends on:

* ``step``: the converged step (load, cuts, sub-increments, and its final Newton state q, u, F,
  P, sigma, W, contact counts, energy and residual norms): the outputs of a resumed run (Table 2,
  load-settlement, slope.h5, pictures) are made from these, and the path continues from the last
  one's q and load;
* ``failures/NNNN``: the failed attempts during that step (step, fraction tried, energy norms);
* ``commits`` (C, G, 2, 2): the F of the Gauss-point history commits during that step (only for a
  material with history, the relaxed RVE), and ``commit_iterates`` (E, G, 2, 2) with
  ``iterates_per_commit`` (C,): the F of every material evaluation of each committed attempt (its
  FE Newton iterates, the committed F last). Resuming replays them in order (evaluate each
  iterate, commit): a relaxed state at a commit depends only on the previous committed state and
  the F evaluated since (each iterate warm-starts from the previous one's trial,
  :class:`gransim.rve.RelaxedMaterial` ``warm_start``), so the history is restored bit for bit.
  A checkpoint without ``commit_iterates`` replays the committed F alone (exact for a material
  that starts every evaluation from its committed state).

So a resumed run is bitwise equal to an uninterrupted one (tests/cli/test_slope_resume.py). A
checkpoint written with other parameters is refused, naming the first differing parameter.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..errors import InputError, ResultFileError
from ..io import atomic_h5, open_result
from .materials import MaterialResult
from .solver import NewtonResult, ResumeState, StepRecord

KIND = "fem-slope-checkpoint"
#: the checkpoint directory inside a run's output directory: one file per converged load step
NAME = "checkpoint"


def step_path(directory, step: int) -> Path:
    """The checkpoint file of load step ``step`` in ``directory``."""
    return Path(directory) / f"step_{int(step):03d}.h5"


def _sequences(commits, G: int) -> list:
    """Each commit as its evaluation sequence (n, G, 2, 2): an item (G, 2, 2) is one evaluation."""
    out = []
    for c in commits:
        a = np.asarray(c, dtype=float)
        if a.ndim == 3:
            a = a[None]
        if a.ndim != 4 or a.shape[1:] != (G, 2, 2) or a.shape[0] < 1:
            raise InputError(f"commits: expected (G, 2, 2) or (n, G, 2, 2) arrays with G = {G}, got shape {a.shape}")
        out.append(a)
    return out


def write_checkpoint(directory, parameters: dict, record, failures: list, commits: list) -> Path:
    """Write the checkpoint of the converged step ``record`` (a StepRecord) into ``directory``:
    its state, the failed attempts of that step (``failures``: (step, fraction, energy norms)) and
    the history commits made during it (``commits``: per commit the F (G, 2, 2) committed, or the
    F (n, G, 2, 2) of every evaluation of the committed attempt, the committed F last: a
    solution's ``iterates``). One small file per step (atomic:
    temporary file, fsync, rename; the provenance carries ``parameters``), so the cost per step
    does not grow with the number of steps; a resume reads steps 1, 2, ... up to the first missing one.
    """
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    path = step_path(directory, record.step)
    with atomic_h5(path, kind=KIND, parameters=parameters) as f:
        f.attrs["step"] = record.step
        g = f.create_group("step")
        g.attrs["load"] = np.asarray(record.load, dtype=float)
        g.attrs["cuts"] = record.cuts
        g.attrs["substeps"] = np.asarray(record.substeps, dtype=float)
        s = record.solution
        for k in ("q", "u", "F", "energy_norms", "residual_norms"):
            g.create_dataset(k, data=np.asarray(getattr(s, k)))
        m = s.material
        for k in ("piola", "cauchy", "energy", "n_contacts"):
            g.create_dataset(k, data=np.asarray(getattr(m, k)))
        for n, (step, frac, enorms) in enumerate(failures):
            h = f.create_group(f"failures/{n:04d}")
            h.attrs["step"] = int(step)
            h.attrs["fraction"] = float(frac)
            h.create_dataset("energy_norms", data=np.asarray(enorms, dtype=float))
        G = s.F.shape[0]
        seqs = _sequences(commits, G)
        last = np.array([q[-1] for q in seqs]).reshape(-1, G, 2, 2)
        f.create_dataset("commits", data=last)
        every = np.concatenate(seqs) if seqs else np.zeros((0, G, 2, 2))
        f.create_dataset("commit_iterates", data=every)
        f.create_dataset("iterates_per_commit", data=np.array([len(q) for q in seqs], dtype=np.int64))
    return path


def commit_sequences(f) -> list:
    """The commits of one checkpoint file (open h5py file) as evaluation sequences (n, G, 2, 2)
    (see the module docstring; a file without ``commit_iterates``: the committed F alone)."""
    commits = f["commits"][()]
    if "commit_iterates" not in f:
        return [c[None] for c in commits]
    every, counts = f["commit_iterates"][()], f["iterates_per_commit"][()]
    ends = np.cumsum(counts)
    if len(counts) != len(commits) or (ends[-1] if len(ends) else 0) != len(every):
        raise InputError(f"--resume: {f.filename}: commit_iterates and iterates_per_commit do not match its commits")
    seqs = np.split(every, ends[:-1]) if len(counts) else []
    for q, c in zip(seqs, commits):
        if len(q) == 0 or not np.array_equal(q[-1], c):
            raise InputError(f"--resume: {f.filename}: a commit's last iterate is not its committed F")
    return seqs


def _params(f) -> dict:
    v = f.attrs.get("parameters", "{}")
    return json.loads(v.decode() if isinstance(v, bytes) else v)


def check_parameters(stored: dict, current: dict, path) -> None:
    """Refuse a checkpoint of other parameters: InputError naming the first that differs."""
    for k in sorted(set(stored) | set(current)):
        a, b = stored.get(k, "<absent>"), current.get(k, "<absent>")
        if json.dumps(a, sort_keys=True) != json.dumps(b, sort_keys=True):
            raise InputError(
                f"--resume: the checkpoint {path} was written with {k} = {a!r}, this run has "
                f"{k} = {b!r}; rerun with the checkpoint's parameters or without --resume"
            )


def clear_checkpoint(directory) -> None:
    """Remove the step files of an earlier run (a fresh run must not leave a mixed checkpoint)."""
    for p in Path(directory).glob("step_*.h5"):
        p.unlink()


def read_checkpoint(directory, parameters: dict) -> tuple[ResumeState, list]:
    """(ResumeState, commits) of the checkpoint in ``directory`` written with ``parameters``;
    commits: per commit the F (n, G, 2, 2) of its evaluations, in order (:func:`replay_history`)."""
    directory = Path(directory)
    if not step_path(directory, 1).exists():
        raise InputError(f"--resume: no checkpoint in {directory} (a run writes one after its first converged step)")
    current = json.loads(json.dumps(parameters, default=str))
    steps, failures, commits = [], [], []
    k = 1
    while step_path(directory, k).exists():
        path = step_path(directory, k)
        try:
            f = open_result(path, kind=KIND)
        except ResultFileError as exc:
            raise InputError(f"--resume: {exc}") from None
        with f:
            check_parameters(_params(f), current, path)
            g = f["step"]
            mat = MaterialResult(
                piola=g["piola"][()],
                tangent=None,
                cauchy=g["cauchy"][()],
                energy=g["energy"][()],
                n_contacts=g["n_contacts"][()],
            )
            sol = NewtonResult(
                q=g["q"][()],
                u=g["u"][()],
                F=g["F"][()],
                material=mat,
                energy_norms=g["energy_norms"][()],
                residual_norms=g["residual_norms"][()],
            )
            steps.append(
                StepRecord(
                    k,
                    tuple(float(x) for x in g.attrs["load"]),
                    sol,
                    int(g.attrs["cuts"]),
                    tuple(float(x) for x in g.attrs["substeps"]),
                )
            )
            for name in sorted(f["failures"].keys()) if "failures" in f else []:
                h = f[f"failures/{name}"]
                failures.append((int(h.attrs["step"]), float(h.attrs["fraction"]), list(h["energy_norms"][()])))
            commits.extend(commit_sequences(f))
        k += 1
    return ResumeState(steps, failures), commits


def replay_history(material, commits, every_iterate: bool = True) -> None:
    """Restore a material's Gauss-point history: per commit, evaluate at each of its F in order
    (an item (n, G, 2, 2): its iterates; (G, 2, 2): the committed F alone), then commit.
    ``every_iterate`` False evaluates only the committed F of each: enough, and exact, for a
    material that starts every evaluation from its committed state (the relaxed RVE's default
    ``warm_start="committed"``)."""
    if not callable(getattr(material, "commit", None)):
        return
    for seq in commits:
        seq = np.asarray(seq, dtype=float)
        seq = seq[None] if seq.ndim == 3 else seq
        for F in seq if every_iterate else seq[-1:]:
            material.evaluate(np.ascontiguousarray(F))
        material.commit()


__all__ = [
    "KIND",
    "NAME",
    "check_parameters",
    "clear_checkpoint",
    "commit_sequences",
    "read_checkpoint",
    "replay_history",
    "step_path",
    "write_checkpoint",
]
