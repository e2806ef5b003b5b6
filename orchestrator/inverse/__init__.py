"""The inverse problem: the cause registry, synthetic measurements, the objective, fitting,
``diagnose`` (residuals → named cause → gain) and ``calibrate`` (surrogate calibration), and their reports.

Imports ``sweeps``, ``results``, ``cosim`` and ``inputs``.
"""
