"""Lost rotor angle is a result: ``lock_lost`` in metrics.json, a warning, exit status 4."""

from __future__ import annotations

import numpy as np
import pytest

from bench._errors import EXIT_LOCK_LOST, EXIT_PLANT_TRIPPED
from bench.runs._metrics import (
    LOCK_LOST_DEG,
    LOCK_LOST_S,
    LOCK_WINDOW_S,
    compute_metrics,
    lock_lost,
)
from bench.runs._results import outcome

T_S = 1e-4


def trace(excursions: list[tuple[float, float, float]], n: int = 20000) -> tuple[np.ndarray, ...]:
    """A 2 s error trace (deg) of 1 deg with excursions (start s, length s, value deg)."""
    t = np.arange(n) * T_S
    e = np.ones(n)
    for t0, dt, v in excursions:
        e[(t >= t0) & (t < t0 + dt)] = v
    return t, e


def test_an_excursion_longer_than_50_ms_above_90_deg_is_lost_lock_at_its_start() -> None:
    t, e = trace([(0.5, 0.04, 170.0), (1.0, 0.07, -120.0)])
    lost, at = lock_lost(t, e, T_S)
    assert lost and at == pytest.approx(1.0)
    assert (LOCK_LOST_DEG, LOCK_LOST_S, LOCK_WINDOW_S) == (90.0, 0.05, 0.2)


@pytest.mark.parametrize("slip_period_s", [0.02, 0.06, 0.099, 0.3])
def test_an_estimate_spinning_against_the_rotor_is_lost_lock(slip_period_s: float) -> None:
    t = (np.arange(20000) * T_S).astype(np.float64)
    e = np.degrees(np.angle(np.exp(2j * np.pi * t / slip_period_s))).astype(np.float64)  # 50 % > 90
    lost, at = lock_lost(t, e, T_S)
    assert lost and at is not None and at < 0.3


@pytest.mark.parametrize(
    "exc",
    [
        [(0.5, 0.049, 179.0)],  # too short
        [(0.5, 0.2, 89.9)],  # not beyond 90 deg
        [(0.5, 0.03, 150.0), (0.75, 0.03, 150.0)],  # two short ones, 250 ms apart
    ],
)
def test_short_or_small_excursions_are_not_lost_lock(exc: list[tuple[float, float, float]]) -> None:
    t, e = trace(exc)
    assert lock_lost(t, e, T_S) == (False, None)


def test_the_metrics_carry_it_from_the_scored_window_only() -> None:
    t, e_deg = trace([(0.2, 0.3, 170.0)])
    theta_e = np.full_like(t, 1.0)
    table = {
        "t": t,
        "theta_e": theta_e,
        "theta_hat": theta_e - np.radians(e_deg),
        "w_m_rpm": np.zeros_like(t),
        "w_hat_rpm": np.zeros_like(t),
        "w_ref_rpm": np.zeros_like(t),
        "i_a": np.zeros_like(t),
        "mode": np.full_like(t, 3.0),
    }
    early = compute_metrics(table, T_s=T_S, n_p=4, score_from_s=0.0)
    assert early["lock_lost"] is True and early["lock_lost_at_s"] == pytest.approx(0.2)
    late = compute_metrics(table, T_s=T_S, n_p=4, score_from_s=0.6)
    assert late["lock_lost"] is False and late["lock_lost_at_s"] is None


def test_the_exit_status_and_its_warnings() -> None:
    ok = {"plant_fault": "none", "lock_lost": False}
    assert outcome(ok, T_S) == (0, [])
    lost = {**ok, "lock_lost": True, "lock_lost_at_s": 1.25}
    status, lines = outcome(lost, T_S)
    assert status == EXIT_LOCK_LOST == 4
    assert len(lines) == 1 and "lost the rotor angle at t = 1.2500 s" in lines[0]
    both = {**lost, "plant_fault": "over_current", "plant_fault_step": 518}
    status, lines = outcome(both, T_S)
    assert status == EXIT_PLANT_TRIPPED == 3  # the trip is the cause
    assert len(lines) == 2 and "over_current" in lines[0]
