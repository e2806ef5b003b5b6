"""track.roots.bracketed_root against closed-form roots."""
import math

import pytest

from track.roots import bracketed_root


@pytest.mark.parametrize("f, lo, hi, root", [
    (lambda x: x ** 3 - 2.0, 0.0, 100.0, 2.0 ** (1.0 / 3.0)),         # the cube root of 2
    (lambda x: math.cos(x) - x, 0.0, 1.0, 0.7390851332151607),        # the Dottie number
    (lambda x: -(x - 37.25) * (1.0 + x * x), -5.0, 200.0, 37.25),     # decreasing through the root
])
def test_root_within_xtol(f, lo, hi, root):
    """The returned x lies within xtol of the closed-form root (the contract; the tolerances
    are the bisection's own, far above double round-off at these magnitudes)."""
    for xtol in (1e-6, 1e-12):
        assert abs(bracketed_root(f, lo, hi, xtol) - root) <= xtol


def test_root_at_a_bracket_end_and_bad_brackets():
    assert bracketed_root(lambda x: x - 1.0, 1.0, 3.0, 1e-12) == 1.0
    with pytest.raises(ValueError, match="same sign"):
        bracketed_root(lambda x: x * x + 1.0, -1.0, 1.0, 1e-9)
    with pytest.raises(ValueError, match="not finite"):
        bracketed_root(lambda x: math.nan, 0.0, 1.0, 1e-9)
