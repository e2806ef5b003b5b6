"""JSON of the inverse problem's results: NumPy scalars and arrays as Python numbers and lists."""
from __future__ import annotations

import numpy as np


def numpy_default(o):
    """``json.dumps(..., default=numpy_default)``: NumPy scalars as numbers, arrays as lists."""
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(type(o).__name__)


__all__ = ["numpy_default"]
