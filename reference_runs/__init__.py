"""LIGGGHTS-PUBLIC 3.8.0 reference runs: deck generators, a job runner and output parsers.

This package imports gransim; gransim never imports it.
"""
