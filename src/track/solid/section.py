"""Rail cross-section as a polygon: geometry, section properties, shear coefficient.

Coordinates of a section are ``(y, z)`` [m]: ``y`` lateral (the section is
symmetric about ``y = 0``), ``z`` vertical upward with ``z = 0`` at the foot
bottom. The solid is extruded from this polygon along ``x`` (the rail axis), so
the solid's frame is the beam frame of :mod:`track.elements`: vertical bending
is bending about the lateral ``y`` axis.

The 60E1-like polygon (:func:`rail_60e1_like`) keeps the 60E1 envelope (height
172 mm, head 72 mm, foot 150 mm) and straight-line versions of its parts (foot
with sloped top, web with chamfered fillets, head with sloped fishing surfaces
and a chamfered crown). Web thickness and head depth were fitted once so that the
polygon's area and vertical second moment hit 60E1 (76.70 cm^2, 3038 cm^4); the
fitted numbers are rounded to 0.1 mm, leaving errors of +0.014 % and +0.001 %
(tests/test_solid.py recomputes them). Its centroid is 81.5 mm above the foot
(60E1: 80.9 mm = I / W_foot).

The Timoshenko shear coefficient of a polygon is computed by
:func:`track.solid.fem.shear_coefficient` (2D finite elements, see there) rather than taken
from the 0.34-0.40 literature range, so that a beam and a solid of the same
polygon can be compared like with like.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

# The fitted 60E1-like shape [m]; see the module docstring. The names follow the
# sketch in RailShape.polygon().
_60E1_LIKE = dict(height=0.172, head_width=0.072, foot_width=0.150, web_thickness=0.0189,
                  foot_edge=0.0115, foot_slope=6.0, head_underside=0.1274, head_side_top=0.160,
                  fillet=0.005)


@dataclass(frozen=True)
class SectionProperties:
    """Area properties of a plane section.

    Attributes
    ----------
    A : float
        Area [m^2].
    centroid : ndarray, shape (2,)
        ``(y_c, z_c)`` [m].
    I_y : float
        Second moment about the lateral axis through the centroid,
        ``int (z - z_c)^2 dA`` [m^4] (vertical bending).
    I_z : float
        Second moment about the vertical axis through the centroid,
        ``int (y - y_c)^2 dA`` [m^4] (lateral bending).
    I_yz : float
        Product moment ``int (y - y_c)(z - z_c) dA`` [m^4] (0 for a symmetric section).
    """

    A: float
    centroid: np.ndarray
    I_y: float
    I_z: float
    I_yz: float


def polygon_properties(vertices: np.ndarray) -> SectionProperties:
    """Exact area properties of a simple polygon (Green's theorem).

    Parameters
    ----------
    vertices : ndarray, shape (k, 2)
        Corner points ``(y, z)`` [m], counter-clockwise, not repeating the first.

    Returns
    -------
    SectionProperties
    """
    P = np.asarray(vertices, dtype=float)
    y, z = P[:, 0], P[:, 1]
    y1, z1 = np.roll(y, -1), np.roll(z, -1)
    cr = y * z1 - y1 * z
    A = 0.5 * cr.sum()
    if A <= 0.0:
        raise ValueError("polygon must be counter-clockwise with positive area")
    yc = ((y + y1) * cr).sum() / (6.0 * A)
    zc = ((z + z1) * cr).sum() / (6.0 * A)
    Iyy0 = ((z * z + z * z1 + z1 * z1) * cr).sum() / 12.0          # int z^2 dA
    Izz0 = ((y * y + y * y1 + y1 * y1) * cr).sum() / 12.0          # int y^2 dA
    Iyz0 = ((y * z1 + 2 * y * z + 2 * y1 * z1 + y1 * z) * cr).sum() / 24.0
    return SectionProperties(A=A, centroid=np.array([yc, zc]), I_y=Iyy0 - A * zc * zc,
                             I_z=Izz0 - A * yc * yc, I_yz=Iyz0 - A * yc * zc)


@dataclass(frozen=True)
class RailShape:
    """Parameters of a symmetric flat-bottom rail polygon [m].

    Sketch of the right half (``y >= 0``), from the foot bottom counter-clockwise::

        z                     crown: chamfers to (0, height)
        |        ____________
        |       |            |  head side: x = head_width/2, from the fishing
        |       |____        |  surface up to head_side_top
        |        \\    `-----'   fishing surface (slope 1:4) down to the web
        |         |             web: y = web_thickness/2, fillet chamfers at both ends
        |      __/ `-----.__    foot top (slope 1:foot_slope) down to foot_edge
        |_____|_____________|   foot bottom, width foot_width
        0                  y

    Attributes
    ----------
    height, head_width, foot_width, web_thickness : float
        [m].
    foot_edge : float
        Foot thickness at its edge [m].
    foot_slope : float
        Foot top slope 1:n, given as n [-].
    head_underside : float
        Height of the head underside where it meets the web (after the fillet) [m].
    head_side_top : float
        Height where the head side meets the crown chamfers [m].
    fillet : float
        Leg length of the 45-degree chamfers that stand in for the web fillets [m].
    """

    height: float
    head_width: float
    foot_width: float
    web_thickness: float
    foot_edge: float
    foot_slope: float
    head_underside: float
    head_side_top: float
    fillet: float

    def polygon(self) -> np.ndarray:
        """Counter-clockwise corner points ``(y, z)`` [m], shape (k, 2)."""
        hw, bf, bh, c = 0.5 * self.web_thickness, 0.5 * self.foot_width, 0.5 * self.head_width, self.fillet
        z_foot = self.foot_edge + (bf - hw - c) / self.foot_slope     # foot top at the fillet
        z_fish = self.head_underside + (bh - hw - c) / 4.0             # fishing surface 1:4 at the head side
        H = self.height
        crown = [(bh - 0.0025, H - 0.004), (bh - 0.012, H - 0.001), (bh - 0.026, H)]
        right = [(bf, 0.0), (bf, self.foot_edge), (hw + c, z_foot), (hw, z_foot + c),
                 (hw, self.head_underside - c), (hw + c, self.head_underside), (bh, z_fish),
                 (bh, self.head_side_top), *crown]
        left = [(-y, z) for (y, z) in reversed(right)]
        return np.array(right + left, dtype=float)


@dataclass(frozen=True, eq=False)
class RailSection:
    """A rail cross-section polygon plus the longitudinal lines the solid mesh must contain.

    Attributes
    ----------
    vertices : ndarray, shape (k, 2)
        Counter-clockwise corners ``(y, z)`` [m].
    name : str
    """

    vertices: np.ndarray
    name: str = "section"
    _props: SectionProperties = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        object.__setattr__(self, "vertices", np.asarray(self.vertices, dtype=float))
        object.__setattr__(self, "_props", polygon_properties(self.vertices))

    @property
    def properties(self) -> SectionProperties:
        return self._props

    @property
    def height(self) -> float:
        return float(np.ptp(self.vertices[:, 1]))

    @property
    def top(self) -> float:
        """Height of the running surface (highest vertex) [m]."""
        return float(self.vertices[:, 1].max())

    def with_points(self, points: np.ndarray) -> "RailSection":
        """The same polygon with extra corners inserted at ``points`` on its edges.

        Every polygon corner becomes a longitudinal line of the extruded solid,
        hence a line of mesh nodes: inserting ``(+-b, 0)`` gives node lines under
        the two bushings of a rail seat, ``(y_c, top)`` the contact path on the
        running surface.

        Parameters
        ----------
        points : ndarray, shape (p, 2)
            Points ``(y, z)`` [m] on the polygon boundary (within 1e-9 m).

        Returns
        -------
        RailSection
        """
        P = [tuple(v) for v in self.vertices]
        for q in np.atleast_2d(np.asarray(points, dtype=float)):
            if any(np.hypot(q[0] - v[0], q[1] - v[1]) < 1e-9 for v in P):
                continue
            for i in range(len(P)):
                a, b = np.array(P[i]), np.array(P[(i + 1) % len(P)])
                ab = b - a
                t = float(np.dot(q - a, ab) / np.dot(ab, ab))
                if 0.0 < t < 1.0 and np.linalg.norm(a + t * ab - q) < 1e-9:
                    P.insert(i + 1, (float(q[0]), float(q[1])))
                    break
            else:
                raise ValueError(f"point {tuple(q)} is not on the section boundary")
        return RailSection(np.array(P), self.name)


def rail_60e1_like() -> RailSection:
    """The 60E1-like polygon (A = 76.71 cm^2, I_y = 3038.0 cm^4, centroid 81.5 mm)."""
    return RailSection(RailShape(**_60E1_LIKE).polygon(), name="60E1-like")


__all__ = ["SectionProperties", "polygon_properties", "RailShape", "RailSection", "rail_60e1_like"]
