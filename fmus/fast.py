"""An FMU instance's fast path through the C shim (``fmus/shim/fmi2_python_shim.c``, its header).

With pythonfmu every fmi2 call enters Python: a co-simulation step of the track FMU costs three
entries (set the wheel inputs, doStep, get the forces), each a few microseconds, plus the slave's
Python around the compiled kernel (~90 us a step in all on the 64-sleeper panel, measured
2026-11-26). A slave that has a compiled step registers it here with the shim: then the shim
copies the per-step inputs and outputs itself and calls the compiled step in ``fmi2DoStep``,
entering Python only for what the compiled step hands back (its return value ≠ 0) and for every
other call — before which it calls :meth:`FastPath.sync`, so the slave's Python objects always hold
the state the steps reached. ``load`` makes the buffers current again before the next compiled step.

Nothing changes for a host: the same calls, the same values. Where the shim is not in the FMU
(a platform without it, see ``fmus.build.compile_shim``) or ``XPANEL_FMU_FAST=0`` is set, the slave
steps in Python as before.
"""
from __future__ import annotations

import ctypes
import logging
import os
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

FAST_ENV = "XPANEL_FMU_FAST"   # "0": no fast path (every call through Python)
_LOG = logging.getLogger(__name__)
_CALLBACK = ctypes.CFUNCTYPE(ctypes.c_int)


class _Spec(ctypes.Structure):
    """The shim's ``XpanelFast``, field by field."""
    _fields_ = [("ctx", ctypes.c_void_p), ("step", ctypes.c_void_p), ("load", ctypes.c_void_p),
                ("sync", ctypes.c_void_p), ("n_in", ctypes.c_int64), ("n_out", ctypes.c_int64),
                ("in_vr", ctypes.c_void_p), ("out_vr", ctypes.c_void_p), ("in_buf", ctypes.c_void_p),
                ("out_buf", ctypes.c_void_p), ("mode", ctypes.c_void_p), ("lazy", ctypes.c_void_p),
                ("n_eager", ctypes.c_int64)]


class LtiStep(ctypes.Structure):
    """The shim's ``LtiStep``: ``y <- G [y | u | 1]``, ``out = Y y + off + tco * t_end`` (its ``xpanel_lti_step``)."""
    _fields_ = [("ny", ctypes.c_int64), ("nz", ctypes.c_int64), ("nout", ctypes.c_int64),
                ("G", ctypes.c_void_p), ("z", ctypes.c_void_p), ("ynew", ctypes.c_void_p), ("Y", ctypes.c_void_p),
                ("off", ctypes.c_void_p), ("tco", ctypes.c_void_p), ("out", ctypes.c_void_p),
                ("u_in", ctypes.c_void_p), ("h", ctypes.c_double), ("rtol", ctypes.c_double),
                ("time", ctypes.c_void_p), ("steps", ctypes.c_int64)]


def _address(a: np.ndarray) -> int:
    return a.__array_interface__["data"][0]


def fast_enabled() -> bool:
    """False when the environment turns the fast path off (``XPANEL_FMU_FAST=0``)."""
    return os.environ.get(FAST_ENV, "").strip() != "0"


def shim_library(resources: str | Path | None) -> ctypes.CDLL | None:
    """The FMU's shim (loaded already by the host: the same handle), or None (no shim, or an old one)."""
    if resources is None:
        return None
    folder = Path(resources).parent / "binaries" / "linux64"
    for so in sorted(folder.glob("*.so")) if folder.is_dir() else ():
        if so.name.endswith("_pythonfmu.so"):
            continue
        try:
            lib = ctypes.CDLL(str(so))
        except OSError:
            continue
        if hasattr(lib, "xpanel_fast_register") and hasattr(lib, "xpanel_fast_forget"):
            return lib
    return None


class FastPath:
    """One instance's registration with the shim.

    Parameters
    ----------
    lib : ctypes.CDLL
        The shim (:func:`shim_library`).
    step : int
        Address of ``int step(void *ctx, double t, double h)``.
    in_vrs, out_vrs : sequences of int
        Value references of the per-step inputs and outputs.
    in_buf, out_buf : float64 arrays
        Their values, in that order: ``in_buf`` must be the slave's own input storage (the shim
        writes it), ``out_buf`` what the step writes.
    lazy : int, optional
        Address of ``int lazy(void *ctx, double, double)``, which fills ``out_buf[n_eager:]`` (outputs
        evaluated only when read, at most once a step; 0 from it: done); ``n_eager`` (default: all) the
        outputs ``step`` writes itself.
    load, sync : callables
        ``load(current)`` -> bool: make the step's buffers current — when ``current`` is False, copy
        the slave's state in; in both cases load pending data (the step returned 2) — False: no
        compiled step now. ``sync()``: the buffers' state into the slave.
        Called by the shim, in a call it is serving; they must not raise (an error is logged and
        treated as False / ignored).
    """

    def __init__(self, lib: ctypes.CDLL, step: int, in_vrs: Sequence[int], in_buf: np.ndarray,
                 out_vrs: Sequence[int], out_buf: np.ndarray, load: Callable[[bool], bool], sync: Callable[[], None],
                 lazy: int = 0, n_eager: int | None = None):
        self.lib = lib
        self.mode = np.zeros(1, np.int64)     # 1: the buffers hold the state
        self._in_vr = np.ascontiguousarray(in_vrs, dtype=np.uint32)
        self._out_vr = np.ascontiguousarray(out_vrs, dtype=np.uint32)
        self.in_buf, self.out_buf = in_buf, out_buf
        if in_buf.dtype != np.float64 or in_buf.size != self._in_vr.size or not in_buf.flags.c_contiguous:
            raise ValueError("FastPath: in_buf must be float64, contiguous, one value per input reference")
        if out_buf.dtype != np.float64 or out_buf.size != self._out_vr.size or not out_buf.flags.c_contiguous:
            raise ValueError("FastPath: out_buf must be float64, contiguous, one value per output reference")
        self._step, self._load_fn, self._sync_fn = step, load, sync
        self._lazy, self._n_eager = lazy, self._out_vr.size if n_eager is None else int(n_eager)
        self._load_cb, self._sync_cb = _CALLBACK(self._load), _CALLBACK(self._sync)   # kept alive here

    def register(self, ctx: int) -> bool:
        """Register with the shim (during a call the shim forwards to this instance); True on success."""
        spec = _Spec(ctx, self._step, ctypes.cast(self._load_cb, ctypes.c_void_p).value,
                     ctypes.cast(self._sync_cb, ctypes.c_void_p).value, self._in_vr.size, self._out_vr.size,
                     _address(self._in_vr), _address(self._out_vr), _address(self.in_buf), _address(self.out_buf),
                     _address(self.mode), self._lazy or None, self._n_eager)
        self.lib.xpanel_fast_register.restype = ctypes.c_int
        return self.lib.xpanel_fast_register(ctypes.byref(spec)) == 0

    def __del__(self):
        # the shim must not call into a freed object (pythonfmu drops the slave at fmi2Reset, ...)
        try:
            self.mode[0] = 0
            self.lib.xpanel_fast_forget(ctypes.c_void_p(_address(self.mode)))
        except Exception:   # interpreter shutdown
            pass

    def _load(self) -> int:
        current = bool(self.mode[0])
        try:
            ok = bool(self._load_fn(current))
        except Exception:   # never into C
            _LOG.exception("fast path: load failed; stepping in Python")
            ok = False
        if current and not ok:
            self._sync()    # Python takes the step: from the state the compiled steps reached
        self.mode[0] = int(ok)
        return int(ok)

    def _sync(self) -> int:
        try:
            self._sync_fn()
        except Exception:
            _LOG.exception("fast path: sync failed")
        self.mode[0] = 0
        return 0


def lti_step_address(lib: ctypes.CDLL) -> int:
    """Address of the shim's ``xpanel_lti_step`` (a linear discrete-time system's step)."""
    return ctypes.cast(lib.xpanel_lti_step, ctypes.c_void_p).value


__all__ = ["FAST_ENV", "FastPath", "LtiStep", "fast_enabled", "lti_step_address", "shim_library"]
