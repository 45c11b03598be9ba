"""Sweeps of the claims: slope fit, sweep scenarios, collection of the results."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from bench.scenarios._schema import load_scenario
from bench.scenarios._setup import build_controller
from bench.studies._sweep import (
    FLAT_DEG,
    SWEEPS,
    SweepJob,
    collect,
    fit_slope,
    is_flat,
    sweep_jobs,
    sweep_scenario,
)


def test_fit_slope_recovers_a_known_line_through_noise() -> None:
    rng = np.random.default_rng(3)
    x = np.linspace(25.0, 400.0, 12)
    y = 0.037 * x - 1.5 + rng.normal(0.0, 0.01, x.size)
    f = fit_slope(x, y)
    assert f.slope == pytest.approx(0.037, abs=2e-4)
    assert f.intercept == pytest.approx(-1.5, abs=0.05)
    assert f.span == pytest.approx(0.037 * 375.0, rel=0.01)
    assert f.n == 12


def test_fit_slope_ignores_failed_points_and_needs_two_x() -> None:
    f = fit_slope([0.0, 1.0, 2.0, 3.0], [1.0, math.nan, 5.0, 7.0])
    assert f.slope == pytest.approx(2.0)
    assert f.n == 3
    g = fit_slope([1.0, 1.0], [2.0, 3.0])
    assert math.isnan(g.slope) and not is_flat(g)


def test_flat_means_less_than_the_tolerance_over_the_range() -> None:
    x = [0.0, 1.0, 2.0, 3.0, 4.0]
    assert is_flat(fit_slope(x, [0.2 * FLAT_DEG * v for v in x]))  # change 0.8 * tol
    assert not is_flat(fit_slope(x, [0.3 * FLAT_DEG * v for v in x]))  # change 1.2 * tol
    assert not is_flat(fit_slope(x, [-0.3 * FLAT_DEG * v for v in x]))


def test_sweep_scenarios_change_only_the_swept_quantity() -> None:
    base = load_scenario("wen-5.1")
    s = sweep_scenario(base, "speed", 250.0)
    assert s.speed_rpm(10.0) == 250.0 and s.speed_rpm(0.1) == 0.0
    assert s.preset == base.preset and s.seed == base.seed
    assert s.known_initial_angle == base.known_initial_angle
    d = sweep_scenario(base, "duty_delay", 3.0)
    assert (d.latency.duty_delay_steps, d.latency.sample_delay_steps) == (3, 0)
    assert d.speed_rpm(10.0) == 100.0
    q = sweep_scenario(base, "sample_delay", 2.0)
    assert (q.latency.duty_delay_steps, q.latency.sample_delay_steps) == (0, 2)
    n = sweep_scenario(base, "noise", 0.05)
    assert n.noise.current_std_a == 0.05
    v = sweep_scenario(base, "v_h", 20.0)
    assert v.estimator_options["V_h"] == 20.0
    # the option name is the one the rotating estimators accept
    for est in ("sfhf", "tt-ab", "tt-dq"):
        ctrl = build_controller(v, est)
        assert ctrl.estimator.V_h == 20.0  # type: ignore[attr-defined]
    with pytest.raises(ValueError):
        sweep_scenario(base, "temperature", 1.0)


def test_sweep_jobs_cover_every_value_and_method() -> None:
    jobs = sweep_jobs(("speed", "noise"), quick=True)
    want = len(SWEEPS["speed"].quick_values) * 3 + len(SWEEPS["noise"].quick_values) * 3
    assert len(jobs) == want
    assert {j.estimator for j in jobs} == {"sfhf", "tt-ab", "tt-dq"}


def test_collect_reports_slopes_in_their_units() -> None:
    base = load_scenario("wen-5.1")
    xs = (50.0, 100.0, 300.0)
    jobs: list[SweepJob] = []
    res: list[dict[str, Any]] = []
    for x in xs:
        scn = sweep_scenario(base, "speed", x, quick=True)
        for est, k in (("sfhf", 0.08), ("tt-ab", 0.11), ("tt-dq", 0.0)):
            jobs.append(SweepJob("speed", x, est, scn))
            res.append(
                {
                    "theta_err_mean_deg": k * x + 0.3,
                    "theta_err_abs_mean_deg": abs(k * x + 0.3),
                    "theta_err_abs_max_deg": abs(k * x) + 1.0,
                    "theta_err_rms_deg": abs(k * x + 0.3),
                }
            )
    jobs.append(SweepJob("speed", 400.0, "tt-dq", scn))
    res.append({"error": "RuntimeError: stalled"})
    sw = collect(jobs, res, quick=True)["speed"]
    assert sw["methods"]["sfhf"]["slope"] == pytest.approx(8.0)  # deg per 100 rpm
    assert sw["methods"]["tt-ab"]["slope"] == pytest.approx(11.0)
    assert sw["methods"]["tt-dq"]["slope"] == pytest.approx(0.0, abs=1e-9)
    assert sw["methods"]["tt-dq"]["flat"] and not sw["methods"]["sfhf"]["flat"]
    assert sw["methods"]["tt-dq"]["errors"] == {"400": "RuntimeError: stalled"}
    assert sw["methods"]["tt-dq"]["fit_points"] == 3
    assert sw["values"] == [50.0, 100.0, 300.0, 400.0]


def test_a_sweep_point_is_the_public_runs_metrics_with_the_overshoot(tmp_path: Any) -> None:
    """A sweep point runs through the function of ``bench.run`` (issue 32): its metrics are
    every key of that run's ``metrics.json`` with the same values, the speed overshoot
    added; only the wall-clock figures differ."""
    import json

    import bench
    from bench.studies._sweep import run_point

    scn = load_scenario("xue-fig13").with_overrides(duration=0.4, score_from_s=0.2)
    point = run_point(scn, "square-wave")
    run = bench.run(scn, estimator="square-wave", out=tmp_path / "run")
    written = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert "speed_overshoot_rpm" not in written  # xue-fig13's paper reports none
    assert "speed_overshoot_rpm" in point  # NaN here: no reference step in the scored window
    point.pop("speed_overshoot_rpm")
    clock = {"wall_s", "realtime_factor"}
    assert set(point) == set(written)
    # through JSON, as metrics.json and points.jsonl hold them (nan as null)
    same = json.loads(json.dumps({k: v for k, v in point.items() if k not in clock}))
    assert same == {k: v for k, v in written.items() if k not in clock}
    assert point["theta_err_abs_max_deg"] == run.metrics["theta_err_abs_max_deg"]
