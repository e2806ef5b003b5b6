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
"""
from __future__ import annotations

import time

import numpy as np

from .contact import HERTZ_CONSTANT, CrossingGeometry, DippedJoint, Flat, hertz_deflection
from .dynamics import ALPHA_DEFAULT, Counters, PointLoad, TrackIntegrator
from .kernel import CompiledContacts, kernel_enabled
from .model import TrackModel, build_track
from .params import TrackParams
from .statics import static_equilibrium

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
        d, j = self._data, self.n
        for name, value in zip(STATE_FIELDS, (q, v, a)):
            if name in self.columns:
                cols = self.columns[name]
                if cols is None:
                    d[name][j] = value
                else:
                    np.take(value, cols, out=d[name][j])
        d["t"][j], d["x"][j], d["Fz"][j], d["parts"][j] = t, x, Fz, parts
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
    def surface_geometry(self, side: str, body: str):
        """The geometry (``heights(x) -> (z1, z2)`` [m]) under a wheel on ``side`` running on ``body``."""
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
        for i, xi in enumerate(x.tolist()):
            body = running(self.sides[i], xi)
            pts.append(point(body, xi))
            surf.append(self.surfaces(i, xi, body))
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
        if self._compiled is not None:
            out = self._compiled.step(x, zc, self.c_h)
        else:
            pts, surf = self._points(x)
            out = self.integ.step_contacts(pts, zc, surf, self.c_h)
        self.Fz = out[:, 0]
        self.parts = out[:, 1:3]
        self.rail_w = out[:, 3]
        self.Fz_coupling = 1.5 * self.Fz - 0.5 * self._Fz_last if self.extrapolate_force else self.Fz
        self._Fz_last = self.Fz
        if not (self.Fz < self._limit).all():  # also catches NaN
            i = int(np.argmax(np.where(np.isfinite(self.Fz), self.Fz, np.inf)))
            raise DivergenceError(
                f"the coupled solution diverged at t = {self.integ.t:.6g} s with the communication step "
                f"{h:.3g} s (contact force on wheel {i + 1}: {self.Fz[i]:.4g} N); reduce simulation.step")
        if self.record_every and self.integ.k % self.record_every == 0:
            self._record(x)
        return self.Fz

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
