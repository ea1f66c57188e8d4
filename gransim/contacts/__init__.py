"""Contact detection (neighbour lists) and the contact laws shared by the RVE and the DEM."""

from .neighbours import NeighbourList, find_neighbours, find_neighbours_bruteforce

#: the modules of the built-in contact laws, each registering its laws when imported
#: (:mod:`gransim.contacts.laws` imports them on the first look-up by name; a new law is one more
#: module here, docs/laws.md "Adding a law")
LAW_MODULES = ("hooke", "hertz", "rolling", "yade_cundall_strack")

__all__ = ["LAW_MODULES", "NeighbourList", "find_neighbours", "find_neighbours_bruteforce"]
