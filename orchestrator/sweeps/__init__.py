"""Sweeps: many runs of one scenario — grids of overrides, executors (local processes, Dask),
the resumable run store, and the per-run case function.

Used by the studies and by the inverse problem; imports ``results``, ``cosim`` and ``inputs``.
"""
