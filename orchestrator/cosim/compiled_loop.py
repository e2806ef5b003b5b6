"""The in-process Gauss–Seidel loop in compiled blocks of steps (``track.fused``).

The master steps the units one call at a time (:func:`orchestrator.cosim.master._step_loop`),
which costs about as much Python per step as the compiled track step itself takes. When both units are
ours and in-process, the algorithm is Gauss–Seidel and the track's step is the compiled one
without Python-side inputs (``track.fused.fused_unavailable``), the steps after the first (which
initializes the track) run in :class:`track.fused.CoupledSteps` instead, in blocks between
progress reports; the units' objects are left as the stepped loop leaves them. The results are
the same (tests/test_fused.py); ``TURNOUT_COMPILED_LOOP=0`` steps one call at a time.
"""
from __future__ import annotations

import os
from typing import Callable

from orchestrator.cosim.units import InProcessTrack, InProcessVehicle

COMPILED_LOOP_ENV = "TURNOUT_COMPILED_LOOP"   # "0": the master steps the units one call at a time
PROGRESS_STEPS = 500   # steps between progress reports (rounded up to output steps)


def compiled_loop(run) -> "CompiledLoop | None":
    """A :class:`CompiledLoop` for ``run`` (a ``master._Run`` after its first step), or None where
    the units cannot run in one (see the module docstring)."""
    if os.environ.get(COMPILED_LOOP_ENV, "").strip() == "0" or run.algorithm != "gauss-seidel":
        return None
    veh, trk = run.vehicle, run.track
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


__all__ = ["COMPILED_LOOP_ENV", "CompiledLoop", "compiled_loop"]
