"""Validation of native gransim against LIGGGHTS reference runs, and the HTML report.

Cases register themselves in :mod:`validation.cases`; :func:`validation.runner.run_validation`
runs a suite, writes ``results/validation.json``, ``results/validation.h5`` and
``results/report/index.html``. This package imports gransim and reference_runs, never the reverse.
"""
