"""Vehicle models for vertical vehicle-track interaction (numpy/scipy only).

* :class:`LinearVehicle` -- ``M q'' + C q' + K q = f_g + W^T Fz``, wheel output ``z = W q``;
  static equilibrium on prescribed wheel positions.
* :class:`VehicleStepper` -- exact (matrix-exponential) fixed-step time stepping with
  zero- or first-order hold of the contact forces, for co-simulation.
* :func:`bogie` / :class:`BogieParams` -- bogie with half car-body mass (9 dofs, 4 wheels).
* :func:`quarter_vehicle` / :class:`QuarterParams` -- one wheelset under a sprung mass,
  optionally with a flexible wheelset (4 or 5 dofs, 2 wheels).

Imports inside this package are relative, so it can be bundled into an FMU under a
different (unique) package name.
"""
from .bogie import BOGIE_DOFS, BogieParams, bogie, bounce_pitch_frequencies
from .linear import GRAVITY, LinearVehicle, StaticState, SuspensionAssembler, param_field
from .quarter import QUARTER_DOFS, QUARTER_DOFS_FLEX, QuarterParams, quarter_vehicle
from .stepper import HOLDS, VehicleStepper

__all__ = [
    "BOGIE_DOFS", "BogieParams", "bogie", "bounce_pitch_frequencies",
    "GRAVITY", "LinearVehicle", "StaticState", "SuspensionAssembler", "param_field",
    "QUARTER_DOFS", "QUARTER_DOFS_FLEX", "QuarterParams", "quarter_vehicle",
    "HOLDS", "VehicleStepper",
]
