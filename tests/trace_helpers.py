"""Shared by the transport tests: short scenarios and exact trace comparison, the same
helpers the reliability study uses (bench/studies/_reliability.py)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import can
import numpy as np

from bench.scenarios._schema import Scenario
from bench.studies._reliability import TRACE_COLUMNS, run_trace, short_scenario
from bench.wire._codec import Codec

CODEC = Codec()


def short(name: str, duration: float, **lat: Any) -> Scenario:
    """A shortened scenario whose speed reference ramps to 100 rpm in 50 ms."""
    scn: Scenario = short_scenario(name, duration, **lat)
    return scn


def trace(frames: Sequence[can.Message], scn: Scenario) -> dict[str, np.ndarray]:
    """The per-step table of a run's frames."""
    return run_trace(frames, scn)


def assert_same_trace(a: dict[str, np.ndarray], b: dict[str, np.ndarray]) -> None:
    """Same steps, and the same position error, estimate, speed, current and duty to 1e-9."""
    assert len(a["step"]) == len(b["step"])
    np.testing.assert_array_equal(a["step"], b["step"])
    for col in TRACE_COLUMNS:
        np.testing.assert_allclose(a[col], b[col], rtol=0, atol=1e-9, equal_nan=True, err_msg=col)
