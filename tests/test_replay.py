"""``bench replay``: a capture back onto a bus with its recorded timing.

Received on a second bus object: the same IDs, payloads and order, and the
receive times follow the capture's time line within the error the replay
reports (plus a generous allowance for the transport; no tight timing
assertion on a shared machine).
"""

from __future__ import annotations

import os
from pathlib import Path

import can
import numpy as np
import pytest

from bench._errors import BenchError
from bench.captures._read import (
    read_capture,
)
from bench.captures._replay import (
    parse_id_map,
    replay_frames,
    schedule,
    select_frames,
)
from bench.cli import main
from bench.wire._bus import BusSpec
from tests.ports import free_port
from tests.replay_helpers import recorded_run


@pytest.fixture(scope="module")
def frames(tmp_path_factory: pytest.TempPathFactory) -> list[can.Message]:
    fr, _ = read_capture(recorded_run(tmp_path_factory, "tt-dq") / "capture.blf")
    return fr


def drain(reader: can.BufferedReader) -> list[can.Message]:
    out = []
    while (m := reader.get_message(0.2)) is not None:
        out.append(m)
    return out


PACE_FRAMES_PER_S = 3000.0


def _pace(chosen: list[can.Message]) -> float:
    """Replay speed for about 3,000 frames/s.

    The capture holds up to 40,000 frames/s (10 kHz). A sender on a loaded
    machine that runs at its own limit never catches up after a stall, and
    then the time line says nothing about the replay; at a tenth of that rate
    it has the spare rate to catch up, which is what the absolute schedule is
    for.
    """
    span = chosen[-1].timestamp - chosen[0].timestamp
    return PACE_FRAMES_PER_S * span / len(chosen)


def _keeps_the_time_line(rel: np.ndarray, want: np.ndarray) -> None:
    """The frames arrive on the capture's (stretched) time line.

    Relative to the span, so that a busy machine does not fail it: the slope
    of the received times against the schedule is 1 within 5 % (frames dumped
    at once give 0, a wrong pace gives the pace's ratio), and the median
    distance from the fitted line is under 3 % of the span (a stall of the
    machine makes a few frames late, the schedule is absolute, so the replay
    catches up). Tight timing belongs in ``bench perf``, not here.
    """
    slope, offset = np.polyfit(want, rel, 1)
    assert 0.95 <= slope <= 1.05, slope
    resid = np.abs(rel - (slope * want + offset))
    assert np.median(resid) <= 0.03 * want[-1], (np.median(resid), want[-1])
    assert want[-1] >= 0.5  # long enough for a stall to be a small part of it


@pytest.mark.parametrize("clock", ["deadline", "messagesync"])
def test_replay_on_virtual_bus_keeps_frames_order_and_timing(
    frames: list[can.Message], clock: str
) -> None:
    chosen = select_frames(frames[:3000])
    chan = f"replay{os.getpid()}{clock}"
    tx = can.Bus(interface="virtual", channel=chan)
    rx = can.Bus(interface="virtual", channel=chan)
    speed = _pace(chosen)
    try:
        res = replay_frames(tx, chosen, clock=clock, speed=speed)
        got = []
        while (m := rx.recv(0.1)) is not None:
            got.append(m)
    finally:
        tx.shutdown()
        rx.shutdown()
    assert res.sent == len(chosen) == len(got)
    assert [m.arbitration_id for m in got] == [m.arbitration_id for m in chosen]
    assert [bytes(m.data) for m in got] == [bytes(m.data) for m in chosen]
    assert [m.is_fd for m in got] == [m.is_fd for m in chosen]
    # the virtual bus stamps each frame when it is sent: relative to the first
    # one, the stamps follow the capture's (stretched) time line
    want = (np.array([m.timestamp for m in chosen]) - chosen[0].timestamp) / speed
    rel = np.array([m.timestamp for m in got]) - got[0].timestamp
    # python-can's MessageSync does not sleep for less than 100 us, so it sends
    # up to 100 us early by design; the deadline clock never sends early
    early_us = 1.0 if clock == "deadline" else 100.0
    assert res.error_worst_us >= res.error_median_us >= -early_us
    _keeps_the_time_line(rel, want)
    # and the replay took the capture's time, not less (frames were not just dumped)
    assert res.wall_s >= 0.99 * want[-1]


def test_replay_on_udp_multicast(frames: list[can.Message]) -> None:
    chosen = select_frames(frames[:2000])
    spec = BusSpec("udp_multicast", "239.74.163.3", free_port())
    rx = spec.open()  # with a large receive buffer: a busy machine must not drop frames
    tx = spec.open()
    reader = can.BufferedReader()
    notifier = can.Notifier(rx, [reader], timeout=0.05)
    span = chosen[-1].timestamp - chosen[0].timestamp
    speed = _pace(chosen)
    try:
        res = replay_frames(tx, chosen, speed=speed)
        got = drain(reader)
    finally:
        notifier.stop()
        tx.shutdown()
        rx.shutdown()
    assert len(got) == len(chosen)
    assert [(m.arbitration_id, bytes(m.data)) for m in got] == [
        (m.arbitration_id, bytes(m.data)) for m in chosen
    ]
    assert res.wall_s >= 0.99 * span / speed
    rel = np.array([m.timestamp for m in got]) - got[0].timestamp
    want = (np.array([m.timestamp for m in chosen]) - chosen[0].timestamp) / speed
    _keeps_the_time_line(rel, want)


TAGGED: list[tuple[int, int | str]] = [
    (0x10, 1),
    (0x11, 1),
    (0x10, 2),
    (0x20, "can2"),
    (0x11, "can1"),
]


def test_filters_and_id_map() -> None:
    ms = [
        can.Message(
            timestamp=0.001 * i,
            arbitration_id=fid,
            is_extended_id=False,
            data=bytes([i]),
            channel=ch,
        )
        for i, (fid, ch) in enumerate(TAGGED)
    ]
    out = select_frames(ms, channels=[1], id_map=parse_id_map(["0x10=0x210", "17=0x1FFFF"]))
    assert [(m.arbitration_id, m.is_extended_id, m.data[0]) for m in out] == [
        (0x210, False, 0),
        (0x1FFFF, True, 1),
        (0x1FFFF, True, 4),
    ]
    assert all(m.channel is None for m in out)
    out = select_frames(ms, ids=[0x10, 0x20], exclude_ids=[0x20])
    assert [m.data[0] for m in out] == [0, 2]
    offs, cut = schedule(
        [can.Message(timestamp=t) for t in (10.0, 10.5, 15.5, 15.6)], speed=2.0, max_gap_s=1.0
    )
    assert offs == pytest.approx([0.0, 0.25, 0.75, 0.8])
    assert cut == pytest.approx(2.0)
    with pytest.raises(BenchError):
        parse_id_map(["0x10:0x210"])


def test_loops_continue_on_one_time_line(frames: list[can.Message]) -> None:
    chosen = select_frames(frames[:200])
    chan = f"loop{os.getpid()}"
    tx = can.Bus(interface="virtual", channel=chan)
    rx = can.Bus(interface="virtual", channel=chan)
    try:
        res = replay_frames(tx, chosen, loops=3, speed=4.0)
        n = 0
        while rx.recv(0.1) is not None:
            n += 1
    finally:
        tx.shutdown()
        rx.shutdown()
    assert n == res.sent == 600 and res.loops == 3
    span = (chosen[-1].timestamp - chosen[0].timestamp) / 4.0
    assert res.wall_s >= 2.9 * span


def test_cli_replay(
    tmp_path: Path, frames: list[can.Message], capsys: pytest.CaptureFixture
) -> None:
    path = tmp_path / "small.asc"
    with can.Logger(str(path)) as w:
        for m in frames[:300]:
            w.on_message_received(m)
    chan = f"cli{os.getpid()}"
    rx = can.Bus(interface="virtual", channel=chan)
    try:
        argv = ["replay", str(path), "--interface", "virtual", "--channel", chan]
        rc = main([*argv, "--speed", "4", "--map", "0x10=0x210", "--channel-filter", "1"])
        got: list[can.Message] = []
        while (r := rx.recv(0.1)) is not None:
            got.append(r)
    finally:
        rx.shutdown()
    out = capsys.readouterr().out
    assert rc == 0
    assert "timing error vs capture: median" in out and "worst" in out
    assert len(got) == 300
    assert 0x210 in {m.arbitration_id for m in got} and 0x10 not in {m.arbitration_id for m in got}
    for argv in (
        ["replay", str(tmp_path / "nope.blf"), "--interface", "virtual"],
        ["replay", str(path), "--interface", "virtual", "--map", "0x10"],
        ["replay", str(path), "--interface", "virtual", "--id", "0x555"],
        ["replay", str(path), "--interface", "virtual", "--speed", "0"],
    ):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("bench: error: "), err
