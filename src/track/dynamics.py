"""Time integration of the reduced track with the bi-linear ballast.

Scheme: HHT-alpha (Hilber, Hughes & Taylor 1977), second-order accurate,
unconditionally stable for linear systems, with numerical damping of the
highest modes controlled by ``alpha`` in [-1/3, 0] (``alpha = 0`` is the
trapezoidal rule). Equation of motion in the reduced coordinates:

    M a + C v + K q = f_gravity + sum_k F_k(w_k, v_k) r_k + f_b(q, v)

with ``f_b`` the ballast reaction and point forces ``F_k`` acting at material
points of the rails (``w_k = r_k . q``), e.g. moving wheel loads or, in the
co-simulation, Hertz contact forces that depend on the rail deflection.

The ballast is written as its all-in-contact linear part plus a correction,
``f_b = -(K_b q + C_b v) + r_b(q, v)``, so the step matrix of the acceleration form

    A a1 = (1+alpha) F1 - alpha F0 - C [(1+alpha) v~ - alpha v0] - K [(1+alpha) q~ - alpha q0],
    A = M + (1+alpha) (gamma h C + beta h^2 K),   q1 = q~ + beta h^2 a1,  v1 = v~ + gamma h a1

(``K``, ``C`` including the linear ballast, ``q~``, ``v~`` the Newmark predictors)
is constant and factorized once (sparse LU with a minimum-degree ordering of
A^T A, a third of the default fill on this structure). One product with K and one
with the (very sparse) C per step. The nonlinear terms (``r_b`` and ``F_k``) are
iterated with the constant A (modified Newton). At the small steps the contact
needs, M dominates A and the iteration contracts by roughly
``k beta h^2 / m`` per pass, so 1-2 passes are the norm; the counters record them.

:class:`TrackIntegrator` is the step interface the co-simulation uses: advance by
one step given the point forces, read the displacement and velocity at any point.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .ballast import DAMPING_ONSET
from .contact import HERTZ_CONSTANT, hertz_pair
from .model import PointMap, TrackModel
from .timegrid import step_count

ALPHA_DEFAULT = -0.05   # slight numerical damping of modes far above the cut-off
MOTION_SAFETY = 4.0      # a bushing is checked when its compression is within this many times
                         # its predicted motion over the step (|v| h + |a| h^2) of the damping onset
MOTION_FLOOR = 1e-6      # m: ... plus this
CONTACT_NEWTON_MAX = 30  # Newton iterations of the contact forces within one pass
CONTACT_TOL = 1e-6       # N: Newton stops when the contact force update is below this ...
CONTACT_REL_TOL = 1e-9   # ... plus this times the largest wheel force (1e-4 N on 100 kN)
MAX_ITER = 50           # modified-Newton passes per step before the step is refused
FORCE_TOL = 1e-3        # N: change of any nonlinear force between passes at convergence
REL_FORCE_TOL = 1e-6    # relative to the largest applied force. A force error f left in one
                        # step moves the state by ~ f beta h^2 / m: 0.1 N -> 1e-13 m at 20 us,
                        # and it is not carried over (the next step re-evaluates the forces)


# ------------------------------------------------------------------------------------------
# Factorizations shared by integrators of the same matrix (a calibration or a diagnosis runs
# hundreds of variants of one track that differ only in void gaps or loads: the matrix
# M + (1+a)(g h C + b h^2 K), its LU and the influence rows are then the same)
# ------------------------------------------------------------------------------------------
FACTOR_CACHE_SIZE = 4   # matrices kept per process (each: LU + ballast rows, ~10-30 MB)


@dataclass(eq=False)
class _SharedFactor:
    A: object                 # the step matrix (csc)
    lu: object = None         # its SuperLU factor: the numpy path's, made on first use (TrackIntegrator._lu)
    influence: dict = field(default_factory=dict)
    Zb: np.ndarray | None = None
    Zb_have: np.ndarray | None = None
    Zb_dofs: np.ndarray | None = None
    # the compiled step's own factorization (track.kernel.LDLFactor) and its influence data
    ldl: object = None
    ldl_rows: dict = field(default_factory=dict)   # track.kernel.element_rows key -> (influence rows, solved)
    ldl_Zb: np.ndarray | None = None
    ldl_have: np.ndarray | None = None
    ldl_Zb_dofs: np.ndarray | None = None


_FACTORS: dict = {}


def _shared_factor(A: sp.csc_matrix) -> _SharedFactor:
    """The shared factorizations of ``A``, from the cache when the same matrix was seen."""
    import hashlib

    A.sort_indices()
    h = hashlib.blake2b(digest_size=20)
    for arr in (np.array(A.shape), A.indptr, A.indices, A.data):
        h.update(np.ascontiguousarray(arr).tobytes())
    key = h.hexdigest()
    hit = _FACTORS.pop(key, None)
    if hit is not None:
        _FACTORS[key] = hit           # most recently used last
        return hit
    while len(_FACTORS) >= FACTOR_CACHE_SIZE:
        _FACTORS.pop(next(iter(_FACTORS)))
    out = _FACTORS[key] = _SharedFactor(A)
    return out


@dataclass
class PointLoad:
    """A vertical force at a material point of the track.

    Attributes
    ----------
    point : PointMap
    force : float or callable
        Constant force [N] (up +) or ``force(w, v) -> F`` of the point's
        displacement ``w = point.weights @ q`` [m] and velocity [m/s] at the end of
        the step. A force law that depends on the deflection under itself (Hertz
        contact) must add the local term ``point.residual * F`` itself.
    """

    point: PointMap
    force: float | Callable[[float, float], float]


@dataclass
class Counters:
    """Work counters of an integration (read by tests, benchmarks and the co-simulation's stats).

    Plain integer increments where the work happens, so counting costs nothing measurable.

    Attributes
    ----------
    steps : int
        Steps taken (a step the co-simulation master repeats counts each time).
    iterations : int
        Modified-Newton passes over all steps (1-2 per step is the norm).
    factorizations : int
        Sparse LU factorizations of the step matrix (none when it came from the shared
        cache), plus the mass-matrix solve of the initial acceleration.
    solves : int
        Solves with the factorized step matrix, each right-hand-side column counted
        (the step's own solve, influence columns of rail elements, ballast rows).
    max_iterations : int
        Most passes one step needed.
    contact_newton : int
        Newton sweeps of the Hertz contact forces (each sweep updates every wheel).
    """

    steps: int = 0
    iterations: int = 0
    factorizations: int = 0
    solves: int = 0
    max_iterations: int = 0
    contact_newton: int = 0


class ConvergenceError(RuntimeError):
    """The nonlinear iteration of a step did not converge."""


class TrackIntegrator:
    """HHT-alpha integrator of a :class:`TrackModel` with a fixed step.

    Parameters
    ----------
    model : TrackModel
    h : float
        Time step [s].
    q0 : ndarray, shape (n,)
        Initial displacement (usually the static equilibrium).
    v0 : ndarray, shape (n,), optional
        Initial velocity (default zero).
    loads0 : sequence of PointLoad
        Point forces acting at t0 (to start from an equilibrium acceleration).
    alpha : float
        HHT parameter in [-1/3, 0].
    """

    def __init__(self, model: TrackModel, h: float, q0: np.ndarray, v0: np.ndarray | None = None,
                 loads0: Sequence[PointLoad] = (), alpha: float = ALPHA_DEFAULT):
        if not (-1.0 / 3.0 <= alpha <= 0.0):
            raise ValueError(f"alpha = {alpha} outside [-1/3, 0]")
        if not h > 0:
            raise ValueError(f"time step h = {h} must be > 0")
        self.model = model
        self.h = float(h)
        self.alpha = float(alpha)
        self.gamma = 0.5 - alpha
        self.beta = 0.25 * (1.0 - alpha) ** 2
        self.counters = Counters()
        n = model.n
        bal = model.ballast
        self._D = bal.dof
        Kb = sp.csr_matrix((bal.k, (bal.dof, bal.dof)), shape=(n, n))
        Cb = sp.csr_matrix((bal.c, (bal.dof, bal.dof)), shape=(n, n))
        self._Kt = (model.K + Kb).tocsr()
        self._Ct = (model.C + Cb).tocsr()
        b, g, a = self.beta, self.gamma, self.alpha
        A = model.M + (1 + a) * (g * h * self._Ct + b * h * h * self._Kt)
        self.step_matrix = A.tocsc()   # M + (1+alpha)(gamma h C + beta h^2 K), constant
        shared = _shared_factor(self.step_matrix)
        self.t0 = 0.0
        self.k = 0  # steps taken: t = t0 + k h (no accumulated round-off)
        self.q = np.array(q0, dtype=float)
        self.v = np.zeros(n) if v0 is None else np.array(v0, dtype=float)
        self.F = self._forces(self.q, self.v, loads0)
        self.Fc = np.array([-ld.force for ld in loads0 if not callable(ld.force)], dtype=float)
        self._influence_cache = shared.influence   # shared by integrators with the same matrix
        self._shared = shared
        self._rhs_const = (1.0 + self.alpha) * model.f_gravity
        # initial acceleration from the equation of motion
        r = self.F - self._Ct @ self.v - self._Kt @ self.q
        self.a = spla.spsolve(model.M.tocsc(), r)
        self.counters.factorizations += 1

    @property
    def _lu(self):
        """The step matrix's SuperLU factor (MMD_ATA ordering; the numpy path's solves), made on
        first use and shared by integrators of the same matrix: the compiled step has its own
        LDL^T (track.kernel.LDLFactor) and never needs it."""
        sh = self._shared
        if sh.lu is None:
            sh.lu = spla.splu(sh.A, permc_spec="MMD_ATA", options={"SymmetricMode": True})
            self.counters.factorizations += 1
        return sh.lu

    # ------------------------------------------------------------------ forces
    def _ballast_correction(self, qD: np.ndarray, vD: np.ndarray) -> np.ndarray:
        """f_b + K_b q + C_b v at the ballast dofs: zero for a bushing closed deeper than the
        damping onset and without gap (the usual case, so this stays cheap)."""
        bal = self.model.ballast
        return bal.forces(qD, vD) + bal.k * qD + bal.c * vD

    def _nonlinear_bushings(self) -> np.ndarray:
        """Ballast bushings whose correction can be non-zero within the next step.

        A bushing without gap whose compression exceeds the damping onset by several
        times its motion over one step stays linear through the step (correction
        exactly zero up to round-off); the others are evaluated.
        """
        bal, D, h = self.model.ballast, self._D, self.h
        delta = -self.q[D] - bal.gap
        reach = MOTION_SAFETY * (np.abs(self.v[D]) * h + np.abs(self.a[D]) * h * h) + MOTION_FLOOR
        return np.flatnonzero((bal.gap > 0.0) | (delta < DAMPING_ONSET + reach))

    def _forces(self, q: np.ndarray, v: np.ndarray, loads: Sequence[PointLoad]) -> np.ndarray:
        """Right-hand side F = f_gravity + point forces + ballast correction."""
        F = self.model.f_gravity.copy()
        D = self._D
        F[D] += self._ballast_correction(q[D], v[D])
        for ld in loads:
            pm = ld.point
            if callable(ld.force):
                val = ld.force(float(pm.weights @ q[pm.gidx]), float(pm.weights @ v[pm.gidx]))
            else:
                val = ld.force
            F[pm.gidx] += val * pm.weights
        return F

    # ------------------------------------------------------------------ stepping
    def step(self, loads: Sequence[PointLoad] = ()) -> None:
        """Advance one step of length ``h`` with the point forces ``loads`` at the step's end.

        Raises
        ------
        ConvergenceError
            If the nonlinear iteration does not converge (the state is left unchanged).
        """
        h, a_, b, g = self.h, self.alpha, self.beta, self.gamma
        q0, v0, acc0 = self.q, self.v, self.a
        bh2, gh = b * h * h, g * h
        qp = q0 + h * v0 + (0.5 - b) * h * h * acc0      # Newmark predictors
        vp = v0 + (1 - g) * h * acc0
        base = -a_ * self.F - self._Ct @ ((1 + a_) * vp - a_ * v0) - self._Kt @ ((1 + a_) * qp - a_ * q0)
        # first guess of the end-of-step forces: at the state reached with a1 = a0
        F1 = self._forces(qp + bh2 * acc0, vp + gh * acc0, loads)
        fscale = max(np.max(np.abs(F1 - self.model.f_gravity)), 1.0)
        for it in range(1, MAX_ITER + 1):
            acc1 = self._lu.solve(base + (1 + a_) * F1)
            self.counters.solves += 1
            q1 = qp + bh2 * acc1
            v1 = vp + gh * acc1
            F_new = self._forces(q1, v1, loads)
            change = np.max(np.abs(F_new - F1))
            F1 = F_new
            if change <= FORCE_TOL + REL_FORCE_TOL * fscale:
                break
        else:
            raise ConvergenceError(
                f"track step at t = {self.t + h:.6g} s did not converge in {MAX_ITER} iterations "
                f"(last force change {change:.3g} N); reduce the step h = {h:.3g} s")
        self.counters.iterations += it
        self.counters.max_iterations = max(self.counters.max_iterations, it)
        self.counters.steps += 1
        self.q, self.v, self.a, self.F = q1, v1, acc1, F1
        self.k += 1

    # ------------------------------------------------------------------ contact
    def influence(self, point: PointMap) -> np.ndarray:
        """``A^{-1} r`` of a rail point (shape (n,)): the step response to a force there.

        Built from the columns ``A^{-1} T[dof, :]`` of the element's load rows, each computed
        once (a beam element's 4 rows are its two nodes' dofs, a segment of the solid's contact
        path has its two path nodes, :meth:`track.model.Body.load_rows`; a neighbour shares one
        node's).
        """
        b, e = self.model.body(point.body), point.element
        ids = [2 * e + j for j in range(4)] if not b.solid else [e, e + 1]   # rows of T / path nodes
        cache = self._influence_cache          # per load row: neighbouring elements share a node's rows
        missing = [j for j, r in enumerate(ids) if (b.name, r) not in cache]
        if missing:
            rows = b.load_rows(e)                # (4, nr) beam element, (2, nr) solid path segment
            E = np.zeros((self.model.n, len(missing)))
            E[b.gdofs, :] = rows[missing].T
            for j, z in zip(missing, self._lu.solve(E).T):
                cache[(b.name, ids[j])] = z
            self.counters.solves += len(missing)
        return np.column_stack([cache[(b.name, r)] for r in ids]) @ point.shape

    def _ballast_rows(self, idx: np.ndarray) -> np.ndarray:
        """``A^{-1} e_d`` as rows for the ballast bushings ``idx`` (shape (len(idx), n)).

        Computed when first needed, a few bushings at a time (a passage changes the
        contact state of the bushings near the wheels only), and kept with the shared
        factorization.
        """
        sh = self._shared
        nb = self._D.size
        if sh.Zb is None or sh.Zb_dofs is None or not np.array_equal(sh.Zb_dofs, self._D):
            sh.Zb = np.zeros((nb, self.model.n))
            sh.Zb_have = np.zeros(nb, bool)
            sh.Zb_dofs = self._D.copy()
        missing = np.unique(idx[~sh.Zb_have[idx]])
        if missing.size:
            E = np.zeros((self.model.n, missing.size))
            E[self._D[missing], np.arange(missing.size)] = 1.0
            sh.Zb[missing] = self._lu.solve(E).T
            sh.Zb_have[missing] = True
            self.counters.solves += missing.size
        return sh.Zb[idx]

    def step_contacts(self, points: Sequence[PointMap], z_wheel: np.ndarray, surfaces: Sequence[tuple],
                      c_h: float = HERTZ_CONSTANT) -> np.ndarray:
        """Advance one step with Hertz contacts solved implicitly with the track.

        Parameters
        ----------
        points : sequence of PointMap, length m
            Rail points under the wheels at the end of the step.
        z_wheel : ndarray, shape (m,)
            Wheel vertical positions at the end of the step [m] (up +).
        surfaces : sequence of (float, float)
            Surface heights under each wheel (:mod:`track.contact`) [m].
        c_h : float or array_like, shape (m, 2)
            Hertz constant [N/m^1.5], one for all, or per wheel and surface (profile contact).

        Returns
        -------
        ndarray, shape (m, 4)
            Per wheel: total contact force on the wheel [N] (up +), its parts on the first
            and second surface [N], and the rail deflection under the wheel [m].

        Notes
        -----
        Within a pass the contact forces ``Fc`` are solved by Newton's method on
        ``Fc = hertz(w(Fc))`` with the rail deflection an exact linear function of
        ``Fc`` over the step, ``w = w_lin - G (Fc - Fc_pass) - residual Fc``,
        ``G_ij = (1+alpha) beta h^2 r_i . A^{-1} r_j``; so the contact is as implicit as
        in a monolithic solution. Passes repeat only while a ballast bushing changes
        state; they correct the solution through the ballast influence rows, not a new
        solve. The force vector is kept as gravity + the few non-zero ballast
        corrections + the contact forces, so a step touches full-length vectors only in
        the predictor, one product with K and C, one solve and the update.

        The stages are methods with the names of the compiled kernel's functions
        (:func:`track.kernel.contact_step`), so the two can be read side by side; this
        path applies the corrector to the whole vector at every pass, the kernel at the
        ballast dofs only until the passes converge.
        """
        m = len(points)
        qp, vp, rhs = self._predict()
        self._ballast_candidates()
        corr = self._ballast_first_guess(qp, vp, rhs)
        Fc = self.Fc.tolist() if self.Fc.size == m else [0.0] * m
        fmax = self._wheel_loads(points, Fc, rhs)
        acc_lin = self._lu.solve(rhs)
        self.counters.solves += 1
        Zs, G, w_pred = self._contact_coupling(points, qp)
        ctol = CONTACT_TOL + CONTACT_REL_TOL * fmax
        ftol = FORCE_TOL + REL_FORCE_TOL * fmax
        zw = z_wheel.tolist() if isinstance(z_wheel, np.ndarray) else [float(z) for z in z_wheel]
        chw = np.broadcast_to(np.asarray(c_h, dtype=float), (m, 2)).tolist()
        Fc_arr = np.array(Fc)
        out = np.zeros((m, 4))
        # modified-Newton passes: they repeat only while a ballast bushing changes state
        for it in range(1, MAX_ITER + 1):
            Fn = self._contact_newton(points, w_pred, acc_lin, G, Fc, zw, surfaces, chw, ctol, out)
            acc1 = self._corrector(acc_lin, Fn, Fc_arr, Zs)
            new_corr, change = self._ballast_change(qp, vp, acc1, corr)
            if change <= ftol:
                Fc = Fn
                break
            acc_lin = self._ballast_row_correction(acc_lin, new_corr - corr)
            corr = new_corr
        else:
            raise ConvergenceError(
                f"track step at t = {self.t + self.h:.6g} s did not converge in {MAX_ITER} iterations "
                f"(last force change {change:.3g} N); reduce the step h = {self.h:.3g} s")
        F = self._end_forces(points, Fc, corr)
        self.counters.iterations += it
        if it > self.counters.max_iterations:
            self.counters.max_iterations = it
        self.counters.steps += 1
        bh2, gh = self.beta * self.h * self.h, self.gamma * self.h
        self.q, self.v, self.a, self.F, self.Fc = qp + bh2 * acc1, vp + gh * acc1, acc1, F, np.array(Fc)
        self.k += 1
        out[:, 0] = Fc  # the converged forces (equal to hertz(w) within CONTACT_TOL)
        return out

    # stages of step_contacts (same names as the compiled kernel's functions, track.kernel)
    def _predict(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Newmark predictors ``qp`` [m], ``vp`` [m/s] and the linear right-hand side [N]
        ``(1+alpha) f_grav - alpha F0 - C ((1+alpha) vp - alpha v0) - K ((1+alpha) qp - alpha q0)``."""
        h, a_, b, g = self.h, self.alpha, self.beta, self.gamma
        q0, v0, acc0 = self.q, self.v, self.a
        a1 = 1.0 + a_
        qp = q0 + h * v0 + (0.5 - b) * h * h * acc0
        vp = v0 + (1 - g) * h * acc0
        rhs = self._rhs_const - a_ * self.F - self._Ct @ (a1 * vp - a_ * v0) - self._Kt @ (a1 * qp - a_ * q0)
        return qp, vp, rhs

    def _ballast_candidates(self) -> None:
        """The ballast bushings that may change state within the step (:meth:`_nonlinear_bushings`)
        and their parameters, kept for :meth:`_candidate_correction`."""
        cand = self._nonlinear_bushings()
        bal = self.model.ballast
        self._cand, self._Dc = cand, self._D[cand]
        self._kc, self._cc, self._gc = bal.k[cand], bal.c[cand], bal.gap[cand]

    def _ballast_first_guess(self, qp: np.ndarray, vp: np.ndarray, rhs: np.ndarray) -> np.ndarray:
        """Corrections [N] of the candidate bushings at the state reached with ``a1 = a0``, added to
        ``rhs`` (times 1+alpha) in place."""
        bh2, gh, a1, Dc, acc0 = self.beta * self.h * self.h, self.gamma * self.h, 1.0 + self.alpha, self._Dc, self.a
        corr = self._candidate_correction(qp[Dc] + bh2 * acc0[Dc], vp[Dc] + gh * acc0[Dc])
        rhs[Dc] += a1 * corr
        return corr

    def _wheel_loads(self, points: Sequence[PointMap], Fc: list, rhs: np.ndarray) -> float:
        """The last step's contact forces ``Fc`` [N] (the first guess) subtracted from ``rhs`` (times
        1+alpha) in place; returns the largest, at least 1 N (the scale of the tolerances)."""
        a1 = 1.0 + self.alpha
        for p, f in zip(points, Fc):
            rhs[p.gidx] -= (a1 * f) * p.weights
        return max(max(Fc, default=0.0), 1.0)

    def _contact_coupling(self, points: Sequence[PointMap], qp: np.ndarray
                          ) -> tuple[np.ndarray, np.ndarray, list]:
        """Influence rows ``Zs[j] = A^{-1} r_j`` (m, n), ``G[i, j] = (1+alpha) beta h^2 r_i . A^-1 r_j``
        [m/N] (deflection at wheel i per force at wheel j) and the predicted deflections [m]."""
        m, a1bh2 = len(points), (1.0 + self.alpha) * (self.beta * self.h * self.h)
        Zs = np.empty((m, self.model.n))
        for j, p in enumerate(points):
            Zs[j] = self.influence(p)
        G = np.empty((m, m))
        for i, p in enumerate(points):
            G[i] = a1bh2 * (Zs[:, p.gidx] @ p.weights)
        return Zs, G, [float(p.weights @ qp[p.gidx]) for p in points]

    def _contact_newton(self, points: Sequence[PointMap], w_pred: list, acc_lin: np.ndarray, G: np.ndarray,
                        Fc: list, zw: list, surfaces: Sequence[tuple], chw: list, ctol: float,
                        out: np.ndarray) -> list:
        """Newton on ``Fc = hertz(w(Fc))`` for one pass; returns the forces [N].

        ``w = w_lin - G (Fn - Fc) - residual Fn`` with ``w_lin`` the deflection of the pass's
        linear solution ``acc_lin``. The wheels couple weakly through G, so each sweep updates
        every wheel with its own diagonal Jacobian (Jacobi-Newton). Per wheel, (hertz force,
        its parts, deflection) go to ``out``; ``chw[i]``: the Hertz constants of wheel i's two
        surfaces [N/m^1.5].
        """
        bh2, m = self.beta * self.h * self.h, len(points)
        Gl = G.tolist()
        res = [p.residual for p in points]
        Fc_arr = np.array(Fc)
        w_lin = [wp + bh2 * float(p.weights @ acc_lin[p.gidx]) for wp, p in zip(w_pred, points)]
        Fn = list(Fc)
        for _ in range(CONTACT_NEWTON_MAX):
            dmax = 0.0
            cpl = (G @ (np.array(Fn) - Fc_arr)).tolist()
            for i in range(m):
                w = w_lin[i] - cpl[i] - res[i] * Fn[i]
                F, k, F1, F2 = hertz_pair(w, zw[i], surfaces[i][0], surfaces[i][1], chw[i][0], chw[i][1])
                step = (F - Fn[i]) / (1.0 + k * (Gl[i][i] + res[i]))
                new = Fn[i] + step
                if new < 0.0:
                    new, step = 0.0, -Fn[i]
                Fn[i] = new
                out[i, 0], out[i, 1], out[i, 2], out[i, 3] = F, F1, F2, w
                if abs(step) > dmax:
                    dmax = abs(step)
            self.counters.contact_newton += 1
            if dmax <= ctol:
                return Fn
        raise ConvergenceError(f"contact forces at t = {self.t + self.h:.6g} s did not converge; "
                               f"reduce the step h = {self.h:.3g} s")

    def _corrector(self, acc_lin: np.ndarray, Fn: list, Fc: np.ndarray, Zs: np.ndarray) -> np.ndarray:
        """End-of-step acceleration ``acc_lin - (1+alpha) sum_i (Fn_i - Fc_i) A^-1 r_i`` [m/s^2]."""
        return acc_lin - (1.0 + self.alpha) * ((np.array(Fn) - Fc) @ Zs) if len(Fn) else acc_lin

    def _ballast_change(self, qp: np.ndarray, vp: np.ndarray, acc1: np.ndarray, corr: np.ndarray
                        ) -> tuple[np.ndarray, float]:
        """Corrections [N] of the candidate bushings at the end-of-step state of this pass and the
        largest change from ``corr`` [N]."""
        bh2, gh, Dc = self.beta * self.h * self.h, self.gamma * self.h, self._Dc
        new_corr = self._candidate_correction(qp[Dc] + bh2 * acc1[Dc], vp[Dc] + gh * acc1[Dc])
        return new_corr, np.max(np.abs(new_corr - corr), initial=0.0)

    def _ballast_row_correction(self, acc_lin: np.ndarray, dD: np.ndarray) -> np.ndarray:
        """A bushing opened or closed (correction change ``dD`` [N]): the linear solution corrected
        through the ballast influence rows instead of a new solve."""
        sel = np.flatnonzero(np.abs(dD) > FORCE_TOL)
        return acc_lin + (1.0 + self.alpha) * (dD[sel] @ self._ballast_rows(self._cand[sel]))

    def _end_forces(self, points: Sequence[PointMap], Fc: list, corr: np.ndarray) -> np.ndarray:
        """The step's right-hand side: gravity + ballast corrections - contact forces on the rails [N]."""
        F = self.model.f_gravity.copy()
        F[self._Dc] += corr
        for p, f in zip(points, Fc):
            F[p.gidx] -= f * p.weights
        return F

    def _candidate_correction(self, qD: np.ndarray, vD: np.ndarray) -> np.ndarray:
        """Ballast correction (f_b + k q + c v) of the candidate bushings, see ballast.py."""
        k, c = self._kc, self._cc
        delta = -qD - self._gc
        f = k * delta - c * vD * np.clip(delta / DAMPING_ONSET, 0.0, 1.0)
        return np.where(delta > 0.0, np.maximum(f, 0.0), 0.0) + k * qD + c * vD

    # ------------------------------------------------------------------ reading
    @property
    def t(self) -> float:
        """Current time [s]."""
        return self.t0 + self.k * self.h

    def surface(self, point: PointMap, force: float = 0.0) -> tuple[float, float]:
        """Displacement [m] and velocity [m/s] of a material point at the current time.

        ``force`` [N] is a force acting at the point itself: it adds the local static
        deflection of the truncated modes, ``point.residual * force``.
        """
        return (float(point.weights @ self.q[point.gidx]) + point.residual * force,
                float(point.weights @ self.v[point.gidx]))

    def get_state(self) -> np.ndarray:
        """Full internal state as one flat array (for FMU state save/restore)."""
        return np.concatenate([[self.t0, self.k, self.Fc.size], self.q, self.v, self.a, self.F, self.Fc])

    def set_state(self, state: np.ndarray) -> None:
        n = self.model.n
        s = np.asarray(state, dtype=float)
        self.t0, self.k, m = float(s[0]), int(s[1]), int(s[2])
        self.q, self.v, self.a, self.F = (s[3 + j * n:3 + (j + 1) * n].copy() for j in range(4))
        self.Fc = s[3 + 4 * n:3 + 4 * n + m].copy()

# ---------------------------------------------------------------------- moving loads
@dataclass
class MovingLoad:
    """A constant vertical load moving with the vehicle.

    Attributes
    ----------
    side : str
        ``"left"`` or ``"right"``: the running rail it acts on.
    x0 : float
        Position at t = 0 [m].
    force : float
        Vertical force [N], up + (a wheel load is negative).
    """

    side: str
    x0: float
    force: float


@dataclass
class MovingLoadResult:
    """Output of :func:`simulate_moving_loads` at the output times.

    Attributes
    ----------
    t : ndarray, shape (nt,)
    q : ndarray, shape (nt, n)
        Generalized displacements.
    v : ndarray, shape (nt, n)
        Generalized velocities.
    x : ndarray, shape (nt, nl)
        Load positions [m].
    w : ndarray, shape (nt, nl)
        Rail displacement under each load [m].
    q_static : ndarray, shape (n,)
        Static equilibrium at t = 0.
    counters : Counters
    """

    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    x: np.ndarray
    w: np.ndarray
    q_static: np.ndarray
    counters: Counters = field(default_factory=Counters)
    error: str | None = None  # set when the run stopped early; the arrays hold what was computed


def simulate_moving_loads(model: TrackModel, loads: Sequence[MovingLoad], speed: float,
                          duration: float, h: float, output_every: int = 1,
                          alpha: float = ALPHA_DEFAULT, progress: Callable[[int, int], None] | None = None
                          ) -> MovingLoadResult:
    """Constant loads moving at ``speed`` over the track, from static equilibrium.

    Parameters
    ----------
    model : TrackModel
    loads : sequence of MovingLoad
    speed : float
        [m/s]
    duration : float
        Simulated time [s].
    h : float
        Time step [s].
    output_every : int
        Record every this many steps.
    progress : callable, optional
        ``progress(k, nsteps)`` called at each recorded step.

    Returns
    -------
    MovingLoadResult
    """
    from .statics import static_equilibrium

    def point_loads(t: float) -> list[PointLoad]:
        return [PointLoad(model.rail_point(ld.side, ld.x0 + speed * t), ld.force) for ld in loads]

    pl0 = point_loads(0.0)
    st = static_equilibrium(model, [(p.point, p.force) for p in pl0])
    integ = TrackIntegrator(model, h, st.q, loads0=pl0, alpha=alpha)
    nsteps = step_count(duration, h)
    nout = nsteps // output_every + 1
    T = np.empty(nout)
    Q = np.empty((nout, model.n))
    V = np.empty((nout, model.n))
    X = np.empty((nout, len(loads)))
    W = np.empty((nout, len(loads)))

    def record(j: int, pls: list[PointLoad]) -> None:
        T[j] = integ.t
        Q[j] = integ.q
        V[j] = integ.v
        for i, pl in enumerate(pls):
            X[j, i] = pl.point.coord
            W[j, i] = integ.surface(pl.point, pl.force)[0]

    record(0, pl0)
    done, error = 1, None
    for k in range(1, nsteps + 1):
        t = k * h  # communication points from an integer counter
        pls = point_loads(t)
        try:
            integ.step(pls)
        except ConvergenceError as exc:
            error = str(exc)
            break
        if k % output_every == 0:
            record(k // output_every, pls)
            done = k // output_every + 1
            if progress is not None:
                progress(k, nsteps)
    return MovingLoadResult(t=T[:done], q=Q[:done], v=V[:done], x=X[:done], w=W[:done], q_static=st.q,
                            counters=integ.counters, error=error)
