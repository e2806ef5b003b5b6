"""Compiled track step: one numba kernel call per co-simulation step.

The co-simulation step of :meth:`track.dynamics.TrackIntegrator.step_contacts`
(HHT-alpha predictor, right-hand side, the ballast bushings that may change state,
one solve with the constant step matrix, the Hertz contact Newton with the
crossing heights, the modified-Newton passes through the ballast influence rows,
the corrector) spends its time in Python overhead, not arithmetic, when written
with numpy calls (a few hundred small calls per step). Here the same algorithm is
one ``@njit`` function, :func:`contact_step`, that works on preallocated arrays.
The numpy path stays the reference (:data:`KERNEL_ENV`, ``kernel=False``);
tests/test_kernel.py checks that both give the same results to round-off.

Step matrix. ``A = M + (1+alpha)(gamma h C + beta h^2 K)`` is symmetric positive
definite, so it is factorized once as ``P A P^T = L D L^T`` (SuperLU without
pivoting on the symmetric permutation ``P`` of a minimum-degree ordering of
``A + A^T``) and solved by the two sparse triangular sweeps of
:func:`ldl_solve`: about 35k factor entries for the 64-sleeper panel (2763 dofs),
against 100k in the LU with the MMD(A^T A) ordering the numpy path uses
(benchmarks/bench_step.py measures both).

Round-off entries. The Craig–Bampton products ``T^T K T`` leave entries that are
zero in exact arithmetic (the constraint modes are K-orthogonal to the
fixed-interface modes) at 1e-20..1e-14 of ``sqrt(K_ii K_jj)``; two thirds of the
stored entries of the track's K are such. Entries below :data:`PRUNE_RTOL` of
``sqrt(|X_ii X_jj|)`` are dropped from K and from A before the products and the
factorization: a relative perturbation of the matrices at the level of the
round-off they already carry.
"""
from __future__ import annotations

import hashlib
import os

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

try:
    import numba
except ImportError:  # pragma: no cover - numba is a dependency; the numpy path still works
    numba = None

from .ballast import DAMPING_ONSET
from .contact import hertz

KERNEL_ENV = "TURNOUT_TRACK_KERNEL"  # "numpy": the pure-numpy reference path; anything else: compiled
PRUNE_RTOL = 1e-14  # drop |X_ij| <= this * sqrt(|X_ii X_jj|): the round-off of the reductions' products
                    # sits at 1e-20..1e-15, the smallest physical couplings at >= 1e-13 (module doc)

# status codes returned by contact_step
OK, PASSES_FAILED, NEWTON_FAILED = 0, 1, 2
# indices of the integer work counters (cnt) updated by contact_step
C_SOLVES, C_PASSES, C_NEWTON, C_MAXPASS = 0, 1, 2, 3


def kernel_enabled(flag: bool | None = None) -> bool:
    """Whether the compiled step is used: ``flag`` when given, else the environment.

    ``TURNOUT_TRACK_KERNEL=numpy`` selects the numpy reference path (also when numba
    is missing); the compiled path is the default.
    """
    if flag is not None:
        if flag and numba is None:
            raise ImportError("the compiled track step needs numba (pip install numba)")
        return bool(flag)
    return numba is not None and os.environ.get(KERNEL_ENV, "").strip().lower() != "numpy"


_HERE = os.path.dirname(os.path.abspath(__file__))
_KERNEL_SOURCES = ("kernel.py", "contact.py", "ballast.py")  # what the compiled code is made of


def _cache_locator():
    """A numba cache locator for this package's kernels that does not depend on where the
    package sits.

    numba's default caches next to the module (or, when that is not writable, in a
    per-user folder named after the module's folder). The track FMU carries its own
    copy of this package, unpacked to a new temporary folder by every host that loads
    it, so a path-based cache would compile afresh (~5 s) at every FMU load. Here the
    cache folder is named after the content of the sources the kernels are compiled
    from (this module, ``contact.hertz``, ``ballast.DAMPING_ONSET``): the same sources
    share one cache wherever they are, a change to any of them compiles anew (numba
    itself checks only the decorated function's own file). The folder is under
    ``NUMBA_CACHE_DIR`` when set, else numba's per-user cache folder; nothing is
    written next to the package (a read-only site-packages is fine).
    """
    from numba.core import caching, config

    user_wide = getattr(caching, "UserWideCacheLocator", None) or getattr(caching, "_UserWideCacheLocator")

    class TrackKernelLocator(user_wide):
        package_dir = _HERE

        def __init__(self, py_func, py_file):
            super().__init__(py_func, py_file)
            h = hashlib.sha256()
            for name in _KERNEL_SOURCES:
                with open(os.path.join(_HERE, name), "rb") as fh:
                    h.update(fh.read())
            base = config.CACHE_DIR or os.path.dirname(self._cache_path)
            self._cache_path = os.path.join(base, f"turnout_track_kernel_{h.hexdigest()[:20]}")

        @classmethod
        def from_function(cls, py_func, py_file):
            if os.path.dirname(os.path.abspath(py_file)) != _HERE:
                return None
            return super().from_function(py_func, py_file)

    impl = getattr(caching, "CacheImpl", None) or getattr(caching, "_CacheImpl")
    # first in line; a locator of an earlier import of this same folder is replaced (other copies,
    # e.g. an FMU's, keep theirs: each answers for its own folder only)
    impl._locator_classes = [TrackKernelLocator] + [c for c in impl._locator_classes
                                                    if getattr(c, "package_dir", None) != _HERE]


if numba is not None:
    _cache_locator()


def _njit(f):
    return numba.njit(cache=True, nogil=True, error_model="numpy")(f) if numba is not None else f


hertz_nb = _njit(hertz)


# ------------------------------------------------------------------------------- matrices
def prune(X: sp.spmatrix, rtol: float = PRUNE_RTOL) -> sp.csr_matrix:
    """``X`` without the entries below ``rtol * sqrt(|X_ii X_jj|)`` (module doc), as CSR.

    Parameters
    ----------
    X : sparse matrix, shape (n, n)
        With a positive diagonal (stiffness, mass or step matrix).
    """
    C = sp.coo_matrix(X)
    C.sum_duplicates()
    d = np.sqrt(np.abs(X.diagonal()))
    keep = np.abs(C.data) > rtol * d[C.row] * d[C.col]
    out = sp.csr_matrix((C.data[keep], (C.row[keep], C.col[keep])), shape=X.shape)
    out.sort_indices()
    return out


def drop_cancelled(D: sp.spmatrix, S: sp.spmatrix, rtol: float = PRUNE_RTOL) -> sp.csr_matrix:
    """Entries of a difference ``D`` that are not cancellation round-off of ``S = |a| + |b|``.

    Parameters
    ----------
    D, S : sparse matrix, shape (n, n)
        ``D = a - b`` and ``S = |a| + |b|`` of the same two matrices.
    """
    D = sp.csr_matrix(D)
    keep = (abs(D) - rtol * abs(S)).tocsr()
    keep.data = (keep.data > 0).astype(float)
    out = D.multiply(keep).tocsr()
    out.eliminate_zeros()
    out.sort_indices()
    return out


class LDLFactor:
    """``P A P^T = L D L^T`` of a symmetric positive definite sparse matrix (module doc).

    Attributes
    ----------
    perm : ndarray of int64, shape (n,)
        ``(P x)[i] = x[perm[i]]``.
    Lp, Li, Lx : ndarray
        Strictly lower part of the unit ``L`` in CSC (int64 pointers and rows).
    d : ndarray, shape (n,)
        Diagonal of ``D``.
    """

    def __init__(self, A: sp.spmatrix):
        A = sp.csc_matrix(A)
        n = A.shape[0]
        p = np.argsort(spla.splu(A, permc_spec="MMD_AT_PLUS_A").perm_c)
        B = sp.csc_matrix(A[p][:, p])
        lu = spla.splu(B, permc_spec="NATURAL", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
        if not (np.array_equal(lu.perm_r, np.arange(n)) and np.array_equal(lu.perm_c, np.arange(n))):
            raise RuntimeError("LDL^T of the step matrix: SuperLU pivoted (matrix not positive definite?)")
        d = lu.U.diagonal()
        if not (d > 0).all():
            raise RuntimeError("LDL^T of the step matrix: non-positive pivot (matrix not positive definite)")
        Ls = sp.tril(lu.L, -1).tocsc()
        Ls.sort_indices()
        self.n = n
        self.perm = p.astype(np.int64)
        self.Lp = Ls.indptr.astype(np.int64)
        self.Li = Ls.indices.astype(np.int64)
        self.Lx = np.ascontiguousarray(Ls.data, dtype=float)
        self.d = np.ascontiguousarray(d, dtype=float)
        self.work = np.empty(n)

    @property
    def nnz(self) -> int:
        """Stored entries of L (strict lower part) plus the diagonal."""
        return int(self.Lx.size + self.n)

    def solve(self, b: np.ndarray) -> np.ndarray:
        """``A^{-1} b`` for b of shape (n,) or (n, k)."""
        b = np.asarray(b, dtype=float)
        if b.ndim == 1:
            out = np.empty(self.n)
            ldl_solve(self.perm, self.Lp, self.Li, self.Lx, self.d, b, out, self.work)
            return out
        out = np.empty_like(b, dtype=float)
        col = np.empty(self.n)
        for j in range(b.shape[1]):
            ldl_solve(self.perm, self.Lp, self.Li, self.Lx, self.d, np.ascontiguousarray(b[:, j]), col, self.work)
            out[:, j] = col
        return out


@_njit
def ldl_solve(perm, Lp, Li, Lx, d, b, x, work):
    """x = A^{-1} b with ``P A P^T = L D L^T`` (see :class:`LDLFactor`); ``work`` of shape (n,)."""
    n = d.size
    for i in range(n):
        work[i] = b[perm[i]]
    for j in range(n):                       # L y = P b, column by column
        yj = work[j]
        if yj != 0.0:
            for k in range(Lp[j], Lp[j + 1]):
                work[Li[k]] -= Lx[k] * yj
    for j in range(n):
        work[j] /= d[j]
    for j in range(n - 1, -1, -1):           # L^T z = D^-1 y, row j of L^T = column j of L
        s = work[j]
        for k in range(Lp[j], Lp[j + 1]):
            s -= Lx[k] * work[Li[k]]
        work[j] = s
    for i in range(n):
        x[perm[i]] = work[i]


@_njit
def _csr_matvec_sub(p, idx, val, x, out):
    """out -= X @ x for X in CSR (p, idx, val)."""
    n = p.size - 1
    for i in range(n):
        s = 0.0
        for k in range(p[i], p[i + 1]):
            s += val[k] * x[idx[k]]
        out[i] -= s


@_njit
def _correction(k, c, gap, u, v):
    """Ballast correction f_b + k u + c v of one bushing (track.ballast.Ballast.forces)."""
    delta = -u - gap
    f = 0.0
    if delta > 0.0:
        s = delta / DAMPING_ONSET
        if s > 1.0:
            s = 1.0
        f = k * delta - c * v * s
        if f < 0.0:
            f = 0.0
    return f + k * u + c * v


@_njit
def _ballast_row(j, D, Zb, have, perm, Lp, Li, Lx, d, e, work, cnt):
    """Make row j of ``Zb`` (``A^{-1} e_{D[j]}``) available; counts the solve."""
    if have[j] == 0:
        e[:] = 0.0
        e[D[j]] = 1.0
        ldl_solve(perm, Lp, Li, Lx, d, e, Zb[j], work)
        have[j] = 1
        cnt[C_SOLVES] += 1


@_njit
def contact_step(par, cnt, q0, v0, acc0, F0, Fc0, fgrav,
                 Kp, Ki, Kx, Cp, Ci, Cx, beta_s,
                 D, bk, bc, bgap, Zb, have,
                 perm, Lp, Li, Lx, dd,
                 W, T, gd, nr, R, Ze, zw, surf,
                 q1, v1, acc1, F1, Fc1, out, work, iwork, wts):
    """One HHT-alpha step with Hertz contacts solved implicitly (TrackIntegrator.step_contacts).

    Parameters (m wheels, n dofs, nb ballast bushings, k <= 4 load rows per wheel)
    ----------
    par : float64[13]
        h, alpha, beta, gamma, motion safety, motion floor [m], Hertz constant [N/m^1.5],
        contact tol [N], contact rel tol, force tol [N], rel force tol, max passes, max Newton.
    cnt : int64[4]
        Work counters, incremented (solves, passes, contact Newton sweeps, most passes).
    q0, v0, acc0, F0 : float64[n]
        State at the step's start (F0: the right-hand side of the last step).
    Fc0 : float64[m]
        Contact forces of the last step [N] (the first guess).
    fgrav : float64[n]
    Kp, Ki, Kx / Cp, Ci, Cx : CSR of the stiffness (with the linear ballast) and of
        ``C_t - beta_s K_t`` (the damping not proportional to K).
    D, bk, bc, bgap : ballast dofs, stiffness [N/m], damping [N s/m], gaps [m].
    Zb : float64[nb, n], have : uint8[nb]
        Ballast influence rows ``A^{-1} e_D`` (filled on demand).
    perm, Lp, Li, Lx, dd : the LDL^T factor of the step matrix (:class:`LDLFactor`).
    W : float64[m, 4]      shape-function values of each wheel's element.
    T : float64[m, 4, nrmax], gd : int64[m, nrmax], nr : int64[m]
        Load rows of each wheel's element on its body's coordinates ``gd``.
    R : float64[m, 4, 4]   residual flexibility of the element [m/N].
    Ze : float64[m, 4, n]  ``A^{-1}`` of each load row.
    zw : float64[m]        wheel positions at the step's end [m].
    surf : float64[m, 2]   surface heights under the wheels [m].
    q1, v1, acc1, F1 : float64[n], Fc1 : float64[m], out : float64[m, 4]   outputs.
    work : float64[8 n + 16 m + 4 nb], iwork : int64[nb], wts : float64[m, nrmax]   workspace.

    Returns
    -------
    status : int
        OK, PASSES_FAILED or NEWTON_FAILED (the outputs are then meaningless).
    change : float
        Last force change between passes [N].
    """
    h, a_, b, g = par[0], par[1], par[2], par[3]
    safety, floor, c_h = par[4], par[5], par[6]
    ctol0, crel, ftol0, frel = par[7], par[8], par[9], par[10]
    max_pass, max_newton = int(par[11]), int(par[12])
    n = q0.size
    m = zw.size
    nbal = D.size
    bh2, gh, a1 = b * h * h, g * h, 1.0 + a_
    qp = work[0:n]
    vp = work[n:2 * n]
    rhs = work[2 * n:3 * n]
    y = work[3 * n:4 * n]
    acc_lin = work[4 * n:5 * n]
    sw = work[5 * n:6 * n]
    unit = work[6 * n:7 * n]
    o = 8 * n
    Fn = work[o:o + m]
    wlin = work[o + m:o + 2 * m]
    wpred = work[o + 2 * m:o + 3 * m]
    res = work[o + 3 * m:o + 4 * m]
    cpl = work[o + 4 * m:o + 5 * m]
    G = work[o + 5 * m:o + 5 * m + m * m].reshape((m, m))
    o2 = o + 16 * m
    corr = work[o2:o2 + nbal]
    newc = work[o2 + nbal:o2 + 2 * nbal]
    cidx = iwork

    # predictors and the linear right-hand side
    c2 = (0.5 - b) * h * h
    c1 = (1.0 - g) * h
    for i in range(n):
        qp[i] = q0[i] + h * v0[i] + c2 * acc0[i]
        vp[i] = v0[i] + c1 * acc0[i]
        sw[i] = a1 * vp[i] - a_ * v0[i]                     # damping argument
        y[i] = a1 * qp[i] - a_ * q0[i] + beta_s * sw[i]     # stiffness argument (K part of C folded in)
        rhs[i] = a1 * fgrav[i] - a_ * F0[i]
    _csr_matvec_sub(Kp, Ki, Kx, y, rhs)
    _csr_matvec_sub(Cp, Ci, Cx, sw, rhs)

    # ballast bushings that may change state within the step (TrackIntegrator._nonlinear_bushings)
    nc = 0
    for j in range(nbal):
        dj = D[j]
        delta = -q0[dj] - bgap[j]
        reach = safety * (abs(v0[dj]) * h + abs(acc0[dj]) * h * h) + floor
        if bgap[j] > 0.0 or delta < DAMPING_ONSET + reach:
            cidx[nc] = j
            nc += 1
    for c in range(nc):
        j = cidx[c]
        dj = D[j]
        corr[c] = _correction(bk[j], bc[j], bgap[j], qp[dj] + bh2 * acc0[dj], vp[dj] + gh * acc0[dj])
        rhs[dj] += a1 * corr[c]

    # contact forces of the last step as the first guess; wheel weights on q
    fmax = 1.0
    for i in range(m):
        Fn[i] = Fc0[i]
        if Fc0[i] > fmax:
            fmax = Fc0[i]
        for a in range(nr[i]):
            wts[i, a] = 0.0
        for r in range(4):
            wr = W[i, r]
            if wr != 0.0:
                for a in range(nr[i]):
                    wts[i, a] += wr * T[i, r, a]
        for a in range(nr[i]):
            rhs[gd[i, a]] -= a1 * Fc0[i] * wts[i, a]
    ldl_solve(perm, Lp, Li, Lx, dd, rhs, acc_lin, unit)
    cnt[C_SOLVES] += 1

    # G[i, j] = (1+alpha) beta h^2 r_i . A^-1 r_j, residual flexibility, predicted deflection
    for i in range(m):
        for j in range(m):
            s = 0.0
            for r in range(4):
                wr = W[j, r]
                if wr != 0.0:
                    t = 0.0
                    for a in range(nr[i]):
                        t += wts[i, a] * Ze[j, r, gd[i, a]]
                    s += wr * t
            G[i, j] = a1 * bh2 * s
        s = 0.0
        for r in range(4):
            for c in range(4):
                s += W[i, r] * R[i, r, c] * W[i, c]
        res[i] = s
        s = 0.0
        for a in range(nr[i]):
            s += wts[i, a] * qp[gd[i, a]]
        wpred[i] = s
    ctol = ctol0 + crel * fmax
    ftol = ftol0 + frel * fmax

    change = 0.0
    it = 0
    converged = False
    while it < max_pass:
        it += 1
        for i in range(m):
            s = 0.0
            for a in range(nr[i]):
                s += wts[i, a] * acc_lin[gd[i, a]]
            wlin[i] = wpred[i] + bh2 * s
            Fn[i] = Fc0[i]
        # Jacobi-Newton on Fc = hertz(w(Fc)) (TrackIntegrator.step_contacts)
        newton_ok = False
        for _ in range(max_newton):
            dmax = 0.0
            for i in range(m):
                s = 0.0
                for j in range(m):
                    s += G[i, j] * (Fn[j] - Fc0[j])
                cpl[i] = s
            for i in range(m):
                w = wlin[i] - cpl[i] - res[i] * Fn[i]
                F, k, Fa, Fb = hertz_nb(w, zw[i], (surf[i, 0], surf[i, 1]), c_h)
                step = (F - Fn[i]) / (1.0 + k * (G[i, i] + res[i]))
                new = Fn[i] + step
                if new < 0.0:
                    new = 0.0
                    step = -Fn[i]
                Fn[i] = new
                out[i, 0] = F
                out[i, 1] = Fa
                out[i, 2] = Fb
                out[i, 3] = w
                if abs(step) > dmax:
                    dmax = abs(step)
            cnt[C_NEWTON] += 1
            if dmax <= ctol:
                newton_ok = True
                break
        if not newton_ok:
            return NEWTON_FAILED, change
        # ballast corrections at the end-of-step state of this pass
        change = 0.0
        for c in range(nc):
            dj = D[cidx[c]]
            s = acc_lin[dj]
            for i in range(m):
                dF = Fn[i] - Fc0[i]
                if dF != 0.0:
                    for r in range(4):
                        if W[i, r] != 0.0:
                            s -= a1 * dF * W[i, r] * Ze[i, r, dj]
            newc[c] = _correction(bk[cidx[c]], bc[cidx[c]], bgap[cidx[c]], qp[dj] + bh2 * s, vp[dj] + gh * s)
            if abs(newc[c] - corr[c]) > change:
                change = abs(newc[c] - corr[c])
        if change <= ftol:
            converged = True
            break
        # a bushing opened or closed: correct the linear solution through the ballast rows
        for c in range(nc):
            dD = newc[c] - corr[c]
            if abs(dD) > ftol0:
                j = cidx[c]
                _ballast_row(j, D, Zb, have, perm, Lp, Li, Lx, dd, unit, y, cnt)
                f = a1 * dD
                for i2 in range(n):
                    acc_lin[i2] += f * Zb[j, i2]
            corr[c] = newc[c]
    if not converged:
        return PASSES_FAILED, change

    # corrector: acc1 = acc_lin - (1+alpha) sum_i dF_i A^-1 r_i
    for i2 in range(n):
        acc1[i2] = acc_lin[i2]
    for i in range(m):
        dF = Fn[i] - Fc0[i]
        if dF != 0.0:
            for r in range(4):
                f = a1 * dF * W[i, r]
                if f != 0.0:
                    for i2 in range(n):
                        acc1[i2] -= f * Ze[i, r, i2]
    for i2 in range(n):
        q1[i2] = qp[i2] + bh2 * acc1[i2]
        v1[i2] = vp[i2] + gh * acc1[i2]
        F1[i2] = fgrav[i2]
    for c in range(nc):
        F1[D[cidx[c]]] += corr[c]
    for i in range(m):
        Fc1[i] = Fn[i]
        out[i, 0] = Fn[i]
        for a in range(nr[i]):
            F1[gd[i, a]] -= Fn[i] * wts[i, a]
    cnt[C_PASSES] += it
    if it > cnt[C_MAXPASS]:
        cnt[C_MAXPASS] = it
    return OK, change


# ------------------------------------------------------------------------------- driver
class CompiledContacts:
    """The compiled counterpart of :meth:`TrackIntegrator.step_contacts` for a wheel set.

    Holds the kernel's buffers and, per wheel, the data of the FE element it is in
    (load rows on the body's coordinates, residual flexibility, the influence columns
    ``A^{-1} r``), reloaded only when a wheel enters another element. Per step in
    Python: each wheel's running body, element and shape-function values (the model's
    own :meth:`BeamBody.shape_row` / ``path_row``) and its surface heights; the rest is
    one :func:`contact_step` call. The integrator's state and counters are updated as
    by ``step_contacts``.

    Parameters
    ----------
    integ : TrackIntegrator
    sides : sequence of str
        Running side of each wheel (``left`` / ``right``).
    surfaces : callable
        ``surfaces(i, x, body) -> (z1, z2)``: surface heights under wheel i [m].
    """

    def __init__(self, integ, sides, surfaces):
        from .dynamics import (CONTACT_NEWTON_MAX, CONTACT_REL_TOL, CONTACT_TOL, FORCE_TOL, MAX_ITER,
                               MOTION_FLOOR, MOTION_SAFETY, REL_FORCE_TOL)
        kernel_enabled(True)
        self.integ = integ
        model = self.model = integ.model
        self.sides = list(sides)
        self.surfaces = surfaces
        n, m = model.n, len(self.sides)
        sh = integ._shared
        if sh.ldl is None:
            sh.ldl = LDLFactor(prune(integ.step_matrix))
            integ.counters.factorizations += 1
        self.f = f = sh.ldl
        bal = model.ballast
        if sh.ldl_Zb is None or not np.array_equal(sh.ldl_Zb_dofs, bal.dof):
            sh.ldl_Zb = np.zeros((bal.dof.size, n))
            sh.ldl_have = np.zeros(bal.dof.size, np.uint8)
            sh.ldl_Zb_dofs = bal.dof.copy()
        self._sh = sh
        self.beta_s = float(model.params.structural_damping)
        Kt, Ct = integ._Kt, integ._Ct
        K = prune(Kt)
        Cr = drop_cancelled(Ct - self.beta_s * Kt, abs(Ct) + self.beta_s * abs(Kt))
        self._K = (K.indptr.astype(np.int64), K.indices.astype(np.int64), K.data.copy())
        self._C = (Cr.indptr.astype(np.int64), Cr.indices.astype(np.int64), Cr.data.copy())
        self._bal = (bal.dof.astype(np.int64), bal.k.astype(float), bal.c.astype(float), bal.gap.astype(float))
        self.par = np.array([integ.h, integ.alpha, integ.beta, integ.gamma, MOTION_SAFETY, MOTION_FLOOR,
                             0.0, CONTACT_TOL, CONTACT_REL_TOL, FORCE_TOL, REL_FORCE_TOL, MAX_ITER,
                             CONTACT_NEWTON_MAX], dtype=float)
        nrmax = max(b.rom.nr for b in model.bodies if b.kind != "sleeper")
        self.W = np.zeros((m, 4))
        self.T = np.zeros((m, 4, nrmax))
        self.gd = np.zeros((m, nrmax), np.int64)
        self.nr = np.zeros(m, np.int64)
        self.R = np.zeros((m, 4, 4))
        self.Ze = np.zeros((m, 4, n))
        self.surf = np.zeros((m, 2))
        self.cnt = np.zeros(4, np.int64)
        self.work = np.empty(8 * n + 16 * m + 4 * bal.dof.size)
        self.iwork = np.empty(bal.dof.size, np.int64)
        self.wts = np.zeros((m, nrmax))
        self._key = [None] * m
        self._running = model.layout.running_body

    # ------------------------------------------------------------------ wheels
    def influence_rows(self, body, e: int) -> np.ndarray:
        """``A^{-1} r`` of the load rows of element ``e`` of ``body``, shape (k, n) (cached)."""
        key = (body.name, e)
        Z = self._sh.ldl_influence.get(key)
        if Z is None:
            rows = body.load_rows(e)
            E = np.zeros((self.model.n, rows.shape[0]))
            E[body.gdofs, :] = rows.T
            Z = self._sh.ldl_influence[key] = np.ascontiguousarray(self.f.solve(E).T)
            self.integ.counters.solves += rows.shape[0]
        return Z

    def _load(self, i: int, body, e: int, x: float) -> None:
        rows = body.load_rows(e)
        k, nr = rows.shape
        self.T[i] = 0.0
        self.T[i, :k, :nr] = rows
        self.gd[i, :nr] = body.gdofs
        self.nr[i] = nr
        self.R[i] = 0.0
        if not body.solid:
            self.model.point(body.name, x)          # computes and caches the element's residual block
            self.R[i] = body.residual_blocks[e]
        self.Ze[i] = 0.0
        self.Ze[i, :k] = self.influence_rows(body, e)
        self._key[i] = (body.name, e)

    def _wheels(self, x: np.ndarray) -> None:
        model, W = self.model, self.W
        for i, xi in enumerate(x.tolist()):
            name = self._running(self.sides[i], xi)
            b = model.body(name)
            e, w = b.fom.path_row(xi - b.origin) if b.solid else b.fom.shape_row(xi - b.origin)
            if self._key[i] != (name, e):
                self._load(i, b, e, xi)
            W[i, :w.size] = w
            self.surf[i] = self.surfaces(i, xi, name)

    # ------------------------------------------------------------------ step
    def step(self, x: np.ndarray, z_wheel: np.ndarray, c_h: float) -> np.ndarray:
        """One step; same contract as :meth:`TrackIntegrator.step_contacts` with the wheels at x [m]."""
        from .dynamics import ConvergenceError

        it = self.integ
        self._wheels(x)
        m, n = len(self.sides), self.model.n
        Fc0 = it.Fc if it.Fc.size == m else np.zeros(m)
        q1, v1, a1, F1 = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
        Fc1, out = np.empty(m), np.zeros((m, 4))
        self.par[6] = c_h
        cnt = self.cnt
        cnt[:] = 0
        f, sh = self.f, self._sh
        status, change = contact_step(
            self.par, cnt, it.q, it.v, it.a, it.F, Fc0, self.model.f_gravity,
            *self._K, *self._C, self.beta_s, *self._bal, sh.ldl_Zb, sh.ldl_have,
            f.perm, f.Lp, f.Li, f.Lx, f.d,
            self.W, self.T, self.gd, self.nr, self.R, self.Ze, np.asarray(z_wheel, float), self.surf,
            q1, v1, a1, F1, Fc1, out, self.work, self.iwork, self.wts)
        c = it.counters
        c.solves += int(cnt[C_SOLVES])
        c.contact_newton += int(cnt[C_NEWTON])
        if status != OK:
            t1 = it.t + it.h
            if status == NEWTON_FAILED:
                raise ConvergenceError(f"contact forces at t = {t1:.6g} s did not converge; "
                                       f"reduce the step h = {it.h:.3g} s")
            raise ConvergenceError(
                f"track step at t = {t1:.6g} s did not converge in {int(self.par[11])} iterations "
                f"(last force change {change:.3g} N); reduce the step h = {it.h:.3g} s")
        c.iterations += int(cnt[C_PASSES])
        if cnt[C_MAXPASS] > c.max_iterations:
            c.max_iterations = int(cnt[C_MAXPASS])
        c.steps += 1
        it.q, it.v, it.a, it.F, it.Fc = q1, v1, a1, F1, Fc1
        it.k += 1
        return out
