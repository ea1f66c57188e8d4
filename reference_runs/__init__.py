"""Reference runs of LIGGGHTS-PUBLIC 3.8.0, LAMMPS 29 Sep 2021 and YADE: deck generators, a job runner
and output parsers.

This package imports gransim; gransim never imports it.
"""
