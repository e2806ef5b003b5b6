"""3D solid rail (DESIGN.md §3 optional solid crossing rail, §6 rung 6 groundwork).

Layers: section properties -> mesh and assembly (patch test) -> prismatic solid
against the Timoshenko beam of the same polygon (static, frequencies, mesh
convergence) -> distributing coupling (rigid motion, averaging, force
distribution, tie) -> sparse vs dense Craig–Bampton -> crossing-nose geometry.

Frame: x along the rail, y lateral, z up; 60E1 material from track.params.
"""
from __future__ import annotations

from dataclasses import replace
from functools import lru_cache

import numpy as np
import pytest
import scipy.linalg as la
from scipy.integrate import trapezoid
from scipy.optimize import curve_fit
from scipy.sparse.linalg import norm as sparse_norm

from track.bodies import beam_body, mesh_line
from track.params import RAIL_60E1, BeamProfile, BeamSection
from track.reduction import craig_bampton, static_correction
from track.solid.body import SolidRailParams, solid_rail
from track.solid.coupling import BEAM, distributing_coupling, rigid_motion, surface_coupling, tie
from track.solid.fem import (SurfaceMoments, assemble, body_force, faces_on_plane, nodes_on_line,
                             nodes_on_plane, surface_moments)
from track.solid.mesh import CrossingGeometry, rail_solid_mesh, refine, section_mesh, tet_volumes
from track.solid.reduction import factorize, lowest_modes, static_correction_sparse
from track.solid.section import (RailSection, polygon_properties, rail_60e1_like,
                                 shear_coefficient)


def _solid_tools_missing() -> str | None:
    """gmsh loads its C library (and system GL libraries) at import: say why it cannot."""
    try:
        import gmsh  # noqa: F401  (import only: does its library load?)
        import skfem  # noqa: F401
    except (ImportError, OSError) as exc:
        return f"{type(exc).__name__}: {exc}"
    return None


_MISSING = _solid_tools_missing()
pytestmark = pytest.mark.skipif(_MISSING is not None, reason=f"gmsh / scikit-fem not usable here: {_MISSING}")

E, G, RHO = RAIL_60E1.E, RAIL_60E1.G, RAIL_60E1.rho
NU = E / (2.0 * G) - 1.0                 # 0.296: the solid has the beam's E and G
GRAV = 9.81                              # m/s^2
SPAN = 2.0                               # m: prismatic test rail (see test_static_and_frequencies...)
H_COMPARE = 0.06                         # m: mesh of the solid-vs-beam comparison
H_SEQUENCE = (0.08, 0.06, 0.045, 0.034)  # m: default-suite convergence study
TOL_BEAM = 0.02                          # the acceptance bound solid vs Timoshenko (issue)
FREE_SHIFT = -(2 * np.pi * 20.0) ** 2    # rad^2/s^2: shift for free-free eigenproblems (K - s M SPD)
RIGID_HZ = 1.0                           # Hz: below this a computed frequency is a rigid-body mode

BOX = np.array([[0.075, 0.0], [0.075, 0.172], [-0.075, 0.172], [-0.075, 0.0]])   # small CB test body


# ----------------------------------------------------------------------------- helpers

def section_beam(section: RailSection, kappa: float) -> BeamSection:
    """A Timoshenko beam with the polygon's own A and I_y and 60E1 material."""
    p = section.properties
    return BeamSection(E=E, G=G, A=p.A, I=p.I_y, rho=RHO, kappa=kappa, height=section.height,
                       width=0.15)


@lru_cache(maxsize=None)
def kappa_60e1_like() -> float:
    return shear_coefficient(rail_60e1_like(), h=0.003)


@lru_cache(maxsize=None)
def prismatic(h: float, length: float = SPAN):
    """Mesh and matrices of the prismatic 60E1-like solid, with a mid-span station."""
    points, tets = rail_solid_mesh(length, rail_60e1_like(), h, stations=[0.5 * length])
    K, M = assemble(points, tets, E, NU, RHO)
    return points, tets, K, M


@pytest.fixture(scope="module", autouse=True)
def _free_cached_meshes():
    """The cached meshes and matrices (~100 MB) are dropped when this module is done."""
    yield
    prismatic.cache_clear()


def h_effective(points, tets) -> float:
    """Mean element size [m]: edge of the regular tetrahedron of the mean element volume."""
    return float((6.0 * np.sqrt(2.0) * tet_volumes(points, tets).mean()) ** (1.0 / 3.0))


def simply_supported(points, tets, K, M, length, n_modes: int = 0):
    """Mid-span deflection [m] (downward +) of the solid under self-weight, simply supported,
    and optionally its lowest ``n_modes`` vertical bending frequencies [Hz].

    Supports through the distributing couplings of the end surfaces: mean
    vertical displacement zero at both ends (rotations free); the axial,
    lateral and torsional rigid motions are removed at x = 0 and the lateral one
    also at x = L (reactions zero: the load is vertical and symmetric). The
    deflection is the area mean of u_z over the mid-span cross-section. The
    eigenproblem reuses the factor of the static solve.
    """
    ends = [surface_coupling(points, tets, 0.0), surface_coupling(points, tets, length)]
    tb = tie(K, M, ends, components=[("ux", "uy", "w", "rx"), ("uy", "w")])
    f = tb.T.T @ body_force(M, (0.0, 0.0, -GRAV))
    free = np.setdiff1d(np.arange(tb.K.shape[0]), np.concatenate(tb.ref_dofs))
    K_ff, M_ff = tb.K[free][:, free], tb.M[free][:, free]
    lu = factorize(K_ff)
    v = np.zeros(tb.K.shape[0])
    v[free] = lu.solve(f[free])
    mid = surface_coupling(points, tets, 0.5 * length)
    w_mid = -mid.motion(tb.T @ v, ("w",))[0]
    if not n_modes:
        return w_mid
    w2, Phi = lowest_modes(K_ff, M_ff, 4 * n_modes + 4, shift=0.0, lu=lu)
    U = tb.T[:, free] @ Phi                                       # mass-normalised solid modes
    z_share = np.einsum("ij,ij->j", U[2::3], (M @ U)[2::3])
    f_vert = np.sqrt(w2[z_share > 0.5]) / (2 * np.pi)
    assert f_vert.size >= n_modes, "not enough vertical modes found"
    return w_mid, f_vert[:n_modes]


def simply_supported_self_weight(points, tets, K, M, length):
    """Mid-span deflection [m] (downward +): :func:`simply_supported` without modes."""
    return simply_supported(points, tets, K, M, length)


def timoshenko_pinned_frequency(beam: BeamSection, length: float) -> float:
    """Exact first pinned-pinned Timoshenko frequency [Hz] (mode sin(pi x / L)).

    ``E I k^4 - rho A w^2 - rho I (1 + E / (kappa G)) k^2 w^2 + rho^2 I / (kappa G) w^4 = 0``,
    ``k = pi / L``, the lower root.
    """
    k = np.pi / length
    kG = beam.kappa * beam.G
    a = beam.rho ** 2 * beam.I / kG
    b = -(beam.rho * beam.A + beam.rho * beam.I * (1 + beam.E / kG) * k * k)
    c = beam.E * beam.I * k ** 4
    w2 = (-b - np.sqrt(b * b - 4 * a * c)) / (2 * a)
    return float(np.sqrt(w2) / (2 * np.pi))


def timoshenko_simply_supported(beam: BeamSection, length: float) -> float:
    """Exact Timoshenko mid-span deflection under self-weight q = rho A g [m]."""
    q = beam.rho * beam.A * GRAV
    bending = 5 * q * length ** 4 / (384 * beam.E * beam.I)
    return bending + q * length ** 2 / (8 * beam.kappa * beam.G * beam.A)


def vertical_bending_frequencies(K, M, n: int, n_search: int = 16) -> np.ndarray:
    """The ``n`` lowest free-free frequencies [Hz] whose modes are mostly vertical motion.

    A mode counts as vertical bending when more than half of its kinetic energy
    is in u_z (lateral bending and torsion are below 0.2, axial ~0).
    """
    w2, Phi = lowest_modes(K, M, n_search, shift=FREE_SHIFT)
    f = np.sqrt(np.abs(w2)) / (2 * np.pi)
    MPhi = M @ Phi
    z_share = np.einsum("ij,ij->j", Phi[2::3], MPhi[2::3])       # Phi is mass-normalised
    vert = f[(f > RIGID_HZ) & (z_share > 0.5)]
    assert vert.size >= n, "not enough vertical modes found; raise n_search"
    return vert[:n]


def beam_free_free(beam: BeamSection, length: float, n: int) -> np.ndarray:
    """First ``n`` elastic free-free frequencies [Hz] of the Timoshenko FE beam (1 cm elements)."""
    fom = beam_body("beam", mesh_line(length, [], 0.01), BeamProfile(beam))
    w2 = la.eigh(fom.K.toarray(), fom.M.toarray(), eigvals_only=True)
    f = np.sqrt(np.abs(w2)) / (2 * np.pi)
    return f[f > RIGID_HZ][:n]


def convergence_rate(h, q):
    """Fit q(h) = q_inf + C h^p (Richardson), then the slope of log|q - q_inf| against log h."""
    h, q = np.asarray(h), np.asarray(q)
    (q_inf, C, p), _ = curve_fit(lambda x, a, c, r: a + c * x ** r, h / h[0], q / q[-1],
                                 p0=(1.0, q[0] / q[-1] - 1.0, 2.0), maxfev=20000)
    err = np.abs(q / q[-1] - q_inf)
    return np.polyfit(np.log(h), np.log(err), 1)[0], q_inf * q[-1], err


def small_box():
    """A 1.2 m block (150 x 172 mm) with 2 seats, bushing lines and a contact path: 2.7k dofs."""
    return SolidRailParams(length=1.2, seats=(0.3, 0.9), h=0.12, section=RailSection(BOX, "box"))


# ----------------------------------------------------------------------------- (1) section

def test_polygon_properties_exact_for_rectangle_and_triangle():
    b, h = 0.3, 0.5
    rect = polygon_properties(np.array([[0, 0], [b, 0], [b, h], [0, h]]) + [1.0, 2.0])
    assert rect.A == pytest.approx(b * h, rel=1e-13)
    assert np.allclose(rect.centroid, [1.0 + b / 2, 2.0 + h / 2], rtol=1e-13)
    assert rect.I_y == pytest.approx(b * h ** 3 / 12, rel=1e-12)
    assert rect.I_z == pytest.approx(h * b ** 3 / 12, rel=1e-12)
    assert abs(rect.I_yz) < 1e-14
    tri = polygon_properties(np.array([[0, 0], [b, 0], [0, h]]))
    assert tri.I_y == pytest.approx(b * h ** 3 / 36, rel=1e-12)
    assert tri.I_yz == pytest.approx(-b * b * h * h / 72, rel=1e-12)    # int (y-yc)(z-zc) dA


def test_60e1_like_section_matches_60e1():
    s = rail_60e1_like()
    p = s.properties
    print(f"\n60E1-like: A = {p.A * 1e4:.3f} cm^2 (60E1 76.70), I_y = {p.I_y * 1e8:.1f} cm^4 (3038), "
          f"z_c = {p.centroid[1] * 1e3:.2f} mm (80.9), I_z = {p.I_z * 1e8:.1f} cm^4")
    assert p.A == pytest.approx(RAIL_60E1.A, rel=0.01)          # issue: within ~2 %
    assert p.I_y == pytest.approx(RAIL_60E1.I, rel=0.01)
    assert s.height == pytest.approx(0.172, abs=1e-12)
    head = s.vertices[s.vertices[:, 1] > 0.13]
    assert np.ptp(head[:, 0]) == pytest.approx(0.072, abs=1e-12)
    assert np.ptp(s.vertices[:, 0]) == pytest.approx(0.150, abs=1e-12)
    assert abs(p.centroid[0]) < 1e-15 and abs(p.I_yz) < 1e-15       # symmetric
    assert p.centroid[1] == pytest.approx(0.0809, abs=1e-3)          # neutral axis I/W_foot of 60E1
    # the meshed section integrates to the same area (mesh.py triangulates the polygon exactly)
    pts, tris = section_mesh(s.vertices, 0.01)
    a, b = pts[tris[:, 1]] - pts[tris[:, 0]], pts[tris[:, 2]] - pts[tris[:, 0]]
    area = 0.5 * np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]).sum()
    assert area == pytest.approx(p.A, rel=1e-12)


def test_shear_coefficient():
    """Rectangle: exactly 5/6 (parabolic shear flow); 60E1-like: within the 0.34-0.40 literature range."""
    rect = RailSection(np.array([[0, 0], [0.1, 0], [0.1, 0.3], [0, 0.3]]))
    assert shear_coefficient(rect, h=0.01) == pytest.approx(5 / 6, rel=1e-5)
    k_fine, k_coarse = kappa_60e1_like(), shear_coefficient(rail_60e1_like(), h=0.006)
    print(f"\nshear coefficient of the 60E1-like polygon: {k_fine:.4f} (h = 6 mm: {k_coarse:.4f})")
    assert abs(k_coarse / k_fine - 1) < 1e-3      # converged to 0.1 %
    assert 0.34 <= k_fine <= 0.41


# ----------------------------------------------------------------------------- mesh + assembly

def test_mesh_is_valid_and_assembly_passes_the_patch_test():
    """Constant-stress patch test: a linear displacement field is exact for P2 tetrahedra.

    Uniaxial stress sigma along x: u = (sigma/E) (x, -nu y, -nu z). Interior
    nodes carry no force (K u = 0 there), the end face x = L carries the
    resultant sigma A, and the mass matrix integrates rho V.
    """
    points, tets, K, M = prismatic(0.08)
    V = tet_volumes(points, tets)
    assert V.min() > 0
    assert V.sum() == pytest.approx(rail_60e1_like().properties.A * SPAN, rel=1e-12)
    sigma = 1.0e6
    u = (sigma / E) * np.column_stack([points[:, 0], -NU * points[:, 1], -NU * points[:, 2]]).ravel()
    f = (K @ u).reshape(-1, 3)
    scale = sigma * rail_60e1_like().properties.A
    loaded = np.concatenate([nodes_on_plane(points, 0, 0.0), nodes_on_plane(points, 0, SPAN)])
    unloaded = np.setdiff1d(np.arange(points.shape[0]), loaded)    # interior and traction-free sides
    assert np.abs(f[unloaded]).max() < 1e-9 * scale
    end = nodes_on_plane(points, 0, SPAN)
    assert f[end, 0].sum() == pytest.approx(scale, rel=1e-9)
    assert np.abs(f[end, 1:].sum(axis=0)).max() < 1e-9 * scale
    assert np.abs(f.sum(axis=0)).max() < 1e-9 * scale               # equilibrium
    ones = np.tile([0.0, 0.0, 1.0], points.shape[0])
    assert ones @ (M @ ones) == pytest.approx(RHO * V.sum(), rel=1e-12)


# ----------------------------------------------------------------------------- (2) solid vs beam

def test_static_and_frequencies_vs_timoshenko():
    """Prismatic 60E1-like solid vs the Timoshenko beam of the same polygon.

    Static case: simply supported under self-weight, supports and mid-span
    deflection taken through distributing couplings (area means over the
    cross-sections). Chosen over a cantilever because its reference is exact and
    clean: the load is a body force as in beam theory, the supports are
    statically determinate, and the end disturbances (Saint-Venant zones, about
    one rail height long) carry no lever arm to mid-span, whereas a clamped root
    of a solid cantilever adds a mesh-dependent root rotation that the tip
    multiplies by the span. Dynamic case: free-free, which needs no supports at
    all in either model.

    The span (2 m) makes shear 6 % of the static deflection, so the Timoshenko
    term is tested, while the uncertainty of the shear coefficient (computed,
    with nu = 0; Cowper's nu-correction is ~2 %) moves the reference by ~0.1 %.
    Measured: static +0.3 %, frequencies +0.06 % / +0.08 %, against 2 %.
    """
    s = rail_60e1_like()
    beam = section_beam(s, kappa_60e1_like())
    points, tets, K, M = prismatic(H_COMPARE)
    w_solid = simply_supported_self_weight(points, tets, K, M, SPAN)
    w_beam = timoshenko_simply_supported(beam, SPAN)
    f_solid = vertical_bending_frequencies(K, M, 2)
    f_beam = beam_free_free(beam, SPAN, 2)
    # the same beam with the 0.34 of track.params: shows how much kappa matters here
    w_034 = timoshenko_simply_supported(section_beam(s, RAIL_60E1.kappa), SPAN)
    print(f"\nsolid vs Timoshenko (L = {SPAN} m, h = {H_COMPARE} m, {points.shape[0]} nodes):"
          f"\n  mid-span deflection {w_solid * 1e6:.4f} um vs {w_beam * 1e6:.4f} um "
          f"({(w_solid / w_beam - 1) * 100:+.3f} %; with kappa = 0.34 the beam gives {w_034 * 1e6:.4f})"
          f"\n  free-free vertical bending {np.round(f_solid, 2)} Hz vs {np.round(f_beam, 2)} Hz "
          f"({np.round((f_solid / f_beam - 1) * 100, 3)} %)")
    assert abs(w_solid / w_beam - 1) < TOL_BEAM
    assert np.all(np.abs(f_solid / f_beam - 1) < TOL_BEAM)


def test_mesh_convergence_of_the_solid():
    """Discretisation error of the solid's static deflection falls faster than h.

    Quadratic tetrahedra: the compliance error goes like h^4 for smooth fields and
    h^(2 lambda) = h^1.6 near the 225-degree re-entrant edges of the chamfered
    fillets (lambda = 0.8); between those, a rate > 1 is the bound asserted.
    h is the measured mean element size (the nominal gmsh size is capped by the
    section's features on coarse meshes), the limit value comes from a Richardson
    fit q = q_inf + C h^p over the sequence.
    """
    hs, qs = [], []
    for h in H_SEQUENCE:
        points, tets, K, M = prismatic(h)
        hs.append(h_effective(points, tets))
        qs.append(simply_supported_self_weight(points, tets, K, M, SPAN))
    rate, q_inf, err = convergence_rate(hs, qs)
    w_beam = timoshenko_simply_supported(section_beam(rail_60e1_like(), kappa_60e1_like()), SPAN)
    print(f"\nconvergence of the mid-span deflection: h_eff = {np.round(hs, 4)} m, "
          f"relative errors {err}, fitted rate {rate:.2f}; "
          f"limit {q_inf * 1e6:.4f} um = Timoshenko {(q_inf / w_beam - 1) * 100:+.3f} %")
    assert np.all(np.diff(hs) < 0)
    assert rate > 1.0
    assert abs(q_inf / w_beam - 1) < TOL_BEAM


@pytest.mark.slow
def test_nested_refinement_convergence():
    """Observed order on nested meshes (each level splits every tetrahedron into 8, h halves).

    p = log2((q0 - q1) / (q1 - q2)) for the mid-span deflection and the first
    vertical frequency of the 2 m simply supported prismatic rail. The finest
    level has ~95k nodes: ~7 min and ~8 GB, most of it one sparse LU. (At 1 m,
    span / height 5.8, the solid is 2.4 % softer than the beam statically: end
    zones and the shear coefficient matter more on short spans.)
    """
    length = SPAN
    points, tets = rail_solid_mesh(length, rail_60e1_like(), 0.2, stations=[0.5 * length])
    w, f = [], []
    for level in range(3):
        if level:
            points, tets = refine(points, tets)
        K, M = assemble(points, tets, E, NU, RHO)
        w_mid, f_vert = simply_supported(points, tets, K, M, length, n_modes=1)
        w.append(w_mid)
        f.append(f_vert[0])
        print(f"\nlevel {level}: {points.shape[0]} nodes, h_eff = {h_effective(points, tets):.4f} m, "
              f"w = {w_mid:.8e} m, f1 = {f_vert[0]:.4f} Hz", flush=True)
    p_w = np.log2((w[0] - w[1]) / (w[1] - w[2]))
    p_f = np.log2((f[0] - f[1]) / (f[1] - f[2]))
    beam = section_beam(rail_60e1_like(), kappa_60e1_like())
    dw = w[2] / timoshenko_simply_supported(beam, length) - 1
    df = f[2] / timoshenko_pinned_frequency(beam, length) - 1
    print(f"observed orders: {p_w:.2f} (static), {p_f:.2f} (f1); finest vs Timoshenko: "
          f"{dw * 100:+.3f} % (static), {df * 100:+.3f} % (f1)")
    assert p_w > 1.0 and p_f > 1.0
    assert abs(dw) < TOL_BEAM and abs(df) < TOL_BEAM


# ----------------------------------------------------------------------------- (3) coupling

def test_rigid_body_motion_has_zero_energy_and_is_returned_by_the_coupling():
    points, tets, K, M = prismatic(0.08)
    end = surface_coupling(points, tets, SPAN)
    centroid = rail_60e1_like().properties.centroid
    assert np.allclose(end.ref_point, [SPAN, *centroid], atol=1e-12)   # weights integrate exactly
    a = np.array([1.0e-3, -2.0e-3, 3.0e-3, 4.0e-4, -5.0e-4, 6.0e-4])    # m, rad
    u = rigid_motion(points, a, end.ref_point)
    K_norm = sparse_norm(K, np.inf)
    assert abs(u @ (K @ u)) < 1e-12 * K_norm * (u @ u)                   # round-off level
    assert np.allclose(end.C @ u[end.dofs], a, rtol=1e-10, atol=0)        # round-off: ~1e-11 seen
    # beam convention: theta = dw/dx. The rigid motion w(x) = w0 + theta x ...
    w0, theta = 2.0e-3, 1.0e-3
    u_beam = rigid_motion(points, [0, 0, w0 + theta * SPAN, 0, -theta, 0], end.ref_point)
    assert np.allclose(u_beam[2::3], w0 + theta * points[:, 0], rtol=1e-12)
    assert np.allclose(end.motion(u_beam, BEAM), [w0 + theta * SPAN, theta], rtol=1e-12)
    # ... turns the section with the slope: the top fibre moves back, u_x = -(z - z_c) theta
    assert np.allclose(u_beam[0::3], -(points[:, 2] - end.ref_point[2]) * theta, rtol=1e-12)


def test_coupling_is_the_area_average_and_distributes_forces_as_a_uniform_traction():
    points, tets, K, M = prismatic(0.08)
    props = rail_60e1_like().properties
    end = surface_coupling(points, tets, 0.0)
    mom = surface_moments(points, faces_on_plane(points, tets, 0, 0.0))
    assert mom.area == pytest.approx(props.A, rel=1e-12)
    assert np.allclose(end.weights, mom.m0 / mom.area, rtol=0, atol=1e-15)
    rng = np.random.default_rng(1)
    u = rng.normal(size=3 * points.shape[0])
    w = end.motion(u, ("w",))[0]
    assert w == pytest.approx(mom.m0 @ u[3 * mom.nodes + 2] / mom.area, rel=1e-12)
    # the area mean of the field itself: exact for linear and quadratic fields over the face
    yc, zc = props.centroid
    for field, mean in ((lambda y, z: 1e-3 + 2e-3 * y - 5e-3 * z, 1e-3 + 2e-3 * yc - 5e-3 * zc),
                        (lambda y, z: y * y, props.I_z / props.A + yc * yc),
                        (lambda y, z: z * z, props.I_y / props.A + zc * zc)):
        u_f = np.zeros((points.shape[0], 3))
        u_f[:, 2] = field(points[:, 1], points[:, 2])
        assert end.motion(u_f.ravel(), ("w",))[0] == pytest.approx(mean, rel=1e-12)
    # tie: a force F on the reference w is the nodal force field (m0_i / A) F on the surface,
    # the consistent loads of a uniform traction: they do the same work on every tied motion
    tb = tie(K, M, [end])
    F = end.matrix(K.shape[0], ("w",)).T.toarray()[:, 0]          # nodal forces for F = 1 N
    assert np.allclose(F[3 * end.nodes + 2], mom.m0 / mom.area, rtol=1e-12, atol=1e-15)
    expected = np.zeros(tb.K.shape[0])
    expected[tb.ref_dofs[0][0]] = 1.0
    assert np.allclose(tb.T.T @ F, expected, atol=1e-12)
    # Abaqus-style nodal weights are a special case: a rigid motion is still returned exactly
    lumped = SurfaceMoments.from_nodal_weights(points, mom.nodes, np.full(mom.nodes.size, 1.0))
    a = np.array([1e-3, 0.0, 2e-3, 1e-4, -3e-4, 2e-4])
    u_r = rigid_motion(points, a, end.ref_point)
    c_l = distributing_coupling(lumped, end.ref_point)
    assert np.allclose(c_l.C @ u_r[c_l.dofs], a, rtol=1e-10)


def test_tie_changes_coordinates_not_physics():
    """Tying is an exact change of coordinates: same eigenfrequencies; a rigid reference motion
    imposed at both ends gives zero strain energy."""
    p = small_box()
    points, tets = rail_solid_mesh(p.length, p.section, p.h, stations=p.seats)
    K, M = assemble(points, tets, E, NU, RHO)
    ends = [surface_coupling(points, tets, 0.0), surface_coupling(points, tets, p.length)]
    six = ("ux", "uy", "uz", "rx", "ry", "rz")
    tb = tie(K, M, ends, components=six)
    f_full = la.eigh(K.toarray(), M.toarray(), eigvals_only=True, subset_by_index=(6, 20))
    f_tied = la.eigh(tb.K.toarray(), tb.M.toarray(), eigvals_only=True, subset_by_index=(6, 20))
    assert np.allclose(f_tied, f_full, rtol=1e-9)
    # the same rigid motion seen from both reference points, interior solved statically
    a0 = np.array([1e-3, 2e-3, -1e-3, 3e-4, 2e-4, -1e-4])
    q = np.concatenate([ends[0].C @ rigid_motion(points, a0, [0, 0, 0])[ends[0].dofs],
                        ends[1].C @ rigid_motion(points, a0, [0, 0, 0])[ends[1].dofs]])
    Q = np.concatenate(tb.ref_dofs)
    F = np.setdiff1d(np.arange(tb.K.shape[0]), Q)
    v = np.zeros(tb.K.shape[0])
    v[Q] = q
    v[F] = factorize(tb.K[F][:, F]).solve(-tb.K[F][:, Q] @ q)
    u = tb.T @ v
    assert np.allclose(u, rigid_motion(points, a0, [0, 0, 0]), atol=1e-12 * np.abs(u).max())
    assert abs(v @ (tb.K @ v)) < 1e-10 * sparse_norm(tb.K, np.inf) * (v @ v)


# ----------------------------------------------------------------------------- (4) Craig–Bampton

def test_sparse_craig_bampton_matches_dense_and_full_model():
    """Retained: (w, theta) at both end couplings, 2 bushing nodes per seat, the contact path.

    Cut-off 1500 Hz (track.params default); fixed-interface modes to 4 x that.
    (With 3 x, one mode of this block was 3 % off and the third vertical bending
    mode of the 2 m 60E1-like rail 1.1 %: the solid needs the larger factor.)
    """
    f_cut = 1500.0
    sr = solid_rail(replace(small_box(), f_modes=4 * f_cut))
    K, M, B = sr.tied.K, sr.tied.M, sr.rom.boundary
    dense = craig_bampton(K.toarray(), M.toarray(), B, f_modes=4 * f_cut)
    sparse = sr.rom
    assert sparse.mode_freqs.size == dense.mode_freqs.size > 0
    assert np.allclose(sparse.mode_freqs, dense.mode_freqs, rtol=1e-8)
    nb = B.size
    assert np.allclose(sparse.T[:, :nb], dense.T[:, :nb], atol=1e-10 * np.abs(dense.T[:, :nb]).max())
    assert np.allclose(np.abs(sparse.T.T @ M @ dense.T)[nb:, nb:], np.eye(sparse.mode_freqs.size),
                       atol=1e-6)                                       # same modes up to sign
    f_full = np.sqrt(np.abs(la.eigh(K.toarray(), M.toarray(), eigvals_only=True)))
    f_red = np.sqrt(np.abs(la.eigh(sparse.K, sparse.M, eigvals_only=True)))
    f_full, f_red = f_full / (2 * np.pi), f_red / (2 * np.pi)
    k = np.searchsorted(f_full, f_cut)
    el = f_full[:k] > RIGID_HZ
    err = np.abs(f_red[:k][el] / f_full[:k][el] - 1)
    print(f"\nsparse CB: nb = {nb}, {sparse.mode_freqs.size} modes; frequencies below {f_cut:.0f} Hz "
          f"{np.round(f_full[:k][el], 1)} Hz, errors {np.round(err * 100, 3)} %")
    assert err.size >= 3 and err.max() < 0.01
    assert np.all(np.abs(f_red[:k][~el]) < RIGID_HZ)                      # (w, theta) free-free rigid modes
    # the retained coordinates mean what SolidRail says they mean
    q = np.zeros(sparse.nr)
    q[sr.contact_q[3]] = 1e-4
    path = nodes_on_line(sr.points, 0.0, sr.points[:, 2].max())
    assert sr.displacements(q)[path[3], 2] == pytest.approx(1e-4, rel=1e-12)
    assert sr.contact_x[3] == sr.points[path[3], 0]
    # static correction for loads on interior dofs: the same as the dense version
    f = np.zeros(K.shape[0])
    f[sparse.interior[::97]] = 1.0e3
    u_s, u_d = static_correction_sparse(sparse, f), static_correction(dense, f)
    assert np.allclose(u_s, u_d, atol=1e-9 * np.abs(u_d).max())


# ----------------------------------------------------------------------------- crossing variant

def test_crossing_nose_geometry():
    """The head above the cut height is trimmed to |y| <= b(x) = max(t/2, (x - x_p) / 2n):
    meshed volume = prism minus the analytically integrated removed head area."""
    s = rail_60e1_like()
    cg = CrossingGeometry(crossing_n=12.0, x_point=-0.1, tip_width=0.012, cut_height=0.1328)
    length = 1.2
    points, tets = rail_solid_mesh(length, s, 0.05, stations=[0.6], crossing=cg)
    V = tet_volumes(points, tets)
    assert V.min() > 0
    head = points[:, 2] >= cg.cut_height + 1e-9
    assert np.all(np.abs(points[head, 1]) <= cg.half_width(points[head, 0]) + 1e-9)
    x = np.linspace(0.0, length, 2401)
    removed = np.array([_area_outside(s.vertices, cg.cut_height, b) for b in cg.half_width(x)])
    expected = s.properties.A * length - trapezoid(removed, x)
    assert V.sum() == pytest.approx(expected, rel=1e-5)       # trapezoid error of the kinked integrand
    assert len(faces_on_plane(points, tets, 0, 0.6)) > 0      # station plane kept after the cut


def _area_outside(vertices, z0, b):
    """Area of the polygon part with z >= z0 and |y| >= b (Sutherland-Hodgman clipping)."""
    def clip(P, inside, cut):
        out = []
        for i in range(len(P)):
            a, c = P[i - 1], P[i]
            if inside(c):
                if not inside(a):
                    out.append(cut(a, c))
                out.append(c)
            elif inside(a):
                out.append(cut(a, c))
        return out

    def cut_y(y):
        return lambda a, c: (y, a[1] + (c[1] - a[1]) * (y - a[0]) / (c[0] - a[0]))

    def cut_z(a, c):
        return (a[0] + (c[0] - a[0]) * (z0 - a[1]) / (c[1] - a[1]), z0)

    total = 0.0
    for sgn in (1.0, -1.0):
        P = clip([tuple(v) for v in vertices], lambda p: p[1] >= z0, cut_z)
        P = clip(P, lambda p: sgn * p[0] >= b, cut_y(sgn * b))
        if len(P) >= 3:
            Q = np.array(P)
            total += 0.5 * abs(np.dot(Q[:, 0], np.roll(Q[:, 1], -1)) - np.dot(Q[:, 1], np.roll(Q[:, 0], -1)))
    return total
