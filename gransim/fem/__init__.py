"""Large-deformation finite elements on the macroscale (Meier, Steinmann & Kuhl section 5).

mesh -> element (total-Lagrangian Q1) -> assembly -> constraints -> solver (Newton, load stepping)
-> slope (the slope stability problem) -> output (VTU, PNG, tables, HDF5).
"""

from .assembly import Assembler
from .constraints import DofMap, RigidBody
from .element import Q1Geometry
from .materials import (
    AssignedRVEs,
    MaterialResult,
    NeoHookean,
    RVEMaterial,
    StVenantKirchhoff,
    lame,
)
from .mesh import Mesh, SlopeGeometry, rectangle_mesh, slope_mesh
from .slope import PROTOCOLS, SlopeSetup, limit_message, run_slope, setup_for, slope_problem
from .solver import (
    LoadPathResult,
    NewtonFailure,
    Problem,
    ResumeState,
    StepRecord,
    Timer,
    newton,
    run_load_steps,
)

__all__ = [
    "PROTOCOLS",
    "Assembler",
    "AssignedRVEs",
    "DofMap",
    "LoadPathResult",
    "MaterialResult",
    "Mesh",
    "NeoHookean",
    "NewtonFailure",
    "Problem",
    "Q1Geometry",
    "RVEMaterial",
    "ResumeState",
    "RigidBody",
    "SlopeGeometry",
    "SlopeSetup",
    "StVenantKirchhoff",
    "StepRecord",
    "Timer",
    "lame",
    "limit_message",
    "newton",
    "rectangle_mesh",
    "run_load_steps",
    "run_slope",
    "setup_for",
    "slope_mesh",
    "slope_problem",
]
