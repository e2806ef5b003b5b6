"""Results: what one run leaves — analysis (peaks, moments, pressures), the files
(``results.h5``, ``sensors.csv``, ``summary.json``) and plots — and the ``run``/``frf`` jobs that write them.

Imports ``orchestrator.cosim`` and ``orchestrator.inputs``.
"""
