"""The native loop's transports, codec and E2E (bench/nodes/native) against python-can.

``echo`` (bench/nodes/native/echo.c) is built with the system's C compiler;
python-can's udp_multicast bus on a port of the test's own drives it.  The
msgpack datagram is checked both ways against python-can's own
``pack_message``/``unpack_message``.
"""

from __future__ import annotations

import ctypes
import subprocess
import time
from pathlib import Path

import can
import pytest
from can.interfaces.udp_multicast.utils import pack_message, unpack_message

from bench.nodes.native import _native
from bench.nodes.native._native import BN_BRS, BN_ESI, BN_EXT, BN_FD, Frame
from bench.wire._bus import UDP_HOP_LIMIT, BusSpec, udp_multicast_group
from bench.wire._codec import Codec
from tests.ports import free_port

pytestmark = pytest.mark.skipif(
    not any(__import__("shutil").which(c) for c in ("cc", "gcc")), reason="needs a C compiler"
)


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> _native.NativeBuild:
    return _native.build(tmp_path_factory.mktemp("native"))


@pytest.fixture(scope="module")
def dll(built: _native.NativeBuild) -> ctypes.CDLL:
    return _native.load(built.lib)


MESSAGES = [
    can.Message(arbitration_id=0x11, data=bytes(range(8)), is_extended_id=False),
    can.Message(arbitration_id=0x1ABCDEF0, data=b"", is_extended_id=True),
    can.Message(
        arbitration_id=0x101,
        data=bytes(range(200, 216)),
        is_extended_id=False,
        is_fd=True,
        bitrate_switch=True,
    ),
    can.Message(
        arbitration_id=0x7FF,
        data=bytes(range(64)),
        is_extended_id=False,
        is_fd=True,
        error_state_indicator=True,
    ),
]


@pytest.mark.parametrize("msg", MESSAGES, ids=["classic", "ext-empty", "fd-brs", "fd64-esi"])
def test_c_packs_what_python_can_packs_and_reads_it_back(
    dll: ctypes.CDLL, msg: can.Message
) -> None:
    # python-can's datagram -> C
    blob = pack_message(msg)
    f = Frame()
    assert dll.bn_mp_unpack(blob, len(blob), ctypes.byref(f)) == 0
    assert f.id == msg.arbitration_id and f.len == len(msg.data)
    assert bytes(f.data[: f.len]) == bytes(msg.data)
    flags = (
        (BN_EXT if msg.is_extended_id else 0)
        | (BN_FD if msg.is_fd else 0)
        | (BN_BRS if msg.bitrate_switch else 0)
        | (BN_ESI if msg.error_state_indicator else 0)
    )
    assert f.flags == flags
    # C -> the same bytes as python-can writes (channel None, same timestamp)
    out = (ctypes.c_uint8 * 256)()
    n = dll.bn_mp_pack(ctypes.byref(f), ctypes.c_double(msg.timestamp), out, 256)
    assert bytes(out[:n]) == blob
    back = unpack_message(bytes(out[:n]), check=True)
    assert back.equals(msg, timestamp_delta=None)


def test_c_rejects_what_is_not_a_python_can_datagram(dll: ctypes.CDLL) -> None:
    blob = pack_message(MESSAGES[0])
    f = Frame()
    for bad in (blob[:-1], b"\x91\x01", b"", blob + b"\x00"):
        assert dll.bn_mp_unpack(bad, len(bad), ctypes.byref(f)) == -1
    big = bytearray(pack_message(MESSAGES[3]))
    i = big.index(b"\xc4\x40")  # bin 8 of 64 bytes -> 65: longer than CAN FD carries
    big[i + 1] = 65
    big[i + 2 : i + 2] = b"\x00"
    assert dll.bn_mp_unpack(bytes(big), len(big), ctypes.byref(f)) == -1


def _start_echo(built: _native.NativeBuild, group: str, port: int, n: int) -> subprocess.Popen:
    proc = subprocess.Popen(
        [str(built.echo), "-u", group, "-p", str(port), "-n", str(n), "-t", "20"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert proc.stdout is not None
    assert proc.stdout.readline().strip() == "READY"
    return proc


def test_echo_answers_each_phase_samples_with_its_step_and_a_valid_crc(
    built: _native.NativeBuild,
) -> None:
    codec = Codec()
    group, port, n = udp_multicast_group(), free_port(), 200
    proc = _start_echo(built, group, port, n)
    bus = BusSpec("udp_multicast", group, port).open()
    got: dict[int, dict[str, float]] = {}
    try:
        # a frame with a broken CRC first: counted, never answered
        bad = codec.encode(
            "PhaseSamples", {"i_a": 1, "i_b": 0, "u_dc": 300, "status": 1, "step": 7}
        )
        bad.data[0] ^= 0xFF
        bus.send(bad)
        for k in range(n):
            i_a = -60.0 + 0.5 * k
            msg = codec.encode(
                "PhaseSamples",
                {"i_a": i_a, "i_b": 1.0, "u_dc": 300.0, "status": 1, "step": (k + 500) % 1024},
            )
            bus.send(msg)
            t_end = time.monotonic() + 5.0
            while time.monotonic() < t_end:
                rx = bus.recv(timeout=0.5)
                if rx is None or rx.arbitration_id != codec.frame_id("PwmDuty"):
                    continue
                d = codec.decode(rx)
                assert d is not None and d.ok, d
                got[int(d.signals["step"])] = {**d.signals, "i_a": i_a}
                break
        out, err = proc.communicate(timeout=10)
    finally:
        bus.shutdown()
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, err
    assert sorted(got) == sorted((k + 500) % 1024 for k in range(n))
    lsb = 1.0 / 16384
    for sig in got.values():
        assert sig["duty_a"] == pytest.approx((sig["i_a"] + 64.0) / 128.0, abs=lsb)
        assert sig["duty_b"] == pytest.approx(0.5, abs=lsb) and sig["enable"] == 0
    assert f"answered={n} rejected=1 " in out, out


def test_echo_and_its_ping_meet_over_udp_multicast(built: _native.NativeBuild) -> None:
    """Two C nodes on one port (both with SO_REUSEPORT): every ping answered."""
    group, port = udp_multicast_group(), free_port()
    echo = _start_echo(built, group, port, 300)
    try:
        ping = subprocess.run(
            [str(built.echo), "-u", group, "-p", str(port), "-P", "300", "-w", "2000"],
            capture_output=True,
            text=True,
            timeout=60,
        )
        out, _ = echo.communicate(timeout=10)
    finally:
        if echo.poll() is None:
            echo.kill()
            echo.wait()
    assert ping.returncode == 0, ping.stdout + ping.stderr
    assert "ping: sent=300 answered=300 " in ping.stdout
    assert "answered=300 rejected=0 " in out


def test_echo_reports_a_bus_it_cannot_open(built: _native.NativeBuild, tmp_path: Path) -> None:
    res = subprocess.run(
        [str(built.echo), "-u", "not-a-group", "-p", "40000", "-t", "1"],
        capture_output=True,
        text=True,
        timeout=10,
    )
    assert res.returncode == 2
    assert res.stderr.startswith("echo: udp_multicast not-a-group: ")


def _send_many_lib() -> ctypes.CDLL:
    """The plant node's library with ``bn_send_many`` declared."""
    from bench.nodes.native._plant_native import _lib

    dll = _lib()
    dll.bn_send_many.argtypes = [ctypes.c_void_p, ctypes.POINTER(Frame), ctypes.c_int]
    dll.bn_send_many.restype = ctypes.c_int
    return dll


def test_a_send_batch_reaches_python_can_and_is_not_received_back() -> None:
    """bn_send_many: one sendmmsg, each datagram python-can's; the kernel loops the batch
    back to the sending socket too, and the receive side drops those copies undecoded."""
    from bench.nodes.native._plant_native import NativeBus

    dll = _send_many_lib()
    group, port = udp_multicast_group(), free_port()
    with can.Bus(interface="udp_multicast", channel=group, port=port, fd=True) as py:
        nb = NativeBus(dll, BusSpec("udp_multicast", group, port))
        try:
            frames = (Frame * 3)()
            for j, f in enumerate(frames):
                f.id, f.len = 0x11 + j, 2
                f.data[0], f.data[1] = j, 0xA5
            assert dll.bn_send_many(nb.ptr, frames, 3) == 3
            got = [py.recv(2.0) for _ in range(3)]
            assert [(m.arbitration_id, bytes(m.data)) for m in got if m is not None] == [
                (0x11 + j, bytes([j, 0xA5])) for j in range(3)
            ]
            py.send(can.Message(arbitration_id=0x21, data=b"\x07", is_extended_id=False))
            f = Frame()
            # the batch's own copies were queued first; the first frame taken is python-can's
            assert dll.bn_recv(nb.ptr, ctypes.byref(f), int(2e9)) == 1
            assert (f.id, bytes(f.data[: f.len])) == (0x21, b"\x07")
            assert dll.bn_recv(nb.ptr, ctypes.byref(f), 0) == 0
        finally:
            nb.close()


@pytest.mark.parametrize("group", [None, "239.74.163.2"], ids=["default-group", "ipv4"])
def test_the_native_bus_sends_for_this_host_only_and_python_can_still_gets_every_frame(
    group: str | None,
) -> None:
    """bn_udp_open sends with hop limit (TTL) 0, BN_UDP_HOPS (the bench's UDP_HOP_LIMIT):
    the kernel's loop-back copy reaches every socket of the group on this host, a plain
    python-can bus's (hop limit 1) included,
    and no network device sends the datagram (in a VM each would be a transmit the
    hypervisor handles, docs/REALTIME.md); python-can's frames still reach it."""
    import os
    import socket

    from bench.nodes.native._plant_native import NativeBus, _lib

    dll = _lib()
    group, port = group or udp_multicast_group(), free_port()
    with can.Bus(interface="udp_multicast", channel=group, port=port, fd=True) as py:
        nb = NativeBus(dll, BusSpec("udp_multicast", group, port))
        addr = nb.ptr.value
        assert addr is not None
        fd = ctypes.c_int.from_address(addr + ctypes.sizeof(ctypes.c_int)).value
        sock = socket.socket(fileno=os.dup(fd))  # bn_bus_t: kind, then the socket
        try:
            if sock.family == socket.AF_INET6:
                hops = sock.getsockopt(socket.IPPROTO_IPV6, socket.IPV6_MULTICAST_HOPS)
                loop = sock.getsockopt(socket.IPPROTO_IPV6, socket.IPV6_MULTICAST_LOOP)
            else:
                hops = sock.getsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL)
                loop = sock.getsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP)
            assert (hops, loop) == (UDP_HOP_LIMIT, 1) == (0, 1)
            frames = [Frame() for _ in range(20)]
            for j, f in enumerate(frames):
                f.id, f.len, f.data[0] = 0x40 + j, 1, j
                assert dll.bn_send(nb.ptr, ctypes.byref(f)) == 0
            got = [py.recv(2.0) for _ in frames]
            assert [(m.arbitration_id, m.data[0]) for m in got if m is not None] == [
                (0x40 + j, j) for j in range(20)
            ]
            py.send(can.Message(arbitration_id=0x22, data=b"\x09", is_extended_id=False))
            f = Frame()
            assert dll.bn_recv(nb.ptr, ctypes.byref(f), int(2e9)) == 1
            while f.id != 0x22:  # the native bus's own copies come back to it first
                assert dll.bn_recv(nb.ptr, ctypes.byref(f), int(2e9)) == 1
            assert bytes(f.data[: f.len]) == b"\x09"
        finally:
            sock.close()
            nb.close()


def test_two_native_buses_get_each_others_frames_and_not_their_own() -> None:
    """Each native bus sends from a socket of its own (an ephemeral source port) and
    its receiving socket's filter drops only that port's datagrams: a second native
    bus on the group (the plant's and the controller's) and python-can's get every
    frame, single sends and batches; the sender gets none of its own back."""
    from bench.nodes.native._plant_native import NativeBus

    dll = _send_many_lib()
    group, port = udp_multicast_group(), free_port()
    with can.Bus(interface="udp_multicast", channel=group, port=port, fd=True) as py:
        a = NativeBus(dll, BusSpec("udp_multicast", group, port))
        b = NativeBus(dll, BusSpec("udp_multicast", group, port))
        try:
            frames = (Frame * 4)()
            for j, f in enumerate(frames):
                f.id, f.len, f.data[0] = 0x50 + j, 1, j
            assert dll.bn_send(a.ptr, ctypes.byref(frames[0])) == 0
            assert dll.bn_send_many(a.ptr, ctypes.byref(frames[1]), 3) == 3
            want = [(0x50 + j, j) for j in range(4)]
            got = [b.recv(2.0) for _ in range(4)]
            assert [(f.id, f.data[0]) for f in got if f is not None] == want
            msgs = [py.recv(2.0) for _ in range(4)]
            assert [(m.arbitration_id, m.data[0]) for m in msgs if m is not None] == want
            assert a.recv(0.2) is None  # none of its own
            back = Frame()
            back.id, back.len, back.data[0] = 0x60, 1, 7
            assert dll.bn_send(b.ptr, ctypes.byref(back)) == 0
            f = a.recv(2.0)
            assert f is not None and (f.id, f.data[0]) == (0x60, 7)
        finally:
            a.close()
            b.close()


def test_a_build_step_that_fails_with_the_lto_flags_is_tried_without() -> None:
    """A compiler that cannot link with link-time optimisation (clang without its linker
    plug-in) still builds the library: the flags that only make it faster are dropped."""
    import sys

    from bench._errors import BenchError

    refuses_lto = [sys.executable, "-c", "import sys; sys.exit('-flto' in sys.argv)"]
    _native._run([*refuses_lto, *_native.LTO_FLAGS], "compile", retry_without=_native.LTO_FLAGS)
    with pytest.raises(BenchError, match="native loop: compile failed"):
        _native._run([*refuses_lto, *_native.LTO_FLAGS], "compile")
    assert set(_native.LTO_FLAGS) <= set(_native.CFLAGS)
