"""Results files: HDF5 with provenance (atomic writes) and VTK export."""

from .hdf5 import (
    atomic_h5,
    atomic_path,
    atomic_text,
    load_packing,
    open_result,
    read_packing_group,
    read_provenance,
    save_packing,
    write_packing_group,
)
from .provenance import git_commit, lammps_version, liggghts_version, provenance
from .vtk import packing_to_vtu, particles_to_vtu

__all__ = [
    "atomic_h5",
    "atomic_path",
    "atomic_text",
    "git_commit",
    "lammps_version",
    "liggghts_version",
    "load_packing",
    "open_result",
    "packing_to_vtu",
    "particles_to_vtu",
    "provenance",
    "read_packing_group",
    "read_provenance",
    "save_packing",
    "write_packing_group",
]
