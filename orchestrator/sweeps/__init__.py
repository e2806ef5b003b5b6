"""Sweeps: many runs of one scenario — the plan (grids of overrides, run ids; ``plan``),
executors (local processes, Dask; ``executors``, their worker processes' setup in
``workers`` and ``dask_plugin``), the resumable run store and the one run a worker does,
by value (``store``), the sweep that ties them together (``sweep``), and the per-run
case function (``study``).

Used by the studies and by the inverse problem; imports ``results``, ``cosim`` and ``inputs``.
"""
