"""A root of a scalar function in a sign-changing bracket, without importing ``scipy.optimize``.

Importing ``scipy.optimize`` costs ~0.4 s of a process's start, and the layout of every turnout
needs a few roots (the theoretical crossing point, the crossing block's ends): bisection on the
bracket is exact enough (the tolerance is reached in ~50 halvings of a 100 m bracket) and
cannot fail on a continuous function whose signs differ at the ends.
"""
from __future__ import annotations

import math
from typing import Callable


def bracketed_root(f: Callable[[float], float], lo: float, hi: float, xtol: float) -> float:
    """A root of ``f`` in ``[lo, hi]`` within ``xtol`` (bisection).

    Parameters
    ----------
    f : callable
        Continuous on the bracket, ``f(lo)`` and ``f(hi)`` of opposite signs (or one of them 0).
    lo, hi : float
        The bracket.
    xtol : float
        > 0: the returned x lies within ``xtol`` of a root.

    Raises
    ------
    ValueError
        ``f`` has the same sign at both ends, or is not finite there.
    """
    f_lo, f_hi = float(f(lo)), float(f(hi))
    if not (math.isfinite(f_lo) and math.isfinite(f_hi)):
        raise ValueError(f"bracketed_root: f is not finite at the bracket [{lo}, {hi}]")
    if f_lo == 0.0:
        return float(lo)
    if f_hi == 0.0:
        return float(hi)
    if (f_lo > 0.0) == (f_hi > 0.0):
        raise ValueError(f"bracketed_root: f has the same sign at both ends of [{lo}, {hi}]")
    while abs(hi - lo) > 2.0 * xtol:
        mid = 0.5 * (lo + hi)
        if mid == lo or mid == hi:       # the bracket is down to adjacent floats
            break
        f_mid = float(f(mid))
        if f_mid == 0.0:
            return mid
        if (f_mid > 0.0) == (f_lo > 0.0):
            lo, f_lo = mid, f_mid
        else:
            hi = mid
    return 0.5 * (lo + hi)
