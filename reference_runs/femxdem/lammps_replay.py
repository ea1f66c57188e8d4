"""A Gauss point's strain history replayed in LAMMPS 29 Sep 2021 on the RVE of
:mod:`gransim.fem.lammps_rve`: one ``run`` per increment under its ``fix deform ... remap x``
(:func:`reference_runs.decks.shear.sequence_deck_text`), the state after each run written by
``write_dump`` and the box and virial stress by the thermo of the run's last step. The native
side is :meth:`gransim.fem.lammps_rve.LammpsRVE.replay`; the two agree to round-off (the sheared
cell's standard: docs/shear.md), tests/fem/test_lammps_gauss_point.py."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gransim.errors import InputError
from gransim.fem.lammps_rve import THICKNESS, LammpsRVE
from gransim.io import atomic_path
from reference_runs.datafile import write_data_file
from reference_runs.decks.shear import DATA, DECK, call_dump, read_dump, sequence_deck_text
from reference_runs.errors import ReferenceRunError
from reference_runs.parsers import parse_log
from reference_runs.runner import run_job

#: thermo columns of the deck (compute pt: the virial stress, compression positive, N/m)
_COLUMNS = {"lx": "Lx", "ly": "Ly", "xy": "Xy", "xlo": "Xlo", "ylo": "Ylo", "sxx": "c_pt[1]", "syy": "c_pt[2]",
            "sxy": "c_pt[4]"}  # fmt: skip


def write_replay_job(job_dir, rve: LammpsRVE, increments) -> tuple[Path, list]:
    """Deck and data file of the replay of ``increments`` (K, 2, 2) in ``job_dir``; returns the
    deck and the (ShearLoading, ns) of each call."""
    inc = np.asarray(increments, np.float64).reshape(-1, 2, 2)
    if inc.shape[0] < 1:
        raise InputError("increments: expected at least one (2, 2) strain increment")
    runs = [rve.call(D) for D in inc]
    job = Path(job_dir)
    job.mkdir(parents=True, exist_ok=True)
    write_data_file(job / DATA, rve.packing, wrap=False)
    deck = job / DECK
    with atomic_path(deck) as tmp:
        Path(tmp).write_text(sequence_deck_text(rve.packing, rve.settings, runs))
    return deck, runs


def replay_in_lammps(job_dir, rve: LammpsRVE, increments, timeout: float | None = 600.0) -> list[dict]:
    """Run the replay with LAMMPS (:func:`reference_runs.runner.run_job`: process group, time-out,
    every call's dump required; a ``run`` missing is a :class:`ReferenceRunError`); the set-up
    state and the state after each call as :meth:`~gransim.fem.lammps_rve.LammpsRVE.replay` gives
    them (positions, velocities, spins, forces, torques, box, stress in Pa tension positive, steps)."""
    deck, runs = write_replay_job(job_dir, rve, increments)
    job = deck.parent
    dumps = tuple(call_dump(k) for k in range(len(runs) + 1))
    res = run_job(
        job, deck.read_text(), files={DATA: (job / DATA).read_bytes()}, np=1, timeout=timeout, outputs=dumps,
        expected_runs=len(runs) + 1, progress=False, force=True, engine="lammps",
    )  # fmt: skip
    log = parse_log(Path(res.log_path))
    if len(log.runs) != len(runs) + 1:
        raise ReferenceRunError(f"{res.log_path}: {len(log.runs)} runs in the log, the deck has {len(runs) + 1}")
    out = []
    for k, (ns, run) in enumerate(zip([0] + [n for _, n in runs], log.runs, strict=True)):
        th = {key: float(run.column(name)[-1]) for key, name in _COLUMNS.items()}
        frames = read_dump(job / call_dump(k))
        fr = frames[max(frames)]
        box = np.array([th["xlo"], th["ylo"], th["xlo"] + th["lx"], th["ylo"] + th["ly"], th["xy"]])
        sig = -np.array([[th["sxx"], th["sxy"]], [th["sxy"], th["syy"]]]) / THICKNESS
        out.append(
            {
                "positions": np.stack([fr["x"], fr["y"]], 1),
                "velocities": np.stack([fr["vx"], fr["vy"]], 1),
                "spins": np.asarray(fr["omegaz"]),
                "forces": np.stack([fr["fx"], fr["fy"]], 1),
                "torques": np.asarray(fr["tqz"]),
                "box": box,
                "stress": sig,
                "steps": ns,
                "lx_ly_xy": np.array([th["lx"], th["ly"], th["xy"]]),
            }
        )
    return out
