"""The biaxial compression test of Kuhn, "Deformation measures for granular materials" (1997),
section 4 (Fig. 7).

Phase 0 (consolidation): both axes servo-controlled to the confining stress p (isotropic).
Phase 1 (compression): y shortened at a constant rate, x servo-controlled to hold sigma_11 = p.
Quasi-static when the inertial number I = |eps_rate| D50 sqrt(rho/p) is small (<= 1e-4;
rho = mass per area, p in N/m, so I is dimensionless in 2D).

Any registered contact law runs the protocol (:func:`law_settings`: a law of
:func:`gransim.contacts.laws.make_law` by name and parameters; its name and parameters go to the
run file's settings JSON, ``law`` and ``law_options``).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from .._validate import as_int, as_positive_float
from ..contacts.laws import law_code, law_parameters, make_law
from ..contacts.material import check_poisson, check_youngs, effective_youngs
from ..errors import InputError
from ..geometry import Packing
from .engine import contact_time
from .output import OutputSettings, read_run
from .run import Phase, run_phases
from .settings import AxisControl, DEMSettings, Loading

#: target mean contact indentation / D50 of the paper ("less than 0.02%")
PAPER_INDENTATION = 2e-4


@dataclass(frozen=True)
class BiaxialSettings:
    """Protocol parameters (SI; stresses in N/m in 2D).

    confining : sigma_11 = p held by the servo (N/m).
    strain : final axial strain magnitude |eps_22| (engineering, of the compression phase).
    strain_rate : axial rate (1/s), > 0 (applied as compression).
    servo_gain : 1/(Pa s). consolidation_tol : relative tolerance that ends the consolidation.
    consolidation_steps : most consolidation steps.
    """

    confining: float
    strain: float = 0.005
    strain_rate: float = 0.01
    servo_gain: float = 1e-3
    consolidation_tol: float = 0.01
    consolidation_steps: int = 200000
    check_every: int = 2000

    def __post_init__(self):
        for k in ("confining", "strain", "strain_rate", "servo_gain"):
            object.__setattr__(self, k, as_positive_float(getattr(self, k), k))
        as_positive_float(self.consolidation_tol, "consolidation_tol")
        for k in ("consolidation_steps", "check_every"):
            object.__setattr__(self, k, as_int(getattr(self, k), k, minimum=1))
        if self.strain >= 0.5:
            raise InputError(f"strain: expected a small strain < 0.5, got {self.strain!r}")


#: default normal stiffness of the protocol (N/m)
DEFAULT_KN = 1e5
#: default confining stress per unit normal stiffness: p = 2.5e-4 kn (N/m per N/m)
CONFINING_PER_KN = 2.5e-4
#: default inertial number of the compression phase, I = rate D50 sqrt(rho / p)
DEFAULT_INERTIAL_NUMBER = 5e-5
#: default Coulomb friction coefficient (Kuhn's biaxial test)
DEFAULT_MU = 0.5


def default_settings(
    packing: Packing,
    kn: float = DEFAULT_KN,
    damping_ratio: float = 0.3,
    steps_per_contact: float = 50.0,
    strain_rate: float | None = None,
    strain: float = 0.005,
    flavour: str = "liggghts",
    *,
    mu: float = DEFAULT_MU,
    kt_ratio: float = 1.0,
    confining: float | None = None,
    inertial_number: float | None = None,
    consolidation_steps: int = 200000,
    consolidation_tol: float = 0.01,
) -> tuple[DEMSettings, BiaxialSettings]:
    """Settings of the protocol from its physical parameters; every derived quantity is derived
    from the final values (a given ``confining`` sets the strain rate of the default inertial
    number, not the default pressure).

    Parameters
    ----------
    packing : the assembly; its masses (``density`` pi r^2, density in kg/m^2) and D50 (m) set
        the damping, the time step, the skin and the inertial number.
    kn : normal spring stiffness (N/m). kt = ``kt_ratio`` kn (Kuhn: kt = kn, ``kt_ratio`` 1).
    damping_ratio : zeta of the normal contact of two median disks: gamma_n = gamma_t =
        2 zeta sqrt(kn/m_eff), m_eff = m_median/2 (1/s).
    steps_per_contact : dt = contact time / ``steps_per_contact`` (contact time of the two
        lightest disks, :func:`gransim.dem.engine.contact_time`).
    mu : Coulomb friction coefficient (default 0.5, Kuhn).
    confining : sigma_11 = p (N/m, 2D). Default 2.5e-4 kn: a mean indentation near 2e-4 D50
        (the paper's; measured 2e-4 on the Kuhn 1002-disk assembly at the start of
        compression) for a dense 2D assembly (mean force ~ p D50 / 2, overlap = force/kn).
    strain_rate, inertial_number : the axial rate (1/s), or the inertial number
        I = rate D50 sqrt(rho / p) it follows from with the final p (:func:`inertial_number`);
        at most one of the two; default I = 5e-5 (quasi-static).
    strain : final axial strain |eps_22|.
    consolidation_steps, consolidation_tol : see :class:`BiaxialSettings`.
    flavour : whose arithmetic the engine follows, "liggghts" or "lammps" (:class:`DEMSettings`).

    The skin is 0.05 D50; the servo gain makes the box react over ~100 steps: gain =
    0.01 / (kn dt).
    """
    kn = as_positive_float(kn, "kn")
    damping_ratio = as_positive_float(damping_ratio, "damping_ratio", allow_zero=True)
    steps_per_contact = as_positive_float(steps_per_contact, "steps_per_contact")
    mu = as_positive_float(mu, "mu", allow_zero=True)
    kt_ratio = as_positive_float(kt_ratio, "kt_ratio", allow_zero=True)
    if strain_rate is not None and inertial_number is not None:
        raise InputError(
            f"strain_rate {strain_rate!r} and inertial_number {inertial_number!r}: give at "
            "most one (the rate follows from the inertial number and the confining stress)"
        )
    p = CONFINING_PER_KN * kn if confining is None else as_positive_float(confining, "confining")
    if strain_rate is None:
        i_num = (
            DEFAULT_INERTIAL_NUMBER
            if inertial_number is None
            else as_positive_float(inertial_number, "inertial_number")
        )
        strain_rate = i_num / (packing.d50 * np.sqrt(packing.density / p))
    strain_rate = as_positive_float(strain_rate, "strain_rate")
    m = np.median(packing.masses)
    gamma = 2.0 * damping_ratio * np.sqrt(kn / (0.5 * m))
    dt = contact_time(packing, kn) / steps_per_contact
    dem = DEMSettings(
        kn=kn, kt=kt_ratio * kn, gamma_n=gamma, gamma_t=gamma, mu=mu, dt=dt, skin=0.05 * packing.d50, flavour=flavour
    )
    bi = BiaxialSettings(
        confining=p,
        strain=strain,
        strain_rate=strain_rate,
        servo_gain=0.01 / (kn * dt),
        consolidation_steps=consolidation_steps,
        consolidation_tol=consolidation_tol,
    )
    return dem, bi


#: parameters of a law that default to the protocol's Hooke settings when not given
_HOOKE_DEFAULTS = {"kn": "kn", "kt": "kt", "gamma_n": "gamma_n", "gamma_t": "gamma_t", "mu": "mu", "friction": "mu"}


def hertz_equivalent_stiffness(packing: Packing, name: str, params: dict) -> float:
    """Tangent normal stiffness (N/m) of the Hertz law ``name`` at the paper's indentation:
    k = 2 Y* sqrt(R* delta) with R* = D50/4 (two median disks) and delta = 2e-4 D50
    (Johnson 1985, eq (4.23) differentiated). Y* from the law's parameters (hertz-liggghts,
    hertz-granular-lammps: youngs_modulus, poisson_ratio; hertz-lammps: kn = 4/3 Y*). The
    protocol's time step, confining stress and servo gain follow from it as from kn of the
    Hooke law (:func:`default_settings`)."""
    if name == "hertz-lammps":
        y = 0.75 * as_positive_float(params.get("kn", float("nan")), f"law {name}: kn")
    else:
        E = params.get("youngs_modulus")
        nu = params.get("poisson_ratio")
        if E is None or nu is None:
            raise InputError(
                f"law {name}: expected parameters youngs_modulus and poisson_ratio "
                "(--law-param youngs_modulus=... --law-param poisson_ratio=...)"
            )
        E = check_youngs(E, f"law {name}: youngs_modulus")
        nu = check_poisson(nu, f"law {name}: poisson_ratio")
        y = effective_youngs(E, nu, E, nu)
    d50 = packing.d50
    return float(2.0 * y * np.sqrt(0.25 * d50 * PAPER_INDENTATION * d50))


def law_settings(packing: Packing, name: str, params: dict | None = None, **defaults):
    """The law ``name`` (:func:`gransim.contacts.laws.law_names`) with ``params`` and the
    protocol's settings for it: (law, DEMSettings, BiaxialSettings, options).

    The flavour is the law's code (:func:`~gransim.contacts.laws.law_code`). The parameters
    kn, kt, gamma_n, gamma_t, mu (and friction) default to those of :func:`default_settings`
    (``defaults``: its keyword arguments, e.g. kn, kt_ratio, mu, damping_ratio, confining,
    strain_rate or inertial_number) where the law takes them (hertz-lammps: only mu; its kn, kt
    in Pa and dampings in 1/(s m) are given). A friction coefficient given as a law parameter
    (mu or friction) is the protocol's mu (InputError when ``defaults`` gives another). A Hertz
    law sets the protocol's stiffness scale from :func:`hertz_equivalent_stiffness` (and with it
    the default confining stress, time step and servo gain). ``options`` = {"name", "params"} as
    run (for the provenance). InputError for an unknown name or a bad, missing or unknown parameter.
    """
    params = dict(params or {})
    code = law_code(name)  # InputError naming the known laws
    defaults.pop("flavour", None)
    for k in ("mu", "friction"):  # the law's friction is the protocol's (one value, recorded once)
        if k in params:
            if "mu" in defaults and defaults["mu"] is not None and float(defaults["mu"]) != params[k]:
                raise InputError(
                    f"law {name}: {k} = {params[k]!r} and mu = {defaults['mu']!r} disagree; "
                    "give the friction coefficient once"
                )
            defaults["mu"] = params[k]
    if name.startswith("hertz"):
        defaults["kn"] = hertz_equivalent_stiffness(packing, name, params)
    dem, bi = default_settings(packing, flavour=code, **defaults)
    req, _ = law_parameters(name)
    for k, field in _HOOKE_DEFAULTS.items():
        if k in req and k not in params and not (name == "hertz-lammps" and k != "mu"):
            params[k] = float(getattr(dem, field))
    law = make_law(name, **params)
    return law, dem, bi, {"name": name, "params": params}


def inertial_number(packing: Packing, strain_rate: float, confining: float) -> float:
    """I = |eps_rate| D50 sqrt(rho / p) (2D: rho mass per area, p in N/m)."""
    return float(abs(strain_rate) * packing.d50 * np.sqrt(packing.density / confining))


def biaxial_phases(dem: DEMSettings, bi: BiaxialSettings) -> list[Phase]:
    """The two phases (consolidation, compression) of the protocol."""
    p = bi.confining
    servo = AxisControl("servo", target=p, gain=bi.servo_gain)
    cons = Phase(
        "consolidation",
        Loading(x=servo, y=servo),
        int(bi.consolidation_steps),
        stop_tol=bi.consolidation_tol,
        check_every=int(bi.check_every),
    )
    n = int(np.ceil(bi.strain / (bi.strain_rate * dem.dt)))
    comp = Phase("compression", Loading(x=servo, y=AxisControl("rate", rate=-bi.strain_rate)), n)
    return [cons, comp]


def run_biaxial(
    packing: Packing,
    dem: DEMSettings,
    bi: BiaxialSettings,
    out_path,
    output: OutputSettings | None = None,
    resume: bool = False,
    threads: int | None = None,
    show_progress: bool = True,
    allow_unsettled: bool = False,
    law=None,
    law_options: dict | None = None,
    order: str = "code",
) -> dict:
    """Run the biaxial test; returns a summary (inertial number, indentation, stresses, peak).
    ``order``: the engine's ordering, "code" or "fast" (:func:`gransim.dem.run.run_phases`).

    A consolidation that does not settle within ``bi.consolidation_steps`` stops the run
    (:class:`~gransim.errors.ConvergenceError`, file written with ``complete`` False) unless
    ``allow_unsettled`` (see :func:`run_phases`). ``law``: a contact-law object (None: the Hooke
    law of ``dem``); ``law_options``: its factory name and parameters ({"name", "params"}, from
    :func:`law_settings`), written to the settings JSON as ``law_options``."""
    phases = biaxial_phases(dem, bi)
    meta = {"biaxial": asdict(bi)}
    if law_options is not None:
        meta["law_options"] = {"name": str(law_options["name"]), "params": dict(law_options["params"])}
    run_phases(
        packing,
        dem,
        phases,
        out_path,
        output=output,
        resume=resume,
        threads=threads,
        show_progress=show_progress,
        metadata=meta,
        allow_unsettled=allow_unsettled,
        law=law,
        order=order,
    )
    return summarize(out_path)


def compression_steps(run) -> int:
    """DEM steps of the compression phase of a biaxial run (``read_run``), not its series rows.

    A complete run did all ``max_steps`` of its compression phase (it has no stop criterion), as
    recorded in the settings JSON (``phases[1].max_steps``). A run stopped during the compression
    counts the steps from the last consolidation row of ``/series`` to the last compression row:
    exact when the consolidation ended on a series row, else up to ``series_every - 1`` more.
    """
    s = run.series
    phases = run.settings.get("phases") or []
    if run.complete and len(phases) > 1 and all(not p.get("stop_tol") for p in phases[1:]):
        return int(sum(int(p["max_steps"]) for p in phases[1:]))
    comp = s["phase"] == 1
    if not np.any(comp):
        return 0
    cons = s["step"][~comp]
    return int(s["step"][comp].max() - (cons.max() if cons.size else 0))


def summarize(path) -> dict:
    """Key figures of a finished biaxial run."""
    run = read_run(path)
    s = run.series
    comp = s["phase"] == 1
    bi = run.settings.get("biaxial", {})
    p = bi.get("confining", float("nan"))
    rate = bi.get("strain_rate", float("nan"))
    out = {
        "n_particles": run.packing.n,
        "complete": run.complete,
        "unsettled_phases": ", ".join(u["name"] for u in run.unsettled_phases) or "none",
        "inertial_number": inertial_number(run.packing, rate, p) if bi else float("nan"),
        "consolidation_steps": int(s["step"][s["phase"] == 0].max()),
    }
    if np.any(comp):
        st = -s["stress"][comp]  # compression positive: the confining stress p is a positive number
        eps = run.strain()[comp]
        ratio = st[:, 1, 1] / st[:, 0, 0]
        k = int(np.argmax(ratio))
        out.update(
            {
                "compression_steps": compression_steps(run),
                "axial_strain": float(-(eps[-1, 1] - eps[0, 1])),
                "sigma11_mean_rel_error": float(np.mean(np.abs(st[:, 0, 0] / p - 1))),
                "stress_ratio_peak": float(ratio[k]),
                "strain_at_peak": float(-(eps[k, 1] - eps[0, 1])),
                "mean_overlap_over_d50_start": float(s["mean_overlap"][comp][0] / run.packing.d50),
                "mean_overlap_over_d50_end": float(s["mean_overlap"][comp][-1] / run.packing.d50),
                "coordination_start": float(2 * s["n_contacts"][comp][0] / run.packing.n),
            }
        )
    return out
