"""Wheel–rail contact geometry tables over track position x and lateral wheelset offset y.

For one wheel and the rail surfaces it can touch (a plain rail; or the wing rail and the nose of
a crossing, :class:`track.profiles.CrossingSections`), and for every ``(x, y)`` of a grid, the
contact point on each surface is where the vertical gap between the wheel profile and the rail
section is smallest (the rigid wheel lowered onto the undeformed rail touches there first):

    d(eta) = z_rail(x, eta) - z_wheel(s),   s = eta - eta_tl - y,
    z_k(x, y) = max_eta d(eta) - z_ref

``z_wheel(s) = -F(s)`` is the wheel surface with the wheel centre at its nominal height
(:class:`track.profiles.WheelProfile`), ``eta_tl`` the taping line's ``eta`` for the centred
wheelset (``(back-to-back + 2 x 70 mm - gauge) / 2 = 32.5 mm`` outside the running edge for
1435 mm gauge) and ``y`` the wheelset's lateral offset towards this wheel's field side. ``z_k`` is
how far the wheel centre must rise for the wheel to just touch surface k: the surface height of
:mod:`track.contact`'s law ``delta_k = z_k + w - z_wheel``, relative to ``z_ref``, the same
quantity for the centred wheel on the plain rail (so the plain rail gives 0, as in the dip model).

Per contact the table also holds the lateral positions on rail (``eta``) and wheel (``s``), the
rolling radius ``r0 + F(s)``, the contact angle ``atan(dz_wheel/ds)``, the relative curvatures
``A`` (rolling direction, ``cos(angle)/r``, :func:`track.hertz.relative_curvatures`) and ``B``
(lateral: the wheel's and the rail's curvature, convex +, as the equivalent curvature of the gap
over the patch, :func:`_gap_curvature`: ``B = -d''/2 cos(angle)^3`` from the least-squares parabola
through the gap within :data:`PATCH_HALF_WIDTH` of the contact; where that has too few samples,
the two profiles' curvatures at the point), the Hertz constant
``C`` (:func:`track.hertz.hertz_constant`, NaN where the contact is conformal or concave:
``B <= 0``) and ``C_vertical = C cos(angle)^2.5`` (vertical force per vertical approach^1.5, the
normal approach being ``cos(angle)`` times the vertical one and the force's vertical part
``cos(angle)`` times the normal force).

Method: the profiles are sampled on a lateral grid of step ``d_eta`` (0.1 mm default) and the
maximum of ``d`` refined by the parabola through the three samples around it (its error for a
smooth gap function is O(d_eta^3 d''') in position and smaller in height). One contact point per
surface (the highest); a second point on the same surface (tread and flange root at once) is not
resolved. The wheelset's roll (the other wheel) and yaw are neglected: each wheel is tabulated
alone, as the vertical kernel treats it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .hertz import equivalent_modulus, hertz_constant, relative_curvatures
from .profiles import BACK_TO_BACK, TAPING_LINE_BACK, PlainRail

FIELDS = ("z", "eta", "s", "radius", "angle", "A", "B", "C", "C_vertical")
D_ETA = 1e-4          # m, lateral sampling step of the profiles
CHUNK = 2_000_000     # gap samples per block (memory ~ 16 MB a block)
_WHEEL_DIFF = 1e-5    # m, step of the wheel profile's central differences (slope, curvature)


def taping_line_offset(gauge: float = 1.435) -> float:
    """``eta`` of the taping line of the centred wheelset [m], outside the running edge:
    ``(back-to-back + 2 x 70 mm - gauge) / 2`` (EN 13260 / S1002; 32.5 mm at 1435 mm)."""
    return 0.5 * (BACK_TO_BACK + 2.0 * TAPING_LINE_BACK - gauge)


@dataclass(frozen=True)
class ContactTable:
    """Contact geometry on a regular ``(x, y)`` grid, per surface.

    Attributes
    ----------
    x : ndarray (nx,)
        Track positions [m] (increasing, evenly spaced).
    y : ndarray (ny,)
        Lateral wheelset offsets [m] (increasing, evenly spaced).
    surfaces : tuple of str
        Surface names (``("rail",)`` or ``("wing", "nose")``).
    data : dict
        ``data[field]``: ndarray (nsurf, nx, ny) for each of :data:`FIELDS`; ``z`` is ``-inf``
        and the rest NaN where a surface is absent.
    z_ref : float
        Reference removed from ``z`` [m] (module docstring).
    """

    x: np.ndarray
    y: np.ndarray
    surfaces: tuple
    data: dict
    z_ref: float

    def lookup(self, field: str, x, y) -> np.ndarray:
        """Bilinear interpolation of ``field`` at ``(x, y)`` (broadcast; clipped to the grid).

        Returns ndarray (nsurf, *broadcast shape). Where a corner is absent the result is absent.
        """
        x, y = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
        fx, ix = _cell(self.x, x)
        fy, iy = _cell(self.y, y)
        v = self.data[field]
        jx = np.minimum(ix + 1, self.x.size - 1)     # a grid of one point: the same node (weight 0)
        jy = np.minimum(iy + 1, self.y.size - 1)
        out = ((1 - fx) * (1 - fy) * v[:, ix, iy] + fx * (1 - fy) * v[:, jx, iy]
               + (1 - fx) * fy * v[:, ix, jy] + fx * fy * v[:, jx, jy])
        if field == "z":
            out = np.where(np.isnan(out), -np.inf, out)
        return out


def _cell(grid: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cell index and fraction of ``v`` on an evenly spaced grid (clipped)."""
    if grid.size == 1:
        return np.zeros(v.shape), np.zeros(v.shape, np.int64)
    t = np.clip((v - grid[0]) / (grid[1] - grid[0]), 0.0, grid.size - 1)
    i = np.minimum(np.floor(t).astype(np.int64), grid.size - 2)
    return t - i, i


def _wheel_samples(wheel, s: np.ndarray) -> dict:
    """Wheel height, slope and convex-positive lateral curvature at ``s`` (central differences of
    the profile function, step :data:`_WHEEL_DIFF`); height ``+inf`` off the profile."""
    h = _WHEEL_DIFF
    z0, zp, zm = (wheel.height(s + d) for d in (0.0, h, -h))
    slope = (zp - zm) / (2 * h)
    curv = (zp - 2 * z0 + zm) / (h * h) / (1.0 + slope * slope) ** 1.5
    bad = ~(np.isfinite(z0) & np.isfinite(zp) & np.isfinite(zm))
    return dict(z=np.where(np.isnan(z0), np.inf, z0), slope=np.where(bad, 0.0, slope),
                curv=np.where(bad, 0.0, curv))


PATCH_HALF_WIDTH = 0.0035   # m, the Hertz semi-axis across the track of the centred new S1002 on 60E1 at 98.1 kN
SMOOTH_RADIUS = 1e-3   # m: a gap function curved tighter than this radius at its maximum is a corner, not refined


def _refine(d: np.ndarray, i: np.ndarray, d_eta: float = D_ETA) -> tuple[np.ndarray, np.ndarray]:
    """Parabolic refinement of the maximum of ``d`` (..., n) at index ``i``: (offset in samples in
    [-0.5, 0.5], refined maximum). Where a neighbour is missing (edge, -inf) no refinement; nor
    where the maximum is a corner (a cut edge of the nose beside a cliff): the second difference
    exceeds ``d_eta^2 / SMOOTH_RADIUS`` (profile radii are >= 13 mm on the rail and a few mm on
    the wheel), where the parabola through a cliff would overshoot by up to 1/8 of its height."""
    n = d.shape[-1]
    with np.errstate(invalid="ignore"):
        return _refine_finite(d, i, n, d_eta * d_eta / SMOOTH_RADIUS)


def _refine_finite(d, i, n, max_bend):
    il, ir = np.clip(i - 1, 0, n - 1), np.clip(i + 1, 0, n - 1)
    take = lambda k: np.take_along_axis(d, k[..., None], axis=-1)[..., 0]   # noqa: E731
    d0, dl, dr = take(i), take(il), take(ir)
    den = dl - 2.0 * d0 + dr
    ok = (i > 0) & (i < n - 1) & np.isfinite(dl) & np.isfinite(dr) & (den < 0.0) & (den >= -max_bend)
    p = np.where(ok, 0.5 * (dl - dr) / np.where(ok, den, -1.0), 0.0)
    p = np.clip(p, -0.5, 0.5)
    return p, np.where(ok, d0 - 0.25 * (dl - dr) * p, d0)


def _surface_contacts(rail_fn, wheel, x: np.ndarray, y: np.ndarray, eta_tl: float, d_eta: float) -> dict:
    """Contact of the wheel on one surface ``rail_fn(x, eta) -> (z, curvature)`` for all (x, y):
    dict of arrays (nx, ny) (unreferenced ``z``)."""
    s_lo, s_hi = wheel.s_range
    eta = eta_tl + np.arange(np.floor((s_lo + y.min()) / d_eta), np.ceil((s_hi + y.max()) / d_eta) + 1) * d_eta
    s = eta[None, :] - eta_tl - y[:, None]                    # (ny, neta)
    ws = _wheel_samples(wheel, s)
    zr, kr = rail_fn(x[:, None], eta[None, :])                 # (nx, neta)
    nx, ny, ne = x.size, y.size, eta.size
    out = {f: np.full((nx, ny), np.nan) for f in ("dz", "eta", "s", "slope", "kw", "kr", "d2")}
    step = max(1, CHUNK // max(1, ny * ne))
    for a in range(0, nx, step):
        b = min(nx, a + step)
        d = zr[a:b, None, :] - ws["z"][None, :, :]             # (bx, ny, neta)
        i = np.argmax(d, axis=-1)
        p, dmax = _refine(d, i, d_eta)
        iy = np.broadcast_to(np.arange(ny)[None, :], i.shape)
        hit = np.isfinite(dmax)
        out["dz"][a:b] = np.where(hit, dmax, -np.inf)
        e = eta[i] + p * d_eta
        out["eta"][a:b] = np.where(hit, e, np.nan)
        out["s"][a:b] = np.where(hit, e - eta_tl - y[None, :], np.nan)
        out["slope"][a:b] = np.where(hit, ws["slope"][iy, i], np.nan)
        out["kw"][a:b] = np.where(hit, ws["curv"][iy, i], np.nan)
        out["kr"][a:b] = np.where(hit, kr[np.arange(a, b)[:, None], i], np.nan)
        out["d2"][a:b] = np.where(hit, _gap_curvature(d, i, d_eta), np.nan)
    return out


def _gap_curvature(d: np.ndarray, i: np.ndarray, d_eta: float, half_width: float = PATCH_HALF_WIDTH) -> np.ndarray:
    """Second derivative of the gap function ``d`` (..., n) at its maximum ``i``, from the least-squares
    parabola through the finite samples within ``half_width`` of it (NaN with fewer than 5 of them).

    The Hertz contact sees the separation of the surfaces across its patch, not their curvature at
    one point: where the contact sits at a kink (the ridge of a narrow nose, two heads intersecting)
    or near a tangent point of two arcs (R13 / R80 of a head), the curvature at the point is that of
    whichever side the sample lies on and jumps as the point crosses; the parabola over the patch
    changes continuously. On a single arc it is the arc's curvature to O((half_width / R)^2)."""
    n = d.shape[-1]
    k = max(2, int(round(half_width / d_eta)))
    off = np.arange(-k, k + 1)
    idx = i[..., None] + off
    inside = (idx >= 0) & (idx < n)
    v = np.take_along_axis(d, np.clip(idx, 0, n - 1), axis=-1)
    ok = inside & np.isfinite(v)
    u = off * d_eta
    w = ok.astype(float)
    v = np.where(ok, v, 0.0)
    S = [np.sum(w * u ** p, axis=-1) for p in range(5)]
    T = [np.sum(v * u ** p, axis=-1) for p in range(3)]
    M = np.stack([np.stack([S[0], S[1], S[2]], -1), np.stack([S[1], S[2], S[3]], -1),
                  np.stack([S[2], S[3], S[4]], -1)], -2)
    enough = ok.sum(axis=-1) >= 5
    M = np.where(enough[..., None, None], M, np.eye(3))
    c = np.linalg.solve(M, np.stack(T, -1)[..., None])[..., 0]
    return np.where(enough, 2.0 * c[..., 2], np.nan)


def contact_table(wheel, surfaces: dict, x, y, gauge: float = 1.435, d_eta: float = D_ETA,
                  E_star: float | None = None, reference=None) -> ContactTable:
    """Tabulate the contact geometry of ``wheel`` on ``surfaces`` over the grid ``x`` x ``y``.

    Parameters
    ----------
    wheel : WheelProfile or ConicalWheel
    surfaces : dict
        ``{name: rail_fn}`` with ``rail_fn(x, eta) -> (height, lateral curvature)`` (broadcast,
        ``-inf`` where absent), e.g. ``{"wing": sections.wing, "nose": sections.nose}``.
    x, y : array_like
        Evenly spaced, increasing track positions [m] and lateral wheelset offsets [m].
    gauge : float
        Track gauge [m] (places the taping line, :func:`taping_line_offset`).
    d_eta : float
        Lateral sampling step [m].
    E_star : float, optional
        Contact modulus [Pa] (default two steels).
    reference : callable, optional
        ``rail_fn`` of the plain rail that defines ``z = 0`` for the centred wheelset; default
        :class:`track.profiles.PlainRail` with the 60E1 head.

    Returns
    -------
    ContactTable
    """
    x = np.atleast_1d(np.asarray(x, dtype=float))
    y = np.atleast_1d(np.asarray(y, dtype=float))
    for name, g in (("x", x), ("y", y)):
        if g.size > 2 and not np.allclose(np.diff(g), g[1] - g[0], rtol=1e-9, atol=1e-12):
            raise ValueError(f"{name}: the grid must be evenly spaced and increasing")
    eta_tl = taping_line_offset(gauge)
    ref_fn = reference if reference is not None else PlainRail().rail
    z_ref = float(_surface_contacts(ref_fn, wheel, np.zeros(1), np.zeros(1), eta_tl, d_eta)["dz"][0, 0])
    Es = equivalent_modulus() if E_star is None else E_star
    fields = {f: [] for f in FIELDS}
    for fn in surfaces.values():
        c = _surface_contacts(fn, wheel, x, y, eta_tl, d_eta)
        angle = np.arctan(c["slope"])
        radius = wheel.radius + wheel.radius_increment(c["s"])
        A, B_point = relative_curvatures(radius, c["kw"], c["kr"], 0.0, angle)
        B = np.where(np.isfinite(c["d2"]), -0.5 * c["d2"] * np.cos(angle) ** 3, B_point)
        with np.errstate(invalid="ignore"):
            C = hertz_constant(A, B, Es)
        vals = dict(z=c["dz"] - z_ref, eta=c["eta"], s=c["s"], radius=radius, angle=angle, A=A, B=B, C=C,
                    C_vertical=C * np.cos(angle) ** 2.5)
        for f in FIELDS:
            fields[f].append(vals[f])
    data = {f: np.stack(v) for f, v in fields.items()}
    return ContactTable(x=x, y=y, surfaces=tuple(surfaces), data=data, z_ref=z_ref)


def crossing_table(wheel, sections, x, y, gauge: float = 1.435, **kw) -> ContactTable:
    """:func:`contact_table` of the wing rail and the nose of ``sections``
    (:class:`track.profiles.CrossingSections`)."""
    return contact_table(wheel, {"wing": sections.wing, "nose": sections.nose}, x, y, gauge, **kw)


def transfer(table: ContactTable, iy: int = None) -> dict:
    """Where the wheel moves from the wing rail to the nose, and the change of its vertical slope.

    For the wheel following the higher surface quasi-statically (rigid track, no dynamics), its
    centre height is ``max(z_wing, z_nose)``; the transfer is the first x where the nose is the
    higher. The kinematic impact angle is the slope of the nose's ``z`` just after the transfer
    minus the wing rail's just before it (one table step either side, averaged over 5 steps).

    Parameters
    ----------
    table : ContactTable
        With surfaces ``wing`` and ``nose``.
    iy : int, optional
        Index of the lateral offset (default: the one closest to 0).

    Returns
    -------
    dict with x [m] (linear interpolation of ``z_nose - z_wing = 0``; the first x of the nose when
    it appears above the wing rail, ``tip_impact`` True: the wheel meets the nose tip), slope_wing,
    slope_nose [rad], angle [rad], and the contact positions ``eta`` on both surfaces there [m];
    NaNs when there is no transfer in the table.
    """
    if iy is None:
        iy = int(np.argmin(np.abs(table.y)))
    zw = table.data["z"][table.surfaces.index("wing"), :, iy]
    zn = table.data["z"][table.surfaces.index("nose"), :, iy]
    diff = np.where(np.isfinite(zn), zn, -np.inf) - np.where(np.isfinite(zw), zw, -np.inf)
    above = np.flatnonzero(diff > 0)
    nan = dict(x=np.nan, tip_impact=False, slope_wing=np.nan, slope_nose=np.nan, angle=np.nan,
               eta_wing=np.nan, eta_nose=np.nan)
    if above.size == 0 or above[0] == 0:
        return nan
    k = int(above[0])
    x = table.x
    tip = not np.isfinite(diff[k - 1])          # the nose appears above the wing: the wheel meets its tip
    xt = x[k] if tip else x[k - 1] + (x[k] - x[k - 1]) * (-diff[k - 1]) / (diff[k] - diff[k - 1])
    n = 5
    a, b = max(0, k - 1 - n), min(x.size - 1, k + n)
    sw = (zw[k - 1] - zw[a]) / (x[k - 1] - x[a])
    sn = (zn[b] - zn[k]) / (x[b] - x[k])
    eta = table.data["eta"]
    return dict(x=float(xt), tip_impact=bool(tip), slope_wing=float(sw), slope_nose=float(sn), angle=float(sn - sw),
                eta_wing=float(eta[table.surfaces.index("wing"), k - 1, iy]),
                eta_nose=float(eta[table.surfaces.index("nose"), k, iy]))


# ----------------------------------------------------------------------------- tables of a scenario
TABLE_DX = 0.005      # m, x step of a crossing table (the wing rail falls ~1 mm per 0.1 m: linear in a step)
TABLE_DY = 0.001      # m, y step (a constant offset is a grid node; 1 mm between nodes of an offset table)
_GEOMETRY_CACHE: dict = {}   # content key -> (crossing TableGeometry or None, plain TableGeometry)


def wheel_profile(contact):
    """The :class:`track.profiles.WheelProfile` of :class:`track.params.ContactParams`."""
    from .profiles import WheelProfile
    if contact.wheel_table:
        return WheelProfile(table=tuple(np.asarray(v, dtype=float) for v in contact.wheel_table))
    return WheelProfile(**dict(contact.wheel))


def lateral_offsets(contact) -> np.ndarray:
    """The wheelset offsets [m] the scenario reaches (its constant or the table's values)."""
    if contact.lateral_offset_table:
        return np.asarray(contact.lateral_offset_table[1], dtype=float)
    return np.array([float(contact.lateral_offset)])


def _y_grid(lo: float, hi: float) -> np.ndarray:
    """Evenly spaced offsets (step TABLE_DY) from ``lo - TABLE_DY`` covering ``hi + TABLE_DY``: ``lo``
    is a node, so a constant offset is looked up without interpolation."""
    n = int(np.ceil((hi - lo) / TABLE_DY - 1e-9)) + 3
    return lo - TABLE_DY + TABLE_DY * np.arange(n)


def table_geometry(table: ContactTable):
    """:class:`track.contact.TableGeometry` of a contact table: heights (NaN where absent) and the
    vertical Hertz constants, two surfaces (a plain rail's second is absent).

    Where a contact exists but the Hertz solution does not (``B <= 0``: a conformal contact, e.g.
    a deeply hollow tread), the constant is the largest of that surface's finite ones at the same
    x (the stiffest nearby contact: the closest a non-conformal model gets to a conformal patch),
    or at any x when there is none at that x (e.g. the flat outer edge of the wing rail's head far
    below the wheel, ``B = 0``); where a surface has no finite constant at all, ``ValueError``.
    """
    from .contact import TableGeometry
    z = np.where(np.isfinite(table.data["z"]), table.data["z"], np.nan)
    c = np.where(np.isfinite(z), table.data["C_vertical"], np.nan)
    bad = np.isfinite(z) & ~np.isfinite(c)
    if bad.any():
        finite = np.where(np.isfinite(c), c, -np.inf)
        fill = np.max(finite, axis=2, keepdims=True)                       # same x, any offset
        fill = np.where(np.isfinite(fill), fill, np.max(finite, axis=(1, 2), keepdims=True))   # any x
        c = np.where(bad, np.broadcast_to(fill, c.shape), c)
        if (np.isfinite(z) & ~np.isfinite(c)).any():
            raise ValueError("contact table: a surface has no non-conformal contact to take a Hertz constant from")
    if z.shape[0] == 1:
        z = np.concatenate([z, np.full_like(z, np.nan)])
        c = np.concatenate([c, np.full_like(c, np.nan)])
    x, y = table.x, table.y
    if x.size == 1:                                   # x-independent: two equal rows
        x, z, c = np.array([x[0], x[0] + 1.0]), np.repeat(z, 2, axis=1), np.repeat(c, 2, axis=1)
    grid = np.array([x[0], x[1] - x[0], x.size, y[0], y[1] - y[0], y.size], float)
    return TableGeometry(grid=grid, z=np.ascontiguousarray(z), c=np.ascontiguousarray(c), table=table)


def scenario_tables(layout, contact, x_range: tuple | None = None):
    """The contact tables of a scenario with ``track.crossing.geometry: profiles``: the wheel on the
    crossing's wing rail and nose over ``x_range`` (when the layout has a crossing) and on a
    plain rail of the layout's rail type; cached by content (layout parameters, wheel, crossing
    parameters, offsets, range).

    Parameters
    ----------
    layout : track.layout.Layout
    contact : track.params.ContactParams
    x_range : (float, float), optional
        Track coordinates [m] the crossing table spans (the crossing rail's running segments).

    Returns
    -------
    crossing : TableGeometry or None
        Its lateral offsets are the wheel's field side's: ``+offset`` (the crossing wheel).
    plain : TableGeometry
        Offsets ``-|offset|max .. +|offset|max`` (both wheels).
    """
    from .profiles import RAIL_HEADS, CrossingSections, PlainRail
    ys = lateral_offsets(contact)
    key = repr((layout.params, contact.wheel, contact.wheel_table, contact.crossing, tuple(ys), x_range))
    hit = _GEOMETRY_CACHE.get(key)
    if hit is not None:
        return hit
    wheel = wheel_profile(contact)
    head = RAIL_HEADS.get(getattr(layout.params, "rail", "60E1"), RAIL_HEADS["60E1"])
    plain_rail = PlainRail(head=head)
    ymax = float(np.max(np.abs(ys)))
    gauge = float(getattr(layout.params, "gauge", 1.435))
    plain = table_geometry(contact_table(wheel, {"rail": plain_rail.rail}, [0.0], _y_grid(-ymax, ymax), gauge,
                                         reference=plain_rail.rail))
    crossing = None
    if layout.x_tcp is not None and x_range is not None:
        sections = CrossingSections.from_layout(layout, **dict(contact.crossing))
        n = int(np.ceil((x_range[1] - x_range[0]) / TABLE_DX)) + 1
        x = x_range[0] + TABLE_DX * np.arange(n)
        crossing = table_geometry(crossing_table(wheel, sections, x, _y_grid(float(ys.min()), float(ys.max())),
                                                 gauge, reference=plain_rail.rail))
    _GEOMETRY_CACHE[key] = (crossing, plain)
    return crossing, plain
