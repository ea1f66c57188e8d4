"""Discrete element engine for 2D disks in a periodic cell (the step order of LIGGGHTS 3.8.0 and LAMMPS
29 Sep 2021, the contact arithmetic of either: DEMSettings.flavour, docs/lammps.md) and the
biaxial test of Kuhn (1997), section 4. See docs/dem.md and docs/schema_dem.md; the fast ordering
(``Engine(..., order="fast")``, ``FastEngine(...)``): docs/performance.md."""

import importlib

from .biaxial import BiaxialSettings, default_settings, inertial_number, run_biaxial
from .engine import DEMEngine, contact_time, damping_ratio, fingerprint, stability_limit
from .output import (
    OutputSettings,
    plot_stress_strain,
    read_run,
    read_snapshot,
    require_complete,
    snapshot_to_vtu,
)
from .run import Phase, run_phases
from .settings import AxisControl, DEMSettings, Integration, Loading, PrescribedBox

#: names imported on first use (PEP 562): the fast path and the sheared cell are not needed by a
#: biaxial run, and importing them decorates their kernels (start-up time, docs/startup.md)
_LAZY = {"FastEngine": ".fast", "ShearEngine": ".sheared", "ShearLoading": ".sheared", "simple_shear": ".sheared"}


def __getattr__(name):
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name], __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "AxisControl",
    "BiaxialSettings",
    "DEMEngine",
    "DEMSettings",
    "FastEngine",
    "Integration",
    "Loading",
    "OutputSettings",
    "Phase",
    "PrescribedBox",
    "ShearEngine",
    "ShearLoading",
    "contact_time",
    "damping_ratio",
    "default_settings",
    "fingerprint",
    "inertial_number",
    "plot_stress_strain",
    "read_run",
    "read_snapshot",
    "require_complete",
    "run_biaxial",
    "run_phases",
    "simple_shear",
    "snapshot_to_vtu",
    "stability_limit",
]
