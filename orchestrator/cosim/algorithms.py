"""Master algorithms: how one communication step of the two units is ordered.

A registry (:data:`ALGORITHMS`, name -> :class:`Algorithm`), as ``scipy.integrate``'s
``METHODS``: adding an algorithm is one entry plus its test. Each algorithm's ``step``
advances both units over ``[t, t + h]`` given the contact forces ``Fz`` at ``t``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from orchestrator.cosim.units import CosimError


def _gauss_seidel(vehicle, track, t: float, h: float, Fz: np.ndarray) -> None:
    """Vehicle first with Fz(t_k); the track gets the wheel motion at t_{k+1}."""
    vehicle.step(t, h, Fz)
    x, z, vz = vehicle.outputs()
    track.step(t, h, x, z, vz)


def _jacobi(vehicle, track, t: float, h: float, Fz: np.ndarray) -> None:
    """Both units step from the values at t_k."""
    x, z, vz = vehicle.outputs()
    vehicle.step(t, h, Fz)
    track.step(t, h, x, z, vz)


IMPLICIT_TOL = 1e-3     # N: the monolithic reference iterates a step until Fz changes less
IMPLICIT_MAX_ITER = 50


def _implicit(vehicle, track, t: float, h: float, Fz: np.ndarray) -> None:
    """Monolithic reference: the step is repeated until the coupling forces converge.

    Vehicle with first-order hold of Fz over the step (so Fz(t_{k+1}) acts at the end
    of the step, as in the track), track with the end-of-step wheel motion: the
    converged step solves vehicle, contact and track simultaneously at t_{k+1}.
    In-process only (needs state save/restore of both units).
    """
    sv, st = vehicle.get_state(), track.get_state()
    guess = np.array(Fz, float)
    for _ in range(IMPLICIT_MAX_ITER):
        vehicle.step(t, h, guess)
        x, z, vz = vehicle.outputs()
        track.step(t, h, x, z, vz)
        new = track.forces()
        if np.max(np.abs(new - guess)) <= IMPLICIT_TOL:
            return
        guess = new.copy()
        vehicle.set_state(sv)
        track.set_state(st)
    raise CosimError(f"the monolithic step at t = {t:.6g} s did not converge in {IMPLICIT_MAX_ITER} iterations")


@dataclass(frozen=True)
class Algorithm:
    """A master algorithm and what the units must know of it.

    Attributes
    ----------
    name : str
        The ``simulation.algorithm`` value.
    step : callable
        ``step(vehicle, track, t, h, Fz)``: advance both units over ``[t, t + h]``.
    inputs_at_start : bool
        The track receives start-of-step wheel motion (so it extrapolates it over the
        step when ``simulation.extrapolation`` asks).
    in_process_only : bool
        Needs state save/restore of both units (not offered through FMUs here).
    hold : str
        How the in-process vehicle holds its force input over the step: ``zoh`` or ``foh``.
    extrapolate_force : bool
        The vehicle's input may be the track's mid-step force (``Fz_coupling``); the
        monolithic reference iterates the forces itself, so it never is.
    """

    name: str
    step: Callable
    inputs_at_start: bool
    in_process_only: bool = False
    hold: str = "zoh"
    extrapolate_force: bool = True


ALGORITHMS: dict[str, Algorithm] = {a.name: a for a in (
    Algorithm("gauss-seidel", _gauss_seidel, inputs_at_start=False),
    Algorithm("jacobi", _jacobi, inputs_at_start=True),
    Algorithm("implicit", _implicit, inputs_at_start=False, in_process_only=True, hold="foh",
              extrapolate_force=False),
)}


__all__ = ["Algorithm", "ALGORITHMS"]
