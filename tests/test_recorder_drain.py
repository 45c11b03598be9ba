"""The recording's end (bench/runs/_recorder.py): it waits for what its sockets still hold,
and no longer than that."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import pytest

from bench.runs import _recorder
from bench.runs._recorder import DRAIN_POLL_S, Recording, drain, queued_bytes
from bench.wire._bus import BusSpec
from bench.wire._codec import Codec
from tests.ports import free_port

N_FRAMES = 3000


def _frame() -> Any:
    import can

    return can.Message(arbitration_id=0x7F0, is_extended_id=False, data=bytes(8))


def test_a_udp_socket_says_what_waits_in_it() -> None:
    spec = BusSpec("udp_multicast", "239.74.163.9", free_port())
    rx, tx = spec.open(), spec.open()
    try:
        assert queued_bytes(rx) == 0
        tx.send(_frame())
        t_end = time.monotonic() + 5.0
        while not queued_bytes(rx) and time.monotonic() < t_end:
            time.sleep(0.01)
        assert (queued_bytes(rx) or 0) > 0
        assert rx.recv(1.0) is not None
        assert queued_bytes(rx) == 0
    finally:
        rx.shutdown()
        tx.shutdown()


def test_the_recording_keeps_every_frame_its_socket_holds(tmp_path: Path) -> None:
    spec = BusSpec("udp_multicast", "239.74.163.9", free_port())
    rec = Recording([spec], tmp_path / "capture.blf", Codec())
    sender = spec.open()
    try:
        for i in range(N_FRAMES):
            sender.send(_frame())
            if i % 100 == 99:
                time.sleep(0.002)  # no more than a receive buffer holds at once
        rec.close()  # at once: the recorder thread may still be far behind
    finally:
        sender.shutdown()
    got = [m for m in rec.frames() if m.arbitration_id == 0x7F0]
    assert len(got) == N_FRAMES and rec.frames_lost == 0


class _Clock:
    """time.monotonic and time.sleep of the drain, on a clock of the test's own."""

    def __init__(self) -> None:
        self.now = 0.0

    def monotonic(self) -> float:
        return self.now

    def sleep(self, s: float) -> None:
        self.now += s


@pytest.mark.parametrize(
    ("queued", "waits_s"),
    [
        ([0], DRAIN_POLL_S),  # every socket empty, nothing new for one look: done (not 0.5 s)
        ([0, 0], DRAIN_POLL_S),
        ([0, 40], 0.5),  # a socket still holds a frame the recorder does not take: quiet_s
        ([None], 0.5),  # a socket that cannot say (SocketCAN): quiet_s, as before
        ([], 0.5),
    ],
)
def test_the_drain_ends_one_look_after_its_sockets_are_empty(
    monkeypatch: pytest.MonkeyPatch, queued: list[int | None], waits_s: float
) -> None:
    clock = _Clock()
    monkeypatch.setattr(_recorder, "time", clock)
    answers = iter(queued * 1000)
    monkeypatch.setattr(_recorder, "queued_bytes", lambda bus: next(answers))

    class Rec:
        def __init__(self) -> None:
            self.frames = [1, 2, 3]  # nothing new comes in

    drain([Rec()], quiet_s=0.5, buses=[object()] * len(queued))  # type: ignore[list-item]
    # within one look of the rule's time (the looks are DRAIN_POLL_S apart)
    assert waits_s - 1e-9 <= clock.now <= waits_s + DRAIN_POLL_S + 1e-9
