"""The track unit's co-simulation step in compiled code, for a caller that is not Python.

A step of the track FMU through pythonfmu enters Python three times (``fmi2SetReal`` of the
wheel inputs, ``fmi2DoStep``, ``fmi2GetReal`` of the forces): ~90 us a step around a ~120 us
kernel on the 64-sleeper panel (measured 2026-11-26, benchmarks/RESULTS.md "Session 14"). The
FMU's C shim (``fmus/shim``) can instead copy the ports and call a compiled step itself. This
module is that step: :func:`unit_step` does what ``fmus.track_fmu.Track.do_step`` and
:meth:`track.cosim.TrackCosim.do_step` do in the common case — the same compiled kernel on the
same state, the same outputs, the same record rows, so the numbers are the same to the last
bit — and hands everything else back to Python *before changing anything*:

* a step size other than the engine's, a non-finite input, a wheel off the panel (Python
  reports them);
* a failing step (no convergence) or a diverged force (Python repeats the step, which fails
  the same way, and reports it);
* a record row beyond the reserved rows.

:class:`UnitSteps` holds the arguments (from an :class:`~track.fused.EngineBuffers`: the
compiled step's data and two state buffers), copies the engine's state in
(:meth:`UnitSteps.read_engine`) and writes the steps' state back (:meth:`UnitSteps.write_engine`),
so the :class:`~track.cosim.TrackCosim` is what the Python path would have left whenever
Python looks at it. :func:`track.unit_cfunc.unit_step_address` is the C entry point.
"""
from __future__ import annotations

import numpy as np

from .ballast import DAMPING_ONSET
from .fused import EngineBuffers, _call_kernel, _track_outputs
from .kernel import C_MAXPASS, C_NEWTON, C_PASSES, C_SOLVES, OK, _njit, record_row

UNIT_TOOK, UNIT_PYTHON = 0, 1   # unit_step's answers: done; Python takes it (the shim's 2, "load data first",
                                # is not used: the kernel loads a rail element's data itself)
# the integer state ``ist``: state buffer, track steps, record rows written / reserved, record every,
# extrapolated force (0/1), steps since the last write-back, inputs at the step's start (0/1: extrapolated),
# sensor values not yet evaluated at the current state (0/1)
I_C, I_K, I_RECN, I_RECCAP, I_EVERY, I_EXTRAP, I_STEPS, I_START, I_STALE = range(9)
# the float settings ``fst``: the engine's step [s], its tolerance, its time origin [s], the panel's ends [m],
# the speed the inputs are extrapolated with [m/s]
F_H, F_RTOL, F_T0, F_LO, F_HI, F_SPEED = range(6)
OUTPUTS = ("Fz", "Fz_coupling", "Fz_rail", "Fz_nose", "rail_z")   # the rows of ``outbuf``, m values each


@_njit
def unit_step(t, h, inp, ist, fst, P, Q, V, A, F, Fc, out, trk, limit, rec, tot, outbuf):
    """One communication step ``[t, t + h]`` of the track unit from its inputs ``inp`` = [x | z | vz]
    (m each; end-of-step values, or start-of-step values extrapolated with the engine's speed and vz
    when ``ist[I_START]``) [m, m, m/s].

    Returns :data:`UNIT_TOOK` (state buffer ``ist[I_C]`` and ``outbuf`` hold the step's end) or
    :data:`UNIT_PYTHON` (let the Python path take this step; nothing of the state changed, but the
    element data of the wheels' elements may have been loaded, as that step would).
    The other arguments: see :class:`UnitSteps`.
    """
    hh = fst[F_H]
    if not h > 0.0 or abs(h - hh) > fst[F_RTOL] * hh:
        return UNIT_PYTHON
    m = limit.size
    for i in range(3 * m):
        if not inp[i] - inp[i] == 0.0:   # NaN or infinite
            return UNIT_PYTHON
    for i in range(m):
        if not (fst[F_LO] <= inp[i] and inp[i] <= fst[F_HI]):
            return UNIT_PYTHON
    every, k1 = ist[I_EVERY], ist[I_K] + 1
    if every > 0 and k1 % every == 0 and ist[I_RECN] >= ist[I_RECCAP]:
        return UNIT_PYTHON
    zoff, xw, zc = trk[0], trk[7], trk[8]
    if ist[I_START] != 0:   # start-of-step inputs, extrapolated over the step as TrackCosim.do_step does
        v = fst[F_SPEED]
        for i in range(m):
            xw[i] = inp[i] + v * hh
            zc[i] = (inp[m + i] + inp[2 * m + i] * hh) + zoff[i]
    else:
        for i in range(m):
            xw[i] = inp[i]
            zc[i] = inp[m + i] + zoff[i]
    cnt = P[1]
    cnt[:] = 0
    c = ist[I_C]
    status, change = _call_kernel(P, Q, V, A, F, Fc, c, xw, zc, out)
    if status != OK:
        return UNIT_PYTHON
    for i in range(m):
        if not out[i, 0] < limit[i]:   # also NaN: Python repeats the step and reports the divergence
            return UNIT_PYTHON
    tot[0] += cnt[C_SOLVES]
    tot[1] += cnt[C_NEWTON]
    tot[2] += cnt[C_PASSES]
    tot[3] = max(tot[3], cnt[C_MAXPASS])
    tot[4] += 1
    c = 1 - c
    ist[I_C] = c
    ist[I_K] = k1
    ist[I_STEPS] += 1
    _track_outputs(out, trk, limit, ist[I_EXTRAP] != 0)
    if every > 0 and k1 % every == 0:
        record_row(ist[I_RECN], fst[F_T0] + k1 * hh, xw, trk[2], trk[5], Q[c], V[c], A[c],
                   rec[0], rec[1], rec[2], rec[3], rec[4], rec[5], rec[6], rec[7], rec[8], rec[9])
        ist[I_RECN] += 1
    ist[I_STALE] = 1
    Fz, Fz_cpl, parts, rail_w = trk[2], trk[4], trk[5], trk[6]
    for i in range(m):
        outbuf[i] = Fz[i]
        outbuf[m + i] = Fz_cpl[i]
        outbuf[2 * m + i] = parts[i, 0]
        outbuf[3 * m + i] = parts[i, 1]
        outbuf[4 * m + i] = rail_w[i]
    return UNIT_TOOK


@_njit
def sensor_read(q, v, a, cols_q, cols_a, dof, k, c, gap, area, C, x, values):
    """Sensor values ``values = C [q[cols_q] | a[cols_a] | p]`` at the state q [m], v [m/s], a [m/s2], with p
    the ballast pressures [Pa] of the bushings ``dof`` (stiffness k, damping c, gap, area: the law of
    ``track.ballast.Ballast.pressure``, operation for operation); ``x`` the gathered entries (scratch).

    The sums run in index order: the FMU's sensor outputs, read in Python (``fmus.track_fmu.SensorReader``)
    or by its shim (:func:`unit_sensors`), are this function's values either way.
    """
    nq, na = cols_q.size, cols_a.size
    for i in range(nq):
        x[i] = q[cols_q[i]]
    for i in range(na):
        x[nq + i] = a[cols_a[i]]
    for j in range(dof.size):
        delta = -q[dof[j]] - gap[j]
        f = 0.0
        if delta > 0.0:
            s = delta / DAMPING_ONSET
            if s > 1.0:
                s = 1.0
            f = k[j] * delta - c[j] * v[dof[j]] * s
            if not f >= 0.0:
                f = 0.0
        x[nq + na + j] = f / area[j]
    for r in range(values.size):
        acc = 0.0
        for i in range(x.size):
            acc += C[r, i] * x[i]
        values[r] = acc


@_njit
def unit_sensors(ist, Q, V, A, sens, outbuf, m):
    """The sensor outputs ``outbuf[5 m:]`` at the current state buffer, when not evaluated since the last step
    (``sens``: :func:`sensor_read`'s cols_q, cols_a, dof, k, c, gap, area, C, x). Returns 0."""
    if ist[I_STALE] != 0:
        c = ist[I_C]
        sensor_read(Q[c], V[c], A[c], sens[0], sens[1], sens[2], sens[3], sens[4], sens[5], sens[6], sens[7],
                    sens[8], outbuf[5 * m:])
        ist[I_STALE] = 0
    return 0


NO_SENSORS = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0), np.zeros(0),
              np.zeros(0), np.zeros(0), np.zeros((0, 0)), np.zeros(0))   # sensor_read's arrays for none


class UnitSteps(EngineBuffers):
    """Compiled steps of a :class:`~track.cosim.TrackCosim` as a unit with wheel inputs (the track FMU).

    Parameters
    ----------
    engine : TrackCosim
        Initialized, with the compiled step, and steppable outside Python
        (:func:`track.fused.fused_unavailable` with ``extrapolated_inputs`` is None).
    inp : float64[3 m]
        The unit's input buffer ``[x | z | vz]`` (the caller's: the FMU's input arrays are views of it).
    lo, hi : float
        The panel's first and last sleeper's x [m] (inputs outside: Python reports them).
    rtol : float
        Tolerance on the step size against the engine's [-].
    sensors : tuple
        :func:`sensor_read`'s arrays (cols_q, cols_a, dof, k, c, gap, area, C, x) of the unit's sensor
        outputs, or :data:`NO_SENSORS`.

    Attributes
    ----------
    ist, fst : the integer state and float settings (``I_*``, ``F_*``).
    outbuf : float64[5 m + n_sensors]   the outputs of the last step, rows :data:`OUTPUTS`, then the
        sensor outputs (:func:`unit_sensors`, on demand).
    """

    def __init__(self, engine, inp: np.ndarray, lo: float, hi: float, rtol: float, sensors: tuple = NO_SENSORS):
        super().__init__(engine, extrapolated_inputs=True)
        if inp.dtype != np.float64 or inp.shape != (3 * engine.n,) or not inp.flags.c_contiguous:
            raise ValueError(f"UnitSteps: the input buffer must be float64[{3 * engine.n}], contiguous")
        self.inp = inp
        self.ist = np.zeros(9, np.int64)
        self.ist[I_START] = int(engine.extrapolate)
        self.fst = np.array([engine.h, rtol, 0.0, lo, hi, engine.speed])
        self.sensors = tuple(sensors)
        self.outbuf = np.zeros(5 * engine.n + self.sensors[7].shape[0])

    def arguments(self) -> tuple:
        """:func:`unit_step`'s arguments after ``t, h`` (current: the record's arrays may move)."""
        e = self.engine
        return (self.inp, self.ist, self.fst, self.P, self.Q, self.V, self.A, self.F, self.Fc, self.out,
                self.trk, e._limit, e.record._args, self.tot, self.outbuf, self.sensors)

    def read_engine(self, reserve: int = 4096) -> None:
        """The engine's state into buffer 0 (the steps go on from it); ``reserve`` record rows more."""
        e, it = self.engine, self.engine.integ
        self._read_state()
        if e.record_every:
            need = len(e.record) + reserve // e.record_every + 1
            if need > e.record.capacity:
                e.record.reserve(max(need, 2 * e.record.capacity))   # doubling: copies stay linear in rows
        ist = self.ist
        ist[I_C], ist[I_K], ist[I_RECN], ist[I_STEPS], ist[I_STALE] = 0, it.k, len(e.record), 0, 1
        ist[I_RECCAP], ist[I_EVERY], ist[I_EXTRAP] = e.record.capacity, e.record_every, int(e.extrapolate_force)
        self.fst[F_T0] = it.t0
        self.tot[:] = 0

    def write_engine(self) -> int:
        """The steps' state, outputs, counters and record rows into the engine; returns the steps taken."""
        e, it, ist = self.engine, self.engine.integ, self.ist
        steps = int(ist[I_STEPS])
        self._write_back(int(ist[I_C]), steps)
        it.k = int(ist[I_K])
        e.record.n = int(ist[I_RECN])
        ist[I_STEPS] = 0
        return steps


__all__ = ["NO_SENSORS", "OUTPUTS", "UNIT_PYTHON", "UNIT_TOOK", "UnitSteps", "sensor_read",
           "unit_sensors", "unit_step"]
