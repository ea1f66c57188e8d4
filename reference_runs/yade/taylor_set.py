"""The Taylor states of several packings through YADE, compared and stored: ``gransim reference
taylor --engine yade``.

One YADE job per packing (:func:`reference_runs.yade.taylor.run_yade_taylor`, reused when complete
and verified); per packing the largest relative difference of YADE's two stresses from the
independent numpy Taylor stress (:func:`reference_runs.cases.compare_taylor`, as for LIGGGHTS and
LAMMPS, tolerance :data:`reference_runs.cases.TAYLOR_RTOL`) and of YADE's tangent from the
material part of gransim's (:func:`reference_runs.yade.compare.compare_yade_taylor`, tolerance
:data:`reference_runs.yade.compare.TANGENT_RTOL`), with the contacts of both sides matched; all
runs stored in one HDF5 file by :func:`reference_runs.taylor.write_taylor_h5` (the schema of the
other two codes, ``engine`` = ``yade``, the YADE version in the root attributes).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from gransim.paper import KN_2D
from gransim.progress import progress as _progress
from gransim.rve import TaylorMaterial

from ..cases import compare_taylor
from ..decks.taylor import PATHS
from ..judge import JudgeError
from ..taylor import write_taylor_h5
from .compare import TANGENT_RTOL, compare_yade_taylor
from .taylor import as_taylor_run, run_yade_taylor


@dataclass(frozen=True)
class YadeTaylorSet:
    """What :func:`run_yade_taylor_set` found.

    Attributes
    ----------
    runs : the :class:`reference_runs.taylor.TaylorRun` of every packing (``engine="yade"``).
    stress : largest relative difference of YADE's stresses from numpy's over all packings and
        states (NaN when a packing could not be judged: its reason was echoed).
    tangent : the same for the tangent against gransim's material part.
    contacts_match : every state of every packing has the same contacts on both sides.
    h5 : the HDF5 file written.
    """

    runs: tuple
    stress: float
    tangent: float
    contacts_match: bool
    h5: Path


def run_yade_taylor_set(
    packings: dict,
    out_dir,
    kn: float = KN_2D,
    n_steps: int = 50,
    stride: int = 1,
    max_strain: float = 0.1,
    timeout=3600.0,
    force: bool = False,
    h5_name: str = "taylor.h5",
    echo=print,
) -> YadeTaylorSet:
    """Run (or reuse) one YADE Taylor job per packing (``out_dir/jobs/<name>``), compare, write
    ``out_dir/<h5_name>``. Raises :class:`~reference_runs.errors.ReferenceRunError` when a job
    fails (the binary missing, a non-zero exit, a timeout, incomplete output)."""
    out_dir = Path(out_dir)
    runs, w_stress, w_tangent, contacts_ok = [], 0.0, 0.0, bool(packings)
    for name, packing in _progress(list(packings.items()), desc="packings"):
        yrun = run_yade_taylor(
            packing,
            kn,
            out_dir / "jobs" / name,
            paths=PATHS,
            n_steps=n_steps,
            max_strain=max_strain,
            stride=stride,
            name=name,
            timeout=timeout,
            force=force,
        )
        run = as_taylor_run(yrun, name)
        runs.append(run)
        head = f"{name}: N = {packing.n}, {len(yrun.states)} states ({yrun.manifest.get('elapsed_s', 0):.2f} s)"
        try:
            s = max(compare_taylor(run).values())
            cmp = compare_yade_taylor(yrun, TaylorMaterial(packing, kn))
            t = float(cmp.tangent.max())
        except JudgeError as exc:  # NaN/inf on either side, no state: a failure, named
            w_stress = w_tangent = math.nan
            echo(f"{head}: FAIL: {exc}")
            continue
        if not cmp.contacts_match:
            contacts_ok = False
            echo(
                f"{head}: FAIL: contacts differ ({int(cmp.unmatched_gransim.sum())} of gransim's and "
                f"{int(cmp.unmatched_yade.sum())} of YADE's without a partner)"
            )
        if not math.isnan(w_stress):
            w_stress, w_tangent = max(w_stress, s), max(w_tangent, t)
        echo(f"{head}, max rel. diff: stress vs numpy {s:.3e}, tangent vs gransim's material part {t:.3e}")
    if not runs:
        w_stress = w_tangent = math.nan
        echo("no packings: nothing was compared (FAIL)")
    h5 = write_taylor_h5(
        out_dir / h5_name,
        runs,
        parameters={
            "kn": kn,
            "n_steps": n_steps,
            "stride": stride,
            "max_strain": max_strain,
            "packings": list(packings),
            "engine": "yade",
            "tangent_rtol": TANGENT_RTOL,
        },
    )
    echo(f"wrote {h5}")
    return YadeTaylorSet(tuple(runs), w_stress, w_tangent, contacts_ok, h5)


__all__ = ["YadeTaylorSet", "run_yade_taylor_set"]
