"""Many co-simulation steps in one compiled call: the track's compiled step coupled with a linear vehicle.

With the compiled track step (:mod:`track.kernel`) a step of the default scenario costs ~90-150 us in
the kernel, and as much again in Python around it when the master steps the units one call at a time:
the master's loop, the vehicle stepper's two products, :meth:`track.cosim.TrackCosim.do_step`,
:meth:`track.kernel.CompiledContacts.step` and the record row (measured 2026-11-25 on the default
scenario: 80 us a step without a state record, 130-140 us with the sensor columns a diagnosis
records). Here the same Gauss–Seidel step (vehicle first with the force of the last step, then the
track with the vehicle's end-of-step wheel motion, ``orchestrator.cosim.algorithms``) runs as a loop
in one ``@njit`` function, :func:`gauss_seidel_steps`, that leaves to Python only what it cannot do:
errors, and progress reports between blocks of steps (the kernel loads a rail element's data
itself when a wheel enters it).

The vehicle comes in as arrays, so this module knows nothing of the vehicle package: the exact
discretisation of a linear vehicle with the force held over the step (``vehicle.stepper``,
``"zoh"``): ``y_{k+1} = G [y_k | Fz_k | 1]`` and the wheels' ``[z | vz] = Y y + offset``, with
the wheel coordinates ``x = a_i + (x0 + v t)``. Every operation is the one the stepped path does,
in the same order (the track's step the same compiled function; the vehicle's products ``dgemv``
calls, numba's through scipy's BLAS where numpy uses its own), so both paths give the same numbers:
to the last bit here, to round-off wherever the two BLAS builds round differently (tests/test_fused.py).

:class:`CoupledSteps` holds the arguments (the track's from its
:class:`~track.kernel.CompiledContacts`, the vehicle's buffers, which it updates in place) and
writes the state back into the :class:`~track.cosim.TrackCosim` after every call, so the objects
are as the stepped path leaves them whenever Python sees them.
"""
from __future__ import annotations

import numpy as np

from .kernel import (
    C_MAXPASS,
    C_NEWTON,
    C_PASSES,
    C_SOLVES,
    CONTACT_STEP_PARAMETERS,
    OK,
    P_CH,
    _njit,
    _STEP_SLOTS,
    contact_step,
    record_row,
)

DONE, DIVERGED = 10, 11   # statuses of gauss_seidel_steps beyond the kernel's (OK is never returned)
# contact_step's arguments without the per-step slots (the state, the wheels, the outputs), in its order
FIXED_PARAMETERS = ("par", "cnt", "fgrav", "Kp", "Ki", "Kx", "Cp", "Ci", "Cx", "D", "bk", "bc", "bgap", "Zb",
                    "have", "perm", "Lp", "Li", "Lx", "dd", "wside", "ts", "etab", "ec", "es", "ent",
                    "erow", "eahead", "eR", "rload", "rbody", "bgd", "bnr", "Zr", "zhave", "zwork",
                    "T", "gd", "nr", "R", "zrow", "E", "fresh", "W", "surf", "wts", "work", "iwork", "yw", "tg",
                    "tz", "tc", "chw")
_SLOT_NAMES = ("q0", "v0", "acc0", "F0", "Fc0", "x", "zw", "q1", "v1", "acc1", "F1", "Fc1", "out")


@_njit
def _call_kernel(P, Q, V, A, F, Fc, c, x, zc, out):
    """contact_step from state buffer ``c`` into buffer ``1 - c`` (P: the fixed arguments)."""
    n = 1 - c
    return contact_step(P[0], P[1], Q[c], V[c], A[c], F[c], Fc[c], P[2],
                        P[3], P[4], P[5], P[6], P[7], P[8], P[9], P[10], P[11], P[12], P[13], P[14],
                        P[15], P[16], P[17], P[18], P[19], x, zc,
                        P[20], P[21], P[22], P[23], P[24], P[25],
                        P[26], P[27], P[28], P[29], P[30], P[31], P[32], P[33], P[34], P[35],
                        P[36], P[37], P[38], P[39], P[40], P[41], P[42], Q[n], V[n], A[n], F[n], Fc[n], out,
                        P[43], P[44], P[45], P[46], P[47], P[48], P[49], P[50], P[51], P[52])


@_njit
def _vehicle_step(veh, Fz_in):
    """One exact step of the linear vehicle with ``Fz_in`` held (``vehicle.stepper.VehicleStepper.step``)."""
    G, z, y, u, ynew, Y, wheel, woff = veh
    for i in range(u.size):
        u[i] = Fz_in[i]
    np.dot(G, z, ynew)
    for i in range(y.size):
        y[i] = ynew[i]
    np.dot(Y, y, wheel)
    for i in range(wheel.size):
        wheel[i] += woff[i]


@_njit
def _wheels_in(base, xoff, wheel, zoff, xw, zc):
    """The track's wheel inputs: ``x = xoff + base`` [m], ``z`` (the vehicle's) + the static offsets [m]."""
    for i in range(xw.size):
        xw[i] = xoff[i] + base
        zc[i] = wheel[i] + zoff[i]


@_njit
def _track_outputs(out, trk, limit, extrap_force):
    """The track unit's outputs from the kernel's ``out`` (as ``TrackCosim.do_step``), the vehicle's next
    input; False when a force is at or above its limit (or NaN)."""
    _, Fz_in, Fz, Fz_last, Fz_cpl, parts, rail_w, _, _ = trk
    ok = True
    for i in range(Fz.size):
        Fz[i] = out[i, 0]
        parts[i, 0] = out[i, 1]
        parts[i, 1] = out[i, 2]
        rail_w[i] = out[i, 3]
        Fz_cpl[i] = 1.5 * Fz[i] - 0.5 * Fz_last[i] if extrap_force else Fz[i]
        Fz_last[i] = Fz[i]
        Fz_in[i] = Fz_cpl[i]
        if not Fz[i] < limit[i]:   # also NaN
            ok = False
    return ok


@_njit
def _signal_row(sig, j, t, xw, wheel, trk):
    """Row ``j`` of the master's signals at time ``t`` [s]: the wheels' x, z, vz and the track's outputs."""
    st, sx, sz, svz, sFz, sparts, srail = sig
    Fz, parts, rail_w = trk[2], trk[5], trk[6]
    m = xw.size
    st[j] = t
    for i in range(m):
        sx[j, i] = xw[i]
        sz[j, i] = wheel[i]
        svz[j, i] = wheel[m + i]
        sFz[j, i] = Fz[i]
        sparts[j, i, 0] = parts[i, 0]
        sparts[j, i, 1] = parts[i, 1]
        srail[j, i] = rail_w[i]


@_njit
def gauss_seidel_steps(k, k_end, t0, h, every, veh, xoff, x0, speed,
                       P, Q, V, A, F, Fc, c, out, trk, limit, extrap_force, k_track, t0_track, record_every,
                       rec, rec_n, sig, tot):
    """Communication steps ``k .. k_end - 1`` of the Gauss–Seidel master, vehicle and track.

    Parameters
    ----------
    k, k_end : int            first step and the step to stop before.
    t0, h : float             master's start time and step [s]; step k runs over [t0 + k h, t0 + (k+1) h].
    every : int               signals every this many steps (row ``(k+1) // every``).
    veh : tuple               (G, z, y, u, ynew, Y, wheel, woff): the vehicle's discrete system and buffers
                              (updated in place), ``z = [y | u | 1]``, ``wheel = [z_w | vz_w]``.
    xoff, x0, speed           wheel i at ``xoff[i] + (x0 + speed t)`` [m].
    P : tuple                 contact_step's fixed arguments (:data:`FIXED_PARAMETERS`).
    Q, V, A, F : (2, n), Fc : (2, m), c : int
                              the track state buffers; ``c`` the current one.
    out : (m, 4)              the kernel's outputs.
    trk : tuple               (zoff, Fz_in, Fz, Fz_last, Fz_cpl, parts, rail_w, xw, zc): the track
                              unit's wheel offsets and outputs (updated in place; ``Fz_in`` the
                              vehicle's next input).
    limit : (m,)              divergence limit of the contact forces [N].
    extrap_force : bool       offer ``1.5 Fz_k - 0.5 Fz_{k-1}`` to the vehicle.
    k_track, t0_track, record_every, rec, rec_n
                              the track's step counter and time origin, its record (every
                              ``record_every`` track steps; ``rec`` the row writer's arrays,
                              ``rec_n`` rows written; capacity reserved by the caller).
    sig : tuple               (t, x, z, vz, Fz, parts, rail_z) arrays of the master's signals.
    tot : int64[5]            counters, incremented: solves, Newton sweeps, passes, most passes, steps.

    Returns
    -------
    (status, k, c, k_track, rec_n, change)
        status DONE (k == k_end), DIVERGED
        (step k - 1 gave a force at or above ``limit``: the outputs hold it), or the kernel's failure
        (step k not taken; ``change`` its last force change [N]).
    """
    wheel, xw, zc = veh[6], trk[7], trk[8]
    cnt = P[1]
    while k < k_end:
        _vehicle_step(veh, trk[1])
        _wheels_in(x0 + speed * (t0 + k * h + h), xoff, wheel, trk[0], xw, zc)   # the vehicle's time after its step
        cnt[:] = 0
        status, change = _call_kernel(P, Q, V, A, F, Fc, c, xw, zc, out)
        tot[0] += cnt[C_SOLVES]
        tot[1] += cnt[C_NEWTON]
        if status != OK:
            return status, k, c, k_track, rec_n, change
        tot[2] += cnt[C_PASSES]
        tot[3] = max(tot[3], cnt[C_MAXPASS])
        tot[4] += 1
        c = 1 - c
        k_track += 1
        k += 1
        if not _track_outputs(out, trk, limit, extrap_force):
            return DIVERGED, k, c, k_track, rec_n, 0.0
        if record_every > 0 and k_track % record_every == 0:
            record_row(rec_n, t0_track + k_track * h, xw, trk[2], trk[5], Q[c], V[c], A[c],
                       rec[0], rec[1], rec[2], rec[3], rec[4], rec[5], rec[6], rec[7], rec[8], rec[9])
            rec_n += 1
        if k % every == 0:
            _signal_row(sig, k // every, t0 + k * h, xw, wheel, trk)
    return DONE, k, c, k_track, rec_n, 0.0


def fused_unavailable(engine, extrapolated_inputs: bool = False) -> str | None:
    """Why ``engine`` (a :class:`track.cosim.TrackCosim`) cannot be stepped by :class:`CoupledSteps`, or None;
    ``extrapolated_inputs``: a caller that extrapolates start-of-step inputs as the engine does
    (:class:`track.unit_step.UnitSteps`) can step an engine that takes them."""
    if engine._compiled is None:
        return "the numpy reference step"
    if engine._compiled._given:
        return "surface heights computed in Python"
    if engine.irregularities is not None:
        return "rail irregularities"
    if engine.extrapolate and not extrapolated_inputs:
        return "inputs at the step's start (extrapolated)"
    if engine.tables is not None and engine.contact.lateral_offset_table:
        return "a lateral offset table"
    return None


class EngineBuffers:
    """The compiled step's arguments for stepping a :class:`track.cosim.TrackCosim` (initialized, compiled
    step) outside it, and the state buffers the steps run in: :class:`CoupledSteps` (with a vehicle) and
    :class:`track.unit_step.UnitSteps` (the track FMU's compiled steps) build on it.

    ``P`` contact_step's fixed arguments; ``Q, V, A, F`` (2, n) and ``Fc`` (2, m): the two state
    buffers; ``out`` (m, 4) the kernel's outputs; ``trk`` the unit's wheel offsets and outputs
    (:func:`gauss_seidel_steps`); ``tot`` the work counters of the steps since the last write-back.
    """

    def __init__(self, engine, extrapolated_inputs: bool = False):
        why = fused_unavailable(engine, extrapolated_inputs)
        if why is not None or not engine.initialized:
            raise ValueError(f"{type(self).__name__}: {why or 'the track is not initialized'}")
        cc = engine._compiled
        slots = {i for s, w in zip(_STEP_SLOTS, (5, 2, 6)) for i in range(s, s + w)}
        names = tuple(p for i, p in enumerate(CONTACT_STEP_PARAMETERS) if i not in slots)
        if names != FIXED_PARAMETERS or tuple(CONTACT_STEP_PARAMETERS[i] for i in sorted(slots)) != _SLOT_NAMES:
            raise RuntimeError("track.kernel.contact_step's arguments changed: update track.fused")
        cc.par[P_CH] = engine.c_h
        if engine.tables is not None:
            cc.yw[:] = engine.lateral_offsets(np.zeros(engine.n))   # a constant offset (no table)
        self.engine, self.cc = engine, cc
        self.P = tuple(a for i, a in enumerate(cc._args) if i not in slots)
        n, m = engine.model.n, engine.n
        self.Q, self.V, self.A, self.F = (np.empty((2, n)) for _ in range(4))
        self.Fc = np.empty((2, m))
        self.out = np.empty((m, 4))
        self.trk = (np.array(engine.offset, dtype=float),) + tuple(np.empty(m) for _ in range(4)) + \
            (np.empty((m, 2)), np.empty(m), np.empty(m), np.empty(m))
        self.tot = np.zeros(5, np.int64)

    def _read_state(self) -> None:
        """Buffer 0, the last contact force (the coupling force's extrapolation) and the wheels' static
        offsets from the engine: the state the steps start from (an FMU state restored into the engine
        may have brought other offsets)."""
        e, it = self.engine, self.engine.integ
        m = e.n
        self.Q[0], self.V[0], self.A[0], self.F[0] = it.q, it.v, it.a, it.F
        self.Fc[0] = it.Fc if it.Fc.size == m else 0.0
        self.trk[3][:] = e._Fz_last
        self.trk[0][:] = e.offset

    def _write_back(self, c: int, steps: int) -> None:
        """The engine's and its integrator's state and counters as the stepped path leaves them."""
        e, it, tot = self.engine, self.engine.integ, self.tot
        if steps:
            it.q, it.v, it.a, it.F = self.Q[c].copy(), self.V[c].copy(), self.A[c].copy(), self.F[c].copy()
            it.Fc = self.Fc[c].copy()
            _, _, Fz, Fz_last, Fz_cpl, parts, rail_w, _, _ = self.trk
            e.Fz, e.parts, e.rail_w = Fz.copy(), parts.copy(), rail_w.copy()
            e.Fz_coupling, e._Fz_last = Fz_cpl.copy(), Fz_last.copy()
        cn = it.counters
        cn.solves += int(tot[0])
        cn.contact_newton += int(tot[1])
        cn.iterations += int(tot[2])
        cn.max_iterations = max(cn.max_iterations, int(tot[3]))
        cn.steps += int(tot[4])
        tot[:] = 0


class CoupledSteps(EngineBuffers):
    """Step a :class:`track.cosim.TrackCosim` (initialized, compiled step) with a linear vehicle.

    Parameters
    ----------
    engine : TrackCosim
    vehicle : tuple
        ``(G, z, y, u, ynew, Y, wheel, woff)`` of the vehicle's exact zoh discretisation, the
        arrays it steps in (see :func:`gauss_seidel_steps`); updated in place.
    xoff, x0, speed
        Wheel coordinates ``xoff[i] + (x0 + speed t)`` [m].
    """

    def __init__(self, engine, vehicle: tuple, xoff: np.ndarray, x0: float, speed: float):
        super().__init__(engine)
        self.veh = tuple(vehicle)
        self.xoff, self.x0, self.speed = np.ascontiguousarray(xoff, dtype=float), float(x0), float(speed)
        self.vehicle_steps = self.signal_steps = 0   # of the last run: vehicle steps taken, steps with signals

    def run(self, k: int, k_end: int, t0: float, h: float, every: int, Fz_in: np.ndarray, sig: tuple) -> tuple:
        """Steps ``k .. k_end - 1`` from the engine's state and the vehicle's input ``Fz_in`` [N].

        Writes the state back into the engine after the call, and raises as the stepped path does (:class:`track.dynamics.ConvergenceError`,
        :class:`track.cosim.DivergenceError`; then :attr:`vehicle_steps` and :attr:`signal_steps`
        say how far the vehicle and the signals got). Returns ``(k, Fz)``: the steps taken up to,
        the vehicle's next input [N] (a copy)."""
        e, it = self.engine, self.engine.integ
        c = 0
        self._read_state()
        fin = self.trk[1]
        fin[:] = Fz_in
        rec = e.record
        if e.record_every:
            rec.reserve(len(rec) + (k_end - k) // e.record_every + 1)
        k0_track, k_start = it.k, k
        self.tot[:] = 0
        self.vehicle_steps, self.signal_steps = 0, k
        status, k, c, k_track, rec_n, change = gauss_seidel_steps(
            k, k_end, t0, h, every, self.veh, self.xoff, self.x0, self.speed, self.P,
            self.Q, self.V, self.A, self.F, self.Fc, c, self.out, self.trk, e._limit, e.extrapolate_force,
            it.k, it.t0, e.record_every, rec._args, len(rec), sig, self.tot)
        it.k, rec.n = k_track, rec_n
        self._write_back(c, it.k - k0_track)
        # what the caller's vehicle and signals hold: a failed step had its vehicle part done, a
        # diverged one has no signal row (the stepped path raises before writing them)
        self.vehicle_steps = k - k_start + (status not in (DONE, DIVERGED))
        self.signal_steps = k - (status == DIVERGED)
        if status == DIVERGED:
            e.check_divergence()
        elif status != DONE:
            self.cc.raise_for(status, change)
        return k, fin.copy()


__all__ = ["CoupledSteps", "EngineBuffers", "fused_unavailable", "gauss_seidel_steps"]
