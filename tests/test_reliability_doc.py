"""docs/RELIABILITY.md is the rendering of docs/reliability/soak.json, and that run passed.

The page is written by ``bench soak --processes --doc`` (``make reliability``)
from the JSON it writes; no figure is typed by hand.  These tests fail when
the page and its JSON disagree, and when the committed run is not what the
page claims: at least 100,000 frames at each node, classic and CAN FD, no
crash, every rejection counted, every process-level check passed.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from bench.cli import main
from bench.studies._reliability import process_checks_ok, render_reliability

ROOT = Path(__file__).resolve().parents[1]
JSON = ROOT / "docs" / "reliability" / "soak.json"
DOC = ROOT / "docs" / "RELIABILITY.md"


@pytest.fixture(scope="module")
def committed() -> dict[str, Any]:
    return dict(json.loads(JSON.read_text()))


def test_the_page_is_the_rendering_of_its_json(committed: dict[str, Any]) -> None:
    assert DOC.read_text() == render_reliability(committed)


def test_the_page_changes_with_its_json(committed: dict[str, Any]) -> None:
    other = json.loads(json.dumps(committed))
    other["exceptions"] = 1
    assert render_reliability(other) != DOC.read_text()


def test_from_json_renders_the_same_page(tmp_path: Path) -> None:
    out = tmp_path / "RELIABILITY.md"
    assert main(["soak", "--from-json", str(JSON), "--doc", str(out)]) == 0
    assert out.read_text() == DOC.read_text()


def test_the_committed_run_fuzzed_both_nodes_classic_and_fd(committed: dict[str, Any]) -> None:
    r = committed
    assert r["ok"] is True and r["exceptions"] == 0 and r["violations"] == 0
    assert r["unchecked_rejections"] == 0 and r["data_lost_periods"] == 0
    for node in ("plant", "controller"):
        n = r[f"frames_fuzzed_{node}"]
        fd = r["frames_fd"][node]
        assert n >= 100_000, node
        assert 0 < fd < n, node  # both kinds of frame, at each node
    assert sum(v for k, v in r["rejected"].items() if k != "repeated_counter") > 0
    assert r["recoveries"] == sum(r["faults_injected"].values()) > 0


def test_the_committed_run_passed_every_process_check(committed: dict[str, Any]) -> None:
    p = committed["processes"]
    assert process_checks_ok(p)
    det = p["determinism_under_load"]
    assert det["busy_processes"] > (p["cpus"] or 1)  # more busy processes than CPUs
    assert {c["case"].split(" (")[0] for c in det["cases"]} >= {"through the latency link"}
    assert all(c["runs"] >= 3 and c["diverged"] == [] for c in det["cases"])
    kills = {(k["mode"], k["killed"]) for k in p["kills"]}
    assert ("lockstep", "controller") in kills and ("realtime", "controller") in kills
    lock = [k for k in p["kills"] if k["mode"] == "lockstep"]
    assert all(k["names_signal"] and "killed by SIGKILL" in k["message"] for k in lock)
    assert {s["signal"] for s in p["signals"]} == {"SIGINT", "SIGTERM"}
    # two runs on one bus: each gives the in-process trace or refuses with one line
    shared = p["parallel"]["shared_bus_runs"]
    assert len(shared) == 2 and all(r["outcome"] in ("identical", "refused") for r in shared)
    assert all("another run" in r["detail"] for r in shared if r["outcome"] == "refused")


def test_a_soak_without_processes_renders_and_says_so(tmp_path: Path) -> None:
    out, doc = tmp_path / "soak.json", tmp_path / "page.md"
    argv = ["soak", "--frames", "400", "--loop-periods", "1000", "--fault-every", "400", "-q"]
    assert main([*argv, "--out", str(out), "--doc", str(doc)]) == 0
    rep = json.loads(out.read_text())
    page = doc.read_text()
    assert page == render_reliability(rep)
    assert "`bench soak --frames 400 --loop-periods 1,000 --seed 0`" in page
    assert "No process-level checks" in page
    assert rep["frames_fd"]["plant"] > 0 and rep["frames_fd"]["controller"] > 0
