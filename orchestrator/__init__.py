"""Orchestrator: scenarios, co-simulation master, recording, command line.

Entry points: :func:`orchestrator.inputs.scenario.load_scenario` and the ``turnout``
command (:func:`orchestrator.cli.main`).
"""
from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("turnout-cosim")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0+unknown"
