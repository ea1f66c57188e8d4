"""Discrete element engine for 2D disks in a periodic cell (LIGGGHTS 3.8.0 step order) and the
biaxial test of Kuhn (002), section 4."""

from .engine import DEMEngine, contact_time, fingerprint, stability_limit
from .settings import AxisControl, DEMSettings, Loading

__all__ = ["AxisControl", "DEMEngine", "DEMSettings", "Loading", "contact_time", "fingerprint",
           "stability_limit"]
