"""The native recorder on SocketCAN (bench/nodes/native/bn_rec.c ``bn_rec_open_can``): the
same capture as python-can's socketcan bus, and the frames the kernel dropped counted."""

from __future__ import annotations

import socket
import time
from pathlib import Path

import can
import pytest

from bench.nodes.native import _recorder_native
from bench.runs._recorder import Recording
from bench.wire._bus import BusSpec
from bench.wire._codec import Codec
from tests.conftest import require_vcan
from tests.test_recorder_native import _fields, _known_frames, _wait_for

pytestmark = [
    pytest.mark.socketcan,
    pytest.mark.skipif(
        _recorder_native.unavailable("socketcan") is not None,
        reason="the native library does not build here",
    ),
]


def test_native_and_python_recorders_write_the_same_capture_on_vcan(tmp_path: Path) -> None:
    require_vcan("vcan0")
    codec = Codec()
    spec = BusSpec("socketcan", "vcan0")
    # both listen at once: the kernel stamps each frame once, for every socket
    native = Recording([spec], tmp_path / "native.blf", codec)
    python = Recording([spec], tmp_path / "python.blf", codec, engine="python")
    frames = _known_frames(codec)
    sender = can.Bus(interface="socketcan", channel="vcan0", fd=True)
    try:
        assert native.engine == "native" and native.engine_note is None
        assert python.engine == "python"
        for m in frames:
            sender.send(m)
        _wait_for(lambda: min(len(native.frames()), len(python.frames())) >= len(frames))
    finally:
        sender.shutdown()
        native.close()
        python.close()
    assert len(native.frames()) == len(python.frames()) == len(frames)
    # python-can's socketcan bus does not say what it lost; the native reader does
    assert native.frames_lost == 0 and python.frames_lost is None
    assert native.recorders[0].step == python.recorders[0].step == 39
    assert [_fields(m) for m in native.frames()] == [_fields(m) for m in python.frames()]
    a = [_fields(m) for m in can.BLFReader(str(tmp_path / "native.blf"))]
    b = [_fields(m) for m in can.BLFReader(str(tmp_path / "python.blf"))]
    assert len(a) == len(frames) and a == b
    assert [(m.arbitration_id, bytes(m.data), m.is_fd) for m in native.frames()] == [
        (m.arbitration_id, bytes(m.data), m.is_fd) for m in frames
    ]


def test_the_kernels_drops_on_vcan_are_counted(tmp_path: Path) -> None:
    """A reader whose socket's queue overflows (the C thread held off by a tiny receive
    buffer and a burst) counts every frame the kernel dropped: received + lost = sent."""
    require_vcan("vcan0")
    got: list[can.Message] = []

    class Keep(can.Listener):
        def on_message_received(self, msg: can.Message) -> None:
            got.append(msg)

    reader = _recorder_native.NativeReader(
        "vcan0", 0, Keep(), interface="socketcan", rcvbuf=1, poll_s=0.05
    )
    # the kernel's smallest receive buffer holds a few frames; a burst from a raw socket
    # (no python-can per frame) outruns a reader that naps 1 ms after each drain
    n = 20000
    with socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW) as tx:
        tx.bind(("vcan0",))
        frame = (0x321).to_bytes(4, "little") + bytes([8, 0, 0, 0]) + bytes(8)
        sent = 0
        for _ in range(n):
            try:
                tx.send(frame)
                sent += 1
            except OSError:  # ENOBUFS: the interface's own queue is full; try again
                time.sleep(0.0005)
        # the kernel says a socket's drops with the next frame it queues for it: one
        # more, once the reader has caught up, carries the count of the whole burst
        _wait_for(lambda: reader.pending() == 0, 30.0)
        tx.send(frame)
        sent += 1
    _wait_for(lambda: reader.pending() == 0 and len(got) + reader.stats()["kernel_drops"] >= sent)
    reader.stop()
    st = reader.stats()
    reader.close()
    assert len(got) == st["frames"] == st["received"]
    assert st["kernel_drops"] > 0, st  # the burst did overflow the socket's queue
    assert st["received"] + st["kernel_drops"] + st["ring_lost"] + st["unread"] == sent, st
