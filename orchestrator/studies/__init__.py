"""Studies: the source papers' figures and tables (seed 001 parameter study, seed 000 figures),
built from sweeps and the inverse problem.

The top layer below the command line.
"""
