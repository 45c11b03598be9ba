"""The recorder says how many frames its sockets lost (``meta.json``'s ``recorder_frames_lost``).

udp_multicast drops a datagram when the receiving socket's buffer is full;
:func:`bench.runs._recorder.socket_drops` reads the kernel's count of them.
A socket with a tiny buffer whose reader stops after two frames: every
other frame sent is counted, whether the kernel dropped it or it was left
unread in the buffer.
"""

from __future__ import annotations

import socket
import sys
import time

import can
import pytest

from bench.runs._recorder import socket_drops
from tests.ports import free_port

GROUP = "239.74.163.9"


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc/net/udp")
def test_every_frame_is_read_or_counted_as_lost() -> None:
    port = free_port()
    rx = can.Bus(interface="udp_multicast", channel=GROUP, port=port)
    tx = can.Bus(interface="udp_multicast", channel=GROUP, port=port)
    try:
        rx._multicast._socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)  # type: ignore[attr-defined]
        assert socket_drops(rx) == 0
        n = 300
        for i in range(n):
            tx.send(can.Message(arbitration_id=0x10, data=i.to_bytes(2, "little")))
        time.sleep(0.2)
        read = 0
        while read < 2 and rx.recv(0.05) is not None:  # a reader that stopped early
            read += 1
        lost = socket_drops(rx)  # the dropped ones and the ones left unread
        assert lost is not None and lost > 0  # the buffer held a few frames only
        assert read == 2 and read + lost == n
    finally:
        rx.shutdown()
        tx.shutdown()


def test_a_bus_without_a_udp_socket_does_not_say() -> None:
    bus = can.Bus(interface="virtual", channel="natext")
    try:
        assert socket_drops(bus) is None
    finally:
        bus.shutdown()
