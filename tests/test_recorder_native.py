"""The native recorder (bench/nodes/native/bn_rec.c, ``_recorder_native.py``): the same
capture as python-can's reader, every lost frame counted, and the Python recorder where
the native one cannot serve."""

from __future__ import annotations

import socket
import threading
import time
from pathlib import Path
from typing import Any

import can
import pytest

from bench.nodes.native import _recorder_native
from bench.runs import _recorder
from bench.runs._recorder import Recording, fd_drops
from bench.wire._bus import BusSpec, udp_multicast_group
from bench.wire._codec import Codec
from tests.conftest import require_vcan
from tests.frame_helpers import message_fields
from tests.ports import free_port

pytestmark = pytest.mark.skipif(
    _recorder_native.unavailable("udp_multicast") is not None,
    reason="the native library does not build here",
)


def _known_frames(codec: Codec) -> list[can.Message]:
    """Frames of every kind the capture keeps: the bench's own (valid E2E: the recorder's
    step and status follow them), extended, remote, CAN FD with and without BRS/ESI."""
    out: list[can.Message] = []
    for step in range(40):
        out.append(
            codec.encode(
                "PhaseSamples",
                {"i_a": 0.5, "i_b": -0.25, "u_dc": 300.0, "status": 0, "step": step},
            )
        )
    out += [
        can.Message(arbitration_id=0x1ABCDE0, is_extended_id=True, data=b"\x01\x02\x03"),
        can.Message(arbitration_id=0x123, is_remote_frame=True, dlc=4, data=b""),
        can.Message(arbitration_id=0x7FF, data=b""),
        can.Message(arbitration_id=0x55, is_fd=True, bitrate_switch=True, data=bytes(range(64))),
        can.Message(
            arbitration_id=0x56, is_fd=True, error_state_indicator=True, data=bytes(range(12))
        ),
    ]
    return out


def _wait_for(cond: Any, timeout_s: float = 30.0) -> None:
    t_end = time.monotonic() + timeout_s
    while not cond() and time.monotonic() < t_end:
        time.sleep(0.01)


@pytest.mark.parametrize(
    "interface", ["udp_multicast", pytest.param("socketcan", marks=pytest.mark.socketcan)]
)
def test_native_and_python_recorders_write_the_same_capture(tmp_path: Path, interface: str) -> None:
    codec = Codec()
    if interface == "socketcan":
        require_vcan("vcan0")
        spec = BusSpec("socketcan", "vcan0")
    else:
        spec = BusSpec("udp_multicast", udp_multicast_group(), free_port())
    # both listen at once: the kernel stamps each datagram once, for every socket
    native = Recording([spec], tmp_path / "native.blf", codec)
    python = Recording([spec], tmp_path / "python.blf", codec, engine="python")
    frames = _known_frames(codec)
    sender = spec.open()
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
    assert native.frames_lost == 0
    # python-can's socketcan bus does not say what it lost; the native reader does
    assert python.frames_lost == (None if interface == "socketcan" else 0)
    # what the run's checks compute from the frames as they come
    assert native.recorders[0].step == python.recorders[0].step == 39
    # in memory and in the file, field by field (time stamps to the bit)
    assert [message_fields(m) for m in native.frames()] == [
        message_fields(m) for m in python.frames()
    ]
    a = [message_fields(m) for m in can.BLFReader(str(tmp_path / "native.blf"))]
    b = [message_fields(m) for m in can.BLFReader(str(tmp_path / "python.blf"))]
    assert len(a) == len(frames) and a == b
    # the frames sent, in order
    assert [(m.arbitration_id, bytes(m.data), m.is_fd) for m in native.frames()] == [
        (m.arbitration_id, bytes(m.data), m.is_fd) for m in frames
    ]


class _Held(can.Listener):
    """A listener that holds its first frame until released (a Python side that lags)."""

    def __init__(self) -> None:
        self.release = threading.Event()
        self.got: list[can.Message] = []

    def on_message_received(self, msg: can.Message) -> None:
        self.release.wait(30.0)
        self.got.append(msg)


def test_a_full_ring_counts_every_frame_it_drops() -> None:
    spec = BusSpec("udp_multicast", udp_multicast_group(), free_port())
    held = _Held()
    reader = _recorder_native.NativeReader(spec.channel, spec.port or 0, held, capacity=16)
    sender = can.Bus(interface="udp_multicast", channel=spec.channel, port=spec.port, fd=True)
    n = 400
    try:
        for i in range(n):
            sender.send(can.Message(arbitration_id=0x10, data=i.to_bytes(2, "little")))
            if i % 50 == 49:
                time.sleep(0.005)  # no more than the socket's buffer holds at once
        _wait_for(lambda: reader.stats()["received"] + reader.stats()["ring_lost"] >= n, 10.0)
        held.release.set()
        reader.stop()
        st = reader.stats()
        kernel = fd_drops(st["fd"])
    finally:
        sender.shutdown()
        reader.close()
    assert kernel is not None
    assert st["ring_lost"] > 0  # the ring held 16 (and one batch taken) while the listener lagged
    # every datagram is recorded or counted as lost, none twice
    assert len(held.got) + st["ring_lost"] + st["unread"] + kernel == n
    assert len(held.got) == st["received"]
    # the ones kept are in the order they were sent
    seq = [int.from_bytes(m.data, "little") for m in held.got]
    assert seq == sorted(seq) and len(set(seq)) == len(seq)


def test_the_recording_reports_what_its_ring_lost(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(_recorder_native, "RING_CAPACITY", 8)
    spec = BusSpec("udp_multicast", udp_multicast_group(), free_port())
    rec = Recording([spec], tmp_path / "capture.blf", Codec())
    sender = can.Bus(interface="udp_multicast", channel=spec.channel, port=spec.port, fd=True)
    n = 300
    try:
        assert rec.engine == "native"
        with rec.recorders[0].lock:  # the Python side cannot record: the ring fills
            for i in range(n):
                sender.send(can.Message(arbitration_id=0x7F0, data=i.to_bytes(2, "little")))
                if i % 50 == 49:
                    time.sleep(0.005)
            _wait_for(lambda: sum(rec.native_stats[0][k] for k in ("received", "ring_lost")) >= n)
    finally:
        sender.shutdown()
        rec.close()
    got = [m for m in rec.frames() if m.arbitration_id == 0x7F0]
    assert rec.frames_lost is not None and rec.frames_lost > 0
    assert len(got) + rec.frames_lost == n


def test_where_the_native_recorder_cannot_serve_the_python_one_records(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from bench._errors import BenchError

    def no_library() -> Any:
        raise BenchError("native loop: no C compiler (set CC, or install gcc)")

    monkeypatch.setattr(_recorder_native, "_DECLARED", [])
    monkeypatch.setattr(_recorder_native, "_lib", no_library)
    spec = BusSpec("udp_multicast", udp_multicast_group(), free_port())
    rec = Recording([spec], tmp_path / "capture.blf", Codec())
    sender = can.Bus(interface="udp_multicast", channel=spec.channel, port=spec.port, fd=True)
    try:
        assert rec.engine == "python"
        assert rec.engine_note is not None and "no C compiler" in rec.engine_note
        for i in range(20):
            sender.send(can.Message(arbitration_id=0x7F0, data=bytes([i])))
        _wait_for(lambda: len(rec.frames()) >= 20)
    finally:
        sender.shutdown()
        rec.close()
    assert [m.data[0] for m in rec.frames()] == list(range(20)) and rec.frames_lost == 0


def test_udp_multicast_and_socketcan_are_read_natively() -> None:
    assert _recorder_native.unavailable("udp_multicast") is None
    assert _recorder_native.unavailable("socketcan") is None
    why = _recorder_native.unavailable("virtual")
    assert why is not None and "virtual" in why


def test_the_recorder_thread_runs_below_both_nodes() -> None:
    from bench.runs._run import recorder_priority

    args = {
        "plant": ["--engine", "native", "--rt-priority", "80"],
        "controller": ["--rt-priority", "79"],
    }
    assert recorder_priority(args) == 78
    assert recorder_priority({"plant": ["--rt-priority", "1"]}) == 1
    assert recorder_priority({"plant": ["--engine", "native"]}) is None
    assert recorder_priority(None) is None


def test_the_python_bus_beside_a_native_reader_stops_receiving(tmp_path: Path) -> None:
    spec = BusSpec("udp_multicast", udp_multicast_group(), free_port())
    rec = Recording([spec], tmp_path / "capture.blf", Codec())
    sender = can.Bus(interface="udp_multicast", channel=spec.channel, port=spec.port, fd=True)
    try:
        for i in range(30):
            sender.send(can.Message(arbitration_id=0x7F0, data=bytes([i])))
        _wait_for(lambda: len(rec.frames()) >= 30)
        # the bench's own bus, kept for its commands: nothing queued for it
        assert _recorder.queued_bytes(rec.plant_bus) == 0
        assert rec.plant_bus.recv(0.05) is None
    finally:
        sender.shutdown()
        rec.close()
    assert len(rec.frames()) == 30


def test_a_datagram_that_is_no_message_is_counted_and_the_rest_recorded(tmp_path: Path) -> None:
    import socket

    spec = BusSpec("udp_multicast", udp_multicast_group(), free_port())
    rec = Recording([spec], tmp_path / "capture.blf", Codec())
    sender = can.Bus(interface="udp_multicast", channel=spec.channel, port=spec.port, fd=True)
    v6 = ":" in spec.channel
    raw = socket.socket(socket.AF_INET6 if v6 else socket.AF_INET, socket.SOCK_DGRAM)
    try:
        if v6:
            raw.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_MULTICAST_HOPS, 1)
        raw.sendto(b"\xc1 not msgpack", (spec.channel, spec.port))
        for i in range(10):
            sender.send(can.Message(arbitration_id=0x7F0, data=bytes([i])))
        _wait_for(lambda: len(rec.frames()) >= 10)
    finally:
        raw.close()
        sender.shutdown()
        rec.close()
    assert [m.data[0] for m in rec.frames()] == list(range(10))
    assert rec.native_stats[0]["malformed"] == 1 and rec.native_stats[0]["received"] == 11


def test_bench_perf_names_the_recorder_that_lost_frames() -> None:
    import json

    from bench.studies._perf import _native_limit

    root = Path(__file__).resolve().parents[1]
    res = json.loads((root / "docs" / "perf" / "perf.json").read_text())
    res["realtime_native"]["recorder_frames_lost"] = 0.0
    score = res.setdefault("realtime_native_score", {}).setdefault("realtime", {})
    score["recorder_frames_lost"] = 12.0
    for r in res["realtime_native"].values():
        if isinstance(r, dict):
            r["recorder_engine"] = "native"
    score["recorder_engine"] = "native"
    native = _native_limit("native_recorder_frames_lost", res)
    assert "native recorder" in native and "12 in the sensorless" in native
    score["recorder_engine"] = "python"  # one run had python-can's reader
    assert "Python thread" in _native_limit("native_recorder_frames_lost", res)


def test_a_socketcan_frame_becomes_the_message_python_can_makes() -> None:
    """``can_message`` on ``struct can(fd)_frame`` bytes: the fields python-can's socketcan
    bus sets (its ``dissect_can_frame`` and ``capture_message``), for each kind of frame."""
    from bench.nodes.native._recorder_native import can_message

    def raw(can_id: int, data: bytes, flags: int = 0, fd: bool = False, len8: int = 0) -> bytes:
        head = can_id.to_bytes(4, "little") + bytes([len(data), flags, 0, len8])
        return head + data.ljust(64 if fd else 8, b"\0")

    m = can_message(raw(0x123, b"\x01\x02"), 5.25, True, "vcan0")
    assert (m.arbitration_id, m.is_extended_id, m.dlc, bytes(m.data)) == (0x123, False, 2, b"\1\2")
    assert (m.timestamp, m.channel, m.is_rx, m.is_fd) == (5.25, "vcan0", False, False)
    m = can_message(raw(0x80000000 | 0x1ABCDE0, b"\x09"), 0.0, False, "can0")
    assert (m.arbitration_id, m.is_extended_id, m.is_rx) == (0x1ABCDE0, True, True)
    m = can_message(raw(0x40000000 | 0x7FF, b"\0" * 4), 0.0, True, "can0")
    assert m.is_remote_frame and m.dlc == 4
    m = can_message(raw(0x20000000 | 0x4, b"\0" * 8), 0.0, True, "can0")
    assert m.is_error_frame
    m = can_message(raw(0x55, bytes(range(12)), flags=0x01 | 0x02, fd=True), 0.0, True, "can0")
    assert m.is_fd and m.bitrate_switch and m.error_state_indicator and m.dlc == 12
    assert bytes(m.data) == bytes(range(12))
    # a classic frame's flags byte means nothing (python-can clears it)
    m = can_message(raw(0x56, bytes(8), flags=0x01), 0.0, True, "can0")
    assert not m.bitrate_switch and not m.is_fd


@pytest.mark.socketcan
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
    backlog_drops_before = _backlog_drops()
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
        # more that is queued after the burst carries the count of the whole burst.  A
        # marker sent while the socket's queue is still full (a raw CAN socket answers
        # no FIONREAD, so ``pending`` cannot see it) is dropped too: send markers, each
        # after a quiet spell, until one is received
        marker = (0x322).to_bytes(4, "little") + bytes([8, 0, 0, 0]) + bytes(8)
        t_end = time.monotonic() + 60.0
        while time.monotonic() < t_end:
            _wait_for(lambda: reader.pending() == 0, 30.0)
            time.sleep(0.2)
            tx.send(marker)
            sent += 1
            _wait_for(lambda: any(m.arbitration_id == 0x322 for m in got), 2.0)
            if any(m.arbitration_id == 0x322 for m in got):
                break
    _wait_for(lambda: reader.pending() == 0 and len(got) + reader.stats()["kernel_drops"] >= sent)
    reader.stop()
    st = reader.stats()
    reader.close()
    assert len(got) == st["frames"] == st["received"]
    assert st["kernel_drops"] > 0, st  # the burst did overflow the socket's queue
    counted = st["received"] + st["kernel_drops"] + st["ring_lost"] + st["unread"]
    # a frame the host's input backlog dropped (netdev_max_backlog, when softirqs lag
    # behind the burst on a busy host) never reached the socket: no socket can count
    # it, the host does (/proc/net/softnet_stat); other traffic may add to the host's
    # count, never to the socket's
    backlog = _backlog_drops() - backlog_drops_before
    assert counted <= sent <= counted + backlog, (st, sent, backlog)


def _backlog_drops() -> int:
    """Frames the host dropped at its per-CPU input backlog: /proc/net/softnet_stat's
    second column, summed over the CPUs."""
    with open("/proc/net/softnet_stat") as f:
        return sum(int(line.split()[1], 16) for line in f if line.strip())
