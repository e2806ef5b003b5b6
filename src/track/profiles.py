"""Wheel and rail cross-section profiles for the wheel–rail contact geometry (issue 15).

Frames and signs
----------------
Every profile is a height function of a lateral coordinate, vectorised (arrays in, arrays out):

* Wheel: ``s`` [m] across the tread from the taping line (the nominal rolling circle), positive
  towards the field side, the flange at ``s < 0`` (back of the flange at ``s = -0.070``).
  :meth:`WheelProfile.radius_increment` is ``F(s) = r(s) - r0`` (flange: ``F > 0``);
  the wheel's surface, seen from the rail with the wheel centre at its nominal height, lies at
  ``z = -F(s)`` (up +, 0 = the taping circle's lowest point).
* Rail: ``u`` [m] from the head centre line, positive towards the field side; ``z`` [m] up from
  the crown top. Off the head the height is ``-inf`` (no surface).
* Crossing panel (:class:`CrossingSections`), per wheel side passing the nose: ``eta`` [m]
  outward (towards the field side of that wheel) from the through route's running edge ``L_t``;
  for a left-hand turnout's through route ``eta = y - g/2``.

S1002 wheel (EN 13715, the UIC 510-2 profile): eight sections, a polynomial of degree 8 on the
tread, of degree 7 at the flange root, circles and a straight 70-degree flank on the flange
(:data:`S1002_SECTIONS`). The coefficients are those of the standard's definition as reproduced
in open railway-dynamics teaching codes (the set attributed to H. Netter, DLR Oberpfaffenhofen,
used with the railway wheelset DAE example); the standard itself was not at hand. The tests check
them against the standard's characteristic dimensions (flange height 28 mm, flange thickness
32.5 mm and qR 10.8 mm of a new wheel, flank angle 70 degrees, back of the flange 70 mm from the
taping line) and the continuity of the sections.

Wear parameters of the wheel (:class:`WheelProfile`), each a smooth change of the new profile:
flange height (a vertical stretch of the flange above the 10 mm measuring height, tip raised by
the change), flange thickness (a lateral reparameterisation that moves the flange face, the back
of the flange and the tread fixed) and hollow wear (a cos^2 depression of the tread).

Hollow wear, the default band: wear removes material where the wheel runs, so the hollow is
centred on the running band and the unworn field side of the tread stands proud of it (the
"false flange", e.g. Fröhling, Ekberg & Kabo, "The detrimental effects of hollow wear — field
experiences and numerical simulations", Wear 265 (2008) 1283-1291). The default centre,
``s = +5 mm``, is where the centred new S1002 touches a 60E1 head inclined 1:40 (EN 13481, the
plain line's inclination on which a wheel wears; :mod:`track.contact_geometry` gives +4.9 mm,
``tests/test_profiles.py``); the default half width, 30 mm, spans the band the contact covers
within the flange clearance (-15 .. +13 mm on that rail for wheelset offsets of -5 .. +5 mm) with
the cos^2 flanks outside it, so the hollow reaches from the flange root (-25 mm; S1002's root
starts at -26 mm) to 35 mm on the field side, inside the tread (which ends at +60 mm): a false
flange from 35 to 60 mm. No published width or depth distribution of hollow bands was at hand:
band and depth are argued here, not taken from measurements.

Rail heads (:class:`RailHead`): 60E1 (EN 13674-1): crown radius R300, then R80, then the R13
gauge/field corners, head sides at 1:20, head width 72 mm. The standard's drawing (tangent
points) was not at hand; this module takes the R300/R80 tangent point at ``|u| = 10 mm`` and the
head side's lower end at (36 mm, 39.2 mm below the crown: the head envelope of the 60E1-like
polygon of :mod:`track.solid.section`), and solves the R80/R13 tangent point so the chain of
tangent arcs meets that side. 54E1 likewise (head width 70 mm, same radii, side to 37.0 mm
below the crown): an approximation of the same kind.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from .roots import bracketed_root

# ----------------------------------------------------------------------------- S1002
# Sections of S1002 in mm (s_mm from the taping line, field side +; F_mm = radius increment).
# (from, to, kind, coefficients): "poly": F = sum c_k s^k; "circle": F = a + sign*sqrt(R^2 - (s + c)^2).
S1002_SECTIONS = (
    (32.15796, 60.0, "poly", (1.364323640, -0.066666667)),                                      # A
    (-26.0, 32.15796, "poly", (0.0, -3.358537058e-02, 1.565681624e-03, -2.810427944e-05,
                               5.844240864e-08, -1.562379023e-08, 5.309217349e-15,
                               -5.957839843e-12, 2.646656573e-13)),                               # B
    (-35.0, -26.0, "poly", (-4.320221063e+03, -1.038384026e+03, -1.065501873e+02, -6.051367875,
                            -2.054332446e-01, -4.169739389e-03, -4.687195829e-05,
                            -2.252755540e-07)),                                                 # C
    (-38.426669071, -35.0, "circle", (16.446, -1.0, 13.0, 26.210665)),                           # D
    (-39.764473993, -38.426669071, "poly", (-93.576667419, -2.747477419)),                       # E
    (-49.662510381, -39.764473993, "circle", (8.834924130, 1.0, 20.0, 58.558326413)),            # F
    (-62.764705882, -49.662510381, "circle", (16.0, 1.0, 12.0, 55.0)),                           # G
    (-70.0, -62.764705882, "circle", (9.519259302, 1.0, 20.5, 49.5)),                            # H
)
S1002_S_MIN, S1002_S_MAX = -0.070, 0.060       # m, extent of the definition
S1002_FLANGE_HEIGHT = 0.028                     # m, top of section G's circle (16 + 12 mm)
FLANGE_MEASURING_HEIGHT = 0.010                 # m above the taping circle (flange thickness, EN 15313)
NOMINAL_WHEEL_RADIUS = 0.46                     # m, the bogie's wheel radius (vehicle.bogie)
TAPING_LINE_BACK = 0.070                        # m, back of the flange to the taping line (S1002)
BACK_TO_BACK = 1.360                            # m, wheelset back-to-back distance (EN 13260)


def s1002_mm(s_mm: np.ndarray) -> np.ndarray:
    """S1002 radius increment F [mm] at ``s_mm`` [mm] (NaN outside [-70, 60] mm)."""
    s = np.asarray(s_mm, dtype=float)
    out = np.full(s.shape, np.nan)
    for lo, hi, kind, c in S1002_SECTIONS:
        m = (s >= lo) & (s <= hi) & np.isnan(out)
        if not m.any():
            continue
        x = s[m]
        if kind == "poly":
            out[m] = np.polynomial.polynomial.polyval(x, c)
        else:
            a, sign, R, cc = c
            out[m] = a + sign * np.sqrt(np.clip(R * R - (x + cc) ** 2, 0.0, None))
    return out


def _smoothstep(t: np.ndarray) -> np.ndarray:
    """C1 ramp 0 -> 1 on t in [0, 1] (3t^2 - 2t^3), clipped outside."""
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _invert_monotone(f, target: np.ndarray, lo: float, hi: float, steps: int = 50) -> np.ndarray:
    """Vectorised bisection for ``f(x) = target`` with f increasing on [lo, hi]."""
    a = np.full(target.shape, lo)
    b = np.full(target.shape, hi)
    for _ in range(steps):
        m = 0.5 * (a + b)
        up = f(m) < target
        a = np.where(up, m, a)
        b = np.where(up, b, m)
    return 0.5 * (a + b)


@dataclass(frozen=True)
class WheelProfile:
    """A wheel profile: S1002 with wear parameters, or a measured table.

    Attributes
    ----------
    radius : float
        Nominal rolling radius at the taping line [m].
    flange_height : float
        Flange height above the taping circle [m] (S1002 new: 0.028). A larger value raises the
        flange tip; the flange is stretched vertically above the 10 mm measuring height.
    flange_thickness_change : float
        Change of the flange thickness at the measuring height [m] (negative: worn, thinner). The
        flange face moves by this much, the back of the flange and the tread stay.
    hollow_depth : float
        Depth of a hollow-worn tread [m] (material removed at the band centre, >= 0).
    hollow_centre, hollow_half_width : float
        Centre ``s`` and half width of the hollow band [m] (cos^2 shape, C1 at its edges).
    table : tuple of 2 arrays, optional
        Measured profile ``(s, F)`` [m] (F = radius increment, flange positive), ``s``
        increasing; replaces S1002 and the wear parameters (PCHIP interpolation, C1).
    """

    radius: float = NOMINAL_WHEEL_RADIUS
    flange_height: float = S1002_FLANGE_HEIGHT
    flange_thickness_change: float = 0.0
    hollow_depth: float = 0.0
    hollow_centre: float = 0.005
    hollow_half_width: float = 0.030
    table: tuple | None = field(default=None, compare=False)

    def __post_init__(self):
        if self.table is None:
            if not 0.012 <= self.flange_height <= 0.045:
                raise ValueError(f"flange_height: expected 0.012 .. 0.045 m, got {self.flange_height!r}")
            if not -0.006 <= self.flange_thickness_change <= 0.004:   # keeps s -> t monotone
                raise ValueError("flange_thickness_change: expected -0.006 .. 0.004 m, "
                                 f"got {self.flange_thickness_change!r}")
            if not 0.0 <= self.hollow_depth <= 0.006 or self.hollow_half_width <= 0.0:
                raise ValueError("hollow_depth: expected 0 .. 0.006 m with hollow_half_width > 0, "
                                 f"got {self.hollow_depth!r}, {self.hollow_half_width!r}")

    @cached_property
    def _table_interp(self):
        s, F = (np.asarray(v, dtype=float) for v in self.table)
        from scipy.interpolate import PchipInterpolator   # here: the import costs ~0.4 s of every start
        return PchipInterpolator(s, F, extrapolate=False)

    @property
    def s_range(self) -> tuple[float, float]:
        """Lateral extent [m] of the profile."""
        if self.table is not None:
            s = np.asarray(self.table[0], dtype=float)
            return float(s[0]), float(s[-1])
        return S1002_S_MIN, S1002_S_MAX

    def _flange_shift(self, s: np.ndarray) -> np.ndarray:
        """Lateral reparameterisation moving the flange face by the thickness change: the weight
        is 1 on the face (s in [-55, -36] mm), ramps to 0 towards the tread (-36 -> -20 mm) and
        to the back of the flange (-55 -> -66 mm); ``s -> s + dt w(s)`` stays monotone."""
        ramp_tread = 1.0 - _smoothstep((s + 0.036) / 0.016)
        ramp_back = _smoothstep((s + 0.066) / 0.011)
        return -self.flange_thickness_change * ramp_tread * ramp_back

    def radius_increment(self, s) -> np.ndarray:
        """``F(s) = r(s) - radius`` [m] at ``s`` [m] (NaN outside the profile)."""
        s = np.asarray(s, dtype=float)
        if self.table is not None:
            return self._table_interp(s)
        if self.flange_thickness_change != 0.0:
            # the profile at s is the new one at t with t + shift(t) = s (thinner: face moves to -s);
            # the shift vanishes outside (-66, -20) mm, so only s near there needs the inversion
            dt = abs(self.flange_thickness_change)
            m = (s > -0.066 - dt) & (s < -0.020 + dt)
            s = s.copy()
            s[m] = _invert_monotone(lambda t: t - self._flange_shift(t), s[m], -0.066 - 2 * dt, -0.020 + 2 * dt)
        F = 1e-3 * s1002_mm(1e3 * s)
        dh = self.flange_height - S1002_FLANGE_HEIGHT
        if dh != 0.0:
            h0 = FLANGE_MEASURING_HEIGHT
            F = F + dh * _smoothstep((F - h0) / (S1002_FLANGE_HEIGHT - h0))
        if self.hollow_depth > 0.0:
            t = (s - self.hollow_centre) / self.hollow_half_width
            F = F - self.hollow_depth * np.where(np.abs(t) < 1.0, np.cos(0.5 * np.pi * t) ** 2, 0.0)
        return F

    def height(self, s) -> np.ndarray:
        """Height of the wheel surface [m] over ``s`` with the wheel centre at its nominal height:
        ``-F(s)`` (the flange hangs below 0); NaN outside the profile."""
        return -self.radius_increment(s)

    def rolling_radius(self, s) -> np.ndarray:
        """Rolling radius [m] at ``s`` [m]."""
        return self.radius + self.radius_increment(s)


@dataclass(frozen=True)
class ConicalWheel:
    """A conical tread of conicity ``gamma`` (tan of the cone angle) without flange (verification
    profile; ``gamma = 0``: a cylinder). ``F(s) = -gamma s``: the radius falls towards the field side.

    Attributes
    ----------
    conicity : float
    radius : float
        Rolling radius at ``s = 0`` [m].
    half_width : float
        The tread spans ``|s| <= half_width`` [m].
    """

    conicity: float = 0.0
    radius: float = NOMINAL_WHEEL_RADIUS
    half_width: float = 0.07

    @property
    def s_range(self) -> tuple[float, float]:
        return -self.half_width, self.half_width

    def radius_increment(self, s) -> np.ndarray:
        s = np.asarray(s, dtype=float)
        return np.where(np.abs(s) <= self.half_width, -self.conicity * s, np.nan)

    def height(self, s) -> np.ndarray:
        return -self.radius_increment(s)

    def rolling_radius(self, s) -> np.ndarray:
        return self.radius + self.radius_increment(s)


# ----------------------------------------------------------------------------- rail heads
@dataclass(frozen=True)
class RailHead:
    """Symmetric rail head of tangent arcs (crown, shoulder, corner) and straight sides.

    Attributes
    ----------
    name : str
    width : float
        Head width at the lower end of the sides [m].
    radii : (float, float, float)
        Crown, shoulder and corner radii [m] (60E1: 0.300, 0.080, 0.013).
    crown_half_width : float
        ``|u|`` where the crown arc meets the shoulder arc [m].
    side_slope : float
        Inclination of the head sides, run per rise [-] (1:20 -> 0.05).
    side_depth : float
        Depth below the crown top of the sides' lower end [m].
    inclination : float
        Rotation of the section about the crown top [rad], positive tilting the surface normal
        towards ``-u`` (a rail inclined 1:40 towards the track centre when ``-u`` is the gauge
        side): the crown then rises towards ``+u`` with slope ``tan(inclination)`` at ``u = 0``.
    """

    name: str
    width: float
    radii: tuple = (0.300, 0.080, 0.013)
    crown_half_width: float = 0.010
    side_slope: float = 0.05
    side_depth: float = 0.0392
    inclination: float = 0.0

    @cached_property
    def _arcs(self) -> dict:
        """Tangent angles (of the outward normal, from vertical) and centres of the arc chain."""
        R1, R2, R3 = self.radii
        p1 = math.asin(self.crown_half_width / R1)
        p3 = math.atan2(1.0, self.side_slope)          # side normal: (1, slope) direction

        def chain(p2):
            c1 = np.array([0.0, -R1])
            c2 = c1 + (R1 - R2) * np.array([math.sin(p1), math.cos(p1)])
            c3 = c2 + (R2 - R3) * np.array([math.sin(p2), math.cos(p2)])
            end = c3 + R3 * np.array([math.sin(p3), math.cos(p3)])
            return c1, c2, c3, end

        def miss(p2):
            end = chain(p2)[3]
            u_bottom = end[0] + self.side_slope * (end[1] + self.side_depth)
            return u_bottom - 0.5 * self.width

        p2 = bracketed_root(miss, p1 + 1e-9, p3 - 1e-9, 1e-14)
        c1, c2, c3, end = chain(p2)
        return dict(p=(p1, p2, p3), c=(c1, c2, c3), end=end)

    def _upright(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Height [m] and curvature [1/m] (convex +) of the uninclined head at ``|u|``."""
        R = self.radii
        a = self._arcs
        c1, c2, c3 = a["c"]
        au = np.abs(u)
        u1 = R[0] * math.sin(a["p"][0])
        u2 = c2[0] + R[1] * math.sin(a["p"][1])
        u3 = a["end"][0]
        u4 = 0.5 * self.width
        z = np.full(au.shape, -np.inf)
        k = np.zeros(au.shape)
        for lo, hi, c, r in ((0.0, u1, c1, R[0]), (u1, u2, c2, R[1]), (u2, u3, c3, R[2])):
            m = (au >= lo) & (au <= hi)
            z[m] = c[1] + np.sqrt(np.clip(r * r - (au[m] - c[0]) ** 2, 0.0, None))
            k[m] = 1.0 / r
        m = (au > u3) & (au <= u4)
        z[m] = a["end"][1] - (au[m] - u3) / self.side_slope
        return z, k

    def height(self, u) -> np.ndarray:
        """Height of the head surface [m] at ``u`` [m] (``-inf`` off the head)."""
        return self.height_and_curvature(u)[0]

    def height_and_curvature(self, u) -> tuple[np.ndarray, np.ndarray]:
        """Height [m] and lateral curvature [1/m] (convex +) at ``u`` [m].

        With an inclination the section is rotated about the crown top: the point of the upright
        head that lands at ``u`` is found by Newton's method (3 steps, the rotation is small).
        """
        u = np.asarray(u, dtype=float)
        th = self.inclination
        if th == 0.0:
            return self._upright(u)
        c, s = math.cos(th), math.sin(th)
        # rotation by th (counter-clockwise in (u, z)): (v, z) -> (v c - z s, v s + z c); the upright
        # abscissa v of the point landing at u solves v c - z(v) s = u
        v = u.copy()
        h = 1e-7
        for _ in range(4):
            z, _ = self._upright(v)
            with np.errstate(invalid="ignore"):                # -inf - -inf off the head
                zp = (self._upright(v + h)[0] - self._upright(v - h)[0]) / (2 * h)
            fz = np.where(np.isfinite(z), z, 0.0)
            fzp = np.where(np.isfinite(zp), zp, 0.0)
            v = v - (v * c - fz * s - u) / (c - fzp * s)
        z, k = self._upright(v)
        return v * s + z * c, k


RAIL_HEADS = {
    "60E1": RailHead("60E1", width=0.072),
    "54E1": RailHead("54E1", width=0.070, side_depth=0.0370),
}
INCLINATION_1_40 = math.atan(1.0 / 40.0)   # rad, plain-line rail inclination (EN 13481, 1:40)


# ----------------------------------------------------------------------------- crossing panel
def _smooth_along(stations, values):
    """A C1 monotone-piecewise (PCHIP) function of x through ``(stations, values)``, held constant
    outside; zero when no stations are given."""
    if stations is None or len(stations) == 0:
        return lambda x: np.zeros(np.shape(x))
    xs = np.asarray(stations, dtype=float)
    vs = np.asarray(values, dtype=float)
    if xs.size == 1:
        return lambda x: np.full(np.shape(x), float(vs[0]))
    from scipy.interpolate import PchipInterpolator   # here: the import costs ~0.4 s of every start
    f = PchipInterpolator(xs, vs, extrapolate=False)
    return lambda x: f(np.clip(np.asarray(x, dtype=float), xs[0], xs[-1]))


@dataclass(frozen=True)
class CrossingSections:
    """Wing rail and nose cross-sections along a crossing panel, for the wheel side at the nose.

    Lateral coordinate ``eta`` [m]: outward from the through route's running edge ``L_t`` (module
    docstring). The wing rail's running edge (gauge corner) is at ``eta_w(x) = max(0, sep(x) +
    flangeway)`` with ``sep(x)`` the signed separation ``L_d - L_t`` of the layout
    (:meth:`track.layout.TurnoutGeometry.separation`: a flare at the crossing angle behind the
    throat); its head is the rail head (:class:`RailHead`) beside it, up to ``x_tcp + wing_end``.
    The nose spans ``eta`` in ``[0, sep(x)]`` where ``sep >= tip_width``: two rail heads cut to
    the nose (:meth:`nose`), optionally lowered by a design drop ``tip_drop * (1 - sep /
    full_width)`` near its tip. Wear: ``nose_wear(x)``, ``wing_wear(x)`` [m] (height loss) are
    PCHIP (C1) functions through stations ``x - x_tcp`` [m].

    Attributes
    ----------
    x_tcp : float
        Theoretical crossing point [m].
    separation : callable
        ``sep(x)`` [m], array in, array out.
    head : RailHead
    flangeway, wing_end, tip_width, tip_drop, full_width : float
        [m]; defaults: track.layout.FLANGEWAY, CROSSING_WING_END, the solid crossing's nose tip
        (12 mm, track.solid.crossing.NOSE_TIP_WIDTH), and a design lowering of the nose top of
        4 mm at the theoretical point vanishing at 40 mm nose width: this module's design value,
        not from a drawing, chosen so that the centred new S1002 wheel transfers from the wing
        rail to the nose at the layout's nominal 20 mm nose width
        (track.layout.NOSE_WIDTH_AT_TRANSFER; tests/test_contact_geometry.py checks it). Without
        it (``tip_drop = 0``) the heads' ridge stands 1-2 mm above the falling wheel at 12-20 mm
        and the wheel would strike the nose tip.
    nose_wear_stations, nose_wear, wing_wear_stations, wing_wear : tuple of float
        Wear (height loss, m) at stations ``x - x_tcp`` [m].
    """

    x_tcp: float
    separation: object
    head: RailHead = field(default_factory=lambda: RAIL_HEADS["60E1"])
    flangeway: float = 0.041
    wing_end: float = 1.8
    tip_width: float = 0.012
    tip_drop: float = 0.004
    full_width: float = 0.040
    nose_wear_stations: tuple = ()
    nose_wear: tuple = ()
    wing_wear_stations: tuple = ()
    wing_wear: tuple = ()

    @classmethod
    def from_layout(cls, layout, **kw) -> "CrossingSections":
        """Sections of a turnout :class:`track.layout.Layout` (``layout.geometry()``'s separation,
        the layout's flangeway and wing-rail end); ``kw`` sets the other attributes.

        Written for the wheel of the through route that passes the nose (``layout.crossing_side``).
        The crossing is symmetric about its bisector, so the wheel of the diverging route sees
        the same sections with x along the through route (its own path is longer by
        1/cos(angle): 0.3 % at 1:13); a right-hand turnout is the mirror image (``eta`` is always
        outward from the running edge)."""
        from .layout import CROSSING_WING_END, FLANGEWAY
        geo = layout.geometry()
        if geo is None:
            raise ValueError("layout: a crossing panel needs a turnout layout (type: turnout)")
        head = RAIL_HEADS.get(layout.params.rail, RAIL_HEADS["60E1"])
        kw.setdefault("head", head)
        return cls(x_tcp=float(layout.x_tcp), separation=geo.separation, flangeway=FLANGEWAY,
                   wing_end=CROSSING_WING_END, **kw)

    def _wear(self, which: str, x):
        st = getattr(self, f"{which}_wear_stations")
        return _smooth_along(np.asarray(st, dtype=float) + self.x_tcp if len(st) else None,
                             getattr(self, f"{which}_wear"))(x)

    def wing_edge(self, x) -> np.ndarray:
        """``eta`` of the wing (or closure) rail's running edge [m] at ``x`` [m]."""
        return np.maximum(0.0, np.asarray(self.separation(x), dtype=float) + self.flangeway)

    def nose_width(self, x) -> np.ndarray:
        """Nose top width [m] at ``x`` (0 where there is no nose yet)."""
        s = np.asarray(self.separation(x), dtype=float)
        return np.where(s >= self.tip_width, s, 0.0)

    def wing(self, x, eta) -> tuple[np.ndarray, np.ndarray]:
        """Height [m] and lateral curvature [1/m] of the wing rail at ``(x, eta)`` (broadcast);
        ``-inf`` off the head and behind the wing rail's end."""
        x, eta = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(eta, dtype=float))
        u = eta - self.wing_edge(x) - 0.5 * self.head.width
        z, k = self.head.height_and_curvature(u)
        z = z - self._wear("wing", x)
        return np.where(x <= self.x_tcp + self.wing_end, z, -np.inf), k

    def nose(self, x, eta) -> tuple[np.ndarray, np.ndarray]:
        """Height [m] and lateral curvature [1/m] of the nose at ``(x, eta)`` (broadcast); ``-inf``
        off the nose.

        The nose of width ``w`` is the rail head with its gauge corner on ``L_t`` (``eta = 0``) cut
        by the mirrored head with its gauge corner on ``L_d`` (``eta = w``): the lower of the two
        where both exist. A narrow nose is thus a ridge of the heads' corner and shoulder arcs,
        lower than the crown (4.6 mm at the 12 mm tip, 60E1). From ``w = head width`` on the nose is
        the two rails side by side, each cut along the nose's centre line ``eta = w / 2`` (taking
        the lower head there would open a cliff of the second head's field-side flank in the middle
        of the nose; at ``w = head width`` both rules give the crown, to the rails' 1:40 cant).
        Then the design drop and the wear are subtracted.
        """
        x, eta = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(eta, dtype=float))
        w = self.nose_width(x)
        hw = 0.5 * self.head.width
        z1, k1 = self.head.height_and_curvature(eta - hw)
        z2, k2 = self.head.height_and_curvature(w - eta - hw)
        both = np.isfinite(z1) & np.isfinite(z2)
        split = w >= self.head.width              # two rails side by side, cut along the nose's centre line
        use2 = np.where(both, np.where(split, eta >= 0.5 * w, z2 < z1), np.isfinite(z2))
        z = np.where(use2, z2, z1)
        k = np.where(use2, k2, k1)
        on = (w > 0.0) & (eta >= 0.0) & (eta <= w) & np.isfinite(z)
        drop = self.tip_drop * np.clip(1.0 - w / self.full_width, 0.0, 1.0)
        z = z - drop - self._wear("nose", x)
        return np.where(on, z, -np.inf), np.where(on, k, 0.0)


@dataclass(frozen=True)
class PlainRail:
    """A plain rail head at ``eta`` [m] of its centre line (the running edge at ``eta_c - width/2``),
    the same interface as the crossing sections for a wheel off the crossing.

    Attributes
    ----------
    head : RailHead
    centre : float
        ``eta`` of the head centre [m]; default: half a head width outside the running edge.
    """

    head: RailHead = field(default_factory=lambda: RAIL_HEADS["60E1"])
    centre: float | None = None

    def rail(self, x, eta) -> tuple[np.ndarray, np.ndarray]:
        """Height [m] and lateral curvature [1/m] at ``(x, eta)``."""
        x, eta = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(eta, dtype=float))
        c = 0.5 * self.head.width if self.centre is None else self.centre
        return self.head.height_and_curvature(eta - c)
