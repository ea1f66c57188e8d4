"""``gransim femxdem``: the biaxial specimen of Guo & Zhao's FEM x DEM benchmark, run end to end.

The Gauss points hold Guo & Zhao's periodic 400-disk DEM RVE in YADE's arithmetic (``rve="dem"``,
:class:`gransim.fem.dem_rve.DemRVE`) or a *stand-in* point law (:data:`RVE_STANDINS`):

* ``taylor``: the affine Taylor RVE of Meier, Steinmann & Kuhl (:class:`gransim.rve.TaylorMaterial`,
  the most uniform standard 700-disk RVE, kn of the slope) as a hyperelastic point law whose state
  is the total F (:class:`gransim.fem.point_laws.HyperelasticPoint`), first compressed isotropically
  to F0 = s 1 with mean Cauchy stress -p (the confining pressure; s by bisection), as Guo & Zhao
  consolidate their RVEs to 100 kPa before the test;
* ``j2``: plane-strain von Mises plasticity (:class:`gransim.fem.point_laws.J2Plasticity`,
  E = 1e8 Pa, nu = 0.3, yield 1.5e5 Pa, hardening 1e6 Pa, initial stress -p), with the 4 Gauss
  points of the element at the specimen's centre 10 % weaker.

Neither is a granular law with friction; they exercise the machinery (stateful Gauss points,
Dask, checkpoints) through the point-law interface the DEM RVE uses (:mod:`gransim.fem.material_points`).

Outputs in ``out``: ``femxdem.h5`` (kind ``fem-biaxial``: per step the curves and Newton's
history; the final configuration and Gauss-point fields; the parameters as provenance),
``curves.png`` (deviatoric stress and volumetric strain against axial strain), ``report.md``
(the curves first, then the maps); at each field step K (``field_steps``) the Gauss-point fields
(deviatoric strain; void ratio and mean particle rotation of the DEM RVE) in ``femxdem.h5``
``fields/step_K``, ``maps_K.png``, ``mesh_K.vtu`` and pictures of chosen RVEs
(:mod:`gransim.fem.output_femxdem`);
``checkpoint/`` holds one small file per converged step (``step_NNN.h5``: its record) and the
committed Gauss-point states of the last one (``states_NNN.h5``, the previous one removed after
the next is written), so ``resume`` continues bit for bit as the uninterrupted run
(tests/fem/test_femxdem.py).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from ..errors import GransimError, InputError, ResultFileError
from ..io import atomic_h5, atomic_text, open_result
from ..progress import (
    Interrupted,
    check_interrupt,
    deferred_interrupts,
    pending_interrupt,
    progress,
    result_written,
)
from .biaxial import BiaxialSpec, BiaxialStep, biaxial_setup, run_biaxial
from .checkpoint import check_parameters
from .incremental import StepFailure
from .material_points import gauss_points
from .output_femxdem import not_available
from .point_laws import HyperelasticPoint, J2Plasticity

RVE_STANDINS = ("taylor", "j2")
#: the DEM RVEs: Guo & Zhao's RVE in YADE's arithmetic (``dem``, gransim.fem.dem_rve) and the same
#: disks with LAMMPS' gran/hooke/history law in LAMMPS' arithmetic (``dem-lammps``, gransim.fem.lammps_rve)
RVE_DEM = ("dem", "dem-lammps")
#: every ``rve``: the DEM RVEs and the stand-ins
RVE_LAWS = (*RVE_DEM, *RVE_STANDINS)
KIND = "fem-biaxial"
CKPT_STEP = "fem-biaxial-step"
CKPT_STATES = "fem-biaxial-states"


class FemxdemInterrupted(GransimError):
    """The run stopped on purpose after a load step (``stop_after``), its checkpoint written."""

    def __init__(self, step: int, out):
        super().__init__(
            f"stopped after load step {step} as asked (--stop-after); its checkpoint is "
            f"{Path(out) / 'checkpoint'}: continue with --resume"
        )
        self.step = step


def _centre_points(spec: BiaxialSpec) -> tuple:
    """The Gauss points of the element containing the specimen's centre (row-major elements)."""
    e = (spec.ny // 2) * spec.nx + spec.nx // 2
    k = spec.gauss**2
    return tuple(range(e * k, (e + 1) * k))


def tangent_parameters(rve: str, tangent: str | None = None, step: float | None = None) -> dict:
    """The tangent of the run's Gauss points as recorded (provenance, the --resume fingerprint):
    ``{"kind": "contact"}`` (Guo & Zhao's eq. 10, the DEM RVEs' default), ``{"kind":
    "perturbation", "step": h}`` (:mod:`gransim.fem.perturbation`), or ``{"kind": "law"}`` (a
    stand-in's own exact tangent); refuses a tangent choice for a stand-in."""
    if tangent is None:
        return {"kind": "contact"} if rve in RVE_DEM else {"kind": "law"}
    from .perturbation import DEFAULT_STEP, TANGENTS  # noqa: PLC0415 - start-up: numpy

    if tangent not in TANGENTS:
        raise InputError(f"--tangent: expected one of {', '.join(TANGENTS)}, got {tangent!r}")
    if rve in RVE_STANDINS:
        raise InputError(
            f"--tangent: applies to the DEM RVEs ({', '.join(RVE_DEM)}); the stand-in {rve} has its exact tangent"
        )
    if tangent == "contact":
        if step is not None:
            raise InputError("--tangent-step: applies to --tangent perturbation only")
        return {"kind": "contact"}
    return {"kind": "perturbation", "step": float(DEFAULT_STEP if step is None else step)}


def _stored_tangent(stored: dict) -> dict:
    """The tangent a checkpoint's parameters record (written before the choice existed: the law's default)."""
    return stored.get("tangent") or tangent_parameters(stored.get("rve", ""))


def standin_law(rve: str, spec: BiaxialSpec, packing=None, packing_dir="results/packings"):
    """(point law, parameters dict) of ``rve`` (module docstring; ``dem``: :class:`gransim.fem.dem_rve.DemRVE`
    with the RVE prepareRVE.py prepared in YADE 2023.02a; ``dem-lammps``: :class:`gransim.fem.lammps_rve.
    LammpsPointLaw` with the same disks and cell and LAMMPS' law, :meth:`gransim.fem.lammps_rve.LammpsRVE.
    guo_zhao`)."""
    if rve not in RVE_LAWS:
        raise InputError(f"--rve: expected one of {', '.join(RVE_LAWS)}, got {rve!r}")
    if rve == "dem":
        from .dem_rve import PREPARED_RVE, DemRVE  # noqa: PLC0415 - start-up: numba

        law = DemRVE.prepared()
        return law, {"law": "DemRVE", "rve": PREPARED_RVE.name, "provenance": json.dumps(law.provenance)}
    if rve == "dem-lammps":
        from .dem_rve import PREPARED_RVE, load_rve_state  # noqa: PLC0415 - start-up: numba
        from .lammps_rve import DAMPING_RATIO, STEPS_PER_CONTACT, LammpsPointLaw, LammpsRVE  # noqa: PLC0415 - start-up: numba

        state, prov = load_rve_state()
        rv = LammpsRVE.guo_zhao(state)
        st = rv.settings
        return LammpsPointLaw(rv), {
            "law": "LammpsPointLaw", "rve": PREPARED_RVE.name, "provenance": json.dumps(prov),
            "settings": json.dumps(st.to_dict(), sort_keys=True), "damping_ratio": DAMPING_RATIO,
            "steps_per_contact": STEPS_PER_CONTACT, "density": float(rv.packing.density),
        }  # fmt: skip
    if rve == "j2":
        law = J2Plasticity(1e8, 0.3, 1.5e5, 1e6, -spec.pressure, weak_points=_centre_points(spec), weak_factor=0.9)
        return law, {"law": "J2Plasticity", "E": 1e8, "nu": 0.3, "yield": 1.5e5, "hardening": 1e6, "weak_factor": 0.9}
    from scipy.optimize import brentq  # noqa: PLC0415 - start-up: scipy

    from ..io import load_packing  # noqa: PLC0415 - start-up: h5py
    from ..rve import TaylorMaterial  # noqa: PLC0415 - start-up: numba
    from .materials import RVEMaterial  # noqa: PLC0415 - start-up: numpy
    from .run import default_rve_packing, packings_fingerprint  # noqa: PLC0415 - start-up: matplotlib
    from .slope import NORMAL_STIFFNESS  # noqa: PLC0415 - start-up: numpy

    if packing is None:
        packing = default_rve_packing(packing_dir)
    elif isinstance(packing, (str, Path)):
        packing = load_packing(packing)
    mat = RVEMaterial(TaylorMaterial(packing, NORMAL_STIFFNESS))

    def mean_stress(s):
        c = mat.evaluate((s * np.eye(2))[None]).cauchy[0]
        return 0.5 * (c[0, 0] + c[1, 1]) + spec.pressure

    lo, hi = 0.9, 1.05
    if not mean_stress(lo) < 0 < mean_stress(hi):
        raise InputError(
            f"--rve taylor: the RVE does not reach a mean stress of -{spec.pressure:g} Pa for F = s 1, "
            f"s in [{lo}, {hi}]"
        )
    s0 = brentq(mean_stress, lo, hi, xtol=1e-15, rtol=1e-15)
    params = {
        "law": "HyperelasticPoint(TaylorMaterial)",
        "normal_stiffness": NORMAL_STIFFNESS,
        "packing": packings_fingerprint([packing]),
        "n_particles": len(packing.radii),
        "consolidation_stretch": float(s0),
    }
    return HyperelasticPoint(mat, s0 * np.eye(2)), params


# ---------------------------------------------------------------------- checkpoint


def _step_path(d: Path, k: int) -> Path:
    return d / f"step_{k:03d}.h5"


def _states_path(d: Path, k: int) -> Path:
    return d / f"states_{k:03d}.h5"


_RECORD_ARRAYS = ("x", "stress", "F", "strain", "errors", "residuals")
_RECORD_SCALARS = ("axial_strain", "deviatoric_stress", "volumetric_strain", "wall_s", "material_s")


def write_step(d: Path, params: dict, rec: BiaxialStep, law, points, states=None, fields=None) -> None:
    """Checkpoint of converged step ``rec``: its record (and, at a field step, its Gauss-point
    ``fields`` (:func:`field_record`)), then the committed states ``states`` (default: fetched
    from ``points``) and their stress and tangent; the previous step's states file is removed
    once both are written."""
    d.mkdir(parents=True, exist_ok=True)
    with atomic_h5(_step_path(d, rec.step), kind=CKPT_STEP, parameters=params) as f:
        f.attrs["step"] = rec.step
        for k in _RECORD_ARRAYS:
            f.create_dataset(k, data=np.asarray(getattr(rec, k)))
        for k in _RECORD_SCALARS:
            f.attrs[k] = float(getattr(rec, k))
        if fields is not None:
            _write_field_record(f.create_group("fields"), fields)
    if states is None:
        states = points.states()
    sigma, T = points.committed_response()
    with atomic_h5(_states_path(d, rec.step), kind=CKPT_STATES, parameters=params) as f:
        f.attrs["step"] = rec.step
        f.create_dataset("stress", data=sigma)
        f.create_dataset("tangent", data=T)
        g = f.create_group("states")
        for k, v in law.pack_states(states).items():
            g.create_dataset(k, data=v)
    old = _states_path(d, rec.step - 1)
    if old.exists():
        old.unlink()


def field_record(rec: BiaxialStep, observables: dict, states, pictures, law=None) -> dict:
    """The Gauss-point fields of field step ``rec`` (:mod:`gransim.fem.output_femxdem`):
    ``deviatoric_strain`` (G,), ``void_ratio`` and ``rotation`` (G,) when the law reports them (the
    DEM RVE), and ``pictures`` {Gauss point: RVE snapshot} of the points ``pictures`` (None: the
    most strained point; ``law.snapshot(state)`` where the law has it, the LAMMPS RVE's, else
    :func:`gransim.fem.output_femxdem.rve_snapshot`; the states of a stand-in give none)."""
    from .output_femxdem import deviatoric_strain, rve_snapshot  # noqa: PLC0415 - start-up: numpy

    out = {"deviatoric_strain": deviatoric_strain(rec.strain)}
    for k in ("void_ratio", "rotation"):
        if k in observables:
            out[k] = np.asarray(observables[k], float)
    if pictures is None:
        pictures = (int(np.argmax(out["deviatoric_strain"])),)
    snaps = {}
    for g in pictures:
        snap = None
        if states is not None:
            fn = getattr(law, "snapshot", None)  # a law that knows its grains (the LAMMPS RVE), else the state's
            snap = fn(states[g]) if callable(fn) else rve_snapshot(states[g])
        if snap is not None:
            snaps[int(g)] = snap
    out["pictures"] = snaps
    return out


def _write_field_record(g, fields: dict) -> None:
    for k, v in fields.items():
        if k != "pictures":
            g.create_dataset(k, data=v)
    pics = g.create_group("pictures")
    for gp, snap in fields["pictures"].items():
        h = pics.create_group(f"gp_{gp:05d}")
        for k, v in snap.items():
            h.create_dataset(k, data=v, compression="gzip")


def _read_field_record(g) -> dict:
    out = {k: g[k][()] for k in g if k != "pictures"}
    out["pictures"] = {int(n[3:]): {k: h[k][()] for k in h} for n, h in g["pictures"].items()}
    return out


def _params_of(f) -> dict:
    v = f.attrs.get("parameters", "{}")
    return json.loads(v.decode() if isinstance(v, bytes) else v)


def _stored_params(f) -> dict:
    """A checkpoint file's parameters, the tangent filled in for one written before it was recorded."""
    p = _params_of(f)
    p["tangent"] = _stored_tangent(p)
    return p


def _tangent_option(t: dict) -> str:
    return f"--tangent {t['kind']}" + (f" --tangent-step {t['step']:g}" if "step" in t else "")


def read_checkpoint(d: Path, params: dict, law, fields: dict | None = None):
    """(records [BiaxialStep], states, (stress, tangent)) of the checkpoint in ``d``: the steps
    1..k whose files are present, k the last step with its states file; refuses other parameters.
    ``fields``: filled with {step: field record} of the field steps among them."""
    current = json.loads(json.dumps(params, default=str))
    recs = []
    k = 1
    while _step_path(d, k).exists():
        path = _step_path(d, k)
        try:
            f = open_result(path, kind=CKPT_STEP)
        except ResultFileError as exc:
            raise InputError(f"--resume: {exc}") from None
        with f:
            check_parameters(_stored_params(f), current, path)
            arrays = {n: f[n][()] for n in _RECORD_ARRAYS}
            scalars = {n: float(f.attrs[n]) for n in _RECORD_SCALARS}
            recs.append(BiaxialStep(step=k, **arrays, **scalars))
            if fields is not None and "fields" in f:
                fields[k] = _read_field_record(f["fields"])
        k += 1
    while recs and not _states_path(d, recs[-1].step).exists():  # killed between the two writes
        recs.pop()
    if not recs:
        raise InputError(f"--resume: no checkpoint in {d} (a run writes one after its first converged step)")
    if fields is not None:
        for k in [k for k in fields if k > recs[-1].step]:
            del fields[k]
    path = _states_path(d, recs[-1].step)
    try:
        f = open_result(path, kind=CKPT_STATES)
    except ResultFileError as exc:
        raise InputError(f"--resume: {exc}") from None
    with f:
        check_parameters(_stored_params(f), current, path)
        states = law.unpack_states({n: f["states"][n][()] for n in f["states"]})
        response = (f["stress"][()], f["tangent"][()])
    return recs, states, response


def check_resumable(
    out, spec: BiaxialSpec, rve: str, options: dict | None = None, tangent: str | None = None,
    tangent_step: float | None = None,
) -> int:  # fmt: skip
    """The last step of the checkpoint in ``out/checkpoint`` that ``resume`` continues, checked
    before any computation: a step file and the states of a step are there, and they were written
    with ``spec``, ``rve`` and the tangent (``tangent``, ``tangent_step``: a Newton history made
    with one tangent does not continue with another; ``options``: the command-line option of each
    ``spec`` field, named in the error). The stand-in's own parameters (the Taylor RVE's packing and consolidation) are
    compared when the run reads the checkpoint (:func:`read_checkpoint`)."""
    d = Path(out) / "checkpoint"
    options = options or {}
    if not _step_path(d, 1).exists():
        raise InputError(f"--resume: no checkpoint in {d} (a run writes one after its first converged step)")
    path = _step_path(d, 1)
    try:
        f = open_result(path, kind=CKPT_STEP)
    except ResultFileError as exc:
        raise InputError(f"--resume: {exc}") from None
    with f:
        stored = _params_of(f)
    if stored.get("rve") != rve:
        raise InputError(
            f"--resume: the checkpoint {path} was written with --rve {stored.get('rve')}, this run has --rve {rve}"
        )
    old_t, new_t = _stored_tangent(stored), tangent_parameters(rve, tangent, tangent_step)
    if json.dumps(old_t, sort_keys=True) != json.dumps(new_t, sort_keys=True):
        raise InputError(
            f"--resume: the checkpoint {path} was written with {_tangent_option(old_t)}, this run has "
            f"{_tangent_option(new_t)}: a run continues with its own tangent; rerun with {_tangent_option(old_t)} "
            "or without --resume"
        )
    current = json.loads(json.dumps(spec.as_dict()))
    for k, v in current.items():
        old = stored.get("spec", {}).get(k, "<absent>")
        if json.dumps(old) != json.dumps(v):
            opt = options.get(k, k)
            raise InputError(
                f"--resume: the checkpoint {path} was written with {opt} {old} ({k}), this run has {opt} {v}; "
                "rerun with the checkpoint's parameters or without --resume"
            )
    k = 1
    while _step_path(d, k + 1).exists():
        k += 1
    while k >= 1 and not _states_path(d, k).exists():  # killed between a step's two writes
        k -= 1
    if k < 1:
        raise InputError(f"--resume: the checkpoint in {d} holds no committed Gauss-point states (states_NNN.h5)")
    return k


def clear_checkpoint(d: Path) -> None:
    """Remove an earlier run's checkpoint files."""
    for p in list(d.glob("step_*.h5")) + list(d.glob("states_*.h5")):
        p.unlink()


# ---------------------------------------------------------------------- outputs


def plot_curves(path: Path, recs: list, spec: BiaxialSpec, label: str) -> Path:
    """Deviatoric stress and volumetric strain against axial strain (two panels)."""
    import matplotlib  # noqa: PLC0415 - start-up: matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415 - start-up: matplotlib

    ea = np.array([0.0] + [r.axial_strain for r in recs]) * 100
    q = np.array([np.nan] + [r.deviatoric_stress for r in recs]) / 1e3
    ev = np.array([0.0] + [r.volumetric_strain for r in recs]) * 100
    fig, ax = plt.subplots(1, 2, figsize=(9, 3.6))
    ax[0].plot(ea, q, "o-", ms=2)
    ax[0].set_xlabel("axial strain (%)")
    ax[0].set_ylabel("q = sigma_1 - sigma_3 (kPa)")
    ax[1].plot(ea, ev, "o-", ms=2)
    ax[1].set_xlabel("axial strain (%)")
    ax[1].set_ylabel("volumetric strain (%, dilation +)")
    fig.suptitle(f"biaxial {spec.nx} x {spec.ny} {spec.element}, p = {spec.pressure / 1e3:g} kPa, {label}")
    fig.tight_layout()
    from ..io import atomic_path  # noqa: PLC0415 - start-up: h5py

    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)
    return path


def write_results(
    path: Path, params: dict, recs: list, observables: dict, stopped: str = "", fields=None, setup=None
) -> Path:
    """``femxdem.h5``: curves and Newton history per step, final fields, and at each field step
    (``fields`` {step: :func:`field_record`}) the mesh and Gauss-point fields under
    ``fields/step_NNN`` (docs/femxdem.md); ``stopped``: why the run stopped before its last step
    ("" when it completed)."""
    by_step = {r.step: r for r in recs}
    with atomic_h5(path, kind=KIND, parameters=params) as f:
        f.attrs["completed"] = not stopped
        f.attrs["stopped"] = stopped
        c = f.create_group("curves")
        c.create_dataset("step", data=np.array([r.step for r in recs], dtype=np.int64))
        for k in ("axial_strain", "deviatoric_stress", "volumetric_strain", "wall_s", "material_s"):
            c.create_dataset(k, data=np.array([getattr(r, k) for r in recs]))
        c.create_dataset("newton_iterations", data=np.array([len(r.errors) for r in recs], dtype=np.int64))
        n = f.create_group("newton")
        for r in recs:
            g = n.create_group(f"{r.step:03d}")
            g.create_dataset("errors", data=r.errors)
            g.create_dataset("residuals", data=r.residuals)
        if recs:
            last = recs[-1]
            fin = f.create_group("final")
            fin.attrs["step"] = last.step
            for k in ("x", "stress", "F", "strain"):
                fin.create_dataset(k, data=getattr(last, k))
            for k, v in observables.items():
                fin.create_dataset(f"observables/{k}", data=v)
        if fields:
            top = f.create_group("fields")
            if setup is not None:
                top.create_dataset("X", data=setup.problem.mesh.nodes)
                top.create_dataset("elements", data=setup.problem.mesh.elements)
                top.attrs["element"] = setup.problem.mesh.element
                top.attrs["gauss"] = setup.spec.gauss
            top.attrs["not_available"] = ", ".join(
                k for k in ("void_ratio", "rotation") if k not in fields[min(fields)]
            )
            top.attrs["not_available_reason"] = (
                not_available(params.get("rve", "")) if top.attrs["not_available"] else ""
            )
            for k in sorted(fields):
                g = top.create_group(f"step_{k:03d}")
                g.attrs["step"] = k
                if k in by_step:
                    g.create_dataset("x", data=by_step[k].x)
                    g.create_dataset("stress", data=by_step[k].stress)
                    g.create_dataset("strain", data=by_step[k].strain)
                _write_field_record(g, fields[k])
    return path


def write_field_outputs(out: Path, setup, recs: list, fields: dict, label: str) -> dict:
    """Per field step: ``maps_NNN.png`` (deviatoric strain, void ratio, rotation on the deformed
    mesh), ``mesh_NNN.vtu`` and ``rve_NNN_gGGGGG.png`` per pictured Gauss point; {name: path}."""
    from .output_femxdem import plot_maps, plot_rve, write_vtu  # noqa: PLC0415 - start-up: matplotlib

    mesh, spec = setup.problem.mesh, setup.spec
    by_step = {r.step: r for r in recs}
    files = {}
    for k in sorted(fields):
        rec, fl = by_step.get(k), fields[k]
        if rec is None:
            continue
        gfields = {n: v for n, v in fl.items() if n != "pictures"}
        ea = 100 * rec.axial_strain
        files[f"maps_{k:03d}"] = plot_maps(
            out / f"maps_{k:03d}.png", mesh, rec.x, spec.gauss, gfields,
            f"step {k}, axial strain {ea:.2f} %, {label} (deformed mesh, true scale)", not_available(label),
        )  # fmt: skip
        files[f"vtu_{k:03d}"] = write_vtu(out / f"mesh_{k:03d}.vtu", mesh, mesh.nodes, rec.x, spec.gauss, gfields,
                                          rec.stress, rec.strain)  # fmt: skip
        for g, snap in fl["pictures"].items():
            files[f"rve_{k:03d}_{g}"] = plot_rve(
                out / f"rve_{k:03d}_g{g:05d}.png", snap,
                f"Gauss point {g}, step {k} (axial strain {ea:.2f} %), deviatoric strain "
                f"{fl['deviatoric_strain'][g]:.3g}",
            )  # fmt: skip
    return files


def field_report(out: Path | None, fields: dict, recs: list, rve: str = "") -> list:
    """Markdown lines of the maps section: per field step the range of each field and the pictures."""
    by_step = {r.step: r for r in recs}
    lines = ["", "### Maps (deformed mesh, each Gauss point's sub-cell coloured by its value)", ""]
    for k in sorted(fields):
        if k not in by_step:
            continue
        fl = fields[k]
        parts = []
        for n in ("deviatoric_strain", "void_ratio", "rotation"):
            if n in fl:
                v = np.asarray(fl[n])
                parts.append(f"{n.replace('_', ' ')} {v.min():.4g} to {v.max():.4g}")
            else:
                parts.append(f"{n.replace('_', ' ')} n/a ({not_available(rve)})")
        lines.append(f"- step {k} (axial strain {100 * by_step[k].axial_strain:.2f} %): " + "; ".join(parts))
        if out is not None:
            lines.append(f"  ![maps at step {k}](maps_{k:03d}.png) VTU: `mesh_{k:03d}.vtu`")
            for g in fl["pictures"]:
                lines.append(f"  ![RVE of Gauss point {g} at step {k}](rve_{k:03d}_g{g:05d}.png)")
    if any("rotation" in fields[k] for k in fields):
        lines.append(
            "- the rotation is each disk's spin dt summed over every DEM step of its RVE's calls, the angle "
            "YADE turns State::ori by (gransim.dem.yade_arithmetic.rve_run_rotation; docs/femxdem.md, "
            "'The disk rotation')"
        )
    return lines


def _law_time_lines(timing: list, wall: float) -> list:
    """The report's line on the time in the point law (:meth:`GaussChunk.timing` per chunk): its
    wall and CPU seconds summed over the chunks, per call, and its share of (chunks x ``wall``),
    the rest being the FE work, Dask, serialisation, outputs and idle chunks."""
    calls = sum(t["law_calls"] for t in timing)
    if not calls or wall <= 0:
        return []
    law_s = sum(t["law_s"] for t in timing)
    cpu_s = sum(t["law_cpu_s"] for t in timing)
    share = law_s / (len(timing) * wall)
    return [
        f"- point law: {calls} updates in {law_s:.1f} s summed over {len(timing)} chunk(s) (CPU {cpu_s:.1f} s; "
        f"{1e3 * law_s / calls:.2f} ms, CPU {1e3 * cpu_s / calls:.2f} ms an update): {100 * share:.1f} % of "
        f"chunks x wall, the rest (FE, Dask, outputs, idle chunks) {100 * (1 - share):.1f} %"
    ]


_TITLES = {
    "dem": "## FEM x DEM biaxial specimen (Guo & Zhao's DEM RVE, YADE's arithmetic)",
    "dem-lammps": "## FEM x DEM biaxial specimen (Guo & Zhao's RVE with LAMMPS' gran/hooke/history law, LAMMPS' "
    "arithmetic)",
}
_TANGENT_LABELS = {
    "contact": "contact stiffness (Guo & Zhao's eq. 10)",
    "perturbation": "perturbation, the central difference of the RVE calls from the committed state "
    "(gransim.fem.perturbation)",
    "law": "the stand-in's exact tangent",
}


def _lost_to_a_signal(exc: BaseException) -> bool:
    """Whether ``exc`` (not itself an interrupt) came after SIGINT/SIGTERM/SIGHUP arrived: the
    workers that received the signal too are gone, and their calls fail."""
    return not isinstance(exc, (KeyboardInterrupt, SystemExit)) and pending_interrupt() is not None


def run_femxdem(
    spec: BiaxialSpec | None = None,
    rve: str = "taylor",
    out=None,
    executor=None,
    resume: bool = False,
    stop_after: int | None = None,
    packing=None,
    packing_dir="results/packings",
    n_chunks: int | None = None,
    law=None,
    field_steps=None,
    rve_pictures=None,
    tangent: str | None = None,
    tangent_step: float | None = None,
) -> dict:
    """Run the biaxial specimen with the stand-in ``rve`` (module docstring); returns a summary
    (``steps`` the records, ``report`` markdown, ``timing``: ``wall_s`` of the steps, ``material_s``
    the driver's wait for the Gauss points, ``law_s``, ``law_cpu_s`` and ``law_calls`` the wall and
    CPU time in and the number of point-law updates summed over the chunks, measured where they
    run, ``chunks`` per chunk;
    ``files``). With ``out`` every converged
    step is checkpointed; ``resume`` continues from the checkpoint; ``stop_after`` = k stops after
    step k's checkpoint (raises :class:`FemxdemInterrupted`). A step that does not converge raises
    :class:`gransim.fem.incremental.StepFailure` after the outputs of the converged steps are
    written (the report says where it stopped). ``law``: another point law with
    ``pack_states``/``unpack_states`` instead of the stand-in (``rve`` is then its label).
    ``field_steps``: the steps whose Gauss-point fields are kept and drawn (default: the last);
    ``rve_pictures``: the Gauss points whose RVE is drawn at those steps (default: the most
    strained point of each; DEM RVE only). ``tangent``: ``contact`` (default of the DEM RVEs) or
    ``perturbation`` of ``tangent_step`` (:mod:`gransim.fem.perturbation`; default
    :data:`gransim.fem.perturbation.DEFAULT_STEP`), recorded with the parameters; None for a stand-in."""
    spec = spec or BiaxialSpec()
    field_steps = {spec.steps} if field_steps is None else {int(k) for k in field_steps}
    bad = sorted(k for k in field_steps if not 1 <= k <= spec.steps)
    if bad:
        raise InputError(f"--field-steps: steps lie in 1..{spec.steps}, got {bad[0]}")
    if rve_pictures is not None:
        rve_pictures = tuple(int(g) for g in rve_pictures)
        bad = [g for g in rve_pictures if not 0 <= g < spec.n_gauss]
        if bad:
            raise InputError(f"--rve-pictures: Gauss points lie in 0..{spec.n_gauss - 1}, got {bad[0]}")
    if resume and out is None:
        raise InputError("--resume: needs the output directory of the interrupted run (--out)")
    tangent_params = tangent_parameters(rve, tangent, tangent_step)
    if law is None:
        law, law_params = standin_law(rve, spec, packing, packing_dir)
    else:
        law_params = {"law": type(law).__name__}
    if tangent_params["kind"] == "perturbation":
        from .perturbation import PerturbationTangent  # noqa: PLC0415 - start-up: numpy

        law = PerturbationTangent(law, tangent_params["step"])
    params = {"spec": spec.as_dict(), "rve": rve, "standin": law_params, "tangent": tangent_params}
    out = Path(out) if out is not None else None
    ck = out / "checkpoint" if out is not None else None
    done, states, response = [], None, None
    fields = {}  # field step -> field_record
    if resume:
        done, states, response = read_checkpoint(ck, params, law, fields)
    elif out is not None:
        out.mkdir(parents=True, exist_ok=True)
        if ck.exists():
            clear_checkpoint(ck)
    setup = biaxial_setup(spec)
    t0 = time.perf_counter()
    points = gauss_points(law, spec.n_gauss, executor, n_chunks, states, response)
    t_setup = time.perf_counter() - t0

    new = []

    def on_step(rec, pts):
        # converged: in femxdem.h5 even if a signal abandons its checkpoint (resumed from the step before)
        new.append(rec)
        st = None
        if rec.step in field_steps:
            st = pts.states()
            fields[rec.step] = field_record(rec, pts.observables(), st, rve_pictures, law)
        if ck is not None:
            write_step(ck, params, rec, law, pts, states=st, fields=fields.get(rec.step))
        if stop_after is not None and rec.step >= stop_after:
            raise FemxdemInterrupted(rec.step, out)
        check_interrupt()

    bar = progress(total=spec.steps, desc=f"femxdem {rve}")
    bar.update(len(done))
    t1 = time.perf_counter()
    stop = None  # why the run ended before its last step: StepFailure, FemxdemInterrupted, Interrupted
    try:
        try:
            with deferred_interrupts():  # SIGINT/SIGTERM stop after the step in progress, its checkpoint written
                run_biaxial(setup, points, start=done[-1] if done else None, on_step=on_step, progress=bar)
        except (StepFailure, FemxdemInterrupted, Interrupted) as exc:
            stop = exc
        except BaseException as exc:  # Dask's failures include asyncio.CancelledError, no Exception
            if not _lost_to_a_signal(exc):
                raise
            # the signal also reached the Gauss points' workers (a process group's SIGTERM): the
            # step in progress is lost, the converged ones are whole
            try:
                check_interrupt()  # consumed here, or the outputs' atomic writes would abandon themselves
            except Interrupted as intr:
                stop = intr
        try:
            observables = points.observables()
            law_timing = points.timing()
        except BaseException as exc:
            if not isinstance(stop, Interrupted) or isinstance(exc, (KeyboardInterrupt, SystemExit)):
                raise
            observables = {}  # the workers are gone with the signal: the file has the curves and the last step
            law_timing = []
    finally:
        bar.close()
        try:
            points.close()
        except BaseException as exc:
            if not isinstance(stop, Interrupted) or isinstance(exc, (KeyboardInterrupt, SystemExit)):
                raise
    wall = time.perf_counter() - t1
    recs = done + new
    last = recs[-1].step if recs else 0
    if isinstance(stop, Interrupted):
        stop = Interrupted(
            stop.signum,
            f"stopped by {stop.signal_name} after load step {last}"
            + (f": the converged steps are in {out}, the checkpoint in {ck}: continue with --resume" if out else ""),
            clean=True,
        )
    mat_s = sum(r.material_s for r in new)
    iters = [len(r.errors) for r in recs]
    lines = [
        _TITLES.get(rve, f"## FEM x DEM biaxial specimen (stand-in `{rve}`: NOT the DEM RVE)"),
        "",
        f"- tangent: {_TANGENT_LABELS[tangent_params['kind']]}"
        + (f", h = {tangent_params['step']:g}" if tangent_params["kind"] == "perturbation" else ""),
        f"- specimen {spec.width * 1e3:g} x {spec.height * 1e3:g} mm, {spec.nx} x {spec.ny} {spec.element} elements, "
        f"{spec.gauss} x {spec.gauss} Gauss points ({spec.n_gauss}), confining {spec.pressure / 1e3:g} kPa "
        f"(follower), top {spec.top_step:g} m per step, {spec.steps} steps, Newton tol {spec.tol:g}",
        f"- Gauss points {points.where}; set-up {t_setup:.2f} s; {len(new)} steps in {wall:.2f} s "
        f"(material {mat_s:.2f} s)" + (f"; resumed after step {len(done)}" if done else ""),
        f"- Newton iterations per step: {iters}",
        *_law_time_lines(law_timing, wall),
        *([f"- STOPPED: {stop}"] if stop is not None else []),
        "",
        "| step | axial strain | q (kPa) | volumetric strain |",
        "|---|---|---|---|",
    ]
    lines += [
        f"| {r.step} | {r.axial_strain:.5f} | {r.deviatoric_stress / 1e3:.4g} | {r.volumetric_strain:.3e} |"
        for r in recs
    ]
    if out is not None:  # the report leads with the curves, then the maps
        lines[1:1] = ["", "![q and volumetric strain against axial strain](curves.png)"]
    lines += field_report(out, fields, recs, rve)
    report = "\n".join(lines)
    files = {}
    if out is not None:
        files["h5"] = write_results(
            out / "femxdem.h5", params, recs, observables, "" if stop is None else str(stop), fields, setup
        )
        files["png"] = plot_curves(out / "curves.png", recs, spec, rve)
        files.update(write_field_outputs(out, setup, recs, fields, rve))
        files["md"] = atomic_text(out / "report.md", report + "\n")
        if stop is None:  # a run stopped early is not a complete result (gransim.progress.result_written)
            for p in files.values():
                result_written(p)
    if isinstance(stop, StepFailure):
        where = f"; the {len(recs)} converged steps are in {out}" if out is not None else ""
        raise StepFailure(f"{stop}{where}", stop.errors, stop.point)
    if stop is not None:
        raise stop
    return {
        "steps": recs,
        "report": report,
        "timing": {
            "wall_s": wall,
            "material_s": mat_s,
            "setup_s": t_setup,
            "law_s": sum(t["law_s"] for t in law_timing),
            "law_cpu_s": sum(t["law_cpu_s"] for t in law_timing),
            "law_calls": sum(t["law_calls"] for t in law_timing),
            "chunks": law_timing,
        },
        "files": files,
        "resumed_after": len(done),
        "parameters": params,
        "fields": fields,
    }


__all__ = [
    "RVE_DEM",
    "RVE_LAWS",
    "RVE_STANDINS",
    "tangent_parameters",
    "FemxdemInterrupted",
    "check_resumable",
    "run_femxdem",
    "standin_law",
]
