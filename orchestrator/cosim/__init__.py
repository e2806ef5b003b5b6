"""Co-simulation: from a validated scenario to the coupled run — the job (FMUs or in-process units),
the master algorithms, the run's statistics and counters, virtual sensors on a run, and the SSP
export for other FMI hosts.

Imports ``orchestrator.inputs`` only (and ``src/``, ``fmus``).
"""
