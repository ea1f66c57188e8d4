"""Contact detection (neighbour lists) and the contact laws shared by the RVE and the DEM."""

from .neighbours import NeighbourList, find_neighbours, find_neighbours_bruteforce

__all__ = ["NeighbourList", "find_neighbours", "find_neighbours_bruteforce"]
