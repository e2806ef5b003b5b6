"""Timoshenko element: matrix properties and convergence to the analytic SS beam."""
import numpy as np
import scipy.linalg as la

from track.bodies import beam_body
from track.elements import deflection_shape, shear_parameter, timoshenko_matrices
from track.params import CONCRETE_BEARER, RAIL_60E1, BeamProfile

R = RAIL_60E1


def ss_timoshenko_frequency(L: float, mode: int = 1, R=R) -> float:
    """Exact first frequency [Hz] of a simply supported Timoshenko beam.

    With k = m pi / L the frequency equation is
    (rho^2 I / (kappa G)) w^4 - (rho A + rho I k^2 (1 + E/(kappa G))) w^2 + E I k^4 = 0
    (Timoshenko 1921); the lower root is the bending branch. ``R``: the section (default 60E1).
    """
    k = mode * np.pi / L
    a = R.rho * R.I * R.rho * R.A / (R.kappa * R.G * R.A)
    b = -(R.rho * R.A + R.rho * R.I * k * k * (1 + R.E / (R.kappa * R.G)))
    c = R.E * R.I * k ** 4
    return float(np.sqrt(np.min(np.roots([a, b, c]).real)) / (2 * np.pi))


def test_element_symmetry_rigid_modes_and_mass():
    L = 0.1
    K, M = timoshenko_matrices(L, R.E, R.G, R.A, R.I, R.rho, R.kappa)
    assert np.allclose(K, K.T, rtol=1e-14, atol=0) and np.allclose(M, M.T, rtol=1e-14, atol=0)
    ev = la.eigvalsh(K)
    # two rigid-body modes (translation, rotation): zero to round-off relative to the largest
    assert np.sum(np.abs(ev) < 1e-10 * ev.max()) == 2
    assert np.all(ev > -1e-10 * ev.max())
    rigid = np.array([1.0, 0.0, 1.0, 0.0])
    assert np.allclose(K @ rigid, 0.0, atol=1e-6 * np.abs(K).max())
    # translational mass of the element is rho A L (partition of unity of the shape functions)
    assert np.isclose(rigid @ M @ rigid, R.rho * R.A * L, rtol=1e-12)
    # linear rotation field w = s - L/2, th = 1 is also strain-free
    lin = np.array([-L / 2, 1.0, L / 2, 1.0])
    assert np.allclose(K @ lin, 0.0, atol=1e-6 * np.abs(K).max())


def test_shape_functions_interpolate_nodal_values():
    L, phi = 0.2, shear_parameter(0.2, R.E, R.G, R.A, R.I, R.kappa)
    N = deflection_shape(np.array([0.0, 1.0]), L, phi)
    assert np.allclose(N, [[1, 0, 0, 0], [0, 0, 1, 0]], atol=1e-14)
    assert np.allclose(deflection_shape(np.linspace(0, 1, 7), L, phi)[:, [0, 2]].sum(axis=1), 1.0)


def test_simply_supported_frequency_converges_at_second_order():
    """SS 60E1 span of 0.6 m: the pinned-pinned frequency of DESIGN.md §6 (1030-1070 Hz).

    Exact answer: the Timoshenko frequency equation above (1033.4 Hz with kappa = 0.34).
    The consistent-mass element converges at O(h^2) in frequency.
    """
    L = 0.6
    f_exact = ss_timoshenko_frequency(L)
    assert 1030.0 <= f_exact <= 1070.0
    hs, errs = [], []
    for ne in (4, 8, 16, 32):
        body = beam_body("b", np.linspace(0, L, ne + 1), BeamProfile(R))
        K, M = body.K.toarray(), body.M.toarray()
        keep = [i for i in range(K.shape[0]) if i not in (0, K.shape[0] - 2)]
        f = np.sqrt(la.eigh(K[np.ix_(keep, keep)], M[np.ix_(keep, keep)], eigvals_only=True)[0]) / (2 * np.pi)
        hs.append(L / ne)
        errs.append(abs(f - f_exact) / f_exact)
    rate = np.polyfit(np.log(hs), np.log(errs), 1)[0]
    assert 1.8 < rate < 2.3, rate  # consistent mass: second order (theory 2)
    assert errs[-1] < 1e-3  # 32 elements per span: 0.1 % is plenty for the 3 % acceptance


def test_a_beam_with_an_empty_span_is_two_beams():
    """The two sleepers of a split position are one body whose gap element is empty
    (``beam_body(..., empty=)``, track.layout.SleeperBody.gap): pinned at the four piece ends, the
    body's lowest frequency is the simply supported Timoshenko frequency of one 2.6 m concrete
    sleeper (closed form above), twice (the two pieces alike). Were the gap element not empty it
    would tie the inner ends' rotations and raise it (72.3 against 56.9 Hz, measured with its material kept).
    26 elements of 0.1 m per piece: the O(h^2) error of the test above is ~1e-4 at L/h = 26; 1e-3."""
    L, gap = 2.6, 0.05
    s = np.concatenate([np.linspace(0.0, L, 27), L + gap + np.linspace(0.0, L, 27)])
    body = beam_body("split", s, BeamProfile(CONCRETE_BEARER), empty=((L, L + gap),))
    assert not body.Ke[26].any() and body.Ke[25].any() and body.Ke[27].any()   # element 26 spans the gap
    K, M = body.K.toarray(), body.M.toarray()
    keep = [i for i in range(K.shape[0]) if i not in (0, 2 * 26, 2 * 27, 2 * 53)]   # w at the piece ends
    f = np.sqrt(la.eigh(K[np.ix_(keep, keep)], M[np.ix_(keep, keep)], eigvals_only=True)[:3]) / (2 * np.pi)
    f_exact = ss_timoshenko_frequency(L, R=CONCRETE_BEARER)
    assert abs(f[0] - f_exact) < 1e-3 * f_exact and abs(f[1] - f_exact) < 1e-3 * f_exact, (f, f_exact)
    assert f[2] > 2.0 * f_exact          # the next is each piece's second mode (~4x for a slender beam)


def test_many_elements_at_once_equal_one_at_a_time():
    """Consistency check (two of our own code paths): timoshenko_matrices of arrays of lengths and
    sections (what a beam's assembly calls) gives each element's matrices as the scalar call does, to
    the last bit; and the bending entry K[0, 0] = 12 E I / ((1 + phi) L^3) equals that formula in
    Python floats to the last bit (L^3 by the C library's pow, as the per-element assembly had it:
    numpy's vectorised power differs from it in the last bit for ~5 % of values, which a comparison of
    the array call with the scalar call alone does not see — both go through the same power)."""
    rng = np.random.default_rng(3)
    L = rng.uniform(0.05, 0.7, 200)
    A = R.A * rng.uniform(0.8, 1.2, 200)
    I = R.I * rng.uniform(0.8, 1.2, 200)
    K, M = timoshenko_matrices(L, R.E, R.G, A, I, R.rho, R.kappa)
    assert K.shape == M.shape == (200, 4, 4)
    for e in range(200):
        Ke, Me = timoshenko_matrices(float(L[e]), R.E, R.G, float(A[e]), float(I[e]), R.rho, R.kappa)
        assert np.array_equal(K[e], Ke) and np.array_equal(M[e], Me), e
        Le, Ae, Ie = float(L[e]), float(A[e]), float(I[e])
        phi = 12.0 * R.E * Ie / (R.kappa * R.G * Ae * Le * Le)
        assert K[e, 0, 0] == (R.E * Ie / ((1.0 + phi) * Le ** 3)) * 12.0, e
