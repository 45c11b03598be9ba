"""Shared by the transport tests: short scenarios and exact trace comparison."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import can
import numpy as np

from bench.runs._analysis import analyze_frames
from bench.scenarios._schema import Profile, Scenario, load_scenario
from bench.scenarios._setup import sample_period
from bench.wire._codec import Codec

CODEC = Codec()


def short(name: str, duration: float, **lat: Any) -> Scenario:
    """A shortened scenario whose speed reference ramps to 100 rpm in 50 ms."""
    s = load_scenario(name).with_overrides(
        duration=duration,
        score_from_s=duration / 2,
        speed_rpm=Profile(((0.0, 0.0), (0.05, 100.0))),
    )
    return replace(s, latency=replace(s.latency, **lat)) if lat else s


def trace(frames: list[can.Message], scn: Scenario) -> dict[str, np.ndarray]:
    """The per-step table of a run's frames."""
    return analyze_frames(frames, CODEC, T_s=sample_period(scn), n_p=4).table


def assert_same_trace(a: dict[str, np.ndarray], b: dict[str, np.ndarray]) -> None:
    """Same steps, and the same position error, estimate, speed, current and duty to 1e-9."""
    assert len(a["step"]) == len(b["step"])
    np.testing.assert_array_equal(a["step"], b["step"])
    for col in ("theta_err_deg", "theta_hat", "w_m_rpm", "i_a", "d_a"):
        np.testing.assert_allclose(a[col], b[col], rtol=0, atol=1e-9, equal_nan=True, err_msg=col)
