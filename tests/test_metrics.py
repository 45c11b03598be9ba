"""Metrics against closed forms: THD of known harmonics, overshoot of a 2nd-order step."""

import math

import numpy as np
import pytest

from bench._errors import EXIT_NOT_SCORED, EXIT_PLANT_TRIPPED
from bench.runs._metrics import compute_metrics, overshoot_rpm, thd_pct, wrap_pi
from bench.runs._results import outcome


@pytest.mark.parametrize("f1", [6.6667, 13.3, 26.67])
def test_thd_of_known_harmonics(f1: float) -> None:
    T_s = 1e-4
    t = np.arange(int(3.3 / T_s)) * T_s
    amps = {1: 4.0, 3: 0.2, 5: 0.3, 7: 0.12, 11: 0.05, 39: 0.04}
    x = 0.7 + sum(a * np.sin(2 * np.pi * h * f1 * t + 0.3 * h) for h, a in amps.items())
    # a 500 Hz injection component is not a harmonic of f1 and must not count
    x = x + 0.25 * np.cos(2 * np.pi * 500.0 * t)
    expected = 100.0 * math.sqrt(sum(a**2 for h, a in amps.items() if h > 1)) / amps[1]
    assert thd_pct(x, T_s, f1) == pytest.approx(expected, abs=0.1)


def test_thd_ignores_harmonics_above_40() -> None:
    T_s = 1e-4
    f1 = 10.0
    t = np.arange(20000) * T_s
    x = np.sin(2 * np.pi * f1 * t) + 0.5 * np.sin(2 * np.pi * 45 * f1 * t)
    assert thd_pct(x, T_s, f1) < 0.1


def test_overshoot_matches_second_order_closed_form() -> None:
    zeta, wn = 0.4, 60.0
    t = np.arange(0, 2.0, 1e-4)
    w_ref = np.where(t >= 0.5, 300.0, 100.0)
    tau = np.clip(t - 0.5, 0, None)
    wd = wn * math.sqrt(1 - zeta**2)
    y = 1 - np.exp(-zeta * wn * tau) * (
        np.cos(wd * tau) + zeta / math.sqrt(1 - zeta**2) * np.sin(wd * tau)
    )
    w = 100.0 + 200.0 * y
    expected = 200.0 * math.exp(-math.pi * zeta / math.sqrt(1 - zeta**2))
    assert overshoot_rpm(t, w_ref, w) == pytest.approx(expected, rel=1e-3)


def test_overshoot_of_a_downward_step_counts_undershoot() -> None:
    t = np.arange(0, 1.0, 1e-3)
    w_ref = np.where(t >= 0.5, 100.0, 300.0)
    w = w_ref.copy()
    w[600] = 80.0  # 20 rpm below the new reference
    w[700] = 130.0  # above the reference after a downward step: not overshoot
    assert overshoot_rpm(t, w_ref, w) == pytest.approx(20.0)


def test_position_error_metrics_wrap_and_sign() -> None:
    T_s = 1e-3
    n = 2000
    t = np.arange(n) * T_s
    theta = (5.0 * t) % (2 * np.pi)
    err = np.radians(2.0 + 1.0 * np.sin(2 * np.pi * 2 * t))
    theta_hat = (theta - err) % (2 * np.pi)  # crosses the 0/2pi seam
    table = {
        "t": t,
        "theta_e": theta,
        "theta_hat": theta_hat,
        "w_m_rpm": np.full(n, 100.0),
        "w_hat_rpm": np.full(n, 103.0),
        "w_ref_rpm": np.full(n, 100.0),
        "i_a": np.zeros(n),
    }
    m = compute_metrics(table, T_s=T_s, n_p=4, score_from_s=0.5)
    assert m["theta_err_mean_deg"] == pytest.approx(2.0, abs=0.01)
    assert m["theta_err_max_deg"] == pytest.approx(3.0, abs=0.01)
    assert m["theta_err_min_deg"] == pytest.approx(1.0, abs=0.01)
    assert m["theta_err_rms_deg"] == pytest.approx(math.sqrt(4 + 0.5), abs=0.01)
    assert m["speed_err_max_rpm"] == pytest.approx(3.0)
    assert m["scored_steps"] == 1500
    assert wrap_pi(np.array([3.5 * np.pi]))[0] == pytest.approx(-0.5 * np.pi)


def _dead_controller_table(n: int = 2000, dies_at: int = 800) -> dict[str, np.ndarray]:
    """A 1 kHz run whose controller stops sending telemetry at row ``dies_at``: the plant's
    rows go on, the rotor coasts down from 100 rpm, the estimate is NaN."""
    t = np.arange(n) * 1e-3
    w = np.full(n, 100.0)
    w[dies_at:] = 100.0 * np.exp(-(t[dies_at:] - t[dies_at]) / 0.5)
    theta = np.cumsum(w) * 1e-3
    theta_hat = theta - np.radians(2.0)
    theta_hat[dies_at:] = np.nan
    w_hat = w + 1.0
    w_hat[dies_at:] = np.nan
    mode = np.full(n, 3.0)
    mode[dies_at:] = np.nan
    return {"t": t, "theta_e": theta, "theta_hat": theta_hat, "w_m_rpm": w, "w_hat_rpm": w_hat,
            "w_ref_rpm": np.full(n, 100.0), "i_a": np.zeros(n), "mode": mode}  # fmt: skip


def test_rows_without_telemetry_count_for_the_speed_tracking_not_the_angle() -> None:
    tab = _dead_controller_table()
    m = compute_metrics(tab, T_s=1e-3, n_p=4, score_from_s=0.5)
    # the safe state's coasting rotor is in the tracking error: 100 (1 - exp(-1.199 / 0.5)) rpm
    assert m["speed_track_err_max_rpm"] == pytest.approx(100.0 * (1 - math.exp(-1.199 / 0.5)))
    # the angle and the speed estimate only where an estimate came (rows 500 .. 799)
    assert m["theta_err_max_deg"] == pytest.approx(2.0) and m["speed_err_max_rpm"] == 1.0
    assert m["scored_steps"] == 1500 and m["steps_without_telemetry"] == 1200
    assert m["lock_lost"] is False and "unscored_reason" not in m


def test_no_scored_row_gives_null_metrics_and_the_reason() -> None:
    tab = _dead_controller_table(dies_at=300)
    m = compute_metrics(tab, T_s=1e-3, n_p=4, score_from_s=0.5)
    assert m["theta_err_max_deg"] is None and m["speed_err_max_rpm"] is None
    assert m["speed_track_err_max_rpm"] > 60.0
    assert "no CtrlTelemetry in the 1,500 scored rows" in m["unscored_reason"]
    m = compute_metrics(tab, T_s=1e-3, n_p=4, score_from_s=3.0, overshoot=True)
    assert m["speed_track_err_max_rpm"] is None and m["speed_overshoot_rpm"] is None
    assert m["scored_steps"] == 0 and m["steps"] == 2000
    assert m["unscored_reason"] == "no row to score: none from score_from_s = 3 s on"


def test_a_run_with_no_scored_row_exits_8_and_one_without_telemetry_0() -> None:
    """Nothing scored is a result of its own (exit status 8, with the reason's warning);
    a drive that sends no telemetry is still scored on its speed (0)."""
    tab = _dead_controller_table(dies_at=300)
    m = compute_metrics(tab, T_s=1e-3, n_p=4, score_from_s=0.5)
    status, lines = outcome(m, 1e-3)
    assert status == 0 and len(lines) == 1 and "no CtrlTelemetry" in lines[0]
    # the controller reported itself disabled (mode 0) throughout the scored window
    live = _dead_controller_table(n=2500, dies_at=2000)  # telemetry on every scored row
    off = {k: v[:2000] for k, v in live.items()}
    off["mode"] = np.where(off["t"] >= 0.5, 0.0, 3.0)
    m = compute_metrics(off, T_s=1e-3, n_p=4, score_from_s=0.5)
    assert m["scored_steps"] == 0
    status, lines = outcome(m, 1e-3)
    assert status == EXIT_NOT_SCORED == 8
    assert lines == [f"warning: metrics left null: {m['unscored_reason']}"]
    assert "disabled (mode 0) from 0.5 s on" in lines[0]
    # no plant period recorded at all (the run's metrics without a table)
    assert outcome({"steps": 0, "unscored_reason": "no rows"}, 1e-3)[0] == EXIT_NOT_SCORED
    # a trip is the cause of a controller that disabled itself
    tripped = {**m, "plant_fault": "over_current", "plant_fault_step": 10}
    assert outcome(tripped, 1e-3)[0] == EXIT_PLANT_TRIPPED
