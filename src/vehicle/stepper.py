"""Exact fixed-step discretisation of a :class:`~vehicle.linear.LinearVehicle`.

The first-order system ``y' = A y + Bu Fz + g`` (``y = [q, q']``) is linear with
constant coefficients, so over one communication step ``h`` it has a closed-form
solution once the input's shape within the step is fixed:

* ``"zoh"`` (zero-order hold): ``Fz`` constant over the step.  With the augmented
  matrix ``S = [[A, Bu, g], [0, 0, 0]] h`` (size 2n + m + 1) and
  ``expm(S) = [[Phi, Gu, gam], [0, I, 0]]``::

      y_{k+1} = Phi y_k + Gu Fz_k + gam

* ``"foh"`` (first-order hold): ``Fz`` varies linearly from ``Fz_k`` to
  ``Fz_{k+1}``.  With ``S = [[A h, [Bu g] h, 0], [0, 0, I], [0, 0, 0]]`` (the last
  block row/column has size m: the input increment ``dFz = Fz_{k+1} - Fz_k``)::

      y_{k+1} = Phi y_k + G1 [Fz_k, 1] + G2 dFz

No other approximation is made: the only error is that of ``scipy.linalg.expm``
(close to machine precision), so the scheme is exact for any ``h`` and has no
stability limit.  Each step is one matrix-vector product ``y_new = G z`` into
preallocated arrays, with ``G = [Phi | input columns]`` and ``z = [y | inputs]``.
"""
from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from .linear import LinearVehicle

HOLDS = ("zoh", "foh")
MAX_CACHED_STEPS = 8  # discretisations kept when the step size changes back and forth



_EXPM: dict = {}


def _expm_rows(S: np.ndarray, rows: int) -> np.ndarray:
    """The first ``rows`` rows of ``expm(S)``, once per matrix and process: the runs of a sweep
    or a diagnosis discretise the same vehicle at the same step (several ms each)."""
    key = (S.shape, S.tobytes(), rows)
    G = _EXPM.get(key)
    if G is None:
        G = np.ascontiguousarray(sla.expm(S)[:rows, :])
        G.setflags(write=False)
        while len(_EXPM) >= MAX_CACHED_STEPS:
            _EXPM.pop(next(iter(_EXPM)))
        _EXPM[key] = G
    return G

class VehicleStepper:
    """Advance a linear vehicle by fixed communication steps with exact discretisation.

    Parameters
    ----------
    vehicle : LinearVehicle
        The model (n coordinates, m wheels).
    h : float or None
        Step size [s]; ``None`` defers the discretisation to :meth:`set_step`.
    hold : {"zoh", "foh"}
        Input shape within a step (see module docstring).
    q0, v0 : array_like, shape (n,), optional
        Initial coordinates [m, rad] and velocities [m/s, rad/s]; default zero.
    Fz0 : array_like, shape (m,), optional
        Initial contact forces [N]; for ``"foh"`` the value at the start of the first
        step.  Default zero.

    Attributes
    ----------
    steps : int
        Number of steps taken (a counter, part of the state).
    wheel_z, wheel_vz : ndarray, shape (m,)
        Wheel displacement [m] and velocity [m/s] of the current state (views into a
        preallocated buffer, updated by every :meth:`step` and :meth:`set_state`).
    """

    def __init__(self, vehicle: LinearVehicle, h: float | None = None, hold: str = "zoh",
                 q0=None, v0=None, Fz0=None):
        if hold not in HOLDS:
            raise ValueError(f"hold must be one of {HOLDS}, got {hold!r}")
        self.vehicle = vehicle
        self.hold = hold
        n, m = vehicle.n_dofs, vehicle.n_wheels
        self._n2, self._m = 2 * n, m
        self._A, self._Bu, self._g = vehicle.first_order()
        # z = [y (2n) | Fz (m) | 1 | dFz (m, foh only)]
        self._z = np.zeros(2 * n + m + 1 + (m if hold == "foh" else 0))
        self._z[2 * n + m] = 1.0
        self._y = self._z[:2 * n]
        self._u = self._z[2 * n:2 * n + m]
        self._du = self._z[2 * n + m + 1:]
        self._ynew = np.empty(2 * n)
        # wheel outputs [z | vz] = blockdiag(W, W) y + [offset | 0]
        self._Y = np.zeros((2 * m, 2 * n))
        self._Y[:m, :n] = vehicle.W
        self._Y[m:, n:] = vehicle.W
        self._wheel = np.empty(2 * m)
        self._wheel_offset = np.concatenate([vehicle.wheel_z_offset, np.zeros(m)])
        self.wheel_z = self._wheel[:m]
        self.wheel_vz = self._wheel[m:]
        self._cache: dict[float, np.ndarray] = {}
        self.h: float | None = None
        self._G: np.ndarray | None = None
        self.steps = 0
        self.reset(q0, v0, Fz0)
        if h is not None:
            self.set_step(h)

    # ---------------------------------------------------------------- set-up
    def reset(self, q0=None, v0=None, Fz0=None) -> None:
        """Set coordinates, velocities and input; reset the step counter."""
        n = self._n2 // 2
        self._y[:n] = 0.0 if q0 is None else q0
        self._y[n:] = 0.0 if v0 is None else v0
        self._u[:] = 0.0 if Fz0 is None else Fz0
        self.steps = 0
        self._update_outputs()

    def set_step(self, h: float) -> None:
        """(Re)discretise for step size ``h`` [s]; the state is kept."""
        h = float(h)
        if not (np.isfinite(h) and h > 0.0):
            raise ValueError(f"step size must be positive and finite, got {h}")
        if h == self.h:
            return
        G = self._cache.get(h)
        if G is None:
            G = self._discretise(h)
            if len(self._cache) >= MAX_CACHED_STEPS:
                self._cache.pop(next(iter(self._cache)))
            self._cache[h] = G
        self._G, self.h = G, h

    def _discretise(self, h: float) -> np.ndarray:
        n2, m = self._n2, self._m
        inputs = np.hstack([self._Bu, self._g[:, None]])            # (2n, m + 1)
        if self.hold == "zoh":
            S = np.zeros((n2 + m + 1, n2 + m + 1))
            S[:n2, :n2] = self._A * h
            S[:n2, n2:] = inputs * h
            return _expm_rows(S, n2)
        S = np.zeros((n2 + 2 * m + 1, n2 + 2 * m + 1))
        S[:n2, :n2] = self._A * h
        S[:n2, n2:n2 + m + 1] = inputs * h
        S[n2:n2 + m, n2 + m + 1:] = np.eye(m)
        return _expm_rows(S, n2)

    # ------------------------------------------------------------------ step
    def step(self, Fz=None) -> None:
        """Advance the state by one step ``h``.

        Parameters
        ----------
        Fz : array_like, shape (m,), optional
            Contact forces [N], upward +.  ``"zoh"``: held over the step.  ``"foh"``:
            the value at the END of the step; the start value is the previous end
            value (or ``Fz0``).  ``None`` reuses the current input buffer.
        """
        if self._G is None:
            raise RuntimeError("no step size set: call set_step(h) first")
        if self.hold == "foh":
            if Fz is not None:
                np.subtract(Fz, self._u, out=self._du)
            else:
                self._du[:] = 0.0
        elif Fz is not None:
            self._u[:] = Fz
        np.dot(self._G, self._z, out=self._ynew)
        self._y[:] = self._ynew
        if self.hold == "foh" and Fz is not None:
            self._u[:] = Fz
        self.steps += 1
        self._update_outputs()

    def _update_outputs(self) -> None:
        np.dot(self._Y, self._y, out=self._wheel)
        self._wheel += self._wheel_offset

    def discrete_system(self) -> tuple:
        """``(G, z, y, u, ynew, Y, wheel, woff)``: the zoh step ``ynew = G z`` with ``z = [y | u | 1]``,
        the wheel outputs ``wheel = [z | vz] = Y y + woff``, and the buffers :meth:`step` works in
        (views of this stepper's state: a caller that steps them itself, e.g. ``track.fused``, keeps
        this object's state, but for :attr:`steps`). Needs a step size and ``hold="zoh"``."""
        if self._G is None or self.hold != "zoh":
            raise RuntimeError("discrete_system: needs a step size (set_step) and hold='zoh'")
        return self._G, self._z, self._y, self._u, self._ynew, self._Y, self._wheel, self._wheel_offset

    # ----------------------------------------------------------------- state
    @property
    def q(self) -> np.ndarray:
        """Coordinates [m, rad], shape (n,) (a view: do not modify)."""
        return self._y[:self._n2 // 2]

    @property
    def v(self) -> np.ndarray:
        """Velocities [m/s, rad/s], shape (n,) (a view: do not modify)."""
        return self._y[self._n2 // 2:]

    @property
    def Fz(self) -> np.ndarray:
        """Current input buffer [N], shape (m,) (a view)."""
        return self._u

    def get_state(self) -> np.ndarray:
        """Flat copy ``[q, v, Fz, steps]`` (2n + m + 1,): everything that evolves."""
        return np.concatenate([self._y, self._u, [float(self.steps)]])

    def set_state(self, state: np.ndarray) -> None:
        """Restore a state from :meth:`get_state` (the step size is not part of it)."""
        state = np.asarray(state, dtype=float)
        n2, m = self._n2, self._m
        if state.shape != (n2 + m + 1,):
            raise ValueError(f"state must have {n2 + m + 1} entries, got {state.shape}")
        self._y[:] = state[:n2]
        self._u[:] = state[n2:n2 + m]
        self.steps = int(state[n2 + m])
        self._update_outputs()
