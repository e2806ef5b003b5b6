"""The fixed time grid of a run: how many steps of length ``h`` a duration takes.

One function, :func:`step_count`, for every fixed-step loop (the co-simulation master, the
moving-load integration, the SSP runners, the scenario's ``simulation.n_steps``); the
communication points are then ``t_k = t0 + k h`` from the integer ``k``.
"""
from __future__ import annotations

import math

STEP_RTOL = 1e-9  # a duration / step ratio this close (relative) above a whole number N is N steps
                  # (float noise, e.g. 0.9 / 3e-4 = 3000.0000000000005); the scenario's
                  # STEP_MULTIPLE_RTOL (output_step / step) has the same value


def step_count(duration: float, step: float, *, cover: bool = False) -> int:
    """Number of fixed steps of length ``step`` that make a run of ``duration``.

    Parameters
    ----------
    duration : float
        Simulated time [s].
    step : float
        Step length [s] (> 0).
    cover : bool
        False (the co-simulation master, the moving-load integration): the nearest whole
        number of steps, ``round(duration / step)``: the run ends at the grid point nearest
        to ``duration`` (0 steps when ``duration < step / 2``).
        True (the FMI hosts: libcosim and FMPy step until ``t >= stop time``;
        ``SimulationSpec.n_steps``): the fewest steps, at least one, whose end reaches
        ``duration``, ``ceil(duration / step)`` with a ratio up to ``STEP_RTOL`` above a
        whole number counted as that number.

    Returns
    -------
    int
        The number of steps. Both ways agree when ``duration`` is a whole multiple of
        ``step`` (to round-off); otherwise ``cover`` may take one step more (0.0104 s at
        1 ms: 10 steps nearest, 11 to cover). The scenario schema does not require a whole
        multiple, so each caller keeps the way it has always counted.
    """
    if cover:
        return max(1, math.ceil(duration / step * (1.0 - STEP_RTOL)))
    return int(round(duration / step))


__all__ = ["STEP_RTOL", "step_count"]
