"""Bi-linear ballast bushings: compression only, with a void gap.

Each bushing connects a sleeper dof (vertical displacement ``u``, up +) to the
ground. With the gap ``g >= 0`` the compression is ``delta = -u - g``; the force on
the sleeper (up +) is

    F = max(0, k delta + c s(delta) d(delta)/dt)   if delta > 0,   else 0,

so no force builds until the sleeper has moved down by the gap, and the bushing
never pulls (seed 000 §2, Fig. 3). ``s(delta) = min(1, delta / DAMPING_ONSET)``
lets the dashpot force grow over the first 10 um of compression instead of
jumping to ``c v`` when a sleeper lands on the ballast: the force stays continuous,
which the implicit time step needs to converge (a jump makes its iteration cycle
between "open" and "closed"). 10 um is about a fifth of a bushing's compression under
the track's self-weight with the default bed stiffness (~50 um) and 1-2 % of it under
a wheel, so the dashpot works at full strength except right at touch-down.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

DAMPING_ONSET = 1e-5  # m: compression over which the dashpot force ramps in (see module doc)


@dataclass
class Ballast:
    """Arrays of all ballast bushings (length nb).

    Attributes
    ----------
    dof : ndarray of int
        Global coordinate of the sleeper node.
    k : ndarray
        Stiffness [N/m] (bed stiffness x tributary length x h1).
    c : ndarray
        Damping [N s/m].
    gap : ndarray
        Void gap [m].
    sleeper : ndarray of int
    y : ndarray
        Lateral position [m].
    area : ndarray
        Tributary sleeper-bottom area [m^2] (pressure = force / area).
    """

    dof: np.ndarray
    k: np.ndarray
    c: np.ndarray
    gap: np.ndarray
    sleeper: np.ndarray
    y: np.ndarray
    area: np.ndarray

    def forces(self, u: np.ndarray, v: np.ndarray | None = None) -> np.ndarray:
        """Force on the sleeper from each bushing [N] (up +).

        Parameters
        ----------
        u, v : ndarray, shape (..., nb)
            Displacement [m] and velocity [m/s] of the bushing nodes.
        """
        delta = -u - self.gap
        f = self.k * delta
        if v is not None:
            f = f - self.c * v * np.clip(delta / DAMPING_ONSET, 0.0, 1.0)
        return np.where(delta > 0.0, np.maximum(f, 0.0), 0.0)

    def subset(self, idx: np.ndarray) -> "Ballast":
        """The bushings ``idx`` alone (index array into the nb bushings)."""
        return Ballast(*(getattr(self, f)[idx] for f in ("dof", "k", "c", "gap", "sleeper", "y", "area")))

    def active(self, u: np.ndarray) -> np.ndarray:
        """Bushings in contact (compression > 0)."""
        return (-u - self.gap) > 0.0

    def tangent(self, u: np.ndarray, v: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Tangent stiffness and damping of each bushing at (u, v) (0 where open)."""
        on = self.active(u)
        if v is not None:
            on &= (self.k * (-u - self.gap) - self.c * v) > 0.0
        return np.where(on, self.k, 0.0), np.where(on, self.c, 0.0)

    def pressure(self, u: np.ndarray, v: np.ndarray | None = None) -> np.ndarray:
        """Sleeper-ballast contact pressure [Pa] per bushing (force / tributary area)."""
        return self.forces(u, v) / self.area
