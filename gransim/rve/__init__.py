"""Taylor RVE homogenization, contact normal fabric and the RVE studies (Meier, Steinmann & Kuhl).

Stresses are tension positive; ``A[i, J, k, L] = dP_iJ/dF_kL``. See :mod:`gransim.rve.taylor`; the relaxed
(periodic-fluctuation) RVE with its condensed tangent is :mod:`gransim.rve.relaxed`.
"""

from .relaxed import RelaxedBatch, RelaxedMaterial, RelaxedResult
from .taylor import (
    ContactState,
    TaylorBatch,
    TaylorMaterial,
    TaylorResult,
    check_deformation_gradients,
    contact_state,
    homogenize,
    material_for,
)

__all__ = [
    "ContactState",
    "RelaxedBatch",
    "RelaxedMaterial",
    "RelaxedResult",
    "TaylorBatch",
    "TaylorMaterial",
    "TaylorResult",
    "check_deformation_gradients",
    "contact_state",
    "homogenize",
    "material_for",
]
