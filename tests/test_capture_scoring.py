"""A capture analysed or rerun away from its run: same scenario, same scoring, same report.

The recorded run (see ``replay_helpers``) is 0.2 s of wen-5.1, scored from
0.1 s: its second half, as ``Scenario.with_overrides(duration=0.2)`` scores
a run shorter than the scenario's scoring start (1.0 s).  Its capture, alone
in a folder and analysed with ``--scenario wen-5.1``, must be scored the same
way, and the ``meta.json`` that analysis writes must let a second analysis
and a rerun find the scenario without ``--scenario``.
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

import pytest

from bench.captures._read import (
    analyze_capture,
    scoring_scenario,
)
from bench.captures._rerun import rerun_capture
from bench.cli.analyze import cmd_analyze
from bench.cli.rerun import cmd_rerun
from bench.runs._metrics import PAPER_COMPARED_AS
from bench.scenarios._schema import load_scenario
from tests.replay_helpers import recorded_run

SCORED = (
    "theta_err_max_deg",
    "theta_err_min_deg",
    "theta_err_mean_deg",
    "theta_err_rms_deg",
    "speed_err_max_rpm",
    "speed_track_err_max_rpm",
    "steps",
    "scored_steps",
)


def metrics(folder: Path) -> dict:
    return json.loads((folder / "metrics.json").read_text())


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return recorded_run(tmp_path_factory, "tt-dq")


@pytest.fixture
def lone(run: Path, tmp_path: Path) -> Path:
    """The run's capture alone in a folder (no meta.json beside it)."""
    folder = tmp_path / "lone"
    folder.mkdir()
    shutil.copy(run / "capture.blf", folder / "capture.blf")
    return folder / "capture.blf"


def test_scoring_window_of_a_short_capture_is_its_second_half() -> None:
    scn = load_scenario("wen-5.1")
    assert scn.score_from_s == 1.0
    # a capture from 0 to 0.5 s: the rule of a live run shortened to 0.5 s
    got, why = scoring_scenario(scn, 0.0, 0.5)
    assert got.score_from_s == scn.with_overrides(duration=0.5).score_from_s == 0.25
    assert got.duration == 0.5
    assert why is not None and "second half" in why and "0.25" in why
    # a capture starting mid-run: the second half of its own span
    got, _ = scoring_scenario(scn, 0.3, 0.5)
    assert got.score_from_s == pytest.approx(0.4, abs=1e-12)
    # a capture reaching past the scoring start keeps the scenario's window
    got, why = scoring_scenario(scn, 0.0, 2.0)
    assert got is scn and why is None


def test_explicit_scenario_scores_a_short_capture_like_the_live_run(
    run: Path, lone: Path, tmp_path: Path
) -> None:
    live = metrics(run)
    lines: list[str] = []
    res = analyze_capture(
        lone, out_dir=tmp_path / "a", scenario="wen-5.1", echo=lines.append, plots=False
    )
    for key in SCORED:
        assert res.metrics[key] == live[key], key
    assert live["scored_steps"] < live["steps"] // 2 + 2  # the second half only
    moved = [s for s in lines if "second half" in s]
    assert len(moved) == 1 and "from 0.1 s" in moved[0]
    # the rerun of the same estimator scores the same window
    rr = rerun_capture(lone, "tt-dq", scenario="wen-5.1", out_dir=tmp_path / "r", echo=lines.append)
    assert rr.report["scored_from_s"] == pytest.approx(0.1, abs=1e-12)
    for key in SCORED:
        assert rr.metrics[key] == live[key], key


def test_metadata_written_by_analyze_is_read_back(run: Path, lone: Path) -> None:
    """analyze --scenario beside the capture, then analyze and rerun without it."""
    first = analyze_capture(lone, scenario="wen-5.1", echo=lambda _: None, plots=False)
    meta = json.loads((lone.parent / "meta.json").read_text())
    assert meta["scenario"]["name"] == "wen-5.1"
    assert meta["scenario"]["score_from_s"] == pytest.approx(0.1, abs=1e-12)
    second = analyze_capture(lone, echo=lambda _: None, plots=False)
    assert json.dumps(second.metrics, sort_keys=True) == json.dumps(first.metrics, sort_keys=True)
    rr = rerun_capture(lone, "tt-dq", echo=lambda _: None, plots=False)
    assert rr.report["scenario"] == "wen-5.1"
    assert rr.metrics["theta_err_rms_deg"] == first.metrics["theta_err_rms_deg"]


def _row(out: str, key: str) -> list[str]:
    (line,) = [s for s in out.splitlines() if s.split() and s.split()[0] == key]
    return line.split()


def test_cli_analyze_prints_the_papers_column_and_the_files_written(
    lone: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    paper = load_scenario("wen-5.1").paper_result
    out_dir = tmp_path / "o"
    args = argparse.Namespace(log=str(lone), out=str(out_dir), scenario="wen-5.1", no_plots=True)
    assert cmd_analyze(args) == 0
    out = capsys.readouterr().out
    for key in ("theta_err_max_deg", "theta_err_min_deg", "theta_err_mean_deg"):
        # the paper's number stands on the row of the quantity it is (Wen's "dtheta avg"
        # beside the mean |dtheta|: PAPER_COMPARED_AS)
        row = _row(out, PAPER_COMPARED_AS.get(key, key))
        assert float(row[2]) == paper[key], row
    (files,) = [s for s in out.splitlines() if s.startswith("files:")]
    names = files.split("(", 1)[1].rstrip(")").split(", ")
    assert "run.png" not in names
    assert all((out_dir / n).is_file() for n in names), names
    assert not (out_dir / "run.png").exists()


def test_cli_rerun_lists_only_the_files_written(
    lone: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    out_dir = tmp_path / "rr"
    args = argparse.Namespace(
        log=str(lone), estimator="tt-ab", scenario="wen-5.1", out=str(out_dir), no_plots=True
    )
    assert cmd_rerun(args) == 0
    out = capsys.readouterr().out
    (files,) = [s for s in out.splitlines() if s.startswith("files:")]
    names = files.split("(", 1)[1].rstrip(")").split(", ")
    assert "run.png" not in names and "rerun.json" in names
    assert all((out_dir / n).is_file() for n in names), names
    assert sorted(p.name for p in out_dir.iterdir()) == sorted(names)
    # as for a live run: the paper's numbers are tt-dq's, so not beside tt-ab's
    assert "(the paper's numbers are for tt-dq; this run is tt-ab)" in out
    assert out.splitlines()[0].split() == ["metric", "bench"]


def test_metadata_without_a_scenario_asks_for_one(
    lone: Path, capsys: pytest.CaptureFixture
) -> None:
    from bench.cli import main

    (lone.parent / "meta.json").write_text('{"analyzed_from": "elsewhere"}')
    rc = main(["analyze", str(lone)])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1, err
    assert "meta.json: no scenario" in err[0] and "--scenario" in err[0]
