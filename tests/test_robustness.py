"""``bench suite robustness``: the studies' keys, the bound check and the report."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from bench.scenarios._schema import load_scenario
from bench.scenarios._setup import get_preset
from bench.studies._grid import build_tasks
from bench.studies._robustness import PAPERS, STUDIES, meets, region, run_robustness, study_plan


def test_every_study_builds_valid_scenarios_for_every_paper() -> None:
    """Each dotted key of each study is a key of the schema, with a valid value (no run)."""
    for paper in PAPERS.values():
        n = 0
        for study in STUDIES.values():
            tasks = build_tasks(study_plan(paper, study, 1.6))
            n += len(tasks)
            assert all(t.scenario.duration == 1.6 for t in tasks)
        # 9 + 9 + 3 + 7 + 8 + 4 points per estimator
        assert n == 40 * len(paper.estimators)
    adc = build_tasks(study_plan(PAPERS["wen"], STUDIES["adc-bits"], 1.6))
    i_max = get_preset(load_scenario("wen-5.1")).motor.i_max
    assert all(t.scenario.sensors["current_full_scale_a"] == 2.0 * i_max for t in adc)
    dead = build_tasks(study_plan(PAPERS["xue"], STUDIES["dead-time"], 1.6))
    combos = {
        (t.scenario.inverter["t_dead"], t.scenario.controller["dead_time_compensation"])
        for t in dead
    }
    assert len(combos) == 8


def test_the_paper_bounds() -> None:
    assert PAPERS["wen"].bound_deg == 4.0  # Table 5: -0.5 to 4 deg
    assert math.isclose(PAPERS["xue"].bound_deg, math.degrees(0.1))  # Fig. 13: 0.1 rad


def test_meets_needs_lock_no_error_and_the_bound() -> None:
    recs: list[dict[str, Any]] = [
        {
            "estimator": "a",
            "values": {"x": 1},
            "metrics": {"theta_err_abs_max_deg": 3.9, "lock_lost": False},
        },
        {
            "estimator": "a",
            "values": {"x": 2},
            "metrics": {"theta_err_abs_max_deg": 4.1, "lock_lost": False},
        },
        {
            "estimator": "a",
            "values": {"x": 3},
            "metrics": {"theta_err_abs_max_deg": 1.0, "lock_lost": True},
        },
        {"estimator": "a", "values": {"x": 4}, "metrics": {"error": "ValueError: x"}},
        {
            "estimator": "b",
            "values": {"x": 1},
            "metrics": {"theta_err_abs_max_deg": 9.0, "lock_lost": False},
        },
    ]
    assert meets(recs[0]["metrics"], 4.0) and not meets(recs[1]["metrics"], 4.0)
    r = region(recs, "a", 4.0)
    assert r["points"] == 4 and r["ok"] == 1
    assert [b["why"] for b in r["not_ok"]] == ["4.1 deg", "lost lock", "not run: ValueError: x"]
    assert r["locked"] == 2


def test_a_small_study_writes_its_report(tmp_path: Path) -> None:
    s = run_robustness(
        tmp_path,
        papers=("xue",),
        studies=("model-resistance",),
        duration=0.6,
        workers=1,
        progress=False,
    )
    st = s["papers"]["xue"]["studies"]["model-resistance"]
    assert st["missing"] == 0
    for est in PAPERS["xue"].estimators:
        assert st["regions"][est]["points"] == 3
    report = (tmp_path / "report.md").read_text()
    assert "controller model: R_s +-30 %" in report and "0.6 simulated seconds" in report
    assert (tmp_path / st["figures"][0]).is_file()
    assert json.loads((tmp_path / "summary.json").read_text())["duration_s"] == 0.6
