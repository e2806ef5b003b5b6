"""The C entry point of :func:`track.unit_step.unit_step`: ``int step(void *ctx, double t, double h)``.

A C caller (the FMU's shim, ``fmus/shim/fmi2_python_shim.c``) cannot pass numpy arrays; it passes
``ctx``, an int64 table with, for each of :func:`~track.unit_step.unit_step`'s arrays in the order of
:data:`SPEC`, its address and up to four dimensions (:func:`pack`). The arrays are rebuilt from it
(no copy) at each call and the step runs on them. The caller keeps the arrays alive and ``ctx``
current (:meth:`track.unit_step.UnitSteps.arguments` may change when the record grows).

Imported only where the entry point is wanted: compiling (or loading from numba's cache) the
C function happens at import.
"""
from __future__ import annotations

import numpy as np
from numba import carray, cfunc, types
from numba.extending import intrinsic

from .kernel import _njit
from .unit_step import unit_sensors, unit_step

# kind of each array of unit_step's arguments after t, h (flattened: P's 53 arrays, trk's 9, the record's 10):
# f/i/w/u float64/int64/uint32/uint8, then the number of dimensions
SPEC = ("f1", "i1", "f1",
        "f1", "i1", "f1", "w1", "w1", "f1", "w1", "w1", "f1", "i1", "f1", "f1", "f1", "f2", "u1", "w1", "w1",
        "w1", "f1", "f1", "i1", "i1", "f2", "f3", "i1", "i2",
        "i2", "i2", "f3", "f2", "i1", "i2", "i1", "f2", "u1", "f1",
        "f3", "i2", "i1", "f3", "i2", "f4", "u1", "f2",
        "f2", "f2", "f1", "i1", "f1", "f2", "f4", "f4", "f2",
        "f2", "f2", "f2", "f2", "f2", "f2",
        "f1", "f1", "f1", "f1", "f1", "f2", "f1", "f1", "f1",
        "f1",
        "i1", "i1", "i1", "f1", "f2", "f2", "f3", "f2", "f2", "f2",
        "i1", "f1",
        "i1", "i1", "i1", "f1", "f1", "f1", "f1", "f2", "f1")   # the sensors' (unit_step.sensor_read)
SLOT = 5   # int64 per array in ctx: address, then 4 dimensions (1 where unused)
_KINDS = {"f": np.float64, "i": np.int64, "w": np.uint32, "u": np.uint8}


def flatten(args: tuple) -> list:
    """unit_step's arguments after ``t, h`` (:meth:`~track.unit_step.UnitSteps.arguments`) as one list of arrays."""
    out = []
    for a in args:
        out.extend(a if isinstance(a, tuple) else (a,))
    return out


def pack(args: tuple, ctx: np.ndarray | None = None) -> np.ndarray:
    """``ctx`` of ``args`` (filled in place when given); ValueError if an array does not fit :data:`SPEC`."""
    arrays = flatten(args)
    if len(arrays) != len(SPEC):
        raise ValueError(f"unit_step takes {len(SPEC)} arrays, got {len(arrays)}")
    ctx = np.ones(SLOT * len(SPEC), np.int64) if ctx is None else ctx
    for k, (a, kind) in enumerate(zip(arrays, SPEC)):
        if a.dtype != _KINDS[kind[0]] or a.ndim != int(kind[1]) or not a.flags.c_contiguous:
            raise ValueError(f"unit_step's array {k}: {a.dtype}[{a.ndim}-d, contiguous {a.flags.c_contiguous}], "
                             f"wanted {_KINDS[kind[0]].__name__}[{kind[1]}-d, contiguous]")
        ctx[SLOT * k] = a.__array_interface__["data"][0]
        ctx[SLOT * k + 1:SLOT * k + 5] = 1
        ctx[SLOT * k + 1:SLOT * k + 1 + a.ndim] = a.shape
    return ctx


@intrinsic
def _pointer(typingctx, address):
    """An int64 address as a ``void *``."""
    if not isinstance(address, types.Integer):
        return None

    def codegen(context, builder, signature, args):
        return builder.inttoptr(args[0], context.get_value_type(types.voidptr))
    return types.voidptr(address), codegen


@_njit
def _f1(ctx, k):
    return carray(_pointer(ctx[SLOT * k]), (ctx[SLOT * k + 1],), np.float64)


@_njit
def _f2(ctx, k):
    return carray(_pointer(ctx[SLOT * k]), (ctx[SLOT * k + 1], ctx[SLOT * k + 2]), np.float64)


@_njit
def _f3(ctx, k):
    return carray(_pointer(ctx[SLOT * k]), (ctx[SLOT * k + 1], ctx[SLOT * k + 2], ctx[SLOT * k + 3]), np.float64)


@_njit
def _f4(ctx, k):
    return carray(_pointer(ctx[SLOT * k]), (ctx[SLOT * k + 1], ctx[SLOT * k + 2], ctx[SLOT * k + 3],
                                            ctx[SLOT * k + 4]), np.float64)


@_njit
def _i1(ctx, k):
    return carray(_pointer(ctx[SLOT * k]), (ctx[SLOT * k + 1],), np.int64)


@_njit
def _i2(ctx, k):
    return carray(_pointer(ctx[SLOT * k]), (ctx[SLOT * k + 1], ctx[SLOT * k + 2]), np.int64)


@_njit
def _w1(ctx, k):
    return carray(_pointer(ctx[SLOT * k]), (ctx[SLOT * k + 1],), np.uint32)


@_njit
def _u1(ctx, k):
    return carray(_pointer(ctx[SLOT * k]), (ctx[SLOT * k + 1],), np.uint8)


@cfunc(types.int32(types.voidptr, types.float64, types.float64), nopython=True, cache=True, error_model="numpy")
def unit_step_c(ctx_address, t, h):
    """:func:`~track.unit_step.unit_step` on the arrays of ``ctx`` (:func:`pack`)."""
    ctx = carray(ctx_address, (SLOT * len(SPEC),), np.int64)
    inp, ist, fst = _f1(ctx, 0), _i1(ctx, 1), _f1(ctx, 2)
    P = (_f1(ctx, 3), _i1(ctx, 4), _f1(ctx, 5), _w1(ctx, 6), _w1(ctx, 7), _f1(ctx, 8), _w1(ctx, 9),
         _w1(ctx, 10), _f1(ctx, 11), _i1(ctx, 12), _f1(ctx, 13), _f1(ctx, 14), _f1(ctx, 15), _f2(ctx, 16),
         _u1(ctx, 17), _w1(ctx, 18), _w1(ctx, 19), _w1(ctx, 20), _f1(ctx, 21), _f1(ctx, 22), _i1(ctx, 23),
         _i1(ctx, 24), _f2(ctx, 25), _f3(ctx, 26), _i1(ctx, 27), _i2(ctx, 28),
         _i2(ctx, 29), _i2(ctx, 30), _f3(ctx, 31), _f2(ctx, 32), _i1(ctx, 33), _i2(ctx, 34), _i1(ctx, 35),
         _f2(ctx, 36), _u1(ctx, 37), _f1(ctx, 38),
         _f3(ctx, 39), _i2(ctx, 40), _i1(ctx, 41), _f3(ctx, 42), _i2(ctx, 43), _f4(ctx, 44), _u1(ctx, 45),
         _f2(ctx, 46), _f2(ctx, 47), _f2(ctx, 48), _f1(ctx, 49), _i1(ctx, 50), _f1(ctx, 51), _f2(ctx, 52),
         _f4(ctx, 53), _f4(ctx, 54), _f2(ctx, 55))
    Q, V, A, F, Fc, out = _f2(ctx, 56), _f2(ctx, 57), _f2(ctx, 58), _f2(ctx, 59), _f2(ctx, 60), _f2(ctx, 61)
    trk = (_f1(ctx, 62), _f1(ctx, 63), _f1(ctx, 64), _f1(ctx, 65), _f1(ctx, 66), _f2(ctx, 67), _f1(ctx, 68),
           _f1(ctx, 69), _f1(ctx, 70))
    limit = _f1(ctx, 71)
    rec = (_i1(ctx, 72), _i1(ctx, 73), _i1(ctx, 74), _f1(ctx, 75), _f2(ctx, 76), _f2(ctx, 77), _f3(ctx, 78),
           _f2(ctx, 79), _f2(ctx, 80), _f2(ctx, 81))
    tot, outbuf = _i1(ctx, 82), _f1(ctx, 83)
    return unit_step(t, h, inp, ist, fst, P, Q, V, A, F, Fc, out, trk, limit, rec, tot, outbuf)


@cfunc(types.int32(types.voidptr, types.float64, types.float64), nopython=True, cache=True, error_model="numpy")
def unit_sensors_c(ctx_address, t, h):
    """:func:`~track.unit_step.unit_sensors` on the arrays of ``ctx`` (``t``, ``h`` unused: the shim's
    signature for a step function)."""
    ctx = carray(ctx_address, (SLOT * len(SPEC),), np.int64)
    sens = (_i1(ctx, 84), _i1(ctx, 85), _i1(ctx, 86), _f1(ctx, 87), _f1(ctx, 88), _f1(ctx, 89), _f1(ctx, 90),
            _f2(ctx, 91), _f1(ctx, 92))
    outbuf = _f1(ctx, 83)
    return unit_sensors(_i1(ctx, 1), _f2(ctx, 56), _f2(ctx, 57), _f2(ctx, 58), sens, outbuf, _f1(ctx, 71).size)


def unit_step_address() -> int:
    """Address of the C function ``int step(void *ctx, double t, double h)``."""
    return unit_step_c.address


def unit_sensors_address() -> int:
    """Address of the C function that evaluates the sensor outputs on demand (same signature)."""
    return unit_sensors_c.address


__all__ = ["SPEC", "pack", "unit_sensors_address", "unit_sensors_c", "unit_step_address", "unit_step_c"]
