"""Hand-derived values for the pieces the mutation run (``make mutants``, docs/testing.md)
found weakly tested: each expected number below is worked out in the docstring, not
recomputed with the code under test."""
from __future__ import annotations

import math

import pytest

from harness import masters

# -- the masters' extrapolation weights ------------------------------------------------------------------------


def test_extrapolation_weights_of_every_degree_on_uniform_steps():
    """Nodes x = (t_j - t)/h.  The polynomial p through the past values, on the step x in [0, 1]:
    mean = integral_0^1 p, slope = 12 integral_0^1 p (x - 1/2) (the least-squares line's slope,
    times h), end = p(1).  By Lagrange's basis:

    degree 0 (x = 0): p = u0: mean 1, slope 0, end 1.
    degree 1 (x = -1, 0): L0 = -x, L1 = x + 1: means (-1/2, 3/2), slopes (-1, 1), ends (-1, 2).
    degree 2 (x = -2, -1, 0): L0 = x(x+1)/2, L1 = -x(x+2), L2 = (x+1)(x+2)/2: means
      (5/12, -16/12, 23/12); a quadratic's least-squares slope on [0, 1] is p'(1/2):
      L0' = x + 1/2 -> 1, L1' = -2x - 2 -> -3, L2' = x + 3/2 -> 2; ends L(1) = (1, -3, 3)."""
    h = 0.25
    expected = {
        1: ([1.0], [0.0], [1.0]),
        2: ([-0.5, 1.5], [-1.0, 1.0], [-1.0, 2.0]),
        3: ([5 / 12, -16 / 12, 23 / 12], [1.0, -3.0, 2.0], [1.0, -3.0, 3.0]),
    }
    for n, (means, slopes, ends) in expected.items():
        past = [2.0 - (n - 1 - j) * h for j in range(n)]
        found = masters.extrapolation_weights(past, 2.0, h)
        for what, got, want in zip(("mean", "slope", "end"), found, (means, slopes, ends)):
            assert got == pytest.approx(want, abs=1e-12), (
                f"extrapolation weights of degree {n - 1}, {what}: {got}, by hand {want}: the extrapolating "
                f"masters' weights are wrong (jacobi-{('zero-order', 'linear', 'quadratic')[n - 1]})")


def test_extrapolation_weights_on_uneven_steps():
    """Past points at x = -3, -1 and 0 (a step of 3h, then h): for u = 1 + x + x^2 the mean
    over [0, 1] is 1 + 1/2 + 1/3 = 11/6, the slope 12 int (x - 1/2)(1 + x + x^2) = 1 + 1 = 2
    (for a quadratic p'(1/2) = 1 + 2 * 1/2), the end 3."""
    h = 0.1
    past = [1.0 - 3 * h, 1.0 - h, 1.0]
    u = [1 + x + x * x for x in (-3.0, -1.0, 0.0)]
    means, slopes, ends = masters.extrapolation_weights(past, 1.0, h)
    assert sum(m * v for m, v in zip(means, u)) == pytest.approx(11 / 6, rel=1e-12)
    assert sum(s * v for s, v in zip(slopes, u)) == pytest.approx(2.0, rel=1e-12)
    assert sum(e * v for e, v in zip(ends, u)) == pytest.approx(3.0, rel=1e-12)
    # the weights of a polynomial through the points reproduce constants
    assert sum(means) == pytest.approx(1.0) and sum(ends) == pytest.approx(1.0) and sum(slopes) == pytest.approx(0.0,
                                                                                                              abs=1e-12)


def test_lagrange_weights_extrapolate_a_parabola():
    """Nodes 0, 1, 2, value at 3: L0 = (3-1)(3-2)/((0-1)(0-2)) = 1, L1 = (3-0)(3-2)/((1-0)(1-2)) = -3,
    L2 = (3-0)(3-1)/((2-0)(2-1)) = 3; at 0.5: (3/8, 3/4, -1/8)."""
    assert masters._lagrange_weights([0.0, 1.0, 2.0], 3.0) == pytest.approx([1.0, -3.0, 3.0], abs=1e-12)
    assert masters._lagrange_weights([0.0, 1.0, 2.0], 0.5) == pytest.approx([0.375, 0.75, -0.125], abs=1e-12)
    assert masters._lagrange_weights([5.0], 7.0) == [1.0]
