"""Discrete element engine for 2D disks in a periodic cell (LIGGGHTS 3.8.0 step order) and the
biaxial test of Kuhn (1997), section 4. See docs/dem.md and docs/schema_dem.md; the reordering fast path
(FastEngine): docs/performance.md."""

from .biaxial import BiaxialSettings, default_settings, inertial_number, run_biaxial
from .engine import DEMEngine, contact_time, damping_ratio, fingerprint, stability_limit
from .fast import FastEngine
from .output import (
    OutputSettings,
    plot_stress_strain,
    read_run,
    read_snapshot,
    require_complete,
    snapshot_to_vtu,
)
from .run import Phase, run_phases
from .settings import AxisControl, DEMSettings, Loading, PrescribedBox
from .sheared import ShearEngine, ShearLoading, simple_shear

__all__ = ["AxisControl", "BiaxialSettings", "DEMEngine", "DEMSettings", "FastEngine", "Loading", "OutputSettings", "Phase",
           "PrescribedBox", "ShearEngine", "ShearLoading", "contact_time", "damping_ratio", "default_settings",
           "fingerprint", "inertial_number", "plot_stress_strain", "read_run", "read_snapshot", "require_complete",
           "run_biaxial", "run_phases", "simple_shear", "snapshot_to_vtu", "stability_limit"]
