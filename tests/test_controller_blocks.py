"""The public per-period blocks are bindings of the controller core: each gives the same
outputs and states as its readable Python in ``tests/oracle/blocks.py``, bit for bit
(:data:`tests.oracle.TOLERANCE`: the core repeats the oracle's operations in the same order,
compiled without fused multiply-adds), on random and representative input sequences."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from controller import PIController, svpwm
from controller._svpwm import limit_magnitude
from tests.oracle import TOLERANCE
from tests.oracle import blocks as ob
from tests.oracle.blocks import oracle

N = 2000


def _same(a: Any, b: Any) -> None:
    """Equal within the oracle tolerance (0: the same float, nan included)."""
    a_ = np.asarray(a, float)
    b_ = np.asarray(b, float)
    assert a_.shape == b_.shape
    if TOLERANCE == 0.0:
        assert np.array_equal(a_, b_, equal_nan=True), (a, b)
    else:  # pragma: no cover - the tolerance is 0
        np.testing.assert_allclose(a_, b_, rtol=0.0, atol=TOLERANCE)


def _pair(make: Any) -> tuple[Any, Any]:
    """The block as built, and a second one made the oracle (:func:`oracle`)."""
    b = make()
    o = oracle(make())
    assert type(o) is ob.ORACLES[type(b)]
    return b, o


def test_pi_controller_is_the_core() -> None:
    rng = np.random.default_rng(1)
    b, o = _pair(lambda: PIController(2.5, 400.0, 1e-4, 1.7))
    u_max = 3.0
    for j in range(N):
        r, y, u_ff = rng.normal(0.0, 2.0, 3)
        if j % 500 == 250:
            b.reset(1.25)
            o.reset(1.25)
        u_b = b.output(r, y, u_ff)
        u_o = o.output(r, y, u_ff)
        _same(u_b, u_o)
        u_lim = min(max(u_b, -u_max), u_max)  # the anti-windup sees saturation
        b.update(u_lim)
        o.update(u_lim)
        _same((b.u_i, b._e, b._u), (o.u_i, o._e, o._u))


def test_pi_controller_keeps_its_api() -> None:
    pi = PIController(2.0, 3.0, 0.5)
    assert (pi.k_p, pi.k_i, pi.k_t, pi.T_s) == (2.0, 3.0, 2.0, 0.5)  # k_t defaults to k_p
    assert pi.output(r=1.0, y=0.25) == 2.0 * 1.0 - 2.0 * 0.25
    with pytest.raises(AttributeError):
        pi.k_p = 1.0  # type: ignore[misc]
    pi.u_i = 0.75  # a state: writable
    assert pi.output(0.0, 0.0) == 0.75
    with pytest.raises(ValueError, match="k_t"):
        PIController(0.0, 1.0, 1e-3)


def test_svpwm_and_limit_are_the_core() -> None:
    rng = np.random.default_rng(2)
    u_dc = 48.0
    for scale in (0.2, 0.5, 0.58, 0.6, 1.0):  # inside, at and beyond the linear range
        for th, mag in zip(
            rng.uniform(0.0, 2.0 * math.pi, N // 5), rng.uniform(0, 1, N // 5), strict=True
        ):
            u_a = scale * u_dc * mag * math.cos(th)
            u_b = scale * u_dc * mag * math.sin(th)
            _same(svpwm(u_a, u_b, u_dc), ob.svpwm(u_a, u_b, u_dc))
            x_max = 0.4 * u_dc
            _same(limit_magnitude(u_a, u_b, x_max), ob.limit_magnitude(u_a, u_b, x_max))
    # the axes and the hexagon's corners, where the min/max branches tie
    for k in range(12):
        th = k * math.pi / 6.0
        u = u_dc / math.sqrt(3.0)
        _same(
            svpwm(u * math.cos(th), u * math.sin(th), u_dc),
            ob.svpwm(u * math.cos(th), u * math.sin(th), u_dc),
        )
    with pytest.raises(ValueError, match="u_dc"):
        svpwm(1.0, 0.0, 0.0)
