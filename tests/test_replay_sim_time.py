"""``bench replay --time sim``: a lockstep capture replayed in simulated time, not at the
slowed pace at which the lockstep processes recorded it."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import can
import numpy as np
import pytest

from bench.captures._read import read_capture
from bench.captures._replay import TIMES, sim_timestamps, with_timestamps
from bench.cli import main
from bench.cli.replay import TIMES as CLI_TIMES
from bench.wire._codec import Codec
from tests.replay_helpers import recorded_run

CODEC = Codec()
T_S = 1e-4  # wen-5.1: 10 kHz


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return recorded_run(tmp_path_factory, "tt-dq")


def test_the_cli_offers_the_replay_time_lines() -> None:
    assert CLI_TIMES == TIMES == ("wall", "sim")


def test_every_truth_frame_is_at_its_step_and_the_rest_keep_their_order(run: Path) -> None:
    frames, _ = read_capture(run / "capture.blf")
    stamps = np.asarray(sim_timestamps(frames, CODEC, T_S))
    tid = CODEC.frame_id("PlantTruth")
    truth = [(i, CODEC.decode(m)) for i, m in enumerate(frames) if m.arbitration_id == tid]
    steps = np.array([d.signals["step"] for _, d in truth if d is not None])
    at = stamps[[i for i, _ in truth]]
    np.testing.assert_allclose(at, steps * T_S, rtol=0, atol=1e-12)
    # the run is 0.2 s simulated (2001 periods); its capture was recorded at the lockstep
    # pair's own pace (slower than real time for the Python nodes, faster for the native
    # ones), so its timestamps are not the periods' times: the replay's are
    assert at[-1] - at[0] == pytest.approx(2000 * T_S, abs=1e-12)
    rec = np.array([frames[i].timestamp for i, _ in truth])
    assert np.max(np.abs((rec - rec[0]) - (at - at[0]))) > 1e-3
    # between two truth frames the other frames keep the capture's order
    first, last = truth[0][0], truth[-1][0]
    rec = np.array([m.timestamp for m in frames[first : last + 1]])
    order = np.argsort(rec, kind="stable")
    assert np.all(np.diff(stamps[first : last + 1][order]) >= 0)
    # the samples of step k are sent in period k (within one period of its truth)
    sid = CODEC.frame_id("PhaseSamples")
    for i, m in enumerate(frames[first:last], start=first):
        if m.arbitration_id == sid:
            d = CODEC.decode(m)
            assert d is not None
            k = int(round(stamps[i] / T_S))
            assert k % 1024 == int(d.signals["step"]) or (k + 1) % 1024 == int(d.signals["step"])


def test_frames_outside_the_anchored_span_keep_their_gaps(run: Path) -> None:
    frames, _ = read_capture(run / "capture.blf")
    stamps = sim_timestamps(frames, CODEC, T_S)
    tid = CODEC.frame_id("PlantTruth")
    idx = [i for i, m in enumerate(frames) if m.arbitration_id == tid]
    i0, i1 = idx[0], idx[-1]
    for j in range(i0):
        gap = frames[i0].timestamp - frames[j].timestamp
        assert stamps[i0] - stamps[j] == pytest.approx(gap, abs=1e-9)
    for j in range(i1 + 1, len(frames)):
        gap = frames[j].timestamp - frames[i1].timestamp
        assert stamps[j] - stamps[i1] == pytest.approx(gap, abs=1e-9)
    moved = with_timestamps(frames, stamps)
    assert [m.timestamp for m in moved] == stamps
    assert [bytes(m.data) for m in moved] == [bytes(m.data) for m in frames]
    assert [m.channel for m in moved] == [m.channel for m in frames]


def test_without_truth_the_samples_anchor_the_time_line(run: Path) -> None:
    frames, _ = read_capture(run / "capture.blf")
    tid = CODEC.frame_id("PlantTruth")
    no_truth = [m for m in frames if m.arbitration_id != tid]
    stamps = np.asarray(sim_timestamps(no_truth, CODEC, T_S))
    sid = CODEC.frame_id("PhaseSamples")
    s_idx = [i for i, m in enumerate(no_truth) if m.arbitration_id == sid]
    # 2001 samples over 10-bit counters that wrap at 1024: unwrapped, one period apart
    firsts = sorted(set(np.round(stamps[s_idx] / T_S).astype(int).tolist()))
    assert firsts == list(range(firsts[0], firsts[0] + 2001))


def test_cli_replays_a_lockstep_capture_in_simulated_time(
    run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    chan = f"simtime{os.getpid()}"
    rx = can.Bus(interface="virtual", channel=chan, receive_own_messages=False)
    try:
        argv = ["replay", str(run), "--interface", "virtual", "--channel", chan]
        assert main([*argv, "--time", "sim", "--speed", "0.5"]) == 0
        got: list[can.Message] = []
        while (r := rx.recv(0.1)) is not None:
            got.append(r)
    finally:
        rx.shutdown()
    frames, _ = read_capture(run / "capture.blf")
    assert len(got) == len(frames)
    err = capsys.readouterr().err
    # the capture spans its recording time; the replay the simulated 0.2 s (and the
    # gaps before the first and after the last period, kept as recorded)
    assert "--time sim:" in err and "s of simulated time (T_s 0.0001 s)" in err
    stamps = sim_timestamps(frames, CODEC, T_S)
    sim_span = max(stamps) - min(stamps)
    line = next(ln for ln in err.splitlines() if ln.startswith("replay: ") and " of " in ln)
    assert f"{sim_span:.3f} s of simulated time" in line
    # the default names the pace and the way out (a lockstep run's meta.json)
    assert main(["replay", str(run), "--interface", "virtual", "--channel", chan + "x",
                 "--speed", "50"]) == 0  # fmt: skip
    assert "--time sim replays it in simulated time" in capsys.readouterr().err


def test_cli_sim_time_needs_the_period(
    run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    alone = tmp_path / "alone.blf"
    shutil.copy(run / "capture.blf", alone)
    argv = ["replay", str(alone), "--interface", "virtual", "--channel", "x", "--time", "sim"]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--time sim:" in err[0] and "--scenario" in err[0], err
    assert main([*argv[:-2], "--scenario", "wen-5.1"]) == 2  # a scenario for wall time
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--scenario" in err[0], err
    chan = f"simtime-s{os.getpid()}"
    ok = ["replay", str(alone), "--interface", "virtual", "--channel", chan, "--time", "sim"]
    assert main([*ok, "--scenario", "wen-5.1", "--speed", "4"]) == 0
