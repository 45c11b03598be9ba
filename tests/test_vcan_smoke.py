"""SocketCAN smoke tests on ``vcan0``: classic and CAN FD frames through the kernel.

Frames go through a real SocketCAN stack (``CAN_RAW`` sockets via python-can's
``socketcan`` interface): between two bus objects of one process, and between two
processes.  ``tools/vcan-tests`` runs these tests natively where ``vcan0`` exists,
otherwise inside User-Mode Linux; it sets ``VCAN_TESTS_RUNNER``, and then a missing
``vcan0`` is a failure instead of a skip.

Every wait is bounded; nothing here measures time.
"""

from __future__ import annotations

import os
import select
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import can
import pytest

pytestmark = pytest.mark.socketcan

CHANNEL = "vcan0"
#: Upper bound of one receive wait [s]; generous because UML system calls are slow.
RECV_TIMEOUT_S = 10.0
#: Upper bound for the child process to import python-can and open its bus [s].
CHILD_READY_TIMEOUT_S = 120.0
#: MTU of a CAN FD capable interface [byte]: ``sizeof(struct canfd_frame)``.
CANFD_MTU = 72

#: Valid CAN FD payload lengths above 8 bytes [byte] (ISO 11898-1 DLC 9..15).
FD_LENGTHS = (12, 16, 20, 24, 32, 48, 64)


def _vcan0_problem() -> str | None:
    """Return why ``vcan0`` cannot carry CAN_RAW frames here, or None when it can."""
    if not hasattr(socket, "AF_CAN"):
        return "this Python has no socket.AF_CAN"
    try:
        with socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW) as sock:
            sock.bind((CHANNEL,))
    except OSError as exc:
        return f"cannot bind a CAN_RAW socket to {CHANNEL}: {exc}"
    return None


@pytest.fixture(scope="module", autouse=True)
def _require_vcan0() -> None:
    problem = _vcan0_problem()
    if problem is None:
        return
    reason = f"{problem} (tools/vcan-tests runs these tests natively or inside User-Mode Linux)"
    if os.environ.get("VCAN_TESTS_RUNNER"):
        pytest.fail(reason)
    pytest.skip(reason)


def _open(arbitration_id: int, *, extended: bool = False, fd: bool = True) -> can.BusABC:
    """Open a socketcan bus on vcan0 that only passes one arbitration ID."""
    mask = 0x1FFFFFFF if extended else 0x7FF
    filters = [{"can_id": arbitration_id, "can_mask": mask, "extended": extended}]
    return can.Bus(interface="socketcan", channel=CHANNEL, fd=fd, can_filters=filters)


@pytest.fixture
def bus_pair() -> Iterator[tuple[can.BusABC, can.BusABC]]:
    """A sender and a receiver on vcan0, both CAN FD enabled, receiver filters 0x123."""
    tx = can.Bus(interface="socketcan", channel=CHANNEL, fd=True)
    rx = _open(0x123)
    try:
        yield tx, rx
    finally:
        rx.shutdown()
        tx.shutdown()


def _recv(bus: can.BusABC, timeout_s: float = RECV_TIMEOUT_S) -> can.Message | None:
    """Receive one message, waiting at most ``timeout_s`` seconds."""
    deadline = time.monotonic() + timeout_s
    while (left := deadline - time.monotonic()) > 0.0:
        msg = bus.recv(timeout=left)
        if msg is not None:
            return msg
    return None


def test_vcan0_is_up_and_fd_capable() -> None:
    """vcan0 carries CAN FD frames only with the CAN FD MTU (72 bytes, not 16)."""
    sysfs = Path("/sys/class/net") / CHANNEL
    assert int((sysfs / "mtu").read_text()) == CANFD_MTU
    flags = int((sysfs / "flags").read_text(), 16)
    assert flags & 0x1, "vcan0 is not up (IFF_UP clear)"


def test_classic_frame_between_two_buses(bus_pair: tuple[can.BusABC, can.BusABC]) -> None:
    tx, rx = bus_pair
    payload = bytes([0xDE, 0xAD, 0xBE, 0xEF, 0x01, 0x02, 0x03, 0x04])
    tx.send(can.Message(arbitration_id=0x123, data=payload, is_extended_id=False))
    msg = _recv(rx)
    assert msg is not None, f"no frame on {CHANNEL} within {RECV_TIMEOUT_S} s"
    assert msg.arbitration_id == 0x123
    assert not msg.is_extended_id
    assert not msg.is_fd
    assert msg.dlc == 8
    assert bytes(msg.data) == payload
    assert msg.channel == CHANNEL


def test_fd_frame_between_two_buses(bus_pair: tuple[can.BusABC, can.BusABC]) -> None:
    tx, rx = bus_pair
    for length in FD_LENGTHS:
        payload = bytes((7 * k + length) & 0xFF for k in range(length))
        tx.send(
            can.Message(
                arbitration_id=0x123,
                data=payload,
                is_extended_id=False,
                is_fd=True,
                bitrate_switch=True,
            )
        )
        msg = _recv(rx)
        assert msg is not None, f"no {length}-byte FD frame within {RECV_TIMEOUT_S} s"
        assert msg.is_fd
        assert msg.bitrate_switch
        assert bytes(msg.data) == payload


def test_classic_only_socket_does_not_see_fd_frames() -> None:
    """A CAN_RAW socket without CAN_RAW_FD_FRAMES drops FD frames, keeps classic ones.

    Both ends of a CAN FD link must therefore open their bus with ``fd=True``.
    """
    tx = can.Bus(interface="socketcan", channel=CHANNEL, fd=True)
    rx = _open(0x0ABCDE1, extended=True, fd=False)
    try:
        fd_payload = bytes(range(16))
        tx.send(can.Message(arbitration_id=0x0ABCDE1, data=fd_payload, is_fd=True))
        tx.send(can.Message(arbitration_id=0x0ABCDE1, data=b"\x05\x06"))
        msg = _recv(rx)
        assert msg is not None, f"no classic frame within {RECV_TIMEOUT_S} s"
        assert not msg.is_fd
        assert msg.is_extended_id
        assert msg.arbitration_id == 0x0ABCDE1
        assert bytes(msg.data) == b"\x05\x06"
    finally:
        rx.shutdown()
        tx.shutdown()


# The child echoes each request (ID 0x321) on ID 0x322 with the payload reversed and
# the same frame format, then exits after the FD request.
_CHILD = """
import sys
import can

bus = can.Bus(
    interface="socketcan",
    channel=sys.argv[1],
    fd=True,
    can_filters=[{"can_id": 0x321, "can_mask": 0x7FF, "extended": False}],
)
print("ready", flush=True)
try:
    while True:
        msg = bus.recv(timeout=float(sys.argv[2]))
        if msg is None:
            sys.exit("child: no request received")
        reply = can.Message(
            arbitration_id=0x322,
            data=bytes(reversed(msg.data)),
            is_extended_id=False,
            is_fd=msg.is_fd,
            bitrate_switch=msg.bitrate_switch,
        )
        bus.send(reply)
        if msg.is_fd:
            break
finally:
    bus.shutdown()
"""


def _wait_ready(proc: subprocess.Popen[str], timeout_s: float) -> None:
    assert proc.stdout is not None
    readable, _, _ = select.select([proc.stdout], [], [], timeout_s)
    if not readable:
        proc.kill()
        pytest.fail(f"child process not ready within {timeout_s} s")
    line = proc.stdout.readline().strip()
    if line != "ready":
        proc.kill()
        _, err = proc.communicate(timeout=RECV_TIMEOUT_S)
        pytest.fail(f"child process did not start: {line!r} {err.strip()}")


def test_classic_and_fd_frames_between_two_processes() -> None:
    proc = subprocess.Popen(
        [sys.executable, "-c", _CHILD, CHANNEL, str(CHILD_READY_TIMEOUT_S)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    bus = _open(0x322)
    try:
        _wait_ready(proc, CHILD_READY_TIMEOUT_S)

        classic = bytes([1, 2, 3, 4, 5, 6, 7])
        bus.send(can.Message(arbitration_id=0x321, data=classic, is_extended_id=False))
        msg = _recv(bus)
        assert msg is not None, "no classic reply from the child process"
        assert msg.arbitration_id == 0x322
        assert not msg.is_fd
        assert bytes(msg.data) == classic[::-1]

        fd_payload = bytes(range(100, 148))
        bus.send(
            can.Message(
                arbitration_id=0x321,
                data=fd_payload,
                is_extended_id=False,
                is_fd=True,
                bitrate_switch=True,
            )
        )
        msg = _recv(bus)
        assert msg is not None, "no CAN FD reply from the child process"
        assert msg.arbitration_id == 0x322
        assert msg.is_fd
        assert msg.bitrate_switch
        assert bytes(msg.data) == fd_payload[::-1]

        _, err = proc.communicate(timeout=CHILD_READY_TIMEOUT_S)
        assert proc.returncode == 0, f"child exited with {proc.returncode}: {err.strip()}"
    finally:
        bus.shutdown()
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
