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
from dataclasses import dataclass, field

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


@dataclass
class Record:
    """Recorded track states at the output times."""

    t: list = field(default_factory=list)
    q: list = field(default_factory=list)
    v: list = field(default_factory=list)
    a: list = field(default_factory=list)
    x: list = field(default_factory=list)
    Fz: list = field(default_factory=list)
    parts: list = field(default_factory=list)

    def arrays(self) -> dict:
        return {k: np.array(getattr(self, k)) for k in ("t", "q", "v", "a", "x", "Fz", "parts")}


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
                 kernel: bool | None = None):
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
        self.record = Record()
        self._limit = DIVERGENCE_FACTOR * self.Q0
        self.wall_statics = 0.0             # wall time of the static equilibrium at initialization [s]
        self.wall_factor = 0.0              # ... and of the integrator's set-up (step-matrix LU) [s]

    # ------------------------------------------------------------------ geometry
    def surfaces(self, i: int, x: float, body: str) -> tuple[float, float]:
        """Surface heights under wheel i at x on ``body`` [m]."""
        side = self.sides[i]
        if self.crossing is not None and side == self.model.layout.crossing_side and \
                self.model.body(body).kind == "crossing":
            return self.crossing.heights(x)
        if self.joint is not None:
            return self.joint.heights(x)
        return FLAT.heights(x)

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
        self._compiled = CompiledContacts(self.integ, self.sides, self.surfaces) if self.kernel else None

    def _record(self, x: np.ndarray) -> None:
        if not self.record_every:
            return
        r = self.record
        r.t.append(self.integ.t)
        r.q.append(self.integ.q.copy())
        r.v.append(self.integ.v.copy())
        r.a.append(self.integ.a.copy())
        r.x.append(np.array(x, float))
        r.Fz.append(self.Fz.copy())
        r.parts.append(self.parts.copy())

    # ------------------------------------------------------------------ state
    def get_state(self) -> dict:
        """Everything that evolves, for FMU state save/restore (arrays copied)."""
        return {"integ": None if self.integ is None else self.integ.get_state(),
                "offset": self.offset.copy(), "z_static": self.z_static.copy(), "Fz": self.Fz.copy(),
                "Fz_coupling": self.Fz_coupling.copy(), "Fz_last": self._Fz_last.copy(),
                "parts": self.parts.copy(), "rail_w": self.rail_w.copy(),
                "record_len": len(self.record.t)}

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
        n = s["record_len"]
        for k in ("t", "q", "v", "a", "x", "Fz", "parts"):
            del getattr(self.record, k)[n:]
