"""Static wheel loads of the vehicles as moving loads (track-only runs).

Until a vehicle is coupled, a run can drive the track with the vehicle's static
wheel loads moving at constant speed. Wheel order follows DESIGN.md §4.4: front
wheelset left, right, then the next wheelset.
"""
from __future__ import annotations

from .dynamics import MovingLoad

BOGIE_WHEELBASE = 2.5  # m, typical passenger/locomotive bogie (vehicle.bogie default)


def wheel_offsets(vehicle: str) -> list[float]:
    """Longitudinal offset of each wheelset behind the front one [m]."""
    if vehicle == "quarter":
        return [0.0]
    return [0.0, -BOGIE_WHEELBASE]


def static_wheel_loads(vehicle: str, axle_load: float, x_front: float) -> list[MovingLoad]:
    """Moving loads of the wheels: axle_load/2 [N] downward per wheel.

    Parameters
    ----------
    vehicle : str
        ``"bogie"`` or ``"quarter"`` (anything else is treated as a bogie).
    axle_load : float
        [N]
    x_front : float
        Position of the front wheelset at t = 0 [m].
    """
    out = []
    for a in wheel_offsets(vehicle):
        out.append(MovingLoad("left", x_front + a, -0.5 * axle_load))
        out.append(MovingLoad("right", x_front + a, -0.5 * axle_load))
    return out
