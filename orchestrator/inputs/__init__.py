"""Inputs: what a user hands in — scenario YAML (schema, defaults, overrides), sensor layouts,
measured data files — and the errors that name what is wrong with them.

* scenarios: :mod:`~orchestrator.inputs.scenario` (load, override, dump; the entry point),
  :mod:`~orchestrator.inputs.schema` (the accepted keys) built from
  :mod:`~orchestrator.inputs.schema_nodes`, :mod:`~orchestrator.inputs.specs` (vehicle and
  simulation dataclasses), :mod:`~orchestrator.inputs.yaml_io` (the YAML rules) and
  :mod:`~orchestrator.inputs.keypath` (``track.ballast.voids[0].gaps``);
* sensor layouts: :mod:`~orchestrator.inputs.sensor_layout`;
* measured data: :mod:`~orchestrator.inputs.measured` (the entry point),
  :mod:`~orchestrator.inputs.measured_files`, :mod:`~orchestrator.inputs.measured_checks`,
  :mod:`~orchestrator.inputs.measured_alignment`;
* :mod:`~orchestrator.inputs.errors`.

The bottom layer of the orchestrator: it imports nothing of the other orchestrator packages.
"""
