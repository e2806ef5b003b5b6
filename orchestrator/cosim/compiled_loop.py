"""The Gauss–Seidel master loop in compiled blocks of steps.

The master steps the units one call at a time (:func:`orchestrator.cosim.master._step_loop`),
which costs about as much Python per step as the compiled track step itself takes. After the first
step (which initializes the track), the steps run in compiled blocks between progress reports where
the units allow it, and the units' objects are left as the stepped loop leaves them:

* both units ours and in-process, the track's step the compiled one without Python-side inputs
  (``track.fused.fused_unavailable``): :class:`track.fused.CoupledSteps` steps both
  (:class:`CompiledLoop`; the same results, tests/test_fused.py);
* both units FMUs (ours or a third party's vehicle): :class:`FmuLoop`, a compiled loop that makes the
  stepped loop's fmi2 calls — set the vehicle's forces, step it, read its wheels, set the track's
  inputs, step it, read its outputs — with the same values in the same order, so the results are the
  same to the last bit; our FMUs then answer those calls in their C shim (``fmus.fast``), and a step
  costs no Python at all.

``TURNOUT_COMPILED_LOOP=0`` steps one call at a time.
"""
from __future__ import annotations

import ctypes
import os
from typing import Callable

import numpy as np

from orchestrator.cosim.units import CosimError, FmuTrack, FmuVehicle, InProcessTrack, InProcessVehicle

COMPILED_LOOP_ENV = "TURNOUT_COMPILED_LOOP"   # "0": the master steps the units one call at a time
PROGRESS_STEPS = 500   # steps between progress reports (rounded up to output steps)


def compiled_loop(run) -> "CompiledLoop | None":
    """A :class:`CompiledLoop` or :class:`FmuLoop` for ``run`` (a ``master._Run`` after its first step),
    or None where the units cannot run in one (see the module docstring)."""
    if os.environ.get(COMPILED_LOOP_ENV, "").strip() == "0" or run.algorithm != "gauss-seidel":
        return None
    veh, trk = run.vehicle, run.track
    if isinstance(veh, FmuVehicle) and isinstance(trk, FmuTrack):
        return FmuLoop(run)
    if not (isinstance(veh, InProcessVehicle) and isinstance(trk, InProcessTrack)) or veh.hold != "zoh":
        return None
    from track.fused import fused_unavailable
    if not trk.engine.initialized or fused_unavailable(trk.engine) is not None or veh.stepper.h != run.h:
        return None
    return CompiledLoop(run)


class CompiledLoop:
    """Blocks of Gauss–Seidel steps of an in-process run (:func:`compiled_loop` makes one)."""

    def __init__(self, run):
        from track.fused import CoupledSteps

        self._run = run
        veh = run.vehicle
        self.steps = CoupledSteps(run.track.engine, veh.stepper.discrete_system(), veh.model.wheel_offsets,
                                  veh.x0, veh.speed)

    def advance(self, k: int, Fz, signals, progress: Callable[[int, int], None] | None) -> None:
        """Steps ``k ..`` to the run's end from the vehicle's input ``Fz`` [N].

        ``signals`` (the master's ``_Signals``) gets its rows; ``progress(k, nsteps)`` is called
        at output steps between blocks. A unit's error propagates once the objects are updated."""
        run = self._run
        veh, every, nsteps = run.vehicle, run.every, run.nsteps
        block = nsteps if progress is None else -(-PROGRESS_STEPS // every) * every   # ends at output steps
        sig = (signals.t, signals.x, signals.z, signals.vz, signals.Fz, signals.parts, signals.rail_z)
        while k < nsteps:
            k_start = k
            try:
                k, Fz = self.steps.run(k, min(nsteps, (k // block + 1) * block), run.t0, run.h, every, Fz, sig)
            finally:
                self._after(k_start, signals)
            if progress is not None and k % every == 0:
                progress(k, nsteps)

    def _after(self, k_start: int, signals) -> None:
        """The vehicle unit and the signals as the stepped loop leaves them (also after an error)."""
        run, veh, st = self._run, self._run.vehicle, self.steps
        nv = st.vehicle_steps
        if nv:
            veh.advanced(nv, run.t0 + (k_start + nv - 1) * run.h + run.h)   # as the last step's t + h
        signals.done = max(signals.done, st.signal_steps // run.every + 1)


# the fmi2 functions the FMU loop calls, with plain C types (numba calls them through their addresses)
_SET_GET = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p)
_DO_STEP = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_int)
# where _fmu_steps stopped: done, or the call that returned an error status
DONE, VEHICLE_SET, VEHICLE_STEP, VEHICLE_GET, TRACK_SET, TRACK_STEP, TRACK_GET = range(7)


def _unit_step_py(fset, fstep, fget, c, vr_in, n_in, values_in, vr_out, n_out, values_out, t, h):
    """One unit's step as the stepped loop makes it: fmi2SetReal of its inputs, fmi2DoStep, fmi2GetReal of
    its outputs. Returns (0: done, or 1, 2, 3: the set, step or get that failed; its status)."""
    s = fset(c, vr_in, n_in, values_in.ctypes.data)
    if s > 1:
        return 1, s
    s = fstep(c, t, h, 1)
    if s > 1:
        return 2, s
    s = fget(c, vr_out, n_out, values_out.ctypes.data)
    if s > 1:
        return 3, s
    return 0, 0


def _fmu_steps_py(k, k_end, t0, h, every, vc, tc, vset, vstep, vget, tset, tstep, tget,
                  vr_force, force, vr_wheels, wheels, vr_inputs, inputs, vr_outputs, outputs,
                  Fs, zs, vzs, Fz, st, sx, sz, svz, sFz, sparts, srail):
    """Gauss–Seidel steps ``k .. k_end - 1`` over two FMUs: the calls and arithmetic of the stepped loop
    (``algorithms._gauss_seidel`` with ``FmuVehicle`` and ``FmuTrack``), in the same order.

    ``vc``, ``tc``: the instances; ``vset`` ... ``tget``: their fmi2SetReal / fmi2DoStep / fmi2GetReal;
    ``vr_*``: addresses of the ports' value references, with their value buffers (``force`` m,
    ``wheels`` 3 m: x | z | vz as the vehicle gives them, ``inputs`` 3 m, ``outputs`` 5 m: Fz_coupling,
    Fz, Fz_rail, Fz_nose, rail_z); ``Fs``, ``zs``, ``vzs`` the sign maps; ``Fz`` the vehicle's next input
    [N] (updated); ``st`` ... ``srail`` the master's signals, a row every ``every`` steps.

    Returns (where: DONE or the failed call, k: the steps done, status of the failed call).
    """
    m = Fz.size
    while k < k_end:
        t = t0 + k * h
        for i in range(m):
            force[i] = Fs[i] * Fz[i]
        failed, s = _unit_step(vset, vstep, vget, vc, vr_force, m, force, vr_wheels, 3 * m, wheels, t, h)
        if failed:
            return VEHICLE_SET + failed - 1, k, s
        for i in range(m):
            inputs[i] = wheels[i]
            inputs[m + i] = zs[i] * wheels[m + i]
            inputs[2 * m + i] = vzs[i] * wheels[2 * m + i]
        failed, s = _unit_step(tset, tstep, tget, tc, vr_inputs, 3 * m, inputs, vr_outputs, 5 * m, outputs, t, h)
        if failed:
            return TRACK_SET + failed - 1, k, s
        for i in range(m):
            Fz[i] = outputs[i]
        k += 1
        if k % every == 0:
            j = k // every
            st[j] = t0 + k * h
            for i in range(m):
                sx[j, i] = inputs[i]
                sz[j, i] = inputs[m + i]
                svz[j, i] = inputs[2 * m + i]
                sFz[j, i] = outputs[m + i]
                sparts[j, i, 0] = outputs[2 * m + i]
                sparts[j, i, 1] = outputs[3 * m + i]
                srail[j, i] = outputs[4 * m + i]
    return DONE, k, 0


try:
    import numba
    _unit_step = numba.njit(cache=True)(_unit_step_py)
    _fmu_steps = numba.njit(cache=True)(_fmu_steps_py)
except ImportError:   # numba is a dependency; without it the loop is Python (no faster than the stepped one)
    _unit_step, _fmu_steps = _unit_step_py, _fmu_steps_py


class FmuLoop:
    """Blocks of Gauss–Seidel steps over a vehicle FMU and our track FMU (:func:`compiled_loop`)."""

    def __init__(self, run):
        veh, trk = run.vehicle, run.track
        self._run = run
        self._vu, self._tu = veh.unit, trk.unit
        self._fns = (self._vu.function("fmi2SetReal", _SET_GET), self._vu.function("fmi2DoStep", _DO_STEP),
                     self._vu.function("fmi2GetReal", _SET_GET), self._tu.function("fmi2SetReal", _SET_GET),
                     self._tu.function("fmi2DoStep", _DO_STEP), self._tu.function("fmi2GetReal", _SET_GET))
        # the units' own ports and buffers: after a block they hold what the stepped loop's last calls left
        self._ports = (veh._F, veh._out, trk._in, trk._out)
        self._signs = tuple(np.ascontiguousarray(a, dtype=float) for a in (veh._Fs, veh._zs, veh._vzs))

    def advance(self, k: int, Fz, signals, progress: Callable[[int, int], None] | None) -> None:
        """Steps ``k ..`` to the run's end from the vehicle's input ``Fz`` [N]; ``signals`` gets its rows,
        ``progress(k, nsteps)`` is called at output steps between blocks; a unit's failure raises the
        stepped loop's error (:class:`orchestrator.cosim.units.CosimError`) with the rows before it kept."""
        run = self._run
        every, nsteps = run.every, run.nsteps
        block = nsteps if progress is None else -(-PROGRESS_STEPS // every) * every
        Fz = np.array(Fz, dtype=float)
        refs = [a for p in self._ports for a in (p.references, p.values)]
        sig = (signals.t, signals.x, signals.z, signals.vz, signals.Fz, signals.parts, signals.rail_z)
        while k < nsteps:
            end = min(nsteps, (k // block + 1) * block)
            where, k, status = _fmu_steps(k, end, run.t0, run.h, every, self._vu._c, self._tu._c, *self._fns,
                                          *refs, *self._signs, Fz, *sig)
            run.vehicle._last = run.track._last = None    # the units re-read their outputs when asked
            signals.done = max(signals.done, k // every + 1)
            if where != DONE:
                raise self._error(where, run.t0 + k * run.h, status)
            if progress is not None and k % every == 0:
                progress(k, nsteps)

    def _error(self, where: int, t: float, status: int) -> CosimError:
        """The stepped loop's error for the call ``where`` that returned ``status`` in the step at ``t`` [s]."""
        force, wheels, inputs, outputs = self._ports
        if where == VEHICLE_SET:
            return force.set_error(status)
        if where == VEHICLE_STEP:
            return self._vu.step_error(t, self._run.h, status)
        if where == VEHICLE_GET:
            return wheels.get_error(status)
        if where == TRACK_SET:
            return inputs.set_error(status)
        if where == TRACK_STEP:
            return self._tu.step_error(t, self._run.h, status)
        return outputs.get_error(status)


__all__ = ["COMPILED_LOOP_ENV", "CompiledLoop", "FmuLoop", "compiled_loop"]
