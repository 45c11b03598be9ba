"""``bench soak`` on its normal path: a short soak through the CLI, and its report.

The soak fuzzes the plant node (half the frames in real time, half in
lockstep) and the controller node with ``--frames`` frames each, then runs a
closed loop of ``--loop-periods`` periods with junk frames every period and a
fault every ``--fault-every`` periods (alternately duty starvation and
forged full-scale duties).  The JSON report must add up: every fuzzed frame
accounted for, every rejection counted by the node as the oracle expected,
every injected fault tripped and recovered, and no sample period lost.
"""

from __future__ import annotations

import contextlib
import io
import json
import re
from pathlib import Path
from typing import Any

import pytest

from bench.cli import main

FRAMES = 2000
LOOP = 3000
EVERY = 500

Soak = tuple[int, dict[str, Any], str]


def soak(out: Path, frames: int = FRAMES, seed: int = 0) -> Soak:
    """Exit code, JSON report and standard output of ``bench soak``."""
    args = ["soak", "--frames", str(frames), "--loop-periods", str(LOOP)]
    args += ["--fault-every", str(EVERY), "--seed", str(seed), "--quiet", "--out", str(out)]
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        rc = main(args)
    return rc, json.loads(out.read_text()), buf.getvalue()


@pytest.fixture(scope="module")
def report(tmp_path_factory: pytest.TempPathFactory) -> Soak:
    return soak(tmp_path_factory.mktemp("soak") / "soak.json")


def test_soak_passes_and_says_so(report: Soak) -> None:
    rc, rep, text = report
    assert rc == 0
    assert rep["ok"] is True
    assert text.strip().splitlines()[-1] == "soak: ok"
    assert rep["notes"] == []
    assert rep["seed"] == 0


def test_every_fuzzed_frame_is_accounted_for(report: Soak) -> None:
    _, rep, text = report
    # each node got the frames asked for: the plant half in real time, half in lockstep
    assert rep["frames_fuzzed_plant"] == 2 * (FRAMES // 2) == FRAMES
    assert rep["frames_fuzzed_controller"] == FRAMES
    assert rep["frames_fuzzed_loop"] >= LOOP  # 1 to 6 junk frames every period
    assert rep["frames_fuzzed"] == (
        rep["frames_fuzzed_plant"] + rep["frames_fuzzed_controller"] + rep["frames_fuzzed_loop"]
    )
    assert rep["frames_fuzzed"] >= 2 * FRAMES
    assert rep["exceptions"] == 0
    assert rep["violations"] == 0
    # the nodes' counts of frames seen and of rejections match the oracle's
    assert rep["unchecked_rejections"] == 0
    m = re.search(r"frames fuzzed (\d+) \(plant (\d+), controller (\d+), closed loop (\d+)\)", text)
    assert m is not None, text
    assert [int(g) for g in m.groups()] == [
        rep["frames_fuzzed"],
        rep["frames_fuzzed_plant"],
        rep["frames_fuzzed_controller"],
        rep["frames_fuzzed_loop"],
    ]


def test_rejections_are_counted_by_reason(report: Soak) -> None:
    _, rep, text = report
    rej = rep["rejected"]
    # the fuzzer's bad lengths and bad checksums were all seen and counted
    assert rej.get("bad_length", 0) > 0
    assert rej.get("bad_crc", 0) > 0
    assert all(isinstance(v, int) and v > 0 for v in rej.values())
    # a rejection is a junk frame: no more of them than frames fuzzed
    assert sum(rej.values()) <= rep["frames_fuzzed"]
    # the printed total is the per-reason sum without repeats (counted apart)
    m = re.search(r"; rejected (\d+);", text)
    assert m is not None, text
    assert int(m.group(1)) == sum(v for k, v in rej.items() if k != "repeated_counter")


def test_every_injected_fault_trips_and_recovers(report: Soak) -> None:
    _, rep, text = report
    faults = rep["faults_injected"]
    # faults at periods 500, 1000, ... before the loop's end, alternating kinds
    assert set(faults) == {"watchdog", "over_current"}
    assert sum(faults.values()) == LOOP // EVERY - 1
    assert rep["recoveries"] == sum(faults.values())
    for kind, n in faults.items():
        assert rep["trips"].get(kind, 0) >= n, kind
    assert rep["loop_periods"] == LOOP
    assert rep["data_lost_periods"] == 0
    assert f"faults injected {sum(faults.values())}, recoveries {rep['recoveries']}" in text


def test_the_soak_is_reproducible_from_its_seed(report: Soak, tmp_path: Path) -> None:
    _, rep, _ = report
    _, again, _ = soak(tmp_path / "again.json")
    _, other, _ = soak(tmp_path / "other.json", seed=1)
    drop = {"wall_s"}
    assert {k: v for k, v in again.items() if k not in drop} == {
        k: v for k, v in rep.items() if k not in drop
    }
    assert other["ok"] is True
    assert other["rejected"] != rep["rejected"]


def test_an_odd_frame_count_reaches_the_plant_in_full(tmp_path: Path) -> None:
    rc, rep, _ = soak(tmp_path / "odd.json", frames=1001)
    assert rc == 0
    assert rep["frames_fuzzed_controller"] == 1001
    assert rep["frames_fuzzed_plant"] >= 1001
