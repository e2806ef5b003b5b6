"""Wheel–rail normal contact and the vertical geometry of the running surfaces.

Hertz normal contact per wheel and per rail surface it can touch:

    F_k = C_H max(0, delta_k)^(3/2),   delta_k = z_k(x) + w(x) - z_wheel

with ``z_k(x)`` the height of surface k under the wheel relative to the nominal
running level (crossing geometry or an irregularity) [m], ``w(x)`` the rail
deflection there (up +) [m] and ``z_wheel`` the wheel's vertical position, zero
when it just touches the undeformed nominal rail [m]. A wheel on the crossing has
two surfaces, the wing rail and the nose, so the wheel transfer from one to the
other follows from the geometry.

Crossing geometry (seed 001 §5, Fig. 2) parameterized by the impact (dip) angle
``beta``: behind the theoretical crossing point (TCP) the wing rail, as seen by the
coned wheel moving outward on it, falls with slope ``beta_w``; the nose rises with
slope ``beta_n`` and meets the wing-rail level at the transfer point; the vertical
heading of the wheel changes there by ``beta = beta_w + beta_n`` (the impact angle).
The nose reaches the nominal level at ``x_full`` and stays there. A measured
geometry can be given as a table of (x, z_wing, z_nose) instead.

Profile contact (:class:`TableGeometry`): the surface heights ``z_k`` and the Hertz constants
``C_k`` (vertical force per vertical approach^1.5) of each surface are looked up bilinearly in
tables over x and the wheelset's lateral offset y built from the wheel and rail profiles
(:mod:`track.contact_geometry`); the force law is the same per surface, with its own constant
(:func:`hertz_pair`).
"""
from __future__ import annotations

from dataclasses import dataclass
from math import sqrt

import numpy as np

HERTZ_CONSTANT = 87e9   # N/m^1.5: DESIGN.md §7, typical for a 0.46 m wheel on a 60E1 head
NO_SURFACE = -1.0       # m: height given to a surface that is absent (never touched)
WING_SHARE = 0.5        # share of the impact angle taken by the falling wing rail
JOINT_RAMP = 1.5        # m: length of each ramp of the V-shaped dipped joint


@dataclass(frozen=True)
class Flat:
    """A nominal running surface (one surface at height 0)."""

    def heights(self, x: float) -> tuple[float, float]:
        return flat_heights(x)


@dataclass(frozen=True)
class CrossingGeometry:
    """Vertical geometry of wing rail and nose for the wheel that passes the crossing.

    Attributes
    ----------
    x_tcp : float
        Theoretical crossing point [m].
    x_transfer : float
        Nominal transfer point wing rail -> nose [m] (> x_tcp).
    impact_angle : float
        beta [rad] (6 mrad nominal, 12 worn, 18 severely worn; seed 001 §5).
    table : tuple of 3 arrays, optional
        Measured geometry (x, z_wing, z_nose) [m]; replaces the parameterization.
        Outside the table the surfaces keep their end values; NaN means absent.
    """

    x_tcp: float
    x_transfer: float
    impact_angle: float
    table: tuple | None = None

    @property
    def dip_depth(self) -> float:
        """Depth of the wing rail under the nominal level at the transfer point [m]."""
        return -crossing_heights(self.x_transfer, self.x_tcp, self.x_transfer, self.impact_angle)[0]

    def heights(self, x: float) -> tuple[float, float]:
        """Heights (z_wing, z_nose) [m] at track coordinate x."""
        if self.table is not None:
            xt, zw, zn = self.table
            a = float(np.interp(x, xt, zw))
            b = float(np.interp(x, xt, zn))
            return (NO_SURFACE if np.isnan(a) else a), (NO_SURFACE if np.isnan(b) else b)
        return crossing_heights(x, self.x_tcp, self.x_transfer, self.impact_angle)


@dataclass(frozen=True)
class DippedJoint:
    """V-shaped dip of total angle ``angle`` [rad] at ``x_joint`` [m] (Jenkins et al. 1974).

    The surface falls with slope angle/2 over JOINT_RAMP before the joint and rises
    with the same slope after it; the wheel's heading changes by ``angle`` at the
    joint.
    """

    x_joint: float
    angle: float

    def heights(self, x: float) -> tuple[float, float]:
        return joint_heights(x, self.x_joint, self.angle)


# The geometry as plain functions of floats: the compiled track step (track.kernel) compiles
# these same functions, as it does hertz.
def flat_heights(x: float) -> tuple[float, float]:
    """Heights [m] of the nominal running surface (:class:`Flat`): one surface at 0."""
    return 0.0, NO_SURFACE


def crossing_heights(x: float, x_tcp: float, x_transfer: float, impact_angle: float) -> tuple[float, float]:
    """Heights (z_wing, z_nose) [m] at track coordinate x [m] of the parameterized crossing
    (:class:`CrossingGeometry` without a table)."""
    if x <= x_tcp:
        return 0.0, NO_SURFACE
    bw = WING_SHARE * impact_angle
    bn = impact_angle - bw
    z_wing = -bw * (x - x_tcp)
    dip = bw * (x_transfer - x_tcp)                      # wing-rail depth at the transfer point
    z_nose = min(0.0, -dip + bn * (x - x_transfer))
    return z_wing, max(z_nose, NO_SURFACE)


def joint_heights(x: float, x_joint: float, angle: float) -> tuple[float, float]:
    """Heights [m] at track coordinate x [m] of the V-shaped dipped joint (:class:`DippedJoint`)."""
    d = abs(x - x_joint)
    return (-0.5 * angle * (JOINT_RAMP - d) if d < JOINT_RAMP else 0.0), NO_SURFACE


def hertz(w: float, z_wheel: float, surfaces: tuple[float, float], c_h: float = HERTZ_CONSTANT
          ) -> tuple[float, float, float, float]:
    """Contact force of one wheel on its (up to two) surfaces.

    Parameters
    ----------
    w : float
        Rail deflection under the wheel [m] (up +).
    z_wheel : float
        Wheel vertical position [m] (up +).
    surfaces : (float, float)
        Surface heights [m] (:data:`NO_SURFACE` where absent).
    c_h : float
        Hertz constant [N/m^1.5].

    Returns
    -------
    F : float
        Total contact force on the wheel [N] (up +, >= 0).
    dF_dw : float
        Derivative with respect to the rail deflection [N/m].
    F1, F2 : float
        Force on each surface [N].
    """
    return hertz_pair(w, z_wheel, surfaces[0], surfaces[1], c_h, c_h)


def hertz_pair(w: float, z_wheel: float, z1: float, z2: float, c1: float, c2: float
               ) -> tuple[float, float, float, float]:
    """:func:`hertz` with a Hertz constant per surface (``c1``, ``c2`` [N/m^1.5]): the same
    operations, so with ``c1 = c2 = c_h`` the same numbers to the last bit."""
    d1 = z1 + w - z_wheel
    d2 = z2 + w - z_wheel
    F1 = F2 = k = 0.0
    if d1 > 0.0:
        s = sqrt(d1)
        F1 = c1 * d1 * s
        k += 1.5 * c1 * s
    if d2 > 0.0:
        s = sqrt(d2)
        F2 = c2 * d2 * s
        k += 1.5 * c2 * s
    return F1 + F2, k, F1, F2


def table_surface(xw: float, yw: float, grid, tz, tc) -> tuple[float, float, float, float]:
    """Bilinear lookup of one contact table (:class:`TableGeometry`) at track coordinate ``xw`` and
    lateral offset ``yw`` [m] (clipped to the grid): ``(z1, z2, c1, c2)``.

    ``grid = (x0, dx, nx, y0, dy, ny)``; ``tz``, ``tc`` (2, NX, NY) with NaN where a surface is
    absent. A surface with a NaN corner in the cell is absent there (height :data:`NO_SURFACE`,
    constant 0).
    """
    x0, dx, nx, y0, dy, ny = grid[0], grid[1], int(grid[2]), grid[3], grid[4], int(grid[5])
    tx = min(max((xw - x0) / dx, 0.0), nx - 1.0)
    ix = min(int(tx), nx - 2)
    fx = tx - ix
    ty = min(max((yw - y0) / dy, 0.0), ny - 1.0)
    iy = min(int(ty), ny - 2)
    fy = ty - iy
    w00, w10, w01, w11 = (1.0 - fx) * (1.0 - fy), fx * (1.0 - fy), (1.0 - fx) * fy, fx * fy
    z1 = w00 * tz[0, ix, iy] + w10 * tz[0, ix + 1, iy] + w01 * tz[0, ix, iy + 1] + w11 * tz[0, ix + 1, iy + 1]
    z2 = w00 * tz[1, ix, iy] + w10 * tz[1, ix + 1, iy] + w01 * tz[1, ix, iy + 1] + w11 * tz[1, ix + 1, iy + 1]
    c1 = w00 * tc[0, ix, iy] + w10 * tc[0, ix + 1, iy] + w01 * tc[0, ix, iy + 1] + w11 * tc[0, ix + 1, iy + 1]
    c2 = w00 * tc[1, ix, iy] + w10 * tc[1, ix + 1, iy] + w01 * tc[1, ix, iy + 1] + w11 * tc[1, ix + 1, iy + 1]
    if not (z1 == z1):          # NaN: absent at a corner
        z1, c1 = NO_SURFACE, 0.0
    if not (z2 == z2):
        z2, c2 = NO_SURFACE, 0.0
    return z1, z2, c1, c2


@dataclass(frozen=True, eq=False)
class TableGeometry:
    """Surface heights and Hertz constants from a contact table (profile contact).

    Attributes
    ----------
    grid : ndarray (6,)
        ``(x0, dx, nx, y0, dy, ny)`` of the regular grid (nx, ny >= 2).
    z : ndarray (2, nx, ny)
        Surface heights [m] (:mod:`track.contact_geometry`'s ``z``; NaN where absent).
    c : ndarray (2, nx, ny)
        Vertical Hertz constants [N/m^1.5] (``C_vertical``).
    table : object
        The :class:`track.contact_geometry.ContactTable` it was made from (outputs).
    """

    grid: np.ndarray
    z: np.ndarray
    c: np.ndarray
    table: object = None

    def heights(self, x: float, y: float = 0.0) -> tuple[float, float]:
        """Heights (z1, z2) [m] at track coordinate x and lateral offset y."""
        return table_surface(x, y, self.grid, self.z, self.c)[:2]

    def constants(self, x: float, y: float = 0.0) -> tuple[float, float]:
        """Hertz constants (c1, c2) [N/m^1.5] at x, y."""
        return table_surface(x, y, self.grid, self.z, self.c)[2:]


def hertz_deflection(F: float, c_h: float = HERTZ_CONSTANT) -> float:
    """Contact compression delta [m] under a force F [N] (inverse of Hertz)."""
    return (max(F, 0.0) / c_h) ** (2.0 / 3.0)
