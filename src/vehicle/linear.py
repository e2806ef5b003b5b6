"""Linear multibody vehicle: matrices, wheel kinematics and static equilibrium.

Equations of motion (all vertical quantities upward positive, SI units)::

    M q'' + C q' + K q = f_g + B Fz,        z = W q,   vz = W q',   B = W^T

* ``q`` (n,) generalised coordinates (bounce [m], roll and pitch [rad], modal
  amplitudes [m]); displacements are absolute and measured from the configuration in
  which every suspension spring is unstrained, so the spring preload is the result of
  gravity and not a separate term.
* ``f_g`` (n,) gravity load (``-m g`` on every bounce coordinate).
* ``Fz`` (m,) vertical wheel-rail contact force on each wheel, upward +.
* ``W`` (m, n) maps the coordinates to the vertical displacement of each wheel's
  contact point.  ``B = W^T`` follows from virtual work, so the input and output maps
  are not independent data.

Wheel numbering (DESIGN §4.4): front wheelset left, right, then the next wheelset;
left is +y.  A wheel's longitudinal position at time ``t`` is
``x_i(t) = x0 + a_i + v t`` with ``a_i <= 0`` its offset behind the front wheelset.

How the wheel dofs relate to the vehicle dofs
---------------------------------------------
The wheel displacements are not coordinates themselves; they are the combinations
``z = W q`` (for a rigid wheelset ``z_L,R = z_ws +/- b0 phi_ws``, for a flexible one
plus the bending amplitude).  Prescribing the wheel positions fixes the component of
``q`` in range(W^T); the remaining coordinates ``y`` move no wheel.  With
``W+ = W^T (W W^T)^-1`` and an orthonormal basis ``N`` of null(W),

    q = W+ z + N y,      (N^T K N) y = N^T (f_g - K W+ z)

which is the textbook partition ``K_ff x_f = f_f - K_fw z_w`` written in coordinates
where the wheel displacements are separate: when ``W`` merely selects coordinates
(e.g. wheelset bounce and roll after the change of variables z_L, z_R), ``W+`` and
``N`` are selection matrices and the two formulas coincide.  The contact forces that
hold this state in equilibrium are ``Fz = (W W^T)^-1 W (K q - f_g)``.  They equal the
nominal share of the weight (axle_load/2 per wheel for the symmetric vehicles here)
unless the prescribed wheel positions twist a statically indeterminate vehicle (a
bogie on four wheels with unequal cross-level on its two wheelsets).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np
import scipy.linalg as sla

GRAVITY = 9.81  # m/s^2, same value as track.params.GRAVITY (kept separate: no cross-import)


def param_field(default: Any, unit: str, doc: str) -> Any:
    """Dataclass field carrying its unit and a one-line description in ``metadata``.

    The FMU slaves turn every such field into an FMU parameter whose description
    is ``f"{doc} [{unit}]"``.
    """
    return field(default=default, metadata={"unit": unit, "doc": doc})


@dataclass(frozen=True)
class StaticState:
    """Static equilibrium of a vehicle standing on prescribed wheel positions.

    Attributes
    ----------
    q : ndarray, shape (n,)
        Generalised coordinates [m, rad].
    Fz : ndarray, shape (m,)
        Contact forces that hold ``q`` in equilibrium, upward + [N].
    """

    q: np.ndarray
    Fz: np.ndarray


class LinearVehicle:
    """Linear vehicle model ``M q'' + C q' + K q = f_g + W^T Fz``, wheel output ``z = W q``.

    Parameters
    ----------
    M, C, K : array_like, shape (n, n)
        Mass [kg, kg m^2], damping [N s/m, ...] and stiffness [N/m, ...] matrices;
        symmetric, ``M`` positive definite.
    f_g : array_like, shape (n,)
        Gravity load [N, N m].
    W : array_like, shape (m, n)
        Wheel contact-point displacement per coordinate [-, m/rad]; full row rank.
    wheel_offsets : array_like, shape (m,)
        Longitudinal offset ``a_i`` of each wheel from the front wheelset [m] (<= 0).
    dof_names : sequence of str, length n
        Names of the coordinates (e.g. ``"frame_pitch"``), for tests and plots.
    wheel_z_offset : array_like, shape (m,), optional
        Constant added to ``W q`` (non-zero only for systems with fixed coordinates
        from :meth:`constrained`) [m].
    """

    def __init__(self, M, C, K, f_g, W, wheel_offsets, dof_names: Sequence[str],
                 wheel_z_offset=None):
        self.M = np.array(M, dtype=float)
        self.C = np.array(C, dtype=float)
        self.K = np.array(K, dtype=float)
        self.f_g = np.array(f_g, dtype=float)
        self.W = np.atleast_2d(np.array(W, dtype=float))
        self.wheel_offsets = np.array(wheel_offsets, dtype=float)
        self.dof_names = tuple(dof_names)
        n = self.M.shape[0]
        m = self.W.shape[0]
        self.wheel_z_offset = (np.zeros(m) if wheel_z_offset is None
                               else np.array(wheel_z_offset, dtype=float))
        for name, A in (("M", self.M), ("C", self.C), ("K", self.K)):
            if A.shape != (n, n):
                raise ValueError(f"{name} has shape {A.shape}, expected ({n}, {n})")
            # symmetric up to rounding of the assembly
            if not np.allclose(A, A.T, rtol=1e-12, atol=1e-12 * np.abs(A).max()):
                raise ValueError(f"{name} is not symmetric")
        if self.f_g.shape != (n,) or self.W.shape[1] != n or len(self.dof_names) != n:
            raise ValueError("f_g, W and dof_names must match the size of M")
        if self.wheel_offsets.shape != (m,) or self.wheel_z_offset.shape != (m,):
            raise ValueError("wheel_offsets and wheel_z_offset must have one entry per wheel")
        self._M_cho = sla.cho_factor(self.M)  # raises LinAlgError if M is not positive definite

    # ------------------------------------------------------------------ sizes
    @property
    def n_dofs(self) -> int:
        return self.M.shape[0]

    @property
    def n_wheels(self) -> int:
        return self.W.shape[0]

    @property
    def B(self) -> np.ndarray:
        """Input matrix (n, m): generalised force per unit wheel force, ``W^T``."""
        return self.W.T

    def dof(self, name: str) -> int:
        """Index of the coordinate called ``name``."""
        return self.dof_names.index(name)

    # ------------------------------------------------------------- kinematics
    def wheel_x(self, t: float, x0: float, speed: float, out: np.ndarray | None = None) -> np.ndarray:
        """Track coordinate of each wheel at time ``t`` [s]: ``x0 + a_i + v t`` [m], shape (m,)."""
        if out is None:
            out = np.empty(self.n_wheels)
        np.add(self.wheel_offsets, x0 + speed * t, out=out)
        return out

    def wheel_z(self, q: np.ndarray) -> np.ndarray:
        """Vertical wheel displacement ``W q`` (+ offset) [m], shape (m,)."""
        return self.W @ q + self.wheel_z_offset

    # --------------------------------------------------------------- dynamics
    def accelerations(self, q: np.ndarray, v: np.ndarray, Fz: np.ndarray) -> np.ndarray:
        """``q'' = M^-1 (f_g + W^T Fz - K q - C v)``, shape (n,)."""
        rhs = self.f_g + self.W.T @ np.asarray(Fz, dtype=float) - self.K @ q - self.C @ v
        return sla.cho_solve(self._M_cho, rhs)

    def first_order(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """First-order form ``y' = A y + Bu Fz + g`` with ``y = [q, q']``.

        Returns
        -------
        A : ndarray, shape (2n, 2n)
        Bu : ndarray, shape (2n, m)
        g : ndarray, shape (2n,)
        """
        n = self.n_dofs
        Minv_K = sla.cho_solve(self._M_cho, self.K)
        Minv_C = sla.cho_solve(self._M_cho, self.C)
        A = np.zeros((2 * n, 2 * n))
        A[:n, n:] = np.eye(n)
        A[n:, :n] = -Minv_K
        A[n:, n:] = -Minv_C
        Bu = np.zeros((2 * n, self.n_wheels))
        Bu[n:] = sla.cho_solve(self._M_cho, self.W.T)
        g = np.zeros(2 * n)
        g[n:] = sla.cho_solve(self._M_cho, self.f_g)
        return A, Bu, g

    def natural_frequencies(self) -> np.ndarray:
        """Undamped natural frequencies [Hz] of the free vehicle (no contact), ascending.

        Rigid-body modes of a floating vehicle appear as (numerically) zero frequencies.
        """
        lam = sla.eigh(self.K, self.M, eigvals_only=True)
        return np.sqrt(np.clip(lam, 0.0, None)) / (2 * np.pi)

    # ----------------------------------------------------------------- statics
    def static_state(self, wheel_z0: Sequence[float]) -> StaticState:
        """Static equilibrium with the wheels held at ``wheel_z0`` [m], shape (m,).

        See the module docstring for the partition into wheel and non-wheel
        coordinates.  Velocities are zero in the static state.
        """
        z0 = np.asarray(wheel_z0, dtype=float) - self.wheel_z_offset
        if z0.shape != (self.n_wheels,):
            raise ValueError(f"wheel_z0 must have {self.n_wheels} entries, got {z0.shape}")
        WWt = self.W @ self.W.T
        if np.linalg.matrix_rank(WWt) < self.n_wheels:
            raise ValueError("W is rank deficient: the wheel positions cannot be prescribed independently")
        W_pinv = sla.solve(WWt, self.W, assume_a="pos").T         # (n, m)
        N = sla.null_space(self.W)                                # (n, n - m), orthonormal
        q_w = W_pinv @ z0
        K_NN = N.T @ self.K @ N
        y = sla.solve(K_NN, N.T @ (self.f_g - self.K @ q_w), assume_a="pos")
        q = q_w + N @ y
        Fz = sla.solve(WWt, self.W @ (self.K @ q - self.f_g), assume_a="pos")
        return StaticState(q=q, Fz=Fz)

    # --------------------------------------------------------------- variants
    def constrained(self, fixed: Sequence[int | str], values: Sequence[float] | None = None) -> "LinearVehicle":
        """The same vehicle with some coordinates held fixed (at ``values``, default 0).

        The fixed coordinates' stiffness coupling becomes a constant load on the free
        ones, and their contribution to the wheel displacements a constant offset.
        Used for analyses such as "bogie frame on its primary suspension, wheelsets
        and car body held fixed".
        """
        idx = [self.dof(f) if isinstance(f, str) else int(f) for f in fixed]
        free = [i for i in range(self.n_dofs) if i not in idx]
        qc = np.zeros(len(idx)) if values is None else np.asarray(values, dtype=float)
        ix = np.ix_(free, free)
        f = self.f_g[free] - self.K[np.ix_(free, idx)] @ qc
        return LinearVehicle(self.M[ix], self.C[ix], self.K[ix], f, self.W[:, free],
                             self.wheel_offsets, [self.dof_names[i] for i in free],
                             wheel_z_offset=self.wheel_z_offset + self.W[:, idx] @ qc)


class SuspensionAssembler:
    """Accumulates Kelvin elements (spring + dashpot in parallel) between points.

    An element's elongation is ``d . q`` with ``d`` (n,) the difference of the
    kinematic rows of its two end points; it adds ``k d d^T`` to K and ``c d d^T``
    to C (elastic energy ``k (d.q)^2 / 2``).
    """

    def __init__(self, n: int):
        self.K = np.zeros((n, n))
        self.C = np.zeros((n, n))

    def add(self, d: np.ndarray, k: float, c: float) -> None:
        dd = np.outer(d, d)
        self.K += k * dd
        self.C += c * dd
