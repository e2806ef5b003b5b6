"""Vehicle models (src/vehicle): statics, modal properties, exact time stepping."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from vehicle import (
    GRAVITY,
    BogieParams,
    QuarterParams,
    VehicleStepper,
    bogie,
    bounce_pitch_frequencies,
    quarter_vehicle,
)

RNG_SEED = 20240611

FRAME_HELD = ("carbody_z", "carbody_roll", "ws1_z", "ws1_roll", "ws2_z", "ws2_roll")


def rigid_quarter():
    return quarter_vehicle(QuarterParams(flexible=False))


def all_models():
    return {"bogie": bogie(), "quarter_flexible": quarter_vehicle(), "quarter_rigid": rigid_quarter()}


# --------------------------------------------------------------------------- kinematics
def test_wheel_numbering_and_positions():
    """Wheel 1 = front left (+y), 2 = front right, 3/4 rear; x_i = x0 + a_i + v t."""
    veh = bogie()
    x = veh.wheel_x(t=0.3, x0=10.0, speed=20.0)
    # 10 + 20*0.3 = 16 exactly representable within 1 ulp
    np.testing.assert_allclose(x, [16.0, 16.0, 13.5, 13.5], rtol=0, atol=1e-12)
    q = np.zeros(veh.n_dofs)
    q[veh.dof("ws1_roll")] = 1e-3          # positive roll lifts the left side
    np.testing.assert_allclose(veh.wheel_z(q), [0.75e-3, -0.75e-3, 0, 0], atol=1e-15)
    q[:] = 0
    q[veh.dof("ws2_z")] = 2e-3
    np.testing.assert_allclose(veh.wheel_z(q), [0, 0, 2e-3, 2e-3], atol=1e-15)


def test_input_matrix_is_transpose_of_output_map():
    """Virtual work: the generalised force of a wheel force is W^T Fz."""
    for veh in all_models().values():
        np.testing.assert_array_equal(veh.B, veh.W.T)


def test_invalid_parameters_are_rejected():
    with pytest.raises(ValueError, match="k1"):
        BogieParams(k1=-1.0)
    with pytest.raises(ValueError, match="axle_load"):
        BogieParams(axle_load=20e3)     # 4.1 t in total < frame + wheelsets (6 t)
    with pytest.raises(ValueError, match="axle_centre_mass"):
        QuarterParams(axle_centre_mass=2000.0)


# ------------------------------------------------------------------------------- statics
@pytest.mark.parametrize("name", ["bogie", "quarter_flexible", "quarter_rigid"])
def test_static_equilibrium_no_drop(name):
    """With Fz = static loads the accelerations vanish: no drop transient.

    Tolerance 1e-9 g: the equilibrium is solved directly; residuals are rounding of
    K q with |K| ~ 1e9 N/m and |q| ~ 0.35 m against loads ~ 1e5 N (~1e-11 relative).
    """
    veh = all_models()[name]
    rng = np.random.default_rng(RNG_SEED)
    z0 = rng.uniform(-2e-3, 0.0, veh.n_wheels)       # deflected track, all wheels different
    st = veh.static_state(z0)
    acc = veh.accelerations(st.q, np.zeros(veh.n_dofs), st.Fz)
    assert np.max(np.abs(acc)) < 1e-9 * GRAVITY
    np.testing.assert_allclose(veh.wheel_z(st.q), z0, rtol=0, atol=1e-14)
    # and it stays there: 1 s of exact stepping with the static loads held
    stepper = VehicleStepper(veh, 1e-3, q0=st.q, Fz0=st.Fz)
    for _ in range(1000):
        stepper.step()
    np.testing.assert_allclose(stepper.wheel_z, z0, rtol=0, atol=1e-12)


def test_bogie_static_loads():
    """Total wheel load = 2 x axle_load for any wheel positions; axle_load/2 per wheel
    unless the wheel positions twist the bogie (it is statically indeterminate once)."""
    p = BogieParams()
    veh = bogie(p)
    # wheel positions on a plane (bounce + pitch + cross-level, no twist)
    x = veh.wheel_offsets
    y = np.array([p.b0, -p.b0, p.b0, -p.b0])
    plane = -1.0e-3 + 0.2e-3 * x + 0.4e-3 * y
    st = veh.static_state(plane)
    np.testing.assert_allclose(st.Fz, p.axle_load / 2, rtol=1e-12)
    # twisted: cross-level 3 mm at the front, 0.2 mm at the rear
    twisted = np.array([1.0e-3, -2.0e-3, 0.5e-3, 0.3e-3])
    st = veh.static_state(twisted)
    np.testing.assert_allclose(st.Fz.sum(), 2 * p.axle_load, rtol=1e-12)
    # the twist loads one diagonal (wheels 1 and 4) and unloads the other
    assert st.Fz[0] > p.axle_load / 2 and st.Fz[3] > p.axle_load / 2
    np.testing.assert_allclose(st.Fz[0] - st.Fz[1], st.Fz[3] - st.Fz[2], rtol=1e-9)


def test_rigid_quarter_static_state_closed_form():
    """The static state given in vehicle.quarter's docstring (for third-party FMUs)."""
    p = QuarterParams(flexible=False)
    z0 = np.array([-0.8e-3, -1.3e-3])
    st = rigid_quarter().static_state(z0)
    z_w = z0.mean()
    phi_w = (z0[0] - z0[1]) / (2 * p.b0)
    expected = [z_w - p.sprung_mass * GRAVITY / (2 * p.k1), phi_w, z_w, phi_w]
    np.testing.assert_allclose(st.q, expected, rtol=1e-12, atol=1e-16)
    np.testing.assert_allclose(st.Fz, p.axle_load / 2, rtol=1e-12)
    assert p.sprung_mass == pytest.approx(18500.0, rel=1e-12)   # documented default


def test_rigid_quarter_equations_as_documented():
    """``quarter_vehicle(flexible=False)`` implements exactly the docstring equations.

    The right-hand side is re-coded here from the docstring; random states and
    forces must give the same accelerations (to rounding, 1e-12 relative).
    """
    p = QuarterParams(flexible=False)
    g, m_s, m_w = GRAVITY, p.sprung_mass, p.wheelset_mass
    J_s, J_w, k1, c1, b0, b1 = (p.sprung_roll_inertia, p.wheelset_roll_inertia, p.k1, p.c1,
                                p.b0, p.b1)

    def documented(q, v, F):
        z_s, phi_s, z_w, phi_w = q
        dz_s, dphi_s, dz_w, dphi_w = v
        d_L = (z_s + b1 * phi_s) - (z_w + b1 * phi_w)
        d_R = (z_s - b1 * phi_s) - (z_w - b1 * phi_w)
        dd_L = (dz_s + b1 * dphi_s) - (dz_w + b1 * dphi_w)
        dd_R = (dz_s - b1 * dphi_s) - (dz_w - b1 * dphi_w)
        P_L, P_R = k1 * d_L + c1 * dd_L, k1 * d_R + c1 * dd_R
        F_L, F_R = F
        return np.array([(-(P_L + P_R) - m_s * g) / m_s,
                         -b1 * (P_L - P_R) / J_s,
                         ((P_L + P_R) - m_w * g + F_L + F_R) / m_w,
                         (b1 * (P_L - P_R) + b0 * (F_L - F_R)) / J_w])

    veh = rigid_quarter()
    rng = np.random.default_rng(RNG_SEED)
    for _ in range(5):
        q = rng.normal(scale=1e-3, size=4)
        v = rng.normal(scale=1e-2, size=4)
        F = rng.uniform(5e4, 1.5e5, size=2)
        expected = documented(q, v, F)
        np.testing.assert_allclose(veh.accelerations(q, v, F), expected,
                                   rtol=1e-12, atol=1e-12 * np.abs(expected).max())
        np.testing.assert_allclose(veh.wheel_z(q), [q[2] + b0 * q[3], q[2] - b0 * q[3]], rtol=1e-15)


# ------------------------------------------------------------------- modal properties
def test_bounce_pitch_eigenfrequencies_match_analytic():
    """Frame on its primary suspension, wheelsets and car body held fixed: the
    undamped eigenfrequencies include the analytic bounce and pitch values.  The
    dofs are uncoupled, so agreement is to rounding (1e-10)."""
    frame = bogie().constrained(FRAME_HELD)
    f = frame.natural_frequencies()
    f_bounce, f_pitch = bounce_pitch_frequencies()
    assert np.min(np.abs(f - f_bounce)) < 1e-10 * f_bounce
    assert np.min(np.abs(f - f_pitch)) < 1e-10 * f_pitch
    assert 5.0 < f_bounce < 12.0 and 5.0 < f_pitch < 15.0   # plausible bogie-frame range


def _zero_crossing_frequency(t, s):
    """Frequency from the mean spacing of upward zero crossings (linear interpolation)."""
    i = np.nonzero((s[:-1] < 0) & (s[1:] >= 0))[0]
    tc = t[i] - s[i] * (t[i + 1] - t[i]) / (s[i + 1] - s[i])
    return (len(tc) - 1) / (tc[-1] - tc[0])


@pytest.mark.parametrize("dof, which", [("frame_z", 0), ("frame_pitch", 1)])
def test_bounce_pitch_time_simulation_matches_analytic(dof, which):
    """Free vibration (undamped, wheelsets and car body held) simulated with the exact
    stepper; the frequency from upward zero crossings matches the analytic value.

    With h = 1 ms (omega h < 0.07) linear interpolation of a sine at its zero
    crossing is accurate to O((omega h)^3 / 12) ~ 3e-5 of a step per crossing, and
    averaging over ~20 periods leaves a frequency error far below the 1e-5 tolerance.
    """
    p = dataclasses.replace(BogieParams(), c1=0.0, c2=0.0)
    frame = bogie(p).constrained(FRAME_HELD)
    q_static = np.linalg.solve(frame.K, frame.f_g)   # all wheels held: K is regular
    q0 = q_static.copy()
    q0[frame.dof(dof)] += 1e-3
    h = 1e-3
    stepper = VehicleStepper(frame, h, q0=q0)
    n = 2000
    s = np.empty(n + 1)
    s[0] = q0[frame.dof(dof)] - q_static[frame.dof(dof)]
    for k in range(n):
        stepper.step()
        s[k + 1] = stepper.q[frame.dof(dof)] - q_static[frame.dof(dof)]
    f_sim = _zero_crossing_frequency(h * np.arange(n + 1), s)
    f_ref = bounce_pitch_frequencies(p)[which]
    assert abs(f_sim - f_ref) < 1e-5 * f_ref


def test_flexible_wheelset_bending_mode():
    """The quarter vehicle's bending mode: 80 Hz free-free, raised by the primary
    springs at the journals.  Rayleigh quotient with the free-free shape:
    omega^2 = (k_b + 2 k1) / m_b (journals move with amplitude 1); the remaining
    coupling to the low-frequency modes (6-10 Hz) is second order in 2 k1 / k_b
    (~2e-3), i.e. ~1e-6, hence the 1e-5 tolerance."""
    p = QuarterParams()
    veh = quarter_vehicle(p)
    m_b = p.bending_modal_mass
    k_b = m_b * (2 * np.pi * p.bending_frequency) ** 2
    f_rayleigh = np.sqrt((k_b + 2 * p.k1) / m_b) / (2 * np.pi)
    lam, modes = np.linalg.eig(np.linalg.solve(veh.M, veh.K))
    f = np.sqrt(np.abs(lam.real)) / (2 * np.pi)
    j = np.argmin(np.abs(f - p.bending_frequency))
    assert abs(f[j] - f_rayleigh) < 1e-5 * f_rayleigh
    assert abs(f[j] - 80.0) < 0.01 * 80.0
    # mode shape: wheels and axle centre move in antiphase
    mode = modes[:, j].real
    wheel = veh.W @ mode
    psi_c = -(p.wheelset_mass - p.axle_centre_mass) / p.axle_centre_mass
    centre = mode[veh.dof("ws_z")] + psi_c * mode[veh.dof("ws_bending")]
    assert np.all(wheel * centre < 0)
    # the rigid quarter has no mode near 80 Hz (its highest is the wheelset roll, < 20 Hz)
    assert rigid_quarter().natural_frequencies().max() < 20.0


def test_flexible_wheelset_mass_properties():
    """The bending mode is mass-orthogonal to bounce: gravity does not load it, and
    the total weight is the axle load."""
    p = QuarterParams()
    veh = quarter_vehicle(p)
    assert veh.f_g[veh.dof("ws_bending")] == 0.0
    np.testing.assert_allclose(-veh.f_g.sum(), p.axle_load, rtol=1e-12)


# ---------------------------------------------------------------------- time stepping
def _reference(veh, y0, h, forces, hold):
    """RK45 reference of the same ODE, integrated step by step with tight tolerances."""
    A, Bu, g = veh.first_order()
    y = y0.copy()
    out = []
    for k in range(len(forces) - 1):
        if hold == "zoh":
            F0 = F1 = forces[k]
        else:
            F0, F1 = forces[k], forces[k + 1]

        def rhs(t, y, F0=F0, F1=F1):
            return A @ y + Bu @ (F0 + (F1 - F0) * t / h) + g

        y = solve_ivp(rhs, (0.0, h), y, method="RK45", rtol=1e-11, atol=1e-14).y[:, -1]
        out.append(y)
    return np.array(out)


@pytest.mark.parametrize("hold", ["zoh", "foh"])
@pytest.mark.parametrize("name", ["bogie", "quarter_flexible"])
def test_exact_step_matches_rk45(name, hold):
    """Exact discretisation vs a tight RK45 solution of the same ODE with the same
    (piecewise constant / piecewise linear) forces.  RK45 with rtol 1e-11 is accurate
    to ~1e-10 of the response, so 1e-8 of the response range is a safe bound for the
    difference (it would be ~1e-2 for a first-order scheme at this step)."""
    veh = all_models()[name]
    st = veh.static_state(np.zeros(veh.n_wheels))
    rng = np.random.default_rng(RNG_SEED)
    h, n = 2e-3, 40
    forces = st.Fz + rng.normal(scale=2e4, size=(n + 1, veh.n_wheels))
    stepper = VehicleStepper(veh, h, hold=hold, q0=st.q, Fz0=forces[0])
    got = []
    for k in range(n):
        stepper.step(forces[k] if hold == "zoh" else forces[k + 1])
        got.append(stepper.get_state()[:2 * veh.n_dofs])
    got = np.array(got)
    ref = _reference(veh, np.concatenate([st.q, np.zeros(veh.n_dofs)]), h, forces, hold)
    scale = np.ptp(ref, axis=0) + 1e-12
    assert np.max(np.abs(got - ref) / scale) < 1e-8
    assert stepper.steps == n


def test_zoh_is_exact_for_constant_input():
    """For a constant force, one step of 2h equals two steps of h (exactness: no
    truncation error to accumulate); 1e-12 relative covers expm rounding."""
    veh = bogie()
    st = veh.static_state(np.zeros(4))
    F = st.Fz + np.array([3e4, -1e4, 0.0, 5e3])
    one = VehicleStepper(veh, 2e-3, q0=st.q)
    two = VehicleStepper(veh, 1e-3, q0=st.q)
    for _ in range(25):
        one.step(F)
        two.step(F)
        two.step(F)
    scale = np.abs(one.get_state()[:18] - np.concatenate([st.q, np.zeros(9)])).max()
    np.testing.assert_allclose(one.get_state()[:18], two.get_state()[:18], rtol=0, atol=1e-12 * scale)


def test_stepper_state_round_trip_is_bit_identical():
    veh = quarter_vehicle()
    st = veh.static_state(np.array([-1e-3, -0.5e-3]))
    stepper = VehicleStepper(veh, 1e-4, q0=st.q, Fz0=st.Fz)
    rng = np.random.default_rng(RNG_SEED)
    forces = st.Fz + rng.normal(scale=1e4, size=(60, 2))
    for F in forces[:20]:
        stepper.step(F)
    saved = stepper.get_state()
    for F in forces[20:]:
        stepper.step(F)
    first = stepper.get_state()
    stepper.set_step(2e-4)          # changing and restoring h must not matter
    stepper.set_step(1e-4)
    stepper.set_state(saved)
    for F in forces[20:]:
        stepper.step(F)
    assert np.array_equal(stepper.get_state(), first)
    assert stepper.steps == 60


def test_step_size_change_keeps_state():
    """Re-discretising keeps the state; the response is the same as a stepper built
    for the new step size (within expm rounding)."""
    veh = bogie()
    st = veh.static_state(np.zeros(4))
    F = st.Fz + np.array([1e4, 0, 0, 0])
    a = VehicleStepper(veh, 1e-3, q0=st.q)
    a.step(F)
    b = VehicleStepper(veh, 5e-4, q0=a.q.copy(), v0=a.v.copy())
    a.set_step(5e-4)
    for _ in range(10):
        a.step(F)
        b.step(F)
    np.testing.assert_allclose(a.wheel_z, b.wheel_z, rtol=1e-12, atol=1e-18)
