"""Turnout / plain-track layout generator.

Takes :class:`track.params.LayoutParams` and returns a :class:`Layout`: every rail
body that crosses the modelled sleepers with its lateral position on each sleeper,
the sleepers (bearers) sized to span their rails, the joints between rail bodies,
the running rails of each wheel side for the chosen route, and plan-view polylines.

Coordinates
-----------
x is the track coordinate along the through route [m], y is lateral (positive to
the left looking in +x), z is vertical (up). Sleepers are perpendicular to the
through route at ``x_j = x_0 + j * spacing``, ``j = 0 .. N-1``.

Geometry model
--------------
Gauge ``g`` is measured between running edges. A rail's centreline (where its
seat is) lies half a head width outside its running edge (60E1: 72 mm head, so
0.036 m). All construction is done for a left-hand turnout (diverging route turns
to +y); a right-hand turnout is the exact mirror image ``y -> -y``.

* Through route: straight running edges at ``y = -g/2`` (outer, ``stock_through``)
  and ``y = +g/2`` (inner, ``L_t``, leads to the crossing).
* Diverging route: the centreline is a circular curve of radius ``R`` tangent to
  the through centreline at ``x = 0`` (theoretical curve start, centre of the
  circle at ``(0, R)``), continued until its heading reaches the nominal crossing
  angle ``alpha = atan(1/n)`` and straight at ``alpha`` from there on. Every
  diverging line is an exact parallel of that centreline at a normal offset ``d``
  (positive towards the curve centre): radius ``r = R - d``; for ``x <= r sin(alpha)``
  ``y = R - sqrt(r^2 - x^2)``, beyond it ``y = R - r cos(alpha) + (x - r sin(alpha))
  tan(alpha)``. Its right running edge ``L_d`` has ``d = -g/2`` (starts at
  ``y = -g/2``), the outer diverging rail ``stock_div`` has its running edge at
  ``d = +g/2``.
* Theoretical crossing point (TCP): where ``L_d`` reaches ``y = +g/2``; found by
  root finding (``scipy.optimize.brentq``). For the usual combinations (R500-1:12,
  R760-1:15) the curve reaches ``y = g/2`` before its heading reaches ``alpha``, so
  the crossing lies in the curve ("curved crossing"): ``x_tcp = sqrt(2 R g)`` and
  the crossing angle ``theta = asin(x_tcp / (R + g/2))`` is flatter than 1:n
  (about 1:13.2 and 1:16.3); ``alpha`` is then the end tangent reached behind the
  crossing. Otherwise the crossing is straight and ``theta = alpha``.
* Cast crossing block (``crossing``) from the crossing front ``x_cf`` (separation
  of ``L_t`` and ``L_d`` = ``CROSSING_FRONT_SEPARATION`` before the TCP) to the
  crossing rear ``x_cr`` (separation ``CROSSING_REAR_SEPARATION`` behind it). The
  closure rails (``closure_through`` on ``L_t``, ``closure_div`` on ``L_d``) run from
  the panel start to ``x_cf``; the nose legs (``rear_through``, ``rear_div``) from
  ``x_cr`` to the panel end. Check rails (``check_through``, ``check_div``) lie
  beside the stock rails opposite the nose.
* The nominal wheel transfer wing rail -> nose (``x_transition``) is where the nose
  between ``L_t`` and ``L_d`` is ``NOSE_WIDTH_AT_TRANSFER`` wide; sleeper
  ``transition_sleeper`` is placed exactly there.

The model covers the crossing panel only: the switch panel (switch rails) ahead of
``x = 0`` is not modelled, so a panel starting before the curve start is rejected.
Near ``x = 0`` the closure and stock rails of the two routes would coincide.
"""
from __future__ import annotations

import functools
import math
import re
from dataclasses import dataclass

import numpy as np

from .params import CHECK_RAIL_33C1, CONCRETE_BEARER, RAIL_SECTIONS, BeamProfile, LayoutParams
from .roots import bracketed_root

# --- rail and flangeway dimensions -------------------------------------------------
# Rail head widths [m]: 60E1 = 72 mm (EN 13674-1). The seat (centreline) of a rail is
# half a head width outside its running edge.
RAIL_HEAD_WIDTH = {"60E1": 0.072}
# Check rail 33C1 (UIC33, U69) head width 80 mm (EN 13674-3; manufacturers' tables).
CHECK_HEAD_WIDTH = 0.080
# Flangeway between a stock rail's running edge and the check face of its check rail,
# and between a wing rail and the running edge it guides [m]. 41 mm is the usual
# value for 1435 mm gauge (check gauge g - 0.041 = 1.394 m, inside the UIC band).
FLANGEWAY = 0.041

# --- cast-crossing extents (typical values, see module docstring) ------------------
# Lateral separation of L_t and L_d at the front of the cast crossing block [m]
# (front weld ~ 2 m ahead of the TCP for 1:12 ... 1:15 crossings).
CROSSING_FRONT_SEPARATION = 0.17
# Lateral separation of L_t and L_d at the rear of the block (end of the V legs) [m].
CROSSING_REAR_SEPARATION = 0.30
# Nose width at the nominal wheel transfer wing rail -> nose [m] (typical nominal
# transfer for new profiles; the transfer zone spans roughly 10 ... 40 mm nose width).
NOSE_WIDTH_AT_TRANSFER = 0.020
# Simplified cast-crossing section: multiples of the running-rail section (area and
# second moment alike) at stations relative to the TCP [m]. Ahead of the nose the block
# carries two rails' worth (two wing rails), from TCP + 0.5 m the nose is full-section
# beside both wing rails (three), the wing rails end at TCP + 1.8 m, and at the rear
# only the two V legs remain.
CROSSING_FACTOR_FRONT = 2.0  # at x_cf and at the TCP
CROSSING_NOSE_FULL = 0.5  # m behind the TCP
CROSSING_WING_END = 1.8  # m behind the TCP (end of the wing rails)
CROSSING_FACTOR_FULL = 3.0  # nose + two wing rails
CROSSING_FACTOR_REAR = 2.0  # the two V legs at x_cr
# Minimum width of a crossing-rail seat [m] = 60E1 foot width (150 mm, EN 13674-1).
CROSSING_SEAT_MIN_WIDTH = 0.15

# --- check rails ---------------------------------------------------------------------
CHECK_RAIL_LENGTH = 6.0  # m, typical check rail of a 1:12 ... 1:15 crossing
CHECK_RAIL_CENTRE_BEHIND_TCP = 0.5  # m, check rail centred opposite the nose tip region

# --- bearers -------------------------------------------------------------------------
BEARER_OVERHANG = 0.5  # m beyond the outermost rail seat (typical bearer end distance)
BEARER_LENGTH_STEP = 0.1  # m, bearer lengths are manufactured in 0.1 m steps

MIN_SEATS_PER_BODY = 2  # a beam body needs two supports to be a statically stable body
PLAN_STEP = 0.1  # m, sampling step of the plan-view polylines (chord sag < 3e-6 m at R 500)
MIN_SLEEPERS = 4
LAYOUT_CACHE_SIZE = 16  # layouts kept per process (build_layout): a few hundred kB each
_ROOT_XTOL = 1e-12  # m, root tolerance (track.roots): far below any geometric tolerance that matters

_CROSSING_RE = re.compile(r"^\s*1\s*:\s*([0-9]+(?:\.[0-9]*)?)\s*$")

@dataclass(frozen=True)
class Seat:
    """A rail seat: where a rail body rests on a sleeper.

    Attributes
    ----------
    sleeper : int
        Sleeper index.
    x : float
        Track coordinate of the seat (= the sleeper's x) [m].
    y : tuple of float
        Lateral position(s) of the bushing(s) on the sleeper [m]: one entry for a
        normal seat; the crossing rail may give the seat centre and its width
        through ``width`` so the model can place two bushings.
    width : float
        Lateral width of the seat [m] (distance between the two bushings when a wide
        seat is split in two).
    """

    sleeper: int
    x: float
    y: float
    width: float


@dataclass(frozen=True)
class RailBody:
    """One structural rail body (a beam along x).

    Attributes
    ----------
    name : str
        Unique name, e.g. ``"stock_through"``, ``"closure_through"``, ``"crossing"``.
    kind : str
        ``"rail"`` (running rail), ``"crossing"`` (cast crossing: wing rails + nose),
        or ``"check"`` (check rail).
    x_start, x_end : float
        Extent along the track [m].
    profile : BeamProfile
        Section (possibly varying with the body coordinate ``s = x - x_start``).
    seats : tuple of Seat
        Rail seats in increasing x.
    """

    name: str
    kind: str
    x_start: float
    x_end: float
    profile: BeamProfile
    seats: tuple


@dataclass(frozen=True)
class SleeperBody:
    """One sleeper / turnout bearer (a beam along y at fixed x).

    Behind a turnout's long bearers, where the two tracks have separated enough, a position
    carries two sleepers, one under each track (:func:`_bearer`); they are one body here
    (one index, as the ballast, voids and sensors address them), spanning both, with ``gap``
    the empty span between them: no material, no ballast.

    Attributes
    ----------
    index : int
    x : float
        Track coordinate of its centre line [m].
    y_start, y_end : float
        Lateral extent [m] (of both sleepers, when split).
    profile : BeamProfile
        Section along the bearer (s = y - y_start).
    gap : tuple
        ``(y0, y1)``: the lateral span between the two sleepers of a split position [m]; ``()``
        for one sleeper or bearer.
    """

    index: int
    x: float
    y_start: float
    y_end: float
    profile: BeamProfile
    gap: tuple = ()

    @property
    def length(self) -> float:
        """Lateral extent [m] (both sleepers and the gap between them, when split)."""
        return self.y_end - self.y_start

    @property
    def pieces(self) -> tuple:
        """The ``(y_start, y_end)`` [m] of each sleeper at this position (two when split)."""
        if not self.gap:
            return ((self.y_start, self.y_end),)
        return ((self.y_start, self.gap[0]), (self.gap[1], self.y_end))


@dataclass(frozen=True)
class Joint:
    """Rail bodies whose ends are rigidly joined (welded) at one x."""

    x: float
    ends: tuple  # tuple of (body name, "start" | "end")


@dataclass(frozen=True)
class RunningSegment:
    """A wheel on one side runs on ``body`` for x in [x0, x1)."""

    body: str
    x0: float
    x1: float


@dataclass(frozen=True)
class PlanLine:
    """A plan-view polyline of a running edge / rail for plots (x, y arrays [m])."""

    name: str
    kind: str  # stock | closure | wing | nose | check | rail
    x: np.ndarray
    y: np.ndarray


@dataclass(frozen=True)
class Layout:
    """The generated layout.

    Attributes
    ----------
    params : LayoutParams
    rails : tuple of RailBody
    sleepers : tuple of SleeperBody
        Indexed 0..N-1 in increasing x.
    joints : tuple of Joint
    running : dict
        ``{"left": (RunningSegment, ...), "right": (...)}`` for the chosen route.
    crossing_side : str or None
        Wheel side ("left"/"right") that passes the crossing nose; None for plain track.
    x_tcp : float or None
        Theoretical crossing point [m].
    x_transition : float or None
        Nominal wheel transfer point wing rail -> nose [m] (over ``transition_sleeper``).
    crossing_angle : float or None
        Angle between the two running edges at the TCP [rad].
    lines : tuple of PlanLine
    """

    params: LayoutParams
    rails: tuple
    sleepers: tuple
    joints: tuple
    running: dict
    crossing_side: str | None
    x_tcp: float | None
    x_transition: float | None
    crossing_angle: float | None
    lines: tuple

    def rail(self, name: str) -> RailBody:
        for r in self.rails:
            if r.name == name:
                return r
        raise KeyError(f"no rail body named {name!r}; have {[r.name for r in self.rails]}")

    def running_body(self, side: str, x: float) -> str:
        """Name of the rail body a wheel on ``side`` runs on at track coordinate ``x``."""
        segs = self.running[side]
        for seg in segs:
            if seg.x0 <= x < seg.x1:
                return seg.body
        return segs[-1].body if x >= segs[-1].x1 else segs[0].body

    def geometry(self) -> "TurnoutGeometry | None":
        """Analytic line functions of this turnout (None for plain track)."""
        if self.params.type != "turnout":
            return None
        return TurnoutGeometry.from_params(self.params)

    def line(self, name: str) -> PlanLine:
        """The plan-view polyline called ``name``."""
        for ln in self.lines:
            if ln.name == name:
                return ln
        raise KeyError(f"no plan line named {name!r}; have {[ln.name for ln in self.lines]}")


# ======================================================================================
# Geometry
# ======================================================================================


@dataclass(frozen=True)
class TurnoutGeometry:
    """Analytic running-edge / rail-line functions of a turnout (module docstring).

    Attributes
    ----------
    radius : float
        Radius ``R`` of the diverging route centreline [m].
    alpha : float
        End-tangent (nominal crossing) angle ``atan(1/n)`` [rad].
    gauge : float
        Gauge ``g`` between running edges [m].
    sign : float
        +1 for a left-hand turnout, -1 for a right-hand one (mirror ``y -> -y``).

    Notes
    -----
    Offsets ``d`` are given in the left-hand (canonical) frame: a through line at
    offset ``d`` lies at ``y = sign * d``; a diverging line at offset ``d`` is parallel
    to the diverging centreline, ``d`` measured normal to it towards the curve centre.
    All returned ``y`` and headings are in the world frame (mirrored for right hand).
    """

    radius: float
    alpha: float
    gauge: float
    sign: float = 1.0

    @classmethod
    def from_params(cls, p: LayoutParams) -> "TurnoutGeometry":
        """Geometry of the (validated) turnout parameters ``p``."""
        n = _parse_crossing(p.crossing)
        return cls(radius=float(p.radius), alpha=math.atan(1.0 / n), gauge=float(p.gauge),
                   sign=1.0 if p.hand == "left" else -1.0)

    # --- line functions -----------------------------------------------------------
    def _div_canonical(self, x: np.ndarray, d: float) -> np.ndarray:
        R, a = self.radius, self.alpha
        r = R - d
        xe, ye = r * math.sin(a), R - r * math.cos(a)
        xc = np.clip(x, 0.0, xe)
        curve = R - np.sqrt(r * r - xc * xc)  # equals d at x = 0 (tangent before the curve)
        straight = ye + (x - xe) * math.tan(a)
        return np.where(x <= xe, curve, straight)

    def diverging_y(self, x, d: float):
        """Lateral position [m] at ``x`` [m] of the diverging line at offset ``d`` [m].

        Scalar in -> float out; array (n,) in -> array (n,) out. Ahead of the curve
        start (``x < 0``) the line is continued along the through route (``y = d``).
        """
        xa = np.asarray(x, dtype=float)
        y = self.sign * self._div_canonical(xa, d)
        return float(y) if y.ndim == 0 else y

    def diverging_heading(self, x, d: float = 0.0):
        """Heading [rad] of the diverging line at offset ``d`` at ``x`` (0 = +x axis)."""
        xa = np.asarray(x, dtype=float)
        r = self.radius - d
        xe = r * math.sin(self.alpha)
        h = np.where(xa <= xe, np.arcsin(np.clip(xa, 0.0, xe) / r), self.alpha)
        h = self.sign * h
        return float(h) if h.ndim == 0 else h

    def through_y(self, d: float) -> float:
        """Lateral position [m] of the through line at offset ``d`` [m]."""
        return self.sign * d

    def separation(self, x):
        """Signed separation ``L_d - L_t`` [m] in the canonical frame at ``x`` [m].

        Negative ahead of the TCP (gap between the closure rails), positive behind it
        (nose width).
        """
        g = self.gauge
        s = self._div_canonical(np.asarray(x, dtype=float), -g / 2) - g / 2
        return float(s) if s.ndim == 0 else s

    # --- characteristic points ----------------------------------------------------
    def _x_far(self) -> float:
        """An x behind every characteristic point (bracket end for the roots) [m]."""
        r = self.radius + self.gauge / 2
        return r * math.sin(self.alpha) + (self.gauge + CROSSING_REAR_SEPARATION + 1.0) / math.tan(self.alpha)

    def _x_at_separation(self, target: float, lo: float, hi: float) -> float:
        return bracketed_root(lambda x: self.separation(x) - target, lo, hi, _ROOT_XTOL)

    @property
    def x_tcp(self) -> float:
        """Theoretical crossing point [m]: ``L_d`` meets ``L_t``."""
        return self._x_at_separation(0.0, 0.0, self._x_far())

    @property
    def crossing_angle(self) -> float:
        """Angle between ``L_t`` and ``L_d`` at the TCP [rad] (always positive)."""
        return abs(self.diverging_heading(self.x_tcp, -self.gauge / 2))

    @property
    def x_transition(self) -> float:
        """Nominal wheel transfer point [m]: nose width ``NOSE_WIDTH_AT_TRANSFER``."""
        return self._x_at_separation(NOSE_WIDTH_AT_TRANSFER, self.x_tcp, self._x_far())

    @property
    def x_crossing_front(self) -> float:
        """Front of the cast crossing block [m] (separation ``CROSSING_FRONT_SEPARATION``)."""
        return self._x_at_separation(-CROSSING_FRONT_SEPARATION, 0.0, self.x_tcp)

    @property
    def x_crossing_rear(self) -> float:
        """Rear of the cast crossing block [m] (separation ``CROSSING_REAR_SEPARATION``)."""
        return self._x_at_separation(CROSSING_REAR_SEPARATION, self.x_tcp, self._x_far())

    @property
    def x_throat(self) -> float:
        """Throat [m]: the wing rails kink out where the separation equals ``FLANGEWAY``."""
        return self._x_at_separation(-FLANGEWAY, 0.0, self.x_tcp)


# ======================================================================================
# Validation
# ======================================================================================


def _parse_crossing(crossing) -> float:
    """``n`` of a crossing ratio ``"1:n"`` (n > 1); ValueError naming ``crossing``."""
    m = _CROSSING_RE.match(crossing) if isinstance(crossing, str) else None
    n = float(m.group(1)) if m else float("nan")
    if not (m and n > 1.0 and math.isfinite(n)):
        raise ValueError(f"crossing: expected a ratio '1:n' with n > 1 (e.g. '1:12'), got {crossing!r}")
    return n


def _positive(name: str, value) -> None:
    ok = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)
    if not (ok and math.isfinite(value) and value > 0):
        raise ValueError(f"{name}: must be a positive number, got {value!r}")


def _validate(p: LayoutParams) -> None:
    """Raise ValueError naming the offending parameter of ``p``."""
    if p.type not in ("plain", "turnout"):
        raise ValueError(f"type: must be 'plain' or 'turnout', got {p.type!r}")
    _positive("sleeper_spacing", p.sleeper_spacing)
    if not isinstance(p.sleepers, (int, np.integer)) or isinstance(p.sleepers, bool) \
            or p.sleepers < MIN_SLEEPERS:
        raise ValueError(f"sleepers: must be an integer >= {MIN_SLEEPERS}, got {p.sleepers!r}")
    _positive("gauge", p.gauge)
    _positive("sleeper_length", p.sleeper_length)
    if p.route not in ("through", "diverging"):
        raise ValueError(f"route: must be 'through' or 'diverging', got {p.route!r}")
    if p.hand not in ("left", "right"):
        raise ValueError(f"hand: must be 'left' or 'right', got {p.hand!r}")
    if p.rail not in RAIL_SECTIONS or p.rail not in RAIL_HEAD_WIDTH:
        raise ValueError(f"rail: unknown rail profile {p.rail!r}; known: {sorted(RAIL_SECTIONS)}")
    if p.type == "plain":
        return
    _parse_crossing(p.crossing)
    _positive("radius", p.radius)
    if p.radius <= p.gauge:
        raise ValueError(f"radius: must exceed the gauge ({p.gauge} m), got {p.radius!r}")
    t = p.transition_sleeper
    if t is not None and (not isinstance(t, (int, np.integer)) or isinstance(t, bool)
                          or not 0 <= t < p.sleepers):
        raise ValueError(f"transition_sleeper: must be an integer in 0..{p.sleepers - 1} "
                         f"(or None), got {t!r}")


# ======================================================================================
# Construction helpers
# ======================================================================================


@dataclass(frozen=True)
class _RailSpec:
    """Internal description of a rail body before seats are attached.

    ``centre(x)`` and ``width(x)`` give the seat's lateral position and width [m];
    ``edges`` holds ``(line name, plan kind, edge(x))`` of its plan-view lines.
    """

    name: str
    kind: str
    x_start: float
    x_end: float
    profile: BeamProfile
    centre: object
    width: object
    edges: tuple


def _grid(a: float, b: float, extra=()) -> np.ndarray:
    """Sampling of [a, b] with step <= PLAN_STEP, including the points ``extra`` inside."""
    n = max(2, int(math.ceil((b - a) / PLAN_STEP)) + 1)
    x = np.linspace(a, b, n)
    inner = [e for e in extra if a < e < b]
    return np.unique(np.concatenate([x, inner])) if inner else x


def _seats(spec: _RailSpec, xs: np.ndarray) -> tuple:
    """Seats of ``spec`` on every sleeper with ``x_start <= x_j < x_end``."""
    idx = np.flatnonzero((xs >= spec.x_start) & (xs < spec.x_end))
    return tuple(Seat(int(j), float(xs[j]), float(spec.centre(xs[j])), float(spec.width(xs[j])))
                 for j in idx)


def _crossing_profile(x_cf: float, x_tcp: float, x_cr: float, base) -> BeamProfile:
    """Simplified cast-crossing section (see the CROSSING_* constants)."""
    length = x_cr - x_cf
    stations = [(0.0, CROSSING_FACTOR_FRONT),
                (x_tcp - x_cf, CROSSING_FACTOR_FRONT),
                (x_tcp + CROSSING_NOSE_FULL - x_cf, CROSSING_FACTOR_FULL),
                (x_tcp + CROSSING_WING_END - x_cf, CROSSING_FACTOR_FULL)]
    # Steep crossings (short blocks) may end before the wing-rail ends: keep what fits.
    stations = [(s, f) for s, f in stations if s < length] + [(length, CROSSING_FACTOR_REAR)]
    s = tuple(float(v) for v, _ in stations)
    f = tuple(float(v) for _, v in stations)
    return BeamProfile(base=base, s=s, area_factor=f, inertia_factor=f)


def _bearer(j: int, x: float, ys: list, p: LayoutParams, sign: float, y_div: float) -> SleeperBody:
    """Bearer ``j`` spanning the canonical seat positions ``ys`` with overhang, or two sleepers.

    Lengths are rounded up to ``BEARER_LENGTH_STEP`` by extending the diverging-side
    end, so the through-side ends line up (as bearers are usually laid).

    Where two sleepers of ``p.sleeper_length``, one centred on each track (the through
    centreline ``y = 0`` and the diverging one ``y_div``, canonical frame), fit side by side
    and carry every seat with at least ``BEARER_OVERHANG``, the position gets those two
    instead, as a turnout's long bearers end where the tracks have separated: the bearers
    reach ~5.2 m (DESIGN.md's 2.6-5 m bearers) and no further, however long the panel.
    """
    half = p.sleeper_length / 2
    lo = min(min(ys) - BEARER_OVERHANG, -half)
    hi = max(max(ys) + BEARER_OVERHANG, half)
    steps = math.ceil(round((hi - lo) / BEARER_LENGTH_STEP, 9))
    hi = lo + steps * BEARER_LENGTH_STEP
    gap = ()
    ys = np.asarray(ys, dtype=float)
    if y_div - half >= half:    # the two sleepers do not overlap; do they carry every seat?
        on_through = np.abs(ys) <= half - BEARER_OVERHANG
        on_div = np.abs(ys - y_div) <= half - BEARER_OVERHANG
        if (on_through | on_div).all():
            lo, hi, gap = -half, y_div + half, (half, y_div - half)
    if sign > 0:
        y0, y1 = lo, hi
    else:
        y0, y1, gap = -hi, -lo, tuple(-g for g in gap[::-1])
    return SleeperBody(index=j, x=float(x), y_start=float(y0), y_end=float(y1),
                       profile=BeamProfile(base=CONCRETE_BEARER), gap=tuple(float(g) for g in gap))


def _check_min_seats(rails) -> None:
    for r in rails:
        if len(r.seats) < MIN_SEATS_PER_BODY:
            raise ValueError(
                f"sleepers/transition_sleeper: rail body {r.name!r} "
                f"({r.x_start:.3f} .. {r.x_end:.3f} m) has {len(r.seats)} seat(s), needs "
                f"{MIN_SEATS_PER_BODY}; the panel does not cover the crossing - use more "
                f"sleepers or move the transition sleeper")


def _other(side: str) -> str:
    return "right" if side == "left" else "left"


# ======================================================================================
# Builders
# ======================================================================================


def build_layout(p: LayoutParams) -> Layout:
    """Generate the layout for ``p`` (plain track or turnout crossing panel).

    Parameters
    ----------
    p : LayoutParams
        Layout parameters (SI units); see the module docstring for the geometry.

    Returns
    -------
    Layout
        Rail bodies with their seats, sleepers ``0..N-1`` in increasing x, joints,
        running segments of both wheel sides for ``p.route``, and plan lines.

    Raises
    ------
    ValueError
        For invalid parameters; the message starts with the parameter's name.
    """
    return _build_layout_cached(p)


@functools.lru_cache(maxsize=LAYOUT_CACHE_SIZE)
def _build_layout_cached(p: LayoutParams) -> Layout:
    """:func:`build_layout`, once per parameter set and process: a sweep, a diagnosis or a
    calibration builds the same layout for every run (~15 ms of a turnout's root finding,
    twice a run: the master's passage and the track model). The result is shared, so a
    :class:`Layout` is never changed after it is built (frozen; no caller writes into it)."""
    _validate(p)
    if p.type == "plain":
        return _build_plain(p)
    return _build_turnout(p)


def _build_plain(p: LayoutParams) -> Layout:
    """Straight plain track: two rails, N sleepers of ``p.sleeper_length``, x_0 = 0."""
    g, h, N = float(p.gauge), float(p.sleeper_spacing), int(p.sleepers)
    hw = RAIL_HEAD_WIDTH[p.rail] / 2
    base = RAIL_SECTIONS[p.rail]
    xs = h * np.arange(N)  # x_j = x_0 + j * spacing with x_0 = 0 (integer counter, no drift)
    xa, xb = -h / 2, float(xs[-1] + h / 2)
    rails, lines = [], []
    for name, side in (("rail_left", 1.0), ("rail_right", -1.0)):
        yc = side * (g / 2 + hw)
        spec = _RailSpec(name, "rail", xa, xb, BeamProfile(base=base),
                         centre=lambda x, yc=yc: yc, width=lambda x: base.width, edges=())
        rails.append(RailBody(name, "rail", xa, xb, spec.profile, _seats(spec, xs)))
        xg = np.array([xa, xb])
        lines.append(PlanLine(name, "rail", xg, np.full(2, side * g / 2)))
    half = p.sleeper_length / 2
    sleepers = tuple(SleeperBody(j, float(xs[j]), -half, half, BeamProfile(base=CONCRETE_BEARER))
                     for j in range(N))
    running = {"left": (RunningSegment("rail_left", -math.inf, math.inf),),
               "right": (RunningSegment("rail_right", -math.inf, math.inf),)}
    return Layout(params=p, rails=tuple(rails), sleepers=sleepers, joints=(), running=running,
                  crossing_side=None, x_tcp=None, x_transition=None, crossing_angle=None,
                  lines=tuple(lines))


def _build_turnout(p: LayoutParams) -> Layout:
    """Crossing panel of a turnout (see the module docstring).

    Stages: geometry -> sleeper positions -> rail bodies with their seats -> bearers sized to
    span them -> joints of the crossing block -> running rails per side -> plan lines.
    """
    geo = TurnoutGeometry.from_params(p)
    N = int(p.sleepers)
    x_cf, x_cr = geo.x_crossing_front, geo.x_crossing_rear
    xs, xa, xb = _sleeper_positions(p, geo)
    specs = _turnout_rail_specs(p, geo, xa, xb)
    rails = tuple(RailBody(sp.name, sp.kind, float(sp.x_start), float(sp.x_end), sp.profile,
                           _seats(sp, xs)) for sp in specs)
    _check_min_seats(rails)

    # bearers: span the seats of every rail on them (canonical frame, then mirrored)
    seat_y = [[] for _ in range(N)]
    for r in rails:
        for st in r.seats:
            seat_y[st.sleeper].append(geo.sign * st.y)
    y_div = np.abs(geo.diverging_y(xs, 0.0))   # the diverging centreline, canonical frame
    sleepers = tuple(_bearer(j, xs[j], seat_y[j], p, geo.sign, float(y_div[j])) for j in range(N))

    joints = (Joint(x_cf, (("closure_through", "end"), ("closure_div", "end"), ("crossing", "start"))),
              Joint(x_cr, (("crossing", "end"), ("rear_through", "start"), ("rear_div", "start"))))
    nose_side, running = _running_segments(p, x_cf, x_cr)
    lines = []
    for sp in specs:
        for name, kind, edge in sp.edges:
            xg = _grid(sp.x_start, sp.x_end)
            lines.append(PlanLine(name, kind, xg, np.asarray(edge(xg), dtype=float)))
    lines.extend(_crossing_lines(geo, x_cf, geo.x_tcp, x_cr))

    return Layout(params=p, rails=rails, sleepers=sleepers, joints=joints, running=running,
                  crossing_side=nose_side, x_tcp=float(geo.x_tcp), x_transition=float(geo.x_transition),
                  crossing_angle=float(geo.crossing_angle), lines=tuple(lines))


def _sleeper_positions(p: LayoutParams, geo: TurnoutGeometry) -> tuple[np.ndarray, float, float]:
    """Sleeper positions x [m] (the transition sleeper under the wheel transfer) and the panel's
    ends ``xa``, ``xb`` (half a spacing beyond the outer sleepers)."""
    h, N = float(p.sleeper_spacing), int(p.sleepers)
    # default N//2 + 1 is < N for every N >= MIN_SLEEPERS (checked in _validate)
    t = N // 2 + 1 if p.transition_sleeper is None else int(p.transition_sleeper)
    x0 = geo.x_transition - t * h
    if x0 < 0:
        raise ValueError(
            f"sleepers/transition_sleeper: the panel would start at x_0 = {x0:.3f} m, ahead of the "
            f"curve start (x = 0, the switch panel is not modelled); use fewer sleepers before "
            f"the transition sleeper (transition_sleeper = {t}, sleeper_spacing = {h} m)")
    xs = x0 + h * np.arange(N)
    return xs, x0 - h / 2, float(xs[-1] + h / 2)


def _turnout_rail_specs(p: LayoutParams, geo: TurnoutGeometry, xa: float, xb: float) -> list[_RailSpec]:
    """The rails of the panel between ``xa`` and ``xb``: stock, closure, crossing block, rear and
    check rails, each with its centre line, seat width and running edges."""
    g = float(p.gauge)
    hw = RAIL_HEAD_WIDTH[p.rail] / 2
    chw = CHECK_HEAD_WIDTH / 2
    base = RAIL_SECTIONS[p.rail]
    x_tcp, x_cf, x_cr = geo.x_tcp, geo.x_crossing_front, geo.x_crossing_rear

    def through(d):
        return lambda x: geo.through_y(d) * np.ones_like(np.asarray(x, dtype=float))

    def div(d):
        return lambda x: geo.diverging_y(x, d)

    def crossing_centre(x):
        return 0.5 * (geo.through_y(g / 2) + geo.diverging_y(x, -g / 2))

    def crossing_width(x):
        return max(abs(geo.separation(x)), CROSSING_SEAT_MIN_WIDTH)

    rail_w = lambda x: base.width  # noqa: E731  (seat = rail foot)
    check_w = lambda x: CHECK_RAIL_33C1.width  # noqa: E731
    const = BeamProfile(base=base)
    check_profile = BeamProfile(base=CHECK_RAIL_33C1)
    xc0 = max(xa, x_tcp + CHECK_RAIL_CENTRE_BEHIND_TCP - CHECK_RAIL_LENGTH / 2)
    xc1 = min(xb, x_tcp + CHECK_RAIL_CENTRE_BEHIND_TCP + CHECK_RAIL_LENGTH / 2)
    return [
        _RailSpec("stock_through", "rail", xa, xb, const, through(-g / 2 - hw), rail_w,
                  (("stock_through", "stock", through(-g / 2)),)),
        _RailSpec("stock_div", "rail", xa, xb, const, div(g / 2 + hw), rail_w,
                  (("stock_div", "stock", div(g / 2)),)),
        _RailSpec("closure_through", "rail", xa, x_cf, const, through(g / 2 + hw), rail_w,
                  (("closure_through", "closure", through(g / 2)),)),
        _RailSpec("closure_div", "rail", xa, x_cf, const, div(-g / 2 - hw), rail_w,
                  (("closure_div", "closure", div(-g / 2)),)),
        _RailSpec("crossing", "crossing", x_cf, x_cr, _crossing_profile(x_cf, x_tcp, x_cr, base),
                  crossing_centre, crossing_width, ()),
        _RailSpec("rear_through", "rail", x_cr, xb, const, through(g / 2 + hw), rail_w,
                  (("rear_through", "rail", through(g / 2)),)),
        _RailSpec("rear_div", "rail", x_cr, xb, const, div(-g / 2 - hw), rail_w,
                  (("rear_div", "rail", div(-g / 2)),)),
        _RailSpec("check_through", "check", xc0, xc1, check_profile,
                  through(-g / 2 + FLANGEWAY + chw), check_w,
                  (("check_through", "check", through(-g / 2 + FLANGEWAY)),)),
        _RailSpec("check_div", "check", xc0, xc1, check_profile,
                  div(g / 2 - FLANGEWAY - chw), check_w,
                  (("check_div", "check", div(g / 2 - FLANGEWAY)),)),
    ]


def _running_segments(p: LayoutParams, x_cf: float, x_cr: float) -> tuple[str, dict]:
    """(side of the crossing nose, the running rail of each side along x) for the route run."""
    nose_side = p.hand if p.route == "through" else _other(p.hand)
    leg = "through" if p.route == "through" else "div"
    other_stock = "stock_through" if p.route == "through" else "stock_div"
    return nose_side, {
        nose_side: (RunningSegment(f"closure_{leg}", -math.inf, x_cf),
                    RunningSegment("crossing", x_cf, x_cr),
                    RunningSegment(f"rear_{leg}", x_cr, math.inf)),
        _other(nose_side): (RunningSegment(other_stock, -math.inf, math.inf),),
    }


def _crossing_lines(geo: TurnoutGeometry, x_cf: float, x_tcp: float, x_cr: float) -> list:
    """Plan lines of the wing rails and the nose (running edges, world frame).

    The wing rails continue the closure rails from ``x_cf``; at the throat (separation
    = ``FLANGEWAY``) each kinks out to leave a flangeway beside the other route's
    running edge: the through-side wing follows ``L_d + FLANGEWAY``, the diverging-side
    wing ``L_t - FLANGEWAY``. They end ``CROSSING_WING_END`` behind the TCP. The nose
    is the V between ``L_t`` and ``L_d`` from the TCP to ``x_cr`` (closed at the heel).
    """
    g, s = geo.gauge, geo.sign
    x_end = min(x_tcp + CROSSING_WING_END, x_cr)
    xg = _grid(x_cf, x_end, extra=(geo.x_throat,))
    yd = s * geo.diverging_y(xg, -g / 2)  # canonical L_d
    wing_t = np.maximum(g / 2, yd + FLANGEWAY)
    wing_d = np.minimum(yd, g / 2 - FLANGEWAY)
    xn = _grid(x_tcp, x_cr)
    nose_x = np.concatenate([xn, xn[::-1]])
    nose_y = np.concatenate([np.full(xn.shape, g / 2), s * geo.diverging_y(xn[::-1], -g / 2)])
    return [PlanLine("wing_through", "wing", xg, s * wing_t),
            PlanLine("wing_div", "wing", xg, s * wing_d),
            PlanLine("nose", "nose", nose_x, s * nose_y)]
