"""The core's ``cc_hypot`` (controller/core/cc_math.h) rounds as this interpreter's
``math.hypot``, bit for bit.

The Python engine's ``normalise = "measured"`` divides by ``math.hypot`` of the
demodulated pair; the compiled core divides by ``cc_hypot``, so the two engines agree
only if the two round alike on every pair.  CPython's ``math.hypot`` is not C's
``hypot``: it scales by a power of two, sums the exact squares with their errors and
corrects the square root once (its ``vector_norm``), and libm's ``hypot`` rounds
differently on about one pair in three thousand.  3.11 and 3.12+ differ below
``2**-1024``; the build defines which (setup.py), and the test is against the running
interpreter.  10**6 pairs: every exponent of either argument (normal and subnormal),
pairs of close magnitude (where the correction decides the last bit), subnormal pairs,
and the edge cases (zeros of either sign, inf beating nan, the largest and least
doubles).
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable

import numpy as np
import pytest

from controller import compiled_controller_missing

N = 1_000_000


@pytest.fixture(scope="module")
def cc_hypot() -> Callable[[float, float], float]:
    why = compiled_controller_missing()
    if why is not None:
        pytest.skip(why)
    from controller import _cctl

    return _cctl.hypot


def _pairs() -> tuple[np.ndarray, np.ndarray]:
    """N pairs: a third over all exponents, a third of ratio 0.01..100 (inf where the
    product overflows), a third below 2**-1024 (the branch where 3.11 and 3.12 part)."""
    rng = np.random.default_rng(20261126)
    m = N // 3

    def wide(k: int) -> np.ndarray:
        return rng.uniform(-1.0, 1.0, k) * np.ldexp(1.0, rng.integers(-1074, 1024, k))

    x1, y1 = wide(m), wide(m)
    x2 = wide(m)
    with np.errstate(over="ignore"):
        y2 = x2 * rng.uniform(0.01, 100.0, m) * rng.choice([-1.0, 1.0], m)
    k = N - 2 * m
    x3 = rng.uniform(-1.0, 1.0, k) * 2.0**-1024
    y3 = rng.uniform(-1.0, 1.0, k) * 2.0**-1024
    return np.concatenate([x1, x2, x3]), np.concatenate([y1, y2, y3])


EDGES = [
    0.0,
    -0.0,
    5e-324,
    -5e-324,
    2.0**-1074 * 3,
    sys.float_info.min,
    sys.float_info.min * (1 - 2.0**-52),
    2.0**-1024,
    2.0**-1023,
    1.0,
    -1.0,
    3.0,
    4.0,
    1.0 + 2.0**-52,
    1e-300,
    1e300,
    sys.float_info.max,
    -sys.float_info.max,
    math.inf,
    -math.inf,
    math.nan,
]


def _bits(v: list[float]) -> np.ndarray:
    return np.asarray(v, dtype=np.float64).view(np.uint64)


def test_cc_hypot_is_math_hypot_bit_for_bit(cc_hypot: Callable[[float, float], float]) -> None:
    """10**6 pairs over every exponent, close magnitudes and subnormals: the same bits."""
    h = cc_hypot
    x, y = _pairs()
    xs, ys = x.tolist(), y.tolist()
    got = _bits(list(map(h, xs, ys)))
    want = _bits(list(map(math.hypot, xs, ys)))
    bad = np.flatnonzero(got != want)
    assert bad.size == 0, (
        f"{bad.size} of {N} pairs differ, the first ({xs[bad[0]].hex()}, {ys[bad[0]].hex()})"
    )
    # the pairs reach where the algorithms part: C's hypot differs from math.hypot on
    # some of them (so this comparison would catch it), and the subnormal branch is taken
    with np.errstate(over="ignore"):
        c_hypot = np.hypot(x, y)
    assert np.count_nonzero(_bits(c_hypot.tolist()) != want) > 100
    assert np.count_nonzero(np.maximum(abs(x), abs(y)) < 2.0**-1024) > N // 4


def test_cc_hypot_edge_cases(cc_hypot: Callable[[float, float], float]) -> None:
    """Every pair of the edge values (either sign of zero, the least subnormal, the
    largest double, inf and nan, inf winning over nan): the same bits."""
    h = cc_hypot
    for a in EDGES:
        for b in EDGES:
            got, want = h(a, b), math.hypot(a, b)
            assert _bits([got]) == _bits([want]), (a, b, got, want)
    assert h(math.nan, math.inf) == math.inf
    assert math.isnan(h(math.nan, 1.0))
    assert h(3.0, 4.0) == 5.0
