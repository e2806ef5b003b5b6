"""The track side of the co-simulation: reduced track + wheel–rail contact.

Inputs per wheel (DESIGN.md §4.4): track coordinate ``x`` [m], vertical position
``z`` [m] (up +) and velocity ``vz`` [m/s]; output: the vertical contact force
``Fz`` on the wheel [N] (up +). The Hertz contact lives here, on the track side,
solved implicitly with the track each step (DESIGN.md §8: with the wheel's
displacement and velocity as inputs the coupling stays accurate at large
communication steps).

Wheel numbering: front wheelset left, right, then the next wheelset; left wheels
run on the layout's left running rails.

Initialization (at the first step, when the inputs are known): static equilibrium
of the track under the static wheel loads at the wheels' positions; a wheel's
static position is then ``z_static = surface + w - delta0``. With ``auto_offset``
the difference between that and the vehicle's own (static) output is kept as an
offset, so any vehicle that starts in its own static equilibrium starts the
coupled run without a drop transient.

Contact geometry (``params.contact``, :class:`track.params.ContactParams`): ``dip`` (the
parameterized crossing, one Hertz constant) or ``profiles``: contact tables of the wheel profile
on the crossing's wing rail and nose (the crossing rail on the crossing side) and on the plain
rail (everywhere else), :func:`track.contact_geometry.scenario_tables`, looked up at each wheel's
x and lateral offset (``+offset`` for the wheels on the crossing side, ``-offset`` on the other:
the wheelset moves towards the crossing wheel's field side), with a Hertz constant per surface.
Irregularities (:class:`track.irregularity.Irregularities`) shift each wheel's contact input.
"""
from __future__ import annotations

import time

import numpy as np

from .contact import HERTZ_CONSTANT, CrossingGeometry, DippedJoint, Flat, TableGeometry, hertz_deflection
from .dynamics import ALPHA_DEFAULT, Counters, PointLoad, TrackIntegrator
from .kernel import CompiledContacts, kernel_enabled, record_row
from .model import TrackModel, build_track
from .params import TrackParams
from .statics import static_equilibrium

IRREGULARITY_MARGIN = 20.0   # m, generated rail irregularity beyond the panel at each end

DIVERGENCE_FACTOR = 50.0   # a contact force above this many static loads means divergence
FLAT = Flat()


class DivergenceError(RuntimeError):
    """The coupled solution blew up (one line, names the time and the step)."""


STATE_FIELDS = ("q", "v", "a")   # the recordable track states: displacements, velocities, accelerations
RECORD_FIRST_ROWS = 256          # rows of a record whose length is not reserved; it doubles when full


class Record:
    """Track states at the output times, in preallocated arrays written in place.

    One row per recorded time: ``t`` [s], the states of :data:`STATE_FIELDS` (all n
    columns, or only the columns asked for), the wheels' ``x`` [m], ``Fz`` [N] and
    ``parts`` [N].  The arrays hold :meth:`reserve`'s rows (or :data:`RECORD_FIRST_ROWS`)
    and double when full, so a run whose output count is known writes every row once
    and never copies the record; memory not yet written is not resident.

    Parameters
    ----------
    n_dofs : int
        Generalized coordinates of the track model.
    n_wheels : int
    columns : dict, optional
        State field -> indices of the columns to record (any order, unique), or ``None``
        for all n; a field not in the dict is not recorded.  Default: all of q, v, a.

    Raises
    ------
    ValueError
        An unknown field or a column outside ``0 .. n_dofs - 1``.
    """

    def __init__(self, n_dofs: int, n_wheels: int, columns: dict | None = None):
        columns = dict.fromkeys(STATE_FIELDS) if columns is None else dict(columns)
        unknown = set(columns) - set(STATE_FIELDS)
        if unknown:
            raise ValueError(f"record columns: unknown field(s) {sorted(unknown)}; known: {list(STATE_FIELDS)}")
        self.n_dofs, self.n_wheels = int(n_dofs), int(n_wheels)
        self.columns: dict = {}
        for name in STATE_FIELDS:
            if name not in columns:
                continue
            cols = columns[name]
            if cols is not None:
                cols = np.unique(np.asarray(cols, dtype=np.intp))
                if cols.size and (cols[0] < 0 or cols[-1] >= self.n_dofs):
                    raise ValueError(f"record columns of {name}: indices must lie in 0..{self.n_dofs - 1}")
            self.columns[name] = cols
        self.n = 0
        self._data: dict = {}
        self._allocate(RECORD_FIRST_ROWS)

    def _shape(self, name: str, rows: int) -> tuple:
        m = self.n_wheels
        if name in STATE_FIELDS:
            cols = self.columns[name]
            return rows, self.n_dofs if cols is None else cols.size
        return {"t": (rows,), "x": (rows, m), "Fz": (rows, m), "parts": (rows, m, 2)}[name]

    def _allocate(self, rows: int) -> None:
        """Arrays of ``rows`` rows holding the first ``n`` rows of the current ones."""
        data = {}
        for name in ("t", *self.columns, "x", "Fz", "parts"):
            data[name] = np.empty(self._shape(name, rows))
            if self.n:
                data[name][:self.n] = self._data[name][:self.n]
        self._data = data
        # record_row's arguments: per state field its columns (all n for None, none when not
        # recorded) and its array (a dummy without columns when not recorded)
        none, dummy = np.zeros(0, np.int64), np.empty((1, 0))
        cols = [none if name not in self.columns else
                np.arange(self.n_dofs, dtype=np.int64) if self.columns[name] is None else
                self.columns[name].astype(np.int64) for name in STATE_FIELDS]
        dst = [data[name] if name in self.columns else dummy for name in STATE_FIELDS]
        self._args = (*cols, data["t"], data["x"], data["Fz"], data["parts"], *dst)

    @property
    def capacity(self) -> int:
        """Rows the arrays hold before they grow."""
        return self._data["t"].shape[0]

    def __len__(self) -> int:
        return self.n

    def reserve(self, rows: int) -> None:
        """Hold at least ``rows`` rows without growing (the run's number of output times)."""
        if rows > self.capacity:
            self._allocate(int(rows))

    def append(self, t: float, q: np.ndarray, v: np.ndarray, a: np.ndarray, x: np.ndarray, Fz: np.ndarray,
               parts: np.ndarray) -> None:
        """Write one row: time [s], states (n,), wheel x [m], Fz [N], parts (m, 2) [N]."""
        if self.n == self.capacity:
            self._allocate(2 * self.capacity)
        j = self.n
        record_row(j, t, x, Fz, parts, q, v, a, *self._args)
        self.n = j + 1

    def truncate(self, n: int) -> None:
        """Forget the rows from ``n`` on (an FMU state restored to an earlier time)."""
        self.n = min(self.n, int(n))

    def arrays(self) -> dict:
        """The recorded rows as arrays (views, no copy): ``t`` (nt,), each recorded state field
        (nt, k) with, when only some columns are recorded, ``<field>_columns`` (k,), ``x``,
        ``Fz`` (nt, m) and ``parts`` (nt, m, 2).  :func:`state_rows` gives full-width rows."""
        out = {name: arr[:self.n] for name, arr in self._data.items()}
        for name, cols in self.columns.items():
            if cols is not None:
                out[f"{name}_columns"] = cols
        return out


def state_rows(record: dict, name: str, n_dofs: int, rows: slice = slice(None)) -> np.ndarray:
    """Rows of a recorded state field at full width, shape (nr, n_dofs).

    The inverse of a column selection of :class:`Record`: a field recorded in all
    columns is returned as a view; one recorded in some columns (``<name>_columns`` in
    ``record``) is scattered into zeros, so a quantity that reads only recorded columns
    comes out exactly as from the full state.  Take a block of rows at a time.

    Parameters
    ----------
    record : dict
        :meth:`Record.arrays` (or the same arrays read back from a file).
    name : str
        ``"q"``, ``"v"`` or ``"a"``.
    n_dofs : int
    rows : slice
        Which rows.

    Raises
    ------
    KeyError
        The field was not recorded.
    """
    values = record[name][rows]
    cols = record.get(f"{name}_columns")
    if cols is None:
        return values
    full = np.zeros((values.shape[0], n_dofs))
    full[:, np.asarray(cols, np.intp)] = values
    return full


def wheel_sides(n_wheels: int) -> list[str]:
    """Side of each wheel: wheels 1, 3, ... left; 2, 4, ... right."""
    return ["left" if i % 2 == 0 else "right" for i in range(n_wheels)]


class TrackCosim:
    """Reduced track with wheel contacts, stepped by a co-simulation master.

    Parameters
    ----------
    params : TrackParams
    n_wheels : int
    static_wheel_load : float or array_like
        Static load of each wheel [N] (positive), e.g. axle_load / 2.
    h : float
        Communication (= integration) step [s].
    speed : float
        Vehicle speed [m/s] (to extrapolate x when ``extrapolate``).
    extrapolate : bool
        Inputs are at the start of the step (Jacobi): use ``z + vz h`` and
        ``x + speed h`` as end-of-step wheel positions. False when the inputs are
        already end-of-step values (Gauss–Seidel with the vehicle first).
    auto_offset : bool
        Align the vehicle's static wheel positions with the track's (see module doc).
    extrapolate_force : bool
        Also offer ``Fz_coupling``: the contact force extrapolated to the middle of the
        next communication step, ``1.5 Fz(t_k) - 0.5 Fz(t_k-1)``. A vehicle that holds
        its force input over a step then integrates it to second order (midpoint rule)
        instead of first: the coupling error of the peak force at the crossing falls
        from 1.5 % to 0.3 % at a 100 us step (tests/test_cosim.py).
    record_every : int
        Record the state every this many steps (0: never).
    record_columns : dict, optional
        What to record of the states (:class:`Record`'s ``columns``): default all columns
        of q, v and a.  Reserve the rows with ``self.record.reserve``.
    model : TrackModel, optional
        A prebuilt model of ``params``.
    kernel : bool, optional
        Step with the compiled kernel (:mod:`track.kernel`) or with the numpy reference
        path of :meth:`TrackIntegrator.step_contacts`; default: the environment variable
        ``TURNOUT_TRACK_KERNEL`` (``numpy`` selects the reference), else compiled.
    """

    def __init__(self, params: TrackParams, n_wheels: int, static_wheel_load, h: float, speed: float = 0.0,
                 extrapolate: bool = False, auto_offset: bool = True, record_every: int = 0,
                 extrapolate_force: bool = False,
                 model: TrackModel | None = None, alpha: float = ALPHA_DEFAULT, c_h: float = HERTZ_CONSTANT,
                 kernel: bool | None = None, record_columns: dict | None = None):
        self.params = params
        self.kernel = kernel_enabled(kernel)
        self._compiled: CompiledContacts | None = None
        self.model = model if model is not None else build_track(params)
        self.n = int(n_wheels)
        self.sides = wheel_sides(self.n)
        self.Q0 = np.broadcast_to(np.asarray(static_wheel_load, float), (self.n,)).copy()
        self.h = float(h)
        self.speed = float(speed)
        self.extrapolate = bool(extrapolate)
        self.auto_offset = bool(auto_offset)
        self.extrapolate_force = bool(extrapolate_force)
        self.record_every = int(record_every)
        self.alpha = alpha
        self.c_h = c_h
        lay = self.model.layout
        self.crossing = None
        if lay.x_tcp is not None:
            self.crossing = CrossingGeometry(lay.x_tcp, lay.x_transition, params.impact_angle)
        self.contact = getattr(params, "contact", None)
        self.tables = None                   # profile contact: (crossing, plain) TableGeometry
        self.irregularities = None
        self._y_sign = np.array([1.0 if s == (lay.crossing_side or "left") else -1.0 for s in self.sides])
        if self.contact is not None and self.contact.geometry == "profiles":
            self.tables = self._contact_tables()
        if self.contact is not None and self.contact.irregular:
            from .irregularity import Irregularities
            xs = [sl.x for sl in lay.sleepers]
            self.irregularities = Irregularities.from_params(
                self.contact, self.n, min(xs) - IRREGULARITY_MARGIN, max(xs) - min(xs) + 2 * IRREGULARITY_MARGIN)
        self.joint = None
        if lay.x_tcp is None and params.dipped_joint > 0.0:
            k = len(lay.sleepers) // 2
            self.joint = DippedJoint(0.5 * (lay.sleepers[k].x + lay.sleepers[k + 1].x), params.dipped_joint)
        self.integ: TrackIntegrator | None = None
        self.offset = np.zeros(self.n)
        self.z_static = np.zeros(self.n)
        self.Fz = self.Q0.copy()           # outputs: contact force on each wheel [N]
        self.Fz_coupling = self.Q0.copy()  # force for the vehicle's input (see extrapolate_force) [N]
        self._Fz_last = self.Q0.copy()
        self.parts = np.zeros((self.n, 2))  # force on first / second surface [N]
        self.rail_w = np.zeros(self.n)      # rail deflection under each wheel [m]
        self.record = Record(self.model.n, self.n, record_columns)
        self._limit = DIVERGENCE_FACTOR * self.Q0
        self.wall_statics = 0.0             # wall time of the static equilibrium at initialization [s]
        self.wall_factor = 0.0              # ... and of the integrator's set-up (step-matrix LU) [s]

    # ------------------------------------------------------------------ geometry
    def _contact_tables(self):
        """The (crossing, plain) contact tables of the profile contact (:func:`contact_tables`)."""
        return contact_tables(self.model, self.contact)

    def lateral_offsets(self, x: np.ndarray) -> np.ndarray:
        """Each wheel's lateral offset towards its field side [m] at its x (profile contact)."""
        c = self.contact
        if c.lateral_offset_table:
            xt, yt = c.lateral_offset_table
            return self._y_sign * np.interp(x, xt, yt)
        return self._y_sign * c.lateral_offset

    def surface_geometry(self, side: str, body: str):
        """The geometry (``heights(x) -> (z1, z2)`` [m]) under a wheel on ``side`` running on ``body``."""
        if self.tables is not None:
            crossing, plain = self.tables
            if crossing is not None and side == self.model.layout.crossing_side and \
                    self.model.body(body).kind == "crossing":
                return crossing
            return plain
        if self.crossing is not None and side == self.model.layout.crossing_side and \
                self.model.body(body).kind == "crossing":
            return self.crossing
        if self.joint is not None:
            return self.joint
        return FLAT

    def surfaces(self, i: int, x: float, body: str) -> tuple[float, float]:
        """Surface heights under wheel i at x on ``body`` [m]."""
        return self.surface_geometry(self.sides[i], body).heights(x)

    def _points(self, x: np.ndarray):
        pts, surf = [], []
        running, point = self.model.layout.running_body, self.model.point
        if self.tables is not None:
            return self._table_points(x)
        for i, xi in enumerate(x.tolist()):
            body = running(self.sides[i], xi)
            pts.append(point(body, xi))
            surf.append(self.surfaces(i, xi, body))
        return pts, surf

    def _table_points(self, x: np.ndarray):
        """Rail points, surface heights [m] and Hertz constants (m, 2) [N/m^1.5] of the profile contact."""
        pts, surf, ch = [], [], np.empty((self.n, 2))
        running, point = self.model.layout.running_body, self.model.point
        for i, (xi, yi) in enumerate(zip(x.tolist(), self.lateral_offsets(x).tolist())):
            body = running(self.sides[i], xi)
            geo: TableGeometry = self.surface_geometry(self.sides[i], body)
            pts.append(point(body, xi))
            surf.append(geo.heights(xi, yi))
            ch[i] = geo.constants(xi, yi)
        self._ch = ch
        return pts, surf

    # ------------------------------------------------------------------ stepping
    @property
    def initialized(self) -> bool:
        return self.integ is not None

    @property
    def counters(self) -> Counters:
        """The integrator's work counters (steps, solves, passes, contact Newton sweeps); zeros
        before the first step."""
        return self.integ.counters if self.integ is not None else Counters()

    def initialize(self, x: np.ndarray, z: np.ndarray, t0: float = 0.0) -> None:
        """Static equilibrium under the static wheel loads at x; offsets from the vehicle's z."""
        x = np.asarray(x, float)
        t_start = time.perf_counter()
        pts, surf = self._points(x)
        loads = [PointLoad(p, -q) for p, q in zip(pts, self.Q0)]
        st = static_equilibrium(self.model, [(ld.point, ld.force) for ld in loads])
        self.wall_statics = time.perf_counter() - t_start
        self.static = st
        w = np.array([p.value(st.q, -q) for p, q in zip(pts, self.Q0)])
        top = np.array([max(s) for s in surf])
        if self.tables is not None:      # the constant of the surface that carries the static load
            c_top = [c[int(np.argmax(s))] for s, c in zip(surf, self._ch)]
            top = top + self._irregularity(x)
            self.z_static = top + w - np.array([hertz_deflection(q, c) for q, c in zip(self.Q0, c_top)])
        else:
            top = top + self._irregularity(x) if self.irregularities is not None else top
            self.z_static = top + w - np.array([hertz_deflection(q, self.c_h) for q in self.Q0])
        self.offset = self.z_static - np.asarray(z, float) if self.auto_offset else np.zeros(self.n)
        t_start = time.perf_counter()
        self.integ = TrackIntegrator(self.model, self.h, st.q, loads0=loads, alpha=self.alpha)
        self._attach_kernel()
        self.wall_factor = time.perf_counter() - t_start
        self.integ.t0 = t0
        self.rail_w = w
        self.Fz = self.Q0.copy()
        self.parts[:, 0], self.parts[:, 1] = self.Q0, 0.0
        self._record(x)

    def do_step(self, x: np.ndarray, z: np.ndarray, vz: np.ndarray) -> np.ndarray:
        """Advance one step; returns the contact forces on the wheels at the step's end [N].

        ``x``, ``z``, ``vz`` are the wheel inputs (start-of-step values if
        ``extrapolate``, else end-of-step values). The first call initializes.
        """
        x = np.asarray(x, float)
        z = np.asarray(z, float)
        if not self.initialized:
            x0 = x if self.extrapolate else x - self.speed * self.h
            z0 = z if self.extrapolate else z - np.asarray(vz, float) * self.h
            self.initialize(x0, z0)
        h = self.h
        if self.extrapolate:
            x = x + self.speed * h
            z = z + np.asarray(vz, float) * h
        zc = z + self.offset
        if self.irregularities is not None:
            zc = zc - self._irregularity(x)
        if self._compiled is not None:
            y = self.lateral_offsets(x) if self.tables is not None else None
            out = self._compiled.step(x, zc, self.c_h, y)
        else:
            pts, surf = self._points(x)
            out = self.integ.step_contacts(pts, zc, surf, self._ch if self.tables is not None else self.c_h)
        self.Fz = out[:, 0]
        self.parts = out[:, 1:3]
        self.rail_w = out[:, 3]
        self.Fz_coupling = 1.5 * self.Fz - 0.5 * self._Fz_last if self.extrapolate_force else self.Fz
        self._Fz_last = self.Fz
        self.check_divergence()
        if self.record_every and self.integ.k % self.record_every == 0:
            self._record(x)
        return self.Fz

    def check_divergence(self) -> None:
        """Raise :class:`DivergenceError` when a contact force is at or above its limit, or NaN."""
        if not (self.Fz < self._limit).all():  # also catches NaN
            i = int(np.argmax(np.where(np.isfinite(self.Fz), self.Fz, np.inf)))
            raise DivergenceError(
                f"the coupled solution diverged at t = {self.integ.t:.6g} s with the communication step "
                f"{self.h:.3g} s (contact force on wheel {i + 1}: {self.Fz[i]:.4g} N); reduce simulation.step")

    def _irregularity(self, x: np.ndarray) -> np.ndarray:
        """Each wheel's irregularity input at x [m] (zeros without irregularities)."""
        if self.irregularities is None:
            return np.zeros(self.n)
        return self.irregularities.at(x, self.sides)

    def _attach_kernel(self) -> None:
        self._compiled = CompiledContacts(self.integ, self.sides, self.surface_geometry) if self.kernel else None

    def _record(self, x: np.ndarray) -> None:
        if self.record_every:
            i = self.integ
            self.record.append(i.t, i.q, i.v, i.a, x, self.Fz, self.parts)

    # ------------------------------------------------------------------ state
    def get_state(self) -> dict:
        """Everything that evolves, for FMU state save/restore (arrays copied)."""
        return {"integ": None if self.integ is None else self.integ.get_state(),
                "offset": self.offset.copy(), "z_static": self.z_static.copy(), "Fz": self.Fz.copy(),
                "Fz_coupling": self.Fz_coupling.copy(), "Fz_last": self._Fz_last.copy(),
                "parts": self.parts.copy(), "rail_w": self.rail_w.copy(),
                "record_len": len(self.record)}

    def set_state(self, s: dict) -> None:
        if s["integ"] is None:
            self.integ = self._compiled = None
        else:
            if self.integ is None:
                self.integ = TrackIntegrator(self.model, self.h, np.zeros(self.model.n), alpha=self.alpha)
                self._attach_kernel()
            self.integ.set_state(s["integ"])
        self.offset, self.z_static = s["offset"].copy(), s["z_static"].copy()
        self.Fz, self.parts, self.rail_w = s["Fz"].copy(), s["parts"].copy(), s["rail_w"].copy()
        self.Fz_coupling, self._Fz_last = s["Fz_coupling"].copy(), s["Fz_last"].copy()
        self.record.truncate(s["record_len"])


# ------------------------------------------------------------------------------- profile outputs
def contact_tables(model: TrackModel, contact):
    """The (crossing, plain) :class:`track.contact.TableGeometry` of ``contact`` (``geometry: profiles``)
    for ``model`` (cached by content: the same objects a :class:`TrackCosim` of the model uses)."""
    from .contact_geometry import scenario_tables
    lay = model.layout
    segs = [g for g in lay.running.get(lay.crossing_side, ()) if model.body(g.body).kind == "crossing"] \
        if lay.crossing_side else []
    x_range = (min(g.x0 for g in segs), max(g.x1 for g in segs)) if segs else None
    return scenario_tables(lay, contact, x_range)


def profile_outputs(model: TrackModel, contact, x: np.ndarray, parts: np.ndarray) -> dict:
    """Contact point and Hertz patch per wheel and surface from recorded positions and forces.

    Parameters
    ----------
    model : TrackModel
    contact : track.params.ContactParams
        With ``geometry: profiles``.
    x : ndarray (nt, m)
        Wheel track coordinates [m].
    parts : ndarray (nt, m, 2)
        Force on each surface [N] (first: rail / wing rail, second: nose).

    Returns
    -------
    dict of ndarray (nt, m, 2): ``eta`` (lateral position on the rail section [m], outward from the
    running edge), ``radius`` (rolling radius [m]), ``a``, ``b`` (patch semi-axes along and across
    the track [m]), ``p0`` (peak pressure [Pa]); NaN where a surface carries no force. The
    curvatures are looked up at the recorded x and lateral offset (bilinear), the patch is
    :func:`track.hertz.hertz_patch` at the normal load ``F / cos(contact angle)``.
    """
    from .hertz import hertz_patch
    crossing, plain = contact_tables(model, contact)
    lay = model.layout
    sides = wheel_sides(x.shape[1])
    sign = np.array([1.0 if s == (lay.crossing_side or "left") else -1.0 for s in sides])
    if contact.lateral_offset_table:
        y = sign * np.interp(x, *contact.lateral_offset_table)
    else:
        y = np.broadcast_to(sign * contact.lateral_offset, x.shape)
    out = {k: np.full(parts.shape, np.nan) for k in ("eta", "radius", "a", "b", "p0")}
    for i, side in enumerate(sides):
        on_x = np.array([crossing is not None and side == lay.crossing_side and
                         model.body(lay.running_body(side, xi)).kind == "crossing" for xi in x[:, i].tolist()])
        for geo, rows in ((crossing, on_x), (plain, ~on_x)):
            if geo is None or not rows.any():
                continue
            tab = geo.table
            xs, ys = x[rows, i], y[rows, i]
            look = {f: tab.lookup(f, xs, ys) for f in ("eta", "radius", "A", "B", "angle")}
            for k in range(len(tab.surfaces)):
                F = parts[rows, i, k]
                loaded = F > 0.0
                with np.errstate(invalid="ignore"):
                    patch = hertz_patch(look["A"][k], look["B"][k], np.where(loaded, F, 1.0) / np.cos(look["angle"][k]))
                for name, v in (("eta", look["eta"][k]), ("radius", look["radius"][k]), ("a", patch.a),
                                ("b", patch.b), ("p0", patch.p0)):
                    out[name][rows, i, k] = np.where(loaded, v, np.nan)
    return out


IMPACT_WINDOW = (0.005, 0.10)   # m: the wheel centre's slope is fitted from 5 mm to 10 cm either side of the transfer


def emergent_impact_angle(x: np.ndarray, z: np.ndarray, nose_force: np.ndarray, wing_force: np.ndarray,
                          window: tuple = IMPACT_WINDOW) -> dict:
    """The impact angle that emerges from one wheel's recorded vertical path through the transfer.

    The transfer is the first x where the nose carries more than the wing rail; the wheel centre's
    vertical slope ``dz/dx`` is the least-squares line through its recorded ``z(x)`` from
    ``window[0]`` to ``window[1]`` before and after it; the impact angle is the slope after minus
    the slope before [rad] (positive: the wheel, falling with the wing rail, is turned upwards).

    Returns
    -------
    dict with ``x_transfer`` [m], ``slope_before``, ``slope_after``, ``angle`` [rad] (NaNs when
    the wheel does not transfer within the record).
    """
    nan = dict(x_transfer=np.nan, slope_before=np.nan, slope_after=np.nan, angle=np.nan)
    k = np.flatnonzero(nose_force > wing_force)
    if k.size == 0 or k[0] == 0:
        return nan
    xt = float(x[k[0]])
    lo, hi = window

    def slope(sel):
        if sel.sum() < 3:
            return np.nan
        return float(np.polyfit(x[sel], z[sel], 1)[0])

    before = slope((x >= xt - hi) & (x <= xt - lo))
    after = slope((x >= xt + lo) & (x <= xt + hi))
    return dict(x_transfer=xt, slope_before=before, slope_after=after, angle=after - before)
