"""The two-process bench on SocketCAN (vcan): lockstep trace, latency link, CAN FD, capture.

The same checks ``test_bench_loop.py`` makes over udp_multicast, on a real
SocketCAN stack: the lockstep run between ``bench plant`` and ``bench
controller`` processes on vcan0 reproduces the in-process trace exactly, also
through the ``bench link`` process between vcan0 and vcan1 with injected
latency; the recorder frames (PlantTruth, CtrlTelemetry) travel as CAN FD; and
the recorded capture is read back by ``bench analyze``.  Scenarios are short
(User-Mode Linux closes about a thousand periods per second).
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import can
import numpy as np
import pytest

from bench.cli import main
from bench.nodes._loops import run_inprocess
from bench.runs._results import RunResult
from bench.runs._run import run_scenario
from bench.scenarios._schema import Latency, Scenario
from bench.wire._bus import BusSpec
from tests.conftest import require_vcan
from tests.trace_helpers import CODEC, assert_same_trace, short, trace

pytestmark = pytest.mark.socketcan

VCAN0 = BusSpec("socketcan", "vcan0")


@pytest.fixture(scope="module")
def lockstep_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Scenario, RunResult]:
    require_vcan("vcan0")
    scn = short("wen-5.1", 0.15)
    out = tmp_path_factory.mktemp("vcan") / "run"
    return scn, run_scenario(scn, "sensored", spec=VCAN0, out_dir=out, progress=False)


def test_two_processes_on_vcan0_equal_inprocess(lockstep_run: tuple[Scenario, RunResult]) -> None:
    scn, res = lockstep_run
    ref = trace(run_inprocess(scn, "sensored", CODEC), scn)
    frames = list(can.LogReader(str(res.capture)))
    assert_same_trace(ref, trace(frames, scn))
    assert res.metrics["steps"] == len(ref["step"])
    assert res.metrics["frames_rejected"] == 0
    assert res.meta["transport"] == "socketcan:vcan0"
    # the native recorder reads SocketCAN, and says what it lost (python-can's bus cannot)
    assert res.meta["recorder"]["engine"] == "native", res.meta["recorder"]
    assert res.meta["recorder_frames_lost"] == 0
    # a closed loop that moves: the motor turns under sensored FOC
    assert ref["w_m_rpm"][-1] > 20.0


def test_recorder_frames_are_can_fd(lockstep_run: tuple[Scenario, RunResult]) -> None:
    """PlantTruth and CtrlTelemetry (over 8 bytes) cross vcan0 as CAN FD; drive frames are classic."""
    _, res = lockstep_run
    frames = list(can.LogReader(str(res.capture)))
    by_id: dict[int, list[can.Message]] = {}
    for f in frames:
        by_id.setdefault(f.arbitration_id, []).append(f)
    steps = res.metrics["steps"]
    for name in ("PlantTruth", "CtrlTelemetry"):
        got = by_id[CODEC.frame_id(name)]
        assert len(got) >= steps
        assert CODEC.length(name) > 8
        assert all(f.is_fd and len(f.data) == CODEC.length(name) for f in got), name
    for name in ("PwmDuty", "PhaseSamples"):
        got = by_id[CODEC.frame_id(name)]
        assert len(got) >= steps
        assert not any(f.is_fd for f in got) and all(len(f.data) == 8 for f in got), name


def test_capture_is_read_back_by_bench_analyze(
    lockstep_run: tuple[Scenario, RunResult], tmp_path: Path
) -> None:
    _, res = lockstep_run
    out = tmp_path / "analysis"
    assert main(["analyze", str(res.capture), "--out", str(out)]) == 0
    again = json.loads((out / "metrics.json").read_text())
    for key in ("steps", "theta_err_max_deg", "theta_err_rms_deg", "speed_err_max_rpm"):
        assert again[key] == pytest.approx(res.metrics[key], rel=1e-12, abs=1e-12), key
    live = np.genfromtxt(res.out_dir / "signals.csv", delimiter=",", names=True)
    read = np.genfromtxt(out / "signals.csv", delimiter=",", names=True)
    np.testing.assert_array_equal(live["w_m_rpm"], read["w_m_rpm"])


def test_lockstep_latency_through_link_between_vcan0_and_vcan1(tmp_path: Path) -> None:
    require_vcan("vcan0", "vcan1")
    assert VCAN0.peer() == BusSpec("socketcan", "vcan1")
    scn = short("wen-5.1", 0.06, duty_delay_steps=2, sample_delay_steps=1)
    ref = trace(run_inprocess(scn, "sensored", CODEC), scn)
    res = run_scenario(scn, "sensored", spec=VCAN0, out_dir=tmp_path / "lat", progress=False)
    frames = list(can.LogReader(str(res.capture)))
    assert_same_trace(ref, trace(frames, scn))
    # frames crossed the link both ways, and the plant saw its duties 2 + 1 periods old
    lat = res.metrics["latency_measured"]
    assert lat["samples"]["frames"] > 0 and lat["duties"]["frames"] > 0
    assert res.metrics["loop_latency_steps"]["median"] == 3
    # and the delay is real: the same run without it differs
    ref0 = trace(run_inprocess(replace(scn, latency=Latency()), "sensored", CODEC), scn)
    n = min(len(ref0["i_a"]), len(ref["i_a"]))
    assert not np.allclose(ref0["i_a"][:n], ref["i_a"][:n])
