"""Sweeps: many runs of one scenario — the plan (grids of overrides, run ids; ``plan``),
executors (local processes, Dask; ``executors``), the resumable run store (``store``),
the sweep that ties them together (``sweep``), and the per-run case function (``study``).

Used by the studies and by the inverse problem; imports ``results``, ``cosim`` and ``inputs``.
"""
