"""Compiled track step: one numba kernel call per co-simulation step.

The co-simulation step of :meth:`track.dynamics.TrackIntegrator.step_contacts`
(HHT-alpha predictor, right-hand side, the ballast bushings that may change state,
one solve with the constant step matrix, the Hertz contact Newton with the
crossing heights, the modified-Newton passes through the ballast influence rows,
the corrector) spends its time in Python overhead, not arithmetic, when written
with numpy calls (a few hundred small calls per step). Here the same algorithm is
one ``@njit`` function, :func:`contact_step`, that works on preallocated arrays; its
stages are small ``@njit`` functions named as the numpy path's methods (``_predict``,
``_ballast_candidates``, ``_ballast_first_guess``, ``_wheel_loads``,
``_contact_coupling``, ``_contact_newton``, ``_ballast_change``,
``_ballast_row_correction``, ``_corrector``, ``_end_forces``), compiled into it.
The numpy path stays the reference (:data:`KERNEL_ENV`, ``kernel=False``);
tests/test_kernel.py checks that both give the same results to round-off.

Wheels. The kernel also finds each wheel's element, its shape-function values and
the surface heights under it (:func:`_locate_wheels`) from per-side element tables
built once (:func:`element_tables`: the running rails' elements in track order, with
the cubic coefficients of the body's own shape functions and a code for the surface
geometry, whose height functions are :mod:`track.contact`'s, compiled). When a wheel
enters another element, the kernel loads that element's data itself from tables built once
(:func:`element_rows`: load rows, residual flexibility, the body's coordinates) and points the
wheel at the element's influence rows ``A^{-1} r`` in a table of every running body's rows,
solved on first use together with those of the next :data:`INFLUENCE_AHEAD` elements
(:func:`_solve_rows`). (Until 2026-11-27 the kernel returned to its caller for that, about one
step in thirty: ~47 us each, 4-6 % of a 64-sleeper passage.)
With the profile contact (:class:`track.contact.TableGeometry`) the surface code is
``SURF_TABLE + t``: the heights and the Hertz constants of both surfaces are looked up
bilinearly in contact table ``t`` at the wheel's x and lateral offset
(:func:`track.contact.table_surface`, compiled), so each wheel and surface has its own
constant (``chw``); every other code gives both surfaces the one constant ``par[P_CH]``,
and the force law (:func:`track.contact.hertz_pair`) does the same operations as before,
so the dip model's numbers are unchanged to the last bit.

Step matrix. ``A = M + (1+alpha)(gamma h C + beta h^2 K)`` is symmetric positive
definite, so it is factorized once as ``P A P^T = L D L^T`` (SuperLU without
pivoting on the symmetric permutation ``P`` of a minimum-degree ordering of
``A + A^T``) and solved by the two sparse triangular sweeps of
:func:`ldl_solve`: about 35k factor entries for the 64-sleeper panel (2763 dofs),
against 100k in the LU with the MMD(A^T A) ordering the numpy path uses
(benchmarks/bench_step.py measures both).

Sparse loops. Every sparse loop of the step runs with ``uint32`` indices: the product with the
symmetric K over its lower triangle by rows, each entry below the diagonal serving its row and its
column (:func:`_sym_matvec_sub`; K is read once: 12.3 -> 9.1 us on the 64-sleeper panel), the
product with C_r (the damping beyond the stiffness-proportional part: 1101 entries in 2770 mostly
empty rows) over its entries (:func:`_coo_matvec_sub`, 2.7 -> 1.5 us), the forward sweep of ``L y = b`` column by column
(``y_j`` is final when column j comes: all its updates come from columns < j) and the backward
sweep of ``L^T z = y`` column by column from the last, as a dot product of column j with the
final ``z_i``, i > j (:func:`ldl_solve`). The forward sweep does each output's operations in the
order of the flat loop over entries (``w[dst[k]] -= val[k] * x[src[k]]``, by columns) it replaced;
the two products sum in another order than the row-by-row loops before them (2026-11-27, session
26): a different rounding, ~1e-12 of every result. The backward sweep
sums each column's dot product in two accumulators (even and odd entries), which breaks the
chain of dependent subtractions in two: a different rounding, up to 4e-13 of the peak contact
force on the default, 64-sleeper and profile scenarios (measured against the single-accumulator
sweep). Why unsigned: numba wraps a negative index around (``x[-1]`` is
the last element), so every access through a signed index carries a test and a select; an
unsigned index has none. Measured on the 64-sleeper panel's matrices in one script, loops
alternating (2026-11-27, benchmarks/RESULTS.md "Session 24"): solve 80 -> 55 us (compressed,
uint32) -> 46 us (two accumulators), K product 17 -> 12 us; compressed loops with int64
indices are no faster than the flat ones (which had been chosen over them on 2026-11-25).

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
import inspect
import os

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

try:
    import numba
except ImportError:  # pragma: no cover - numba is a dependency; the numpy path still works
    numba = None

from .ballast import DAMPING_ONSET
from .contact import (
    CrossingGeometry,
    DippedJoint,
    Flat,
    TableGeometry,
    crossing_heights,
    flat_heights,
    hertz,
    hertz_pair,
    joint_heights,
    table_surface,
)

KERNEL_ENV = "TURNOUT_TRACK_KERNEL"  # "numpy": the pure-numpy reference path; anything else: compiled
PRUNE_RTOL = 1e-14  # drop |X_ij| <= this * sqrt(|X_ii X_jj|): the round-off of the reductions' products
                    # sits at 1e-20..1e-15, the smallest physical couplings at >= 1e-13 (module doc)

# status codes returned by contact_step
OK, PASSES_FAILED, NEWTON_FAILED = 0, 1, 2
# surface codes of the element tables: which geometry gives the surface heights under a wheel
SURF_FLAT, SURF_CROSSING, SURF_JOINT, SURF_GIVEN = 0, 1, 2, 3   # GIVEN: computed by the caller
SURF_TABLE = 4   # codes SURF_TABLE + t: contact table t (profile contact, track.contact.TableGeometry)
# the parameter vector ``par`` of contact_step
(P_H, P_ALPHA, P_BETA, P_GAMMA, P_SAFETY, P_FLOOR, P_CH, P_CTOL, P_CREL, P_FTOL, P_FREL, P_MAXPASS,
 P_MAXNEWTON, P_BETA_S, P_XTCP, P_XTRANSFER, P_IMPACT, P_XJOINT, P_JOINT) = range(19)
N_PAR = 19
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
# what the compiled code is made of
_KERNEL_SOURCES = ("kernel.py", "contact.py", "ballast.py", "fused.py", "unit_step.py", "unit_cfunc.py")


def _cache_locator():
    """A numba cache locator for this package's kernels that does not depend on where the
    package sits.

    numba's default caches next to the module (or, when that is not writable, in a
    per-user folder named after the module's folder). The track FMU carries its own
    copy of this package, unpacked to a new temporary folder by every host that loads
    it, so a path-based cache would compile afresh (~5 s) at every FMU load. Here the
    cache folder is named after the content of the sources the kernels are compiled
    from (this module, ``contact.hertz``, ``ballast.DAMPING_ONSET``) and after the
    module's import name: the same sources imported under the same name share one cache
    wherever they are, a change to any of them compiles anew (numba itself checks only
    the decorated function's own file). The name is part of it because numba re-imports
    the module by name when it loads a cached function: an entry written by an FMU's
    copy (imported as ``xpanel_track_<hash>``) cannot be loaded where only ``track`` is
    importable. The folder is under
    ``NUMBA_CACHE_DIR`` when set, else numba's per-user cache folder; nothing is
    written next to the package (a read-only site-packages is fine).
    """
    from numba.core import caching, config

    user_wide = getattr(caching, "UserWideCacheLocator", None) or getattr(caching, "_UserWideCacheLocator")

    class TrackKernelLocator(user_wide):
        package_dir = _HERE

        def __init__(self, py_func, py_file):
            super().__init__(py_func, py_file)
            h = hashlib.sha256(py_func.__module__.encode())   # numba re-imports it by name on loading
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


def warm_up_in_background():
    """Start numba's one-time set-up of its CPU target in a daemon thread; returns the thread (None
    without numba, or where numba's internals differ from 0.5x-0.6x's).

    A process's first compiled call, even one loaded from numba's cache, first loads the registries
    of numba's lowering implementations (``BaseContext.refresh``: ~0.3 s on the benchmark machine,
    a tenth of ``turnout run``'s wall time). Started when a run starts, the set-up overlaps with
    the run's own (reading the scenario, unpacking the FMUs, building and factoring the track):
    ``turnout run`` of the default scenario, 2.84-3.03 s against 2.88-3.34 s without
    (benchmarks/RESULTS.md, 2026-11-27). The thread holds numba's compiler lock, so a compiled call
    made meanwhile waits for the set-up instead of doing it beside it."""
    if numba is None:
        return None
    try:
        from numba.core.compiler_lock import global_compiler_lock
        from numba.core.registry import cpu_target
    except ImportError:   # pragma: no cover - other numba internals: the first call does the set-up
        return None
    import threading

    def _refresh():
        with global_compiler_lock:
            cpu_target.target_context.refresh()

    thread = threading.Thread(target=_refresh, name="numba-warm-up", daemon=True)
    thread.start()
    return thread


hertz_nb = _njit(hertz)
hertz_pair_nb = _njit(hertz_pair)
table_surface_nb = _njit(table_surface)
flat_heights_nb = _njit(flat_heights)
crossing_heights_nb = _njit(crossing_heights)
joint_heights_nb = _njit(joint_heights)


@_njit
def record_row(j, t, x, Fz, parts, q, v, a, cq, cv, ca, dt, dx, dFz, dparts, dq, dv, da):
    """Row ``j`` of a state record (:class:`track.cosim.Record`) in one call: the time, the
    wheels' ``x``, ``Fz`` and ``parts`` (m, 2), and the columns ``cq``, ``cv``, ``ca`` of the
    states (an empty column list: the field is not recorded)."""
    dt[j] = t
    for i in range(x.size):
        dx[j, i] = x[i]
        dFz[j, i] = Fz[i]
        dparts[j, i, 0] = parts[i, 0]
        dparts[j, i, 1] = parts[i, 1]
    for k in range(cq.size):
        dq[j, k] = q[cq[k]]
    for k in range(cv.size):
        dv[j, k] = v[cv[k]]
    for k in range(ca.size):
        da[j, k] = a[ca[k]]


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


INDEX = np.uint32   # index type of the compressed sparse loops (module docstring, "Sparse loops")


def _indices(a, what: str) -> np.ndarray:
    """``a`` as :data:`INDEX` (contiguous); ValueError when a value does not fit."""
    a = np.asarray(a)
    if a.size and (a.min() < 0 or a.max() > np.iinfo(INDEX).max):
        raise ValueError(f"{what}: indices outside 0..{np.iinfo(INDEX).max} ({INDEX.__name__})")
    return np.ascontiguousarray(a, dtype=INDEX)


class LDLFactor:
    """``P A P^T = L D L^T`` of a symmetric positive definite sparse matrix (module doc).

    Attributes
    ----------
    perm : ndarray of uint32, shape (n,)
        ``(P x)[i] = x[perm[i]]``.
    Lp, Li, Lx : ndarray of uint32 (n + 1,), uint32 (nnz,), float64 (nnz,)
        The strictly lower part of the unit ``L`` by compressed columns, rows ascending within a
        column: column j holds ``L[Li[k], j] = Lx[k]`` for ``Lp[j] <= k < Lp[j + 1]``. One copy
        serves both sweeps of :func:`ldl_solve` (module docstring, "Sparse loops").
    d : ndarray, shape (n,)
        Diagonal of ``D``.
    """

    def __init__(self, A: sp.spmatrix):
        A = sp.csc_matrix(A)
        n = A.shape[0]
        p = fill_ordering(A)
        B = sp.csc_matrix(A[p][:, p])
        lu = spla.splu(B, permc_spec="NATURAL", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
        if not (np.array_equal(lu.perm_r, np.arange(n)) and np.array_equal(lu.perm_c, np.arange(n))):
            raise RuntimeError("LDL^T of the step matrix: SuperLU pivoted (matrix not positive definite?)")
        d = lu.U.diagonal()
        if not (d > 0).all():
            raise RuntimeError("LDL^T of the step matrix: non-positive pivot (matrix not positive definite)")
        Lc = sp.tril(lu.L, -1).tocsc()
        Lc.sort_indices()
        self.n = n
        self.perm = _indices(p, "LDL^T permutation")
        self.Lp = _indices(Lc.indptr, "LDL^T column pointers")
        self.Li = _indices(Lc.indices, "LDL^T row indices")
        self.Lx = np.ascontiguousarray(Lc.data, dtype=float)
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
        ldl_solve_many(self.perm, self.Lp, self.Li, self.Lx, self.d, np.ascontiguousarray(b), out,
                       np.empty(b.shape))
        return out


_ORDERINGS: dict = {}
ORDERING_CACHE_SIZE = 8   # sparsity patterns kept per process (an int64[n] each)


def fill_ordering(A: sp.csc_matrix) -> np.ndarray:
    """The symmetric fill-reducing permutation of :class:`LDLFactor`: SuperLU's minimum degree
    on ``A + A^T`` (its ``perm_c``, inverted), once per sparsity pattern and process.

    SuperLU has no ordering-only call, so the ordering costs a whole LU; the variants of a
    calibration (other pad or bed stiffness) change the values of the step matrix but not its
    pattern. The ordering depends on the pattern alone, so a cached one is the one a new LU
    would give: the factor, and every result, is the same as without the cache.
    """
    A.sort_indices()
    h = hashlib.blake2b(digest_size=20)
    for arr in (np.array(A.shape), A.indptr, A.indices):
        h.update(np.ascontiguousarray(arr, dtype=np.int64).tobytes())
    key = h.hexdigest()
    p = _ORDERINGS.get(key)
    if p is None:
        p = np.argsort(spla.splu(A, permc_spec="MMD_AT_PLUS_A").perm_c)
        while len(_ORDERINGS) >= ORDERING_CACHE_SIZE:
            _ORDERINGS.pop(next(iter(_ORDERINGS)))
        _ORDERINGS[key] = p
    return p.copy()


@_njit
def ldl_solve(perm, Lp, Li, Lx, d, b, x, work):
    """x = A^{-1} b with ``P A P^T = L D L^T`` (see :class:`LDLFactor`); ``work`` of shape (n,).

    Forward sweep ``L y = P b`` by columns: ``y_j`` is final when column j comes, and its
    entries update rows > j. Backward sweep ``L^T z = D^-1 y`` by columns from the last:
    ``z_j = y_j - sum_i L_ij z_i`` over column j's entries (each ``z_i``, i > j, final), summed
    in two accumulators, even and odd entries, added at the end (module docstring, "Sparse
    loops": 55 -> 46 us on the 64-sleeper panel against one accumulator).
    """
    n = d.size
    for i in range(n):
        work[i] = b[perm[i]]
    for j in range(n):                       # L y = P b
        yj = work[j]
        for k in range(Lp[j], Lp[j + 1]):
            work[Li[k]] -= Lx[k] * yj
    for j in range(n):
        work[j] /= d[j]
    for j in range(n - 1, -1, -1):           # L^T z = D^-1 y, two accumulators
        s = work[j]
        t = 0.0
        a, e = Lp[j], Lp[j + 1]
        m = a + ((e - a) & ~1)
        for k in range(a, m, 2):
            s -= Lx[k] * work[Li[k]]
            t -= Lx[k + 1] * work[Li[k + 1]]
        if m < e:
            s -= Lx[m] * work[Li[m]]
        work[j] = s + t
    for i in range(n):
        x[perm[i]] = work[i]


@_njit
def ldl_solve_many(perm, Lp, Li, Lx, d, B, X, work):
    """X = A^{-1} B for k columns at once (B, X, work of shape (n, k), C order): the sweeps of
    :func:`ldl_solve` reading the factor once for all columns (the same operations per column,
    whatever the other columns; the backward sweep's sums in one accumulator per column: the k
    columns are already independent chains).

    For the influence columns (4 per element a wheel enters). Not used for one column: at
    k = 1 it takes twice :func:`ldl_solve`'s time (125 vs 65 us at n = 2763, measured).
    """
    n, k = B.shape
    for i in range(n):
        for c in range(k):
            work[i, c] = B[perm[i], c]
    for j in range(n):                       # L Y = P B
        for p in range(Lp[j], Lp[j + 1]):
            t, l = Li[p], Lx[p]
            for c in range(k):
                work[t, c] -= l * work[j, c]
    for j in range(n):
        for c in range(k):
            work[j, c] /= d[j]
    for j in range(n - 1, -1, -1):           # L^T Z = D^-1 Y
        for p in range(Lp[j + 1] - 1, Lp[j] - 1, -1):
            t, l = Li[p], Lx[p]
            for c in range(k):
                work[j, c] -= l * work[t, c]
    for i in range(n):
        for c in range(k):
            X[perm[i], c] = work[i, c]


@_njit
def _sym_matvec_sub(Xp, Xi, Xx, x, out):
    """out -= X @ x for a symmetric X given by its lower triangle by rows (:func:`lower_rows`: columns
    ascending, the diagonal last in every row); each entry below the diagonal serves its row and its
    column, so X is read once (12.3 -> 9.1 us for the 64-sleeper step matrix's 18k entries)."""
    for i in range(Xp.size - 1):
        xi = x[i]
        end = Xp[i + 1] - 1                 # the diagonal
        s = out[i] - Xx[end] * xi
        for k in range(Xp[i], end):
            j = Xi[k]
            s -= Xx[k] * x[j]
            out[j] -= Xx[k] * xi
        out[i] = s


@_njit
def _coo_matvec_sub(Xr, Xc, Xx, x, out):
    """out -= X @ x for X by its entries (:func:`coordinate_entries`): for a matrix whose rows are mostly
    empty (the damping beyond the stiffness-proportional part), no pass over the empty rows."""
    for k in range(Xx.size):
        out[Xr[k]] -= Xx[k] * x[Xc[k]]


def lower_rows(X: sp.spmatrix) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(indptr, indices, data)`` of the lower triangle of a symmetric X by rows, columns ascending and
    the diagonal last in every row (stored even where it is zero): uint32, uint32, float64
    (:func:`_sym_matvec_sub`).

    Raises
    ------
    ValueError
        X is not square or not exactly symmetric (its upper triangle would be lost).
    """
    X = sp.csr_matrix(X)
    if X.shape[0] != X.shape[1] or (X != X.T).nnz:
        raise ValueError("lower_rows needs an exactly symmetric matrix")
    L = sp.csr_matrix(sp.tril(X, k=-1))
    L.sort_indices()
    n = X.shape[0]
    ends = L.indptr[1:]
    indptr = L.indptr + np.arange(n + 1)
    indices = np.insert(L.indices, ends, np.arange(n))
    data = np.insert(L.data, ends, X.diagonal())
    return _indices(indptr, "row pointers"), _indices(indices, "column indices"), np.ascontiguousarray(data, float)


def coordinate_entries(X: sp.spmatrix) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(rows, columns, data)`` of X's stored entries, by rows: uint32, uint32, float64
    (:func:`_coo_matvec_sub`)."""
    X = sp.csr_matrix(X)
    X.sort_indices()
    rows = np.repeat(np.arange(X.shape[0]), np.diff(X.indptr))
    return (_indices(rows, "row indices"), _indices(X.indices, "column indices"),
            np.ascontiguousarray(X.data, dtype=float))


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
def _solve_rows(k, erow, eahead, rload, rbody, bgd, bnr, Zr, zhave, zwork, perm, Lp, Li, Lx, d, cnt):
    """Make the influence rows of table entry ``k`` available: when one is missing, solve the missing
    rows of ``eahead[k]`` (those of its element and the next INFLUENCE_AHEAD - 1 of its body, in
    order) in one :func:`ldl_solve_many` call, each row's load vector ``rload[r]`` placed on its
    body's coordinates ``bgd[rbody[r]]``; counts the solves. A column takes the same operations
    whatever the others, so a row is the same to the last digit however it was grouped."""
    missing = False
    for j in range(4):
        if zhave[erow[k, j]] == 0:
            missing = True
    if not missing:
        return
    n = d.size
    nc = 0
    for r in eahead[k]:
        if r >= 0 and zhave[r] == 0:
            nc += 1
    B = zwork[0:n * nc].reshape((n, nc))
    X = zwork[n * nc:2 * n * nc].reshape((n, nc))
    Wk = zwork[2 * n * nc:3 * n * nc].reshape((n, nc))
    B[:] = 0.0
    c = 0
    for r in eahead[k]:
        if r >= 0 and zhave[r] == 0:
            b = rbody[r]
            for a in range(bnr[b]):
                B[bgd[b, a], c] = rload[r, a]
            c += 1
    ldl_solve_many(perm, Lp, Li, Lx, d, B, X, Wk)
    c = 0
    for r in eahead[k]:
        if r >= 0 and zhave[r] == 0:
            for i in range(n):
                Zr[r, i] = X[i, c]
            zhave[r] = 1
            c += 1
    cnt[C_SOLVES] += nc


@_njit
def _load_entry(i, k, erow, eahead, eR, rload, rbody, bgd, bnr, Zr, zhave, zwork, perm, Lp, Li, Lx, d,
                T, gd, nr, R, zrow, fresh, ent, cnt):
    """Wheel i's element data from table entry ``k``: load rows ``T[i]`` (zero beyond the element's),
    coordinates ``gd[i]``, ``nr[i]``, residual flexibility ``R[i]``, influence rows ``zrow[i]`` (solved
    when missing, :func:`_solve_rows`); marks the wheel ``fresh`` and ``k`` loaded."""
    _solve_rows(k, erow, eahead, rload, rbody, bgd, bnr, Zr, zhave, zwork, perm, Lp, Li, Lx, d, cnt)
    b = rbody[erow[k, 0]]
    nb = bnr[b]
    for j in range(4):
        r = erow[k, j]
        zrow[i, j] = r
        for a in range(T.shape[2]):
            T[i, j, a] = rload[r, a] if a < nb else 0.0
        for c in range(4):
            R[i, j, c] = eR[k, j, c]
    for a in range(nb):
        gd[i, a] = bgd[b, a]
    nr[i] = nb
    fresh[i] = 1
    ent[0, i] = k


@_njit
def _enter_elements(ent, erow, eahead, eR, rload, rbody, bgd, bnr, Zr, zhave, zwork, perm, Lp, Li, Lx, d,
                    T, gd, nr, R, zrow, fresh, cnt):
    """Load the element data of each wheel whose table entry changed (``ent[1]`` from :func:`_locate_wheels`)."""
    for i in range(ent.shape[1]):
        if ent[0, i] != ent[1, i]:
            _load_entry(i, ent[1, i], erow, eahead, eR, rload, rbody, bgd, bnr, Zr, zhave, zwork, perm, Lp, Li, Lx,
                        d, T, gd, nr, R, zrow, fresh, ent, cnt)


# ------------------------------------------------------------------------------- step stages
# The stages of one step, in the order contact_step calls them; the numpy reference
# (TrackIntegrator.step_contacts) has methods of the same names (but for the first: the
# numpy path takes the wheels' rail points from the caller).
@_njit
def _locate_wheels(par, x, yw, wside, ts, etab, ec, es, ent, W, surf, tg, tz, tc, chw):
    """Element, shape-function values and surface heights under each wheel.

    The element tables (:func:`element_tables`) hold, per side, the elements of the
    running rails in increasing track coordinate: entry ``k`` of side ``s`` (``ts[s] <= k
    < ts[s+1]``) is used for ``etab[k, 0] <= x < etab[k+1, 0]``, its local coordinate is
    ``(x - etab[k, 1]) / etab[k, 2]`` clipped to [0, 1] and ``ec[k, r]`` are the cubic
    coefficients of shape function r in it. Writes the entry into ``ent[1, i]``, ``W[i]``
    and, unless ``es[k]`` is SURF_GIVEN, ``surf[i]`` [m]; the Hertz constant of each surface
    into ``chw[i]`` [N/m^1.5] (``par[P_CH]``, or a contact table's at ``x`` and the lateral
    offset ``yw[i]`` for the codes ``SURF_TABLE + t``: grid ``tg[t]``, heights ``tz[t]``,
    constants ``tc[t]``); returns False when an entry differs from the loaded one ``ent[0, i]``.
    """
    ok = True
    for i in range(x.size):
        xw = x[i]
        lo = ts[wside[i]]
        a, b = lo + 1, ts[wside[i] + 1]
        while a < b:                        # largest k with etab[k, 0] <= xw (lo when none)
            mid = (a + b) // 2
            if etab[mid, 0] <= xw:
                a = mid + 1
            else:
                b = mid
        k = a - 1
        ent[1, i] = k
        if ent[0, i] != k:
            ok = False
        t = (xw - etab[k, 1]) / etab[k, 2]
        t = min(max(t, 0.0), 1.0)
        for r in range(4):
            W[i, r] = ((ec[k, r, 3] * t + ec[k, r, 2]) * t + ec[k, r, 1]) * t + ec[k, r, 0]
        code = es[k]
        chw[i, 0] = par[P_CH]
        chw[i, 1] = par[P_CH]
        if code == SURF_FLAT:
            surf[i, 0], surf[i, 1] = flat_heights_nb(xw)
        elif code == SURF_CROSSING:
            surf[i, 0], surf[i, 1] = crossing_heights_nb(xw, par[P_XTCP], par[P_XTRANSFER], par[P_IMPACT])
        elif code == SURF_JOINT:
            surf[i, 0], surf[i, 1] = joint_heights_nb(xw, par[P_XJOINT], par[P_JOINT])
        elif code >= SURF_TABLE:
            t = code - SURF_TABLE
            surf[i, 0], surf[i, 1], chw[i, 0], chw[i, 1] = table_surface_nb(xw, yw[i], tg[t], tz[t], tc[t])
    return ok


@_njit
def _predict(h, a_, b, g, beta_s, q0, v0, acc0, F0, fgrav, Kp, Ki, Kx, Cp, Ci, Cx, qp, vp, sw, y, rhs):
    """Newmark predictors and the linear right-hand side of the step.

    Fills ``qp``, ``vp`` (predicted displacement [m] and velocity [m/s]) and
    ``rhs = (1+alpha) f_grav - alpha F0 - K y - C_r sw`` [N], with
    ``sw = (1+alpha) vp - alpha v0`` and ``y = (1+alpha) qp - alpha q0 + beta_s sw``
    (the stiffness-proportional damping folded into the K product, ``C_r`` the rest).
    """
    n = q0.size
    a1 = 1.0 + a_
    c2 = (0.5 - b) * h * h
    c1 = (1.0 - g) * h
    for i in range(n):
        qp[i] = q0[i] + h * v0[i] + c2 * acc0[i]
        vp[i] = v0[i] + c1 * acc0[i]
        sw[i] = a1 * vp[i] - a_ * v0[i]                     # damping argument
        y[i] = a1 * qp[i] - a_ * q0[i] + beta_s * sw[i]     # stiffness argument (K part of C folded in)
        rhs[i] = a1 * fgrav[i] - a_ * F0[i]
    _sym_matvec_sub(Kp, Ki, Kx, y, rhs)
    _coo_matvec_sub(Cp, Ci, Cx, sw, rhs)


@_njit
def _ballast_candidates(h, safety, floor, q0, v0, acc0, D, bgap, cidx):
    """Ballast bushings that may change state within the step (TrackIntegrator._nonlinear_bushings).

    Writes their indices into ``cidx`` and returns how many there are.
    """
    nc = 0
    for j in range(D.size):
        dj = D[j]
        delta = -q0[dj] - bgap[j]
        reach = safety * (abs(v0[dj]) * h + abs(acc0[dj]) * h * h) + floor
        if bgap[j] > 0.0 or delta < DAMPING_ONSET + reach:
            cidx[nc] = j
            nc += 1
    return nc


@_njit
def _ballast_first_guess(a1, bh2, gh, nc, cidx, D, bk, bc, bgap, qp, vp, acc0, corr, rhs):
    """Corrections ``corr`` [N] of the candidate bushings at the state reached with ``a1 = a0``,
    added to ``rhs`` (times 1+alpha)."""
    for c in range(nc):
        j = cidx[c]
        dj = D[j]
        corr[c] = _correction(bk[j], bc[j], bgap[j], qp[dj] + bh2 * acc0[dj], vp[dj] + gh * acc0[dj])
        rhs[dj] += a1 * corr[c]


@_njit
def _wheel_loads(a1, W, T, gd, nr, Fc0, Fn, wts, rhs):
    """The last step's contact forces as the first guess.

    Sets ``Fn = Fc0``, each wheel's weights ``wts[i] = W[i] @ T[i]`` on its body's
    coordinates ``gd[i]``, subtracts the forces (times 1+alpha) from ``rhs``; returns the
    largest force, at least 1 N (the scale of the tolerances).
    """
    fmax = 1.0
    for i in range(Fc0.size):
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
    return fmax


@_njit
def _coupling_blocks(T, gd, nr, Zr, zrow, fresh, E):
    """``E[i, j, r, c] = T_i[r] . Zr[zrow[j, c]][gd_i]`` (4 x 4 per wheel pair): load rows of wheel i's
    element times the influence columns of wheel j's, on wheel i's coordinates.

    Recomputed only for the pairs with a wheel whose element data were loaded since
    (``fresh``, cleared here): G then costs 16 products per pair and step instead of
    16 ``nr``-long gathers (7 us of a 64-sleeper step, measured).
    """
    m = fresh.size
    for i in range(m):
        for j in range(m):
            if fresh[i] or fresh[j]:
                for r in range(4):
                    for c in range(4):
                        z = Zr[zrow[j, c]]
                        t = 0.0
                        for a in range(nr[i]):
                            t += T[i, r, a] * z[gd[i, a]]
                        E[i, j, r, c] = t
    for i in range(m):
        fresh[i] = 0


@_njit
def _contact_coupling(a1, bh2, W, R, gd, nr, wts, E, qp, G, res, wpred):
    """Deflection per force between the wheels over the step, and the predicted deflection.

    ``G[i, j] = (1+alpha) beta h^2 r_i . A^-1 r_j = (1+alpha) beta h^2 W_i E_ij W_j`` [m/N]
    (:func:`_coupling_blocks`), ``res[i] = W_i R_i W_i`` the residual flexibility under
    wheel i [m/N], ``wpred[i] = r_i . qp`` [m].
    """
    m = G.shape[0]
    for i in range(m):
        for j in range(m):
            s = 0.0
            for r in range(4):
                wr = W[i, r]
                if wr != 0.0:
                    t = 0.0
                    for c in range(4):
                        t += E[i, j, r, c] * W[j, c]
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


@_njit
def _contact_newton(chw, ctol, max_newton, bh2, wpred, acc_lin, wts, gd, nr, G, res, zw, surf, Fc0,
                    Fn, wlin, cpl, out, cnt):
    """Jacobi-Newton on ``Fc = hertz(w(Fc))`` for one pass (TrackIntegrator._contact_newton).

    ``w = wlin - G (Fc - Fc0) - res Fc`` with ``wlin`` the deflection of the pass's linear
    solution ``acc_lin``; each sweep updates every wheel with its own diagonal Jacobian.
    ``chw[i]``: the Hertz constants of wheel i's surfaces [N/m^1.5]. Leaves the forces in ``Fn`` [N]
    and, per wheel, (hertz force, its parts, deflection)
    in ``out``; returns False when ``max_newton`` sweeps do not converge.
    """
    m = Fn.size
    for i in range(m):
        s = 0.0
        for a in range(nr[i]):
            s += wts[i, a] * acc_lin[gd[i, a]]
        wlin[i] = wpred[i] + bh2 * s
        Fn[i] = Fc0[i]
    for _ in range(max_newton):
        dmax = 0.0
        for i in range(m):
            s = 0.0
            for j in range(m):
                s += G[i, j] * (Fn[j] - Fc0[j])
            cpl[i] = s
        for i in range(m):
            w = wlin[i] - cpl[i] - res[i] * Fn[i]
            F, k, Fa, Fb = hertz_pair_nb(w, zw[i], surf[i, 0], surf[i, 1], chw[i, 0], chw[i, 1])
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
            return True
    return False


@_njit
def _ballast_change(a1, bh2, gh, nc, cidx, D, bk, bc, bgap, qp, vp, acc_lin, Fn, Fc0, W, Zr, zrow, corr, newc):
    """Corrections ``newc`` [N] of the candidate bushings at the end-of-step state of this pass;
    returns the largest change from ``corr`` [N]."""
    m = Fn.size
    change = 0.0
    for c in range(nc):
        dj = D[cidx[c]]
        s = acc_lin[dj]
        for i in range(m):
            dF = Fn[i] - Fc0[i]
            if dF != 0.0:
                for r in range(4):
                    if W[i, r] != 0.0:
                        s -= a1 * dF * W[i, r] * Zr[zrow[i, r], dj]
        newc[c] = _correction(bk[cidx[c]], bc[cidx[c]], bgap[cidx[c]], qp[dj] + bh2 * s, vp[dj] + gh * s)
        if abs(newc[c] - corr[c]) > change:
            change = abs(newc[c] - corr[c])
    return change


@_njit
def _ballast_row_correction(a1, ftol0, nc, cidx, D, Zb, have, perm, Lp, Li, Lx, dd, unit, work,
                            corr, newc, acc_lin, cnt):
    """A bushing opened or closed: correct the linear solution ``acc_lin`` through the ballast
    influence rows (solved on first use) instead of a new solve; ``corr = newc``."""
    n = acc_lin.size
    for c in range(nc):
        dD = newc[c] - corr[c]
        if abs(dD) > ftol0:
            j = cidx[c]
            _ballast_row(j, D, Zb, have, perm, Lp, Li, Lx, dd, unit, work, cnt)
            f = a1 * dD
            for i2 in range(n):
                acc_lin[i2] += f * Zb[j, i2]
        corr[c] = newc[c]


@_njit
def _corrector(a1, bh2, gh, qp, vp, acc_lin, Fn, Fc0, W, Zr, zrow, acc1, q1, v1):
    """End-of-step state: ``acc1 = acc_lin - (1+alpha) sum_i (Fn_i - Fc0_i) A^-1 r_i``,
    ``q1 = qp + beta h^2 acc1``, ``v1 = vp + gamma h acc1``.

    One pass over the n dofs per influence column ``Zr[zrow[i, r]]``: the passes are
    vectorized axpys, measured 3x faster than one pass over n with an inner loop over the
    4 m columns of an (n, 4 m) layout (7 vs 20 us at n = 2763, m = 4).
    """
    n = acc_lin.size
    for i2 in range(n):
        acc1[i2] = acc_lin[i2]
    for i in range(Fn.size):
        dF = Fn[i] - Fc0[i]
        if dF != 0.0:
            for r in range(4):
                f = a1 * dF * W[i, r]
                if f != 0.0:
                    z = Zr[zrow[i, r]]
                    for i2 in range(n):
                        acc1[i2] -= f * z[i2]
    for i2 in range(n):
        q1[i2] = qp[i2] + bh2 * acc1[i2]
        v1[i2] = vp[i2] + gh * acc1[i2]


@_njit
def _end_forces(fgrav, nc, cidx, D, corr, Fn, wts, gd, nr, F1, Fc1, out):
    """The step's right-hand side ``F1`` = gravity + ballast corrections - contact forces on
    the rails [N], the contact forces ``Fc1`` and ``out[:, 0]`` [N]."""
    for i2 in range(fgrav.size):
        F1[i2] = fgrav[i2]
    for c in range(nc):
        F1[D[cidx[c]]] += corr[c]
    for i in range(Fn.size):
        Fc1[i] = Fn[i]
        out[i, 0] = Fn[i]
        for a in range(nr[i]):
            F1[gd[i, a]] -= Fn[i] * wts[i, a]


def work_sizes(n: int, m: int, nb: int) -> tuple[int, int]:
    """Lengths of the float and integer workspaces of :func:`contact_step` for n dofs, m
    wheels and nb ballast bushings."""
    return 7 * n + 5 * m + m * m + 2 * nb, nb


@_njit
def _workspace(work, n, m, nbal):
    """Views of one step's work arrays in ``work`` (:func:`work_sizes`): the predictors ``qp``, ``vp``,
    the right-hand side, a scratch vector, the linear acceleration, the stiffness-proportional
    scratch, a unit vector, per wheel Fn, wlin, wpred, res, cpl, the m x m contact coupling G, and
    per ballast bushing the corrections ``corr``, ``newc``."""
    qp = work[0:n]
    vp = work[n:2 * n]
    rhs = work[2 * n:3 * n]
    y = work[3 * n:4 * n]
    acc_lin = work[4 * n:5 * n]
    sw = work[5 * n:6 * n]
    unit = work[6 * n:7 * n]
    o = 7 * n
    Fn = work[o:o + m]
    wlin = work[o + m:o + 2 * m]
    wpred = work[o + 2 * m:o + 3 * m]
    res = work[o + 3 * m:o + 4 * m]
    cpl = work[o + 4 * m:o + 5 * m]
    G = work[o + 5 * m:o + 5 * m + m * m].reshape((m, m))
    o2 = o + 5 * m + m * m
    corr = work[o2:o2 + nbal]
    newc = work[o2 + nbal:o2 + 2 * nbal]
    return qp, vp, rhs, y, acc_lin, sw, unit, Fn, wlin, wpred, res, cpl, G, corr, newc


@_njit
def _passes(max_pass, chw, ctol, ftol, ftol0, max_newton, a1, bh2, gh, wpred, acc_lin, wts, gd, nr, G, res, zw,
            surf, Fc0, Fn, wlin, cpl, out, cnt, nc, cidx, D, bk, bc, bgap, qp, vp, W, Zr, zrow, corr, newc, Zb, have,
            perm, Lp, Li, Lx, dd, unit, y):
    """The modified-Newton passes of a step: contact Newton, then the ballast bushings' change;
    repeated (with the bushings' influence rows) while a bushing changes state.

    Returns (status OK / NEWTON_FAILED / PASSES_FAILED, last force change [N], passes taken).
    """
    change = 0.0
    it = 0
    while it < max_pass:
        it += 1
        if not _contact_newton(chw, ctol, max_newton, bh2, wpred, acc_lin, wts, gd, nr, G, res, zw, surf,
                               Fc0, Fn, wlin, cpl, out, cnt):
            return NEWTON_FAILED, change, it
        change = _ballast_change(a1, bh2, gh, nc, cidx, D, bk, bc, bgap, qp, vp, acc_lin, Fn, Fc0, W, Zr, zrow,
                                 corr, newc)
        if change <= ftol:
            return OK, change, it
        _ballast_row_correction(a1, ftol0, nc, cidx, D, Zb, have, perm, Lp, Li, Lx, dd, unit, y,
                                corr, newc, acc_lin, cnt)
    return PASSES_FAILED, change, it


@_njit
def contact_step(par, cnt, q0, v0, acc0, F0, Fc0, fgrav,
                 Kp, Ki, Kx, Cp, Ci, Cx,
                 D, bk, bc, bgap, Zb, have,
                 perm, Lp, Li, Lx, dd,
                 x, zw, wside, ts, etab, ec, es, ent,
                 erow, eahead, eR, rload, rbody, bgd, bnr, Zr, zhave, zwork,
                 T, gd, nr, R, zrow, E, fresh,
                 q1, v1, acc1, F1, Fc1, out, W, surf, wts, work, iwork,
                 yw, tg, tz, tc, chw):
    """One HHT-alpha step with Hertz contacts solved implicitly (TrackIntegrator.step_contacts).

    Parameters (m wheels, n dofs, nb ballast bushings, E table entries, nrmax the most coordinates of a
    running body)
    ----------
    par : float64[N_PAR]   by the ``P_*`` constants: h [s], alpha, beta, gamma, motion safety, motion floor [m],
        Hertz constant [N/m^1.5], contact tol [N] and rel tol, force tol [N] and rel tol, max passes, max Newton
        sweeps, beta_s [s] (stiffness-proportional damping), crossing x_tcp, x_transfer [m], impact angle [rad],
        joint x [m], angle [rad].
    cnt : int64[4]         work counters, incremented (solves, passes, contact Newton sweeps, most passes).
    q0, v0, acc0, F0 : float64[n]   state at the step's start (F0: the right-hand side of the last step).
    Fc0 : float64[m]       contact forces of the last step [N] (the first guess).  fgrav : float64[n].
    Kp, Ki, Kx : the stiffness (with the linear ballast) by its lower triangle (:func:`lower_rows`);
        Cp, Ci, Cx : ``C_t - beta_s K_t`` (the damping not proportional to K) by entries (:func:`coordinate_entries`).
    D, bk, bc, bgap : ballast dofs, stiffness [N/m], damping [N s/m], gaps [m]; Zb : float64[nb, n], have :
        uint8[nb]: their influence rows ``A^{-1} e_D`` (filled on demand).
    perm, Lp, Li, Lx, dd : the LDL^T factor of the step matrix (:class:`LDLFactor`).
    x, zw : float64[m]     wheel track coordinates and vertical positions at the step's end [m].
    wside, ts, etab, ec, es : each wheel's side (0 left, 1 right) and the element tables (:func:`_locate_wheels`).
    ent : int64[2, m]      table entry loaded for each wheel / wanted (written).
    erow, eahead, eR, rload, rbody, bgd, bnr : the entries' element data (:func:`element_rows`); Zr : float64[NR,
        n], zhave : uint8[NR]: the influence rows ``A^{-1} r`` of their load rows (row 0 zero; solved on demand,
        shared by every step on the same factor); zwork : float64[3 n AH] (:func:`_solve_rows`).
    T, gd, nr, R, zrow : float64[m, 4, nrmax], int64[m, nrmax], int64[m], float64[m, 4, 4], int64[m, 4]: each
        wheel's element: load rows on its body's coordinates ``gd``, residual flexibility [m/N], rows of ``Zr``
        (written when it enters, :func:`_load_entry`).
    E, fresh : float64[m, m, 4, 4], uint8[m]   coupling blocks of the wheels' elements (:func:`_coupling_blocks`)
        and which wheels' element data were loaded since they were computed.
    q1, v1, acc1, F1 : float64[n], Fc1 : float64[m], out : float64[m, 4]   outputs; wts : float64[m, nrmax], work,
        iwork : float64, int64 (:func:`work_sizes`): workspace.
    W, surf : float64[m, 4], float64[m, 2]   shape-function values, surface heights [m] (written; ``surf`` read
        where the surface is SURF_GIVEN).
    yw : float64[m]        lateral offset of each wheel towards its field side [m] (contact tables).
    tg, tz, tc : float64[nt, 6], float64[nt, 2, NX, NY] (twice)   contact tables (:func:`track.contact.table_surface`;
        codes ``SURF_TABLE + t``); chw : float64[m, 2]: the Hertz constant of each wheel's surfaces (written).

    Returns ``(status, change)``: OK, PASSES_FAILED or NEWTON_FAILED (the outputs then meaningless); the last
    force change between passes [N].
    """
    if not _locate_wheels(par, x, yw, wside, ts, etab, ec, es, ent, W, surf, tg, tz, tc, chw):
        _enter_elements(ent, erow, eahead, eR, rload, rbody, bgd, bnr, Zr, zhave, zwork, perm, Lp, Li, Lx, dd,
                        T, gd, nr, R, zrow, fresh, cnt)
    h, a_, b, g = par[P_H], par[P_ALPHA], par[P_BETA], par[P_GAMMA]
    n, m, nbal = q0.size, zw.size, D.size
    bh2, gh, a1 = b * h * h, g * h, 1.0 + a_
    qp, vp, rhs, y, acc_lin, sw, unit, Fn, wlin, wpred, res, cpl, G, corr, newc = _workspace(work, n, m, nbal)
    cidx = iwork
    _predict(h, a_, b, g, par[P_BETA_S], q0, v0, acc0, F0, fgrav, Kp, Ki, Kx, Cp, Ci, Cx, qp, vp, sw, y, rhs)
    nc = _ballast_candidates(h, par[P_SAFETY], par[P_FLOOR], q0, v0, acc0, D, bgap, cidx)
    _ballast_first_guess(a1, bh2, gh, nc, cidx, D, bk, bc, bgap, qp, vp, acc0, corr, rhs)
    fmax = _wheel_loads(a1, W, T, gd, nr, Fc0, Fn, wts, rhs)
    ldl_solve(perm, Lp, Li, Lx, dd, rhs, acc_lin, unit)
    cnt[C_SOLVES] += 1
    _coupling_blocks(T, gd, nr, Zr, zrow, fresh, E)
    _contact_coupling(a1, bh2, W, R, gd, nr, wts, E, qp, G, res, wpred)
    ctol = par[P_CTOL] + par[P_CREL] * fmax
    ftol0, ftol = par[P_FTOL], par[P_FTOL] + par[P_FREL] * fmax

    # modified-Newton passes: they repeat only while a ballast bushing changes state
    status, change, it = _passes(int(par[P_MAXPASS]), chw, ctol, ftol, ftol0, int(par[P_MAXNEWTON]), a1, bh2, gh,
                                 wpred, acc_lin, wts, gd, nr, G, res, zw, surf, Fc0, Fn, wlin, cpl, out, cnt, nc, cidx,
                                 D, bk, bc, bgap, qp, vp, W, Zr, zrow, corr, newc, Zb, have, perm, Lp, Li, Lx, dd,
                                 unit, y)
    if status != OK:
        return status, change

    _corrector(a1, bh2, gh, qp, vp, acc_lin, Fn, Fc0, W, Zr, zrow, acc1, q1, v1)
    _end_forces(fgrav, nc, cidx, D, corr, Fn, wts, gd, nr, F1, Fc1, out)
    cnt[C_PASSES] += it
    cnt[C_MAXPASS] = max(cnt[C_MAXPASS], it)
    return OK, change


# where CompiledContacts' argument list of contact_step takes the state (q0 v0 acc0 F0 Fc0), the
# wheels (x zw) and the outputs (q1 v1 acc1 F1 Fc1 out) at each step
CONTACT_STEP_PARAMETERS = tuple(inspect.signature(getattr(contact_step, "py_func", contact_step)).parameters)
_STEP_SLOTS = tuple(CONTACT_STEP_PARAMETERS.index(name) for name in ("q0", "x", "q1"))


# ------------------------------------------------------------------------------- element tables
_SAMPLE_XI = np.array([0.125, 0.375, 0.625, 0.875])   # interior points: each lies in its own element


def _surface_code(geo, par: np.ndarray, tables: list) -> int:
    """Surface code of a geometry object; its parameters go into ``par`` (a contact table into
    ``tables``, once)."""
    if isinstance(geo, TableGeometry):
        for t, g in enumerate(tables):
            if g is geo:
                return SURF_TABLE + t
        tables.append(geo)
        return SURF_TABLE + len(tables) - 1
    if isinstance(geo, Flat):
        return SURF_FLAT
    if isinstance(geo, CrossingGeometry) and geo.table is None:
        par[[P_XTCP, P_XTRANSFER, P_IMPACT]] = geo.x_tcp, geo.x_transfer, geo.impact_angle
        return SURF_CROSSING
    if isinstance(geo, DippedJoint):
        par[[P_XJOINT, P_JOINT]] = geo.x_joint, geo.angle
        return SURF_JOINT
    return SURF_GIVEN


def element_tables(model, geometry, par: np.ndarray, tables: list | None = None):
    """Per side, the elements a wheel can run on, in increasing track coordinate (:func:`_locate_wheels`).

    Follows :meth:`Layout.running_body` (segments ``[x0, x1)``, the first and last extended
    to the ends of their bodies) and :meth:`Body.point_row` (element ``e`` spans nodes e,
    e+1; the local coordinate clipped). The cubic coefficients of the shape functions are
    fitted to the body's own :meth:`Body.point_row` at four interior points (exact for
    the cubic beam shape functions and the solid's linear weights, to round-off).

    Parameters
    ----------
    model : TrackModel
    geometry : callable
        ``geometry(side, body_name)``: the object whose ``heights(x)`` gives the surfaces
        there (:class:`Flat`, :class:`CrossingGeometry`, :class:`DippedJoint`, ...).
    par : ndarray
        contact_step's parameters; the geometries' parameters are written into it.
    tables : list, optional
        The contact tables (:class:`TableGeometry`) met are appended to it (code ``SURF_TABLE + t``).

    Returns
    -------
    ts : int64[3]; etab : float64[E, 3]; ec : float64[E, 4, 4]; es : int64[E]
        As :func:`contact_step` takes them (sides ``left``, ``right``).
    bodies : list of Body, elements : list of int
        Body and element of each entry.
    """
    V = np.vander(_SAMPLE_XI, 4, increasing=True)
    ts, etab, ec, es, bodies, elements = [0], [], [], [], [], []
    tables = [] if tables is None else tables
    for side in ("left", "right"):
        segs = model.layout.running[side]
        for j, seg in enumerate(segs):
            if j and abs(segs[j - 1].x1 - seg.x0) > 1e-9:
                raise ValueError(f"running segments of the {side} side are not contiguous at x = {seg.x0:.6g} m")
            b = model.body(seg.body)
            s, o = b.point_nodes(), b.origin
            ne = s.size - 1
            e0 = 0 if j == 0 else min(max(int(np.searchsorted(s, seg.x0 - o, side="right")) - 1, 0), ne - 1)
            e1 = ne - 1 if j == len(segs) - 1 else min(max(int(np.searchsorted(s, seg.x1 - o, side="left")) - 1,
                                                           0), ne - 1)
            code = _surface_code(geometry(side, seg.body), par, tables)
            el = np.arange(e0, e1 + 1)
            L = s[el + 1] - s[el]
            e_, w = b.point_rows((s[el, None] + _SAMPLE_XI[None, :] * L[:, None]).ravel())
            bad = np.flatnonzero(e_.reshape(-1, 4) != el[:, None])
            if bad.size:
                raise RuntimeError(f"{b.name}: element table does not match point_row at element "
                                   f"{int(el[bad[0] // 4])}")
            tab = np.column_stack([o + s[el], o + s[el], L])
            if j > 0:
                tab[0, 0] = seg.x0
            etab.append(tab)
            ec.append(np.linalg.solve(V[None], w.reshape(-1, 4, 4)).transpose(0, 2, 1))
            es.append(np.full(el.size, code, np.int64))
            bodies += [b] * el.size
            elements += el.tolist()
        ts.append(len(elements))
    cat = (lambda parts, shape: np.ascontiguousarray(np.concatenate(parts).reshape(shape)) if parts
           else np.zeros((0,) + shape[1:]))   # C order: one array type for every compiled caller
    return (np.array(ts, np.int64), cat(etab, (-1, 3)), cat(ec, (-1, 4, 4)), cat(es, (-1,)).astype(np.int64),
            bodies, elements)


def _stack_tables(tables: list) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The contact tables (:class:`TableGeometry`) as the kernel's ``tg`` (nt, 6) and ``tz``, ``tc``
    (nt, 2, NX, NY), padded with NaN (never read: each table's own nx, ny bound its lookups); one
    all-NaN dummy when there are none (fixed array types for the compiled function)."""
    if not tables:
        return np.zeros((1, 6)), np.full((1, 2, 2, 2), np.nan), np.full((1, 2, 2, 2), np.nan)
    NX = max(g.z.shape[1] for g in tables)
    NY = max(g.z.shape[2] for g in tables)
    tg = np.array([g.grid for g in tables], float)
    tz = np.full((len(tables), 2, NX, NY), np.nan)
    tc = np.full((len(tables), 2, NX, NY), np.nan)
    for t, g in enumerate(tables):
        tz[t, :, :g.z.shape[1], :g.z.shape[2]] = g.z
        tc[t, :, :g.c.shape[1], :g.c.shape[2]] = g.c
    return tg, tz, tc


# ------------------------------------------------------------------------------- driver
INFLUENCE_AHEAD = 16   # elements whose influence rows are solved with a missing one (CompiledContacts.influence_rows)


def _row_ids(body, e: int) -> list:
    """Ids of the load rows of element ``e`` (rows of T for a beam, path nodes for the solid)."""
    return [2 * e + j for j in range(4)] if not body.solid else [e, e + 1]


def _element_count(body) -> int:
    """Elements a wheel can run on along ``body`` (its point nodes - 1: FE nodes or the solid's path nodes)."""
    return body.point_nodes().size - 1


def element_rows(bodies: list, elements: list) -> dict:
    """The element data :func:`contact_step` loads when a wheel enters table entry ``k`` (body
    ``bodies[k]``, element ``elements[k]``, as :func:`element_tables` returns them).

    Every load row of the running bodies gets a row id (row 0: a zero row, for the unused rows
    of an element with fewer than four); rows shared by neighbouring elements (a beam node's two
    dofs, a solid path node) have one id.

    Returns
    -------
    dict with
        ``erow`` int64[E, 4]: the row ids of entry k's load rows (:meth:`Body.load_rows`, 0 beyond);
        ``eahead`` int64[E, AH]: the rows solved together when one of entry k's is missing: those of
        its element and of the next INFLUENCE_AHEAD - 1 of its body, in order, each once (-1 after);
        ``eR`` float64[E, 4, 4]: the residual flexibility of the element [m/N];
        ``rload`` float64[NR, nrmax], ``rbody`` int64[NR]: each row's load vector on the coordinates
        of its body (index into ``bgd`` int64[NB, nrmax], ``bnr`` int64[NB]: the bodies' global
        coordinates and their number);
        ``key``: the rows' identity (body names and row counts): steps on the same factor with the
        same key share their influence rows.
    """
    order: dict = {}
    for b in bodies:
        order.setdefault(b.name, b)
    names = list(order)
    per = [_body_rows(order[nm]) for nm in names]
    first = np.cumsum([1] + [p["rload"].shape[0] for p in per])
    nrmax = max(order[nm].rom.nr for nm in names)
    rload = np.zeros((first[-1], nrmax))
    rbody = np.zeros(first[-1], np.int64)
    bgd = np.zeros((len(names), nrmax), np.int64)
    bnr = np.zeros(len(names), np.int64)
    for bi, (name, p) in enumerate(zip(names, per)):
        b, o = order[name], first[bi]
        nr = b.rom.nr
        bgd[bi, :nr], bnr[bi] = b.gdofs, nr
        rload[o:first[bi + 1], :nr] = p["rload"]
        rbody[o:first[bi + 1]] = bi
    E = len(bodies)
    width = max(p["ahead"].shape[1] for p in per)
    erow = np.zeros((E, 4), np.int64)
    eahead = np.full((E, width), -1, np.int64)
    eR = np.zeros((E, 4, 4))
    which = np.array([names.index(b.name) for b in bodies], np.int64)
    el = np.asarray(elements, np.int64)
    for bi, p in enumerate(per):
        k = np.flatnonzero(which == bi)
        ids, ahead = p["ids"][el[k]], p["ahead"][el[k]]
        erow[k] = np.where(ids >= 0, ids + first[bi], 0)
        eahead[k, :ahead.shape[1]] = np.where(ahead >= 0, ahead + first[bi], -1)
        eR[k] = p["R"][el[k]]
    key = tuple(zip(names, first[:-1].tolist())) + (int(first[-1]),)
    return dict(erow=erow, eahead=eahead, eR=eR, rload=rload, rbody=rbody, bgd=bgd, bnr=bnr, key=key)


def _body_rows(body) -> dict:
    """One body's part of :func:`element_rows`, by local row id (computed once per reduced body: kept
    in ``body.rom.kernel_rows``, which a process reuses across the builds of a diagnosis's variants):
    ``rload`` (rows, nr) the load vectors, ``ids`` int64[ne, 4] each element's rows (-1 beyond),
    ``ahead`` int64[ne, AH] the rows of elements e .. e + INFLUENCE_AHEAD - 1, each once, in order
    (-1 after), ``R`` (ne, 4, 4) the elements' residual flexibility [m/N]."""
    cache = body.rom.kernel_rows
    hit = cache.get(INFLUENCE_AHEAD)
    if hit is not None:
        return hit
    ne = _element_count(body)
    ids = np.full((ne, 4), -1, np.int64)
    rows_of = [_row_ids(body, e) for e in range(ne)]
    rload = np.zeros((max(max(r) for r in rows_of) + 1, body.rom.nr))
    for e, rows in enumerate(rows_of):
        ids[e, :len(rows)] = rows
        rload[rows] = body.load_rows(e)
    ahead_of = [list(dict.fromkeys(r for el in range(e, min(e + INFLUENCE_AHEAD, ne)) for r in rows_of[el]))
                for e in range(ne)]
    ahead = np.full((ne, max(len(a) for a in ahead_of)), -1, np.int64)
    for e, a in enumerate(ahead_of):
        ahead[e, :len(a)] = a
    R = np.array([body.residual_block(e) for e in range(ne)]).reshape(ne, 4, 4)
    cache[INFLUENCE_AHEAD] = hit = dict(rload=rload, ids=ids, ahead=ahead, R=R)
    return hit


class CompiledContacts:
    """The compiled counterpart of :meth:`TrackIntegrator.step_contacts` for a wheel set.

    Holds the kernel's buffers and element tables (:func:`element_tables`,
    :func:`element_rows`) and the influence rows of the running bodies (shared by the
    integrators of one factor). The wheels' elements, shape-function values and surface
    heights are found in the kernel, which also loads an element's data when a wheel enters
    it; per step in Python there is one :func:`contact_step` call. The integrator's state
    and counters are updated as by ``step_contacts``.

    Parameters
    ----------
    integ : TrackIntegrator
    sides : sequence of str
        Running side of each wheel (``left`` / ``right``).
    geometry : callable
        ``geometry(side, body) -> object`` with ``heights(x) -> (z1, z2)``: the surface
        heights [m] under a wheel on ``side`` running on ``body``.
    """

    def __init__(self, integ, sides, geometry):
        from .dynamics import (
            CONTACT_NEWTON_MAX,
            CONTACT_REL_TOL,
            CONTACT_TOL,
            FORCE_TOL,
            MAX_ITER,
            MOTION_FLOOR,
            MOTION_SAFETY,
            REL_FORCE_TOL,
        )
        kernel_enabled(True)
        self.integ = integ
        model = self.model = integ.model
        self.sides = list(sides)
        self.geometry = geometry
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
        beta_s = float(model.params.structural_damping)
        Kt, Ct = integ._Kt, integ._Ct
        K = prune(Kt)
        Cr = drop_cancelled(Ct - beta_s * Kt, abs(Ct) + beta_s * abs(Kt))
        self._K = lower_rows(K)
        self._C = coordinate_entries(Cr)
        self._bal = (bal.dof.astype(np.int64), bal.k.astype(float), bal.c.astype(float), bal.gap.astype(float))
        self.par = par = np.zeros(N_PAR)
        par[[P_H, P_ALPHA, P_BETA, P_GAMMA, P_SAFETY, P_FLOOR, P_CTOL, P_CREL, P_FTOL, P_FREL, P_MAXPASS,
             P_MAXNEWTON, P_BETA_S]] = (integ.h, integ.alpha, integ.beta, integ.gamma, MOTION_SAFETY,
                                        MOTION_FLOOR, CONTACT_TOL, CONTACT_REL_TOL, FORCE_TOL, REL_FORCE_TOL,
                                        MAX_ITER, CONTACT_NEWTON_MAX, beta_s)
        tables: list = []
        *self._tables, self._entry_body, self._entry_element = element_tables(model, geometry, par, tables)
        self._given = bool((self._tables[3] == SURF_GIVEN).any())   # some heights from Python
        self._contact_tables = _stack_tables(tables)
        rows = element_rows(self._entry_body, self._entry_element)
        shared = sh.ldl_rows.get(rows["key"])
        if shared is None:                        # row 0 is the zero row: always "solved"
            shared = sh.ldl_rows[rows["key"]] = (np.zeros((rows["rload"].shape[0], n)),
                                                 np.zeros(rows["rload"].shape[0], np.uint8))
            shared[1][0] = 1
        self.Zr, self.zhave = shared            # the influence rows A^{-1} r and which are solved
        self._rows = (rows["erow"], rows["eahead"], rows["eR"], rows["rload"], rows["rbody"], rows["bgd"],
                      rows["bnr"], self.Zr, self.zhave, np.empty(3 * n * rows["eahead"].shape[1]))
        self.yw = np.zeros(m)
        self.chw = np.zeros((m, 2))
        self.wside = np.array([("left", "right").index(s) for s in self.sides], np.int64)
        self.ent = np.full((2, m), -1, np.int64)
        nrmax = max(b.rom.nr for b in model.bodies if b.kind != "sleeper")
        self.W = np.zeros((m, 4))
        self.T = np.zeros((m, 4, nrmax))
        self.gd = np.zeros((m, nrmax), np.int64)
        self.nr = np.zeros(m, np.int64)
        self.R = np.zeros((m, 4, 4))
        self.zrow = np.zeros((m, 4), np.int64)
        self.E = np.zeros((m, m, 4, 4))
        self.fresh = np.ones(m, np.uint8)
        self.surf = np.zeros((m, 2))
        self.cnt = np.zeros(4, np.int64)
        nw, niw = work_sizes(n, m, bal.dof.size)
        self.work = np.empty(nw)
        self.iwork = np.empty(niw, np.int64)
        self.wts = np.zeros((m, nrmax))
        self._args = self._argument_list()

    def _argument_list(self) -> list:
        """contact_step's arguments; :meth:`step` fills the slots of :data:`_STEP_SLOTS` each step
        (the state, the wheels, the outputs), the rest are this object's arrays, fixed."""
        f, sh = self.f, self._sh
        args = [self.par, self.cnt, None, None, None, None, None, self.model.f_gravity,
                *self._K, *self._C, *self._bal, sh.ldl_Zb, sh.ldl_have,
                f.perm, f.Lp, f.Li, f.Lx, f.d,
                None, None, self.wside, *self._tables, self.ent, *self._rows,
                self.T, self.gd, self.nr, self.R, self.zrow, self.E, self.fresh,
                None, None, None, None, None, None, self.W, self.surf, self.wts, self.work, self.iwork,
                self.yw, *self._contact_tables, self.chw]
        if len(args) != len(CONTACT_STEP_PARAMETERS):
            raise RuntimeError(f"contact_step takes {len(CONTACT_STEP_PARAMETERS)} arguments, the list has {len(args)}")
        return args

    # ------------------------------------------------------------------ wheels
    def influence_rows(self, body, e: int) -> np.ndarray:
        """``A^{-1} r`` of the load rows of element ``e`` of ``body``, shape (k, n): the rows the kernel
        uses when a wheel enters that element (:func:`_solve_rows`: solved on first use with those of
        the next INFLUENCE_AHEAD - 1 elements, where the wheels, running towards increasing x, go
        next; a column costs ~20 us in a call of 16-32 columns against ~100 us in one of two, n = 1741,
        benchmarks/RESULTS.md 2026-11-25). The solves counter counts them all."""
        k = next((k for k, (b, el) in enumerate(zip(self._entry_body, self._entry_element))
                  if b is body and el == e), None)
        if k is None:
            raise ValueError(f"{body.name}: element {e} is not one a wheel runs on")
        erow, eahead, _, rload, rbody, bgd, bnr, Zr, zhave, zwork = self._rows
        f, cnt = self.f, np.zeros(4, np.int64)
        _solve_rows(k, erow, eahead, rload, rbody, bgd, bnr, Zr, zhave, zwork, f.perm, f.Lp, f.Li, f.Lx, f.d, cnt)
        self.integ.counters.solves += int(cnt[C_SOLVES])
        return Zr[erow[k, :len(_row_ids(body, e))]].copy()

    def _given_surfaces(self, x: np.ndarray) -> None:
        """Surface heights computed in Python (a geometry the kernel does not have, e.g. a table)."""
        running, surf = self.model.layout.running_body, self.surf
        for i, xi in enumerate(x.tolist()):
            side = self.sides[i]
            surf[i] = self.geometry(side, running(side, xi)).heights(xi)

    def raise_for(self, status: int, change: float) -> None:
        """Raise the :class:`track.dynamics.ConvergenceError` of a failed step (``status`` of
        :func:`contact_step`, ``change`` its last force change [N]) at the integrator's time."""
        from .dynamics import ConvergenceError
        it = self.integ
        t1 = it.t + it.h
        if status == NEWTON_FAILED:
            raise ConvergenceError(f"contact forces at t = {t1:.6g} s did not converge; "
                                   f"reduce the step h = {it.h:.3g} s")
        raise ConvergenceError(
            f"track step at t = {t1:.6g} s did not converge in {int(self.par[P_MAXPASS])} iterations "
            f"(last force change {change:.3g} N); reduce the step h = {it.h:.3g} s")

    # ------------------------------------------------------------------ step
    def step(self, x: np.ndarray, z_wheel: np.ndarray, c_h: float, y: np.ndarray | None = None) -> np.ndarray:
        """One step; same contract as :meth:`TrackIntegrator.step_contacts` with the wheels at x [m]
        (``y``: each wheel's lateral offset towards its field side [m], for contact tables)."""
        it = self.integ
        m, n = len(self.sides), self.model.n
        x = np.ascontiguousarray(x, dtype=float)
        zw = np.ascontiguousarray(z_wheel, dtype=float)
        if y is not None:
            self.yw[:] = y
        if self._given:
            self._given_surfaces(x)
        Fc0 = it.Fc if it.Fc.size == m else np.zeros(m)
        new = np.empty((4, n))                 # q1, v1, a1, F1: new arrays (callers may hold the old)
        Fc1, out = np.empty(m), np.empty((m, 4))
        self.par[P_CH] = c_h
        cnt = self.cnt
        cnt[:] = 0
        args = self._args
        s0, sx, sn = _STEP_SLOTS
        args[s0:s0 + 5] = it.q, it.v, it.a, it.F, Fc0
        args[sx:sx + 2] = x, zw
        args[sn:sn + 6] = new[0], new[1], new[2], new[3], Fc1, out
        status, change = contact_step(*args)
        c = it.counters
        c.solves += int(cnt[C_SOLVES])
        c.contact_newton += int(cnt[C_NEWTON])
        if status != OK:
            self.raise_for(status, change)
        c.iterations += int(cnt[C_PASSES])
        if cnt[C_MAXPASS] > c.max_iterations:
            c.max_iterations = int(cnt[C_MAXPASS])
        c.steps += 1
        it.q, it.v, it.a, it.F = new
        it.Fc = Fc1
        it.k += 1
        return out
