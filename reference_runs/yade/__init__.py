"""YADE (Debian ``yade`` 2023.02a), the independent third reference code: its jobs
(:mod:`.job`), the script of the Taylor states (:mod:`.script`) and their reader and driver
(:mod:`.taylor`). Facts the code relies on, with YADE's source lines: docs/yade.md."""
