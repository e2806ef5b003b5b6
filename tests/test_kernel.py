"""The compiled track step (track.kernel) against the numpy reference path.

The compiled step is the same algorithm as TrackIntegrator.step_contacts, so both must
give the same co-simulation to round-off, take the same decisions (passes, contact
Newton sweeps) and count the same work.
"""
import numpy as np
import pytest
import scipy.sparse as sp
from conftest import DEFAULT_SCENARIO

from orchestrator.cosim.master import run_cosim
from orchestrator.inputs.scenario import load_scenario
from track import dynamics
from track.dynamics import TrackIntegrator
from track.kernel import (INFLUENCE_AHEAD, KERNEL_ENV, LDLFactor, _coo_matvec_sub, _indices, _sym_matvec_sub,
                          coordinate_entries, lower_rows, prune)
from track.layout import build_layout
from track.model import build_track
from track.statics import static_equilibrium

pytest.importorskip("numba")


def crossing_with_voids(duration=0.03):
    """Bogie over the 1:12 crossing (worn, 12 mrad) with voids under the transition sleeper and
    the one before it, from 0.4 m ahead of the transfer point."""
    sc = load_scenario(DEFAULT_SCENARIO)
    lay = build_layout(sc.track.layout)
    k = sc.track.layout.transition_sleeper
    k = len(lay.sleepers) // 2 + 1 if k is None else k
    gaps = "[0.0, 0.4e-3, 0.9e-3, 0.9e-3, 0.4e-3, 0.0]"
    return load_scenario(DEFAULT_SCENARIO, [
        "track.crossing.impact_angle=0.012", f"simulation.x_start={lay.x_transition - 0.4}",
        f"simulation.duration={duration}",
        f"track.ballast.voids=[{{sleeper: {k}, gaps: {gaps}}}, {{sleeper: {k - 1}, gaps: {gaps}}}]"])


def test_compiled_step_matches_numpy_reference(monkeypatch):
    """Same co-simulation (in-process, bogie, crossing, ballast voids) with both paths.

    Tolerance 1e-9 relative on contact forces, rail deflections and the final state: the
    two paths differ in round-off only (the LDL^T solve vs SuperLU's LU, summation order,
    matrix entries below 1e-14 of the diagonal scale dropped), amplified by the
    contact Newton and the ballast passes no further than their stopping tolerances
    (CONTACT_REL_TOL = 1e-9 of the wheel force); observed ~1e-13.
    """
    sc = crossing_with_voids()
    res = {}
    for mode in ("numpy", "compiled"):
        monkeypatch.setenv(KERNEL_ENV, mode)
        # both start from a cold factor cache: influence rows solved by earlier runs in this
        # process (other tests) would otherwise not be counted as this run's solves
        monkeypatch.setattr(dynamics, "_FACTORS", {})
        r = run_cosim(sc, backend="inprocess", record_states=True)
        assert r.error is None, r.error
        res[mode] = r
    a, b = res["compiled"], res["numpy"]
    ca, cb = a.stats.counters, b.stats.counters
    # the same decisions: every pass and Newton sweep; the same solves counted, but for the influence
    # rows the compiled path solves ahead of the wheels (track.kernel._solve_rows): at most
    # INFLUENCE_AHEAD elements' new rows (2 each on a beam) past the last element of each running body
    assert (ca.passes, ca.contact_iterations) == (cb.passes, cb.contact_iterations)
    running = sum(body.kind != "sleeper" for body in a.track_model.bodies)
    assert 0 <= ca.linear_solves - cb.linear_solves <= 2 * INFLUENCE_AHEAD * running
    assert cb.passes > cb.track_steps, "the case must exercise ballast passes (voids closing)"
    scale = np.abs(b.Fz).max()
    assert np.abs(a.Fz - b.Fz).max() <= 1e-9 * scale
    assert np.abs(a.rail_z[1:] - b.rail_z[1:]).max() <= 1e-9 * np.abs(b.rail_z[1:]).max()   # row 0: no step yet (NaN)
    qa, qb = a.track_record["q"][-1], b.track_record["q"][-1]
    assert np.abs(qa - qb).max() <= 1e-9 * np.abs(qb).max()


def test_ldl_solve_is_exact_to_round_off():
    """The compiled path's LDL^T solve against SuperLU on the unpruned step matrix.

    Backward error ||A x - b|| / (||A|| ||x||) below 1e-13: a backward-stable solve gives
    ~1e-16 times a modest growth factor; the pruned entries (<= 1e-14 of the diagonal
    scale, track.kernel.PRUNE_RTOL) add at most ~1e-14 per row.
    """
    sc = load_scenario(DEFAULT_SCENARIO)
    model = build_track(sc.track)
    st = static_equilibrium(model, [])
    integ = TrackIntegrator(model, sc.simulation.step, st.q)
    A = integ.step_matrix
    f = LDLFactor(prune(A))
    rng = np.random.default_rng(1)
    b = rng.standard_normal(model.n)
    x = f.solve(b)
    norm_A = abs(A).sum(axis=1).max()
    assert np.abs(A @ x - b).max() / (norm_A * np.abs(x).max()) < 1e-13
    x_ref = integ._lu.solve(b)
    assert np.abs(x - x_ref).max() <= 1e-10 * np.abs(x_ref).max()   # cond(A) ~ 1e3 x round-off
    assert f.nnz < integ._lu.L.nnz + integ._lu.U.nnz   # the point of it: less fill than the LU
    # several columns at once (influence rows) against one at a time: the same sweeps, but the
    # one-column backward sweep sums in two accumulators (track.kernel.ldl_solve), the many-column
    # one in one, so they differ by round-off (1e-14 of the largest entry allows for it)
    B = rng.standard_normal((model.n, 4))
    X = f.solve(B)
    for c in range(4):
        xc = f.solve(np.ascontiguousarray(B[:, c]))
        # round-off of a few operations per entry (a few ulp), far below any use of the solution
        assert np.abs(X[:, c] - xc).max() <= 1e-14 * np.abs(xc).max()
    assert np.abs(A @ X - B).max() / (norm_A * np.abs(X).max()) < 1e-13


def test_the_step_products_against_scipy():
    """``_sym_matvec_sub`` (the step's K product, by the lower triangle) and ``_coo_matvec_sub`` (the
    C product, by entries) against scipy's own sparse product, on random matrices with an empty row
    (the symmetric one: empty but for a zero diagonal); the symmetric form refuses a matrix that is not;
    and the uint32 index check.

    Tolerance 1e-14 of the largest |out| entry: both sum at most a few terms per row in float64
    (a few ulp of round-off apart when their summation orders differ)."""
    rng = np.random.default_rng(3)
    X = sp.random(300, 300, density=0.02, random_state=4, format="lil")
    X[17, :] = 0.0                        # an empty row
    X = sp.csr_matrix(X)
    S = sp.lil_matrix(X + X.T)
    S[17, :] = 0.0
    S[:, 17] = 0.0                        # and its column: row 17 of S empty, diagonal included
    S = sp.csr_matrix(S)
    x = rng.standard_normal(300)
    out0 = rng.standard_normal(300)
    for M, product, form in ((S, _sym_matvec_sub, lower_rows), (X, _coo_matvec_sub, coordinate_entries)):
        out = out0.copy()
        product(*form(M), x, out)
        ref = out0 - M @ x
        assert np.abs(out - ref).max() <= 1e-14 * np.abs(ref).max()
        assert out[17] == out0[17]
    with pytest.raises(ValueError, match="symmetric"):
        lower_rows(X)
    with pytest.raises(ValueError, match="uint32"):
        _indices(np.array([0, -1]), "test indices")


def test_kernel_wheel_lookup_matches_model_points():
    """The kernel's element tables give the element, shape-function values and surface heights
    the model's own lookup gives (running_body + model.point + TrackCosim.surfaces).

    Positions: random along each side, every node and every running-segment boundary
    (exactly and 1e-9 m either side), and beyond both ends. Tolerances: the element and
    body exactly, the element too but on a node (where either element gives the same map
    on q, compared instead); the weights within 1e-12 (cubic coefficients fitted to four samples of
    the shape functions, Vandermonde condition ~1e2, weights <= 1 and rotation weights
    ~ element length, so round-off ~1e-14); the surface heights within 1e-15 m (the same
    functions, compiled).
    """
    from track.cosim import TrackCosim
    from track.kernel import N_PAR, P_CH, SURF_GIVEN, _locate_wheels, _stack_tables, element_tables

    sc = load_scenario(DEFAULT_SCENARIO, ["track.crossing.impact_angle=0.012"])
    tc = TrackCosim(sc.track, 4, 98100.0, 1e-4, kernel=False)
    model, lay = tc.model, tc.model.layout
    par = np.zeros(N_PAR)
    ts, etab, ec, es, bodies, elements = element_tables(model, tc.surface_geometry, par)
    assert not (es == SURF_GIVEN).any()
    rng = np.random.default_rng(3)
    checked = 0
    for iside, side in enumerate(("left", "right")):
        segs = lay.running[side]
        nodes = [model.body(seg.body).origin + model.body(seg.body).point_nodes() for seg in segs]
        lo, hi = min(a[0] for a in nodes), max(a[-1] for a in nodes)
        ends = np.array([e for seg in segs for e in (seg.x0, seg.x1) if np.isfinite(e)])
        x = np.concatenate([rng.uniform(lo - 1.0, hi + 1.0, 400), *nodes,
                            (ends[:, None] + np.array([-1e-9, 0.0, 1e-9])).ravel()])
        m = x.size
        ent = np.full((2, m), -1, np.int64)
        W, surf = np.zeros((m, 4)), np.zeros((m, 2))
        _locate_wheels(par, x, np.zeros(m), np.full(m, iside, np.int64), ts, etab, ec, es, ent, W, surf,
                       *_stack_tables([]), np.zeros((m, 2)))
        wheel = 0 if side == "left" else 1     # a wheel on this side (wheel_sides)
        for i, xi in enumerate(x.tolist()):
            name = lay.running_body(side, xi)
            p = model.point(name, xi)
            k = ent[1, i]
            assert bodies[k].name == name, (side, xi)
            if elements[k] == p.element:
                assert np.abs(W[i, :p.shape.size] - p.shape).max() <= 1e-12, (side, xi)
                assert np.abs(W[i, p.shape.size:]).max(initial=0.0) <= 1e-12
            else:   # on a node (to round-off): either element, the same map on q
                assert i >= 400, (side, xi)
                rows = bodies[k].load_rows(elements[k])
                wq = W[i, :rows.shape[0]] @ rows
                assert np.abs(wq - p.weights).max() <= 1e-12 * np.abs(p.weights).max(), (side, xi)
            assert np.abs(surf[i] - np.array(tc.surfaces(wheel, xi, name))).max() <= 1e-15, (side, xi)
            checked += 1
    assert checked > 1000
    assert par[P_CH] == 0.0   # the tables write only the geometry's parameters


def test_influence_rows_are_solved_once_per_node_and_ahead_of_the_wheel(monkeypatch):
    """A wheel entering a beam element whose rows are not cached solves, in one call, the rows of
    the nodes of that element and of the next INFLUENCE_AHEAD - 1 (neighbouring elements share a
    node: 2 new rows per element); the next element then solves nothing. The rows are ``A^{-1} r``
    to round-off against SuperLU's own solve of the same unpruned matrix (an independent
    factorization; 1e-10 of the largest entry: cond(A) ~ 1e3 times round-off, as in
    test_ldl_solve_is_exact_to_round_off), and the very same digits as a solve of the element's
    four rows alone (ldl_solve_many: each column the same operations whatever the others)."""
    import scipy.sparse.linalg as spla

    from track.cosim import TrackCosim

    # a cold factor cache: rows solved by earlier runs of the default scenario in this process
    # (other tests) are shared by every integrator of the same step matrix
    monkeypatch.setattr(dynamics, "_FACTORS", {})
    sc = load_scenario(DEFAULT_SCENARIO)
    tc = TrackCosim(sc.track, 1, 1e5, sc.simulation.step, speed=30.0, kernel=True)
    x0 = tc.model.layout.sleepers[5].x
    tc.do_step(np.array([x0]), np.zeros(1), np.zeros(1))
    cc, model = tc._compiled, tc.model
    body = model.body(model.layout.running_body("left", x0))
    e = int(body.point_row(x0 - body.origin)[0]) + INFLUENCE_AHEAD + 3   # beyond what the step solved
    assert e + INFLUENCE_AHEAD < body.point_nodes().size - 1
    counters = tc.integ.counters
    solves = counters.solves
    first = cc.influence_rows(body, e)
    assert counters.solves - solves == 2 * INFLUENCE_AHEAD + 2
    second = cc.influence_rows(body, e + 1)
    assert counters.solves - solves == 2 * INFLUENCE_AHEAD + 2   # from the cache
    for rows, el in ((first, e), (second, e + 1)):
        E = np.zeros((model.n, 4))
        E[body.gdofs, :] = body.load_rows(el).T
        ref = spla.spsolve(tc.integ.step_matrix.tocsc(), E).T
        assert np.abs(rows - ref).max() <= 1e-10 * np.abs(ref).max()
        assert np.array_equal(rows, cc.f.solve(E).T)
    assert np.array_equal(first[2:], second[:2])               # the shared node: the very same rows


def test_the_kernel_loads_the_element_a_wheel_enters(monkeypatch):
    """The element data the kernel loads itself when a wheel enters an element (track.kernel._load_entry,
    from the tables of element_rows) are the body's own: its load rows and coordinates
    (Body.load_rows, gdofs: exactly, they are copies), its residual flexibility (Body.residual_block,
    exactly) and the influence rows A^{-1} r against SuperLU's solve of the unpruned step matrix
    (1e-10 of the largest entry, as in test_influence_rows_are_solved_once_per_node_and_ahead_of_the_wheel).
    Rows past an element's load rows are zero. Checked for two wheels on both rails, after steps
    that crossed elements (the last loaded ones are compared)."""
    import scipy.sparse.linalg as spla

    from track.cosim import TrackCosim

    monkeypatch.setattr(dynamics, "_FACTORS", {})
    sc = load_scenario(DEFAULT_SCENARIO)
    tc = TrackCosim(sc.track, 2, 1e5, sc.simulation.step, speed=30.0, kernel=True)   # wheels left, right
    x0 = tc.model.layout.sleepers[5].x
    for k in range(40):   # 0.12 m: a few elements
        tc.do_step(np.array([x0, x0]) + 3e-3 * k, np.zeros(2), np.zeros(2))
    cc, model = tc._compiled, tc.model
    Zr = cc.Zr
    A = tc.integ.step_matrix.tocsc()
    assert len(set(cc.ent[0].tolist())) == 2
    for i in range(2):
        k = int(cc.ent[0, i])
        body, e = cc._entry_body[k], cc._entry_element[k]
        rows = body.load_rows(e)
        kr, nr = rows.shape
        assert cc.nr[i] == nr and np.array_equal(cc.gd[i, :nr], body.gdofs)
        assert np.array_equal(cc.T[i, :kr, :nr], rows) and not cc.T[i, kr:].any() and not cc.T[i, :, nr:].any()
        assert np.array_equal(cc.R[i], body.residual_block(e))
        E = np.zeros((model.n, kr))
        E[body.gdofs, :] = rows.T
        ref = spla.spsolve(A, E).T
        got = Zr[cc.zrow[i, :kr]]
        assert np.abs(got - ref).max() <= 1e-10 * np.abs(ref).max()
        assert not Zr[cc.zrow[i, kr:]].any()


def test_fill_ordering_depends_on_the_pattern_only():
    """The LDL^T ordering cached per sparsity pattern (track.kernel.fill_ordering) is the one a new
    minimum-degree LU of a matrix with the same pattern and other values gives (computed here
    with SuperLU directly); a matrix of another pattern gets its own."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    from track.kernel import fill_ordering

    sc = load_scenario(DEFAULT_SCENARIO)
    model = build_track(sc.track)
    A = TrackIntegrator(model, sc.simulation.step, np.zeros(model.n)).step_matrix.tocsc()
    fill_ordering(A)                                           # now cached
    B = A.copy()
    B.data = B.data * np.random.default_rng(3).uniform(0.5, 2.0, B.data.size)
    B = (B + B.T).tocsc()                                      # same pattern (A is symmetric), other values
    assert np.array_equal(fill_ordering(B), np.argsort(spla.splu(B, permc_spec="MMD_AT_PLUS_A").perm_c))
    C = (A + sp.eye(A.shape[0], k=40) + sp.eye(A.shape[0], k=-40)).tocsc()   # another pattern
    assert np.array_equal(fill_ordering(C), np.argsort(spla.splu(C, permc_spec="MMD_AT_PLUS_A").perm_c))
