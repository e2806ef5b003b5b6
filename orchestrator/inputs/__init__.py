"""Inputs: what a user hands in — scenario YAML (schema, defaults, overrides), sensor layouts,
measured data files — and the errors that name what is wrong with them.

The bottom layer of the orchestrator: it imports nothing of the other orchestrator packages.
"""
