"""A bus that refuses frames (buffer full, bus-off): counted, retried, never fatal.

``bench.nodes._send.send_all`` tries each frame up to ``SEND_ATTEMPTS`` times;
every refusal (``can.CanOperationError`` or ``OSError``, e.g. ``ENOBUFS``
of a full SocketCAN queue) adds one to ``send_errors``, and a frame still
refused at the last attempt adds one to ``frames_lost_on_send``.  In lockstep
a lost frame is recovered by the plant's retransmission, so a run on a bus
that refuses sends still gives the in-process trace.
"""

from __future__ import annotations

import errno
import os
import threading
from collections.abc import Callable
from typing import Any

import can
import pytest

from bench.nodes._counters import NodeCounters
from bench.nodes._loops import (
    command_frames,
    controller_loop,
    make_controller_node,
    make_plant_node,
    plant_loop,
    run_inprocess,
)
from bench.nodes._send import SEND_ATTEMPTS, send_all
from tests.trace_helpers import CODEC, assert_same_trace, short, trace


def bus_error() -> can.CanOperationError:
    return can.CanOperationError("Transmit buffer full", error_code=errno.ENOBUFS)


def os_error() -> OSError:
    return OSError(errno.ENOBUFS, os.strerror(errno.ENOBUFS))


class RefusingBus(can.BusABC):
    """A bus whose ``send`` raises ``error()`` at the calls ``refuse(n)`` picks (n from 0).

    Accepted frames are kept in ``sent`` and, when ``inner`` is given, sent on it;
    ``recv`` reads from ``inner`` (or nothing).
    """

    def __init__(
        self,
        refuse: Callable[[int], bool],
        error: Callable[[], Exception] = bus_error,
        inner: can.BusABC | None = None,
        **kwargs: Any,
    ) -> None:
        super().__init__(channel="refusing", **kwargs)
        self.refuse = refuse
        self.error = error
        self.inner = inner
        self.calls = 0
        self.refused = 0
        self.sent: list[can.Message] = []

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        n = self.calls
        self.calls += 1
        if self.refuse(n):
            self.refused += 1
            raise self.error()
        self.sent.append(msg)
        if self.inner is not None:
            self.inner.send(msg)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if self.inner is None:
            return None, False
        return self.inner.recv(timeout), False

    def shutdown(self) -> None:
        if self.inner is not None:
            self.inner.shutdown()
        super().shutdown()


def frames(n: int) -> list[can.Message]:
    return [can.Message(arbitration_id=0x10 + i, data=bytes([i] * 8)) for i in range(n)]


@pytest.mark.parametrize("error", [bus_error, os_error], ids=["CanOperationError", "OSError"])
@pytest.mark.parametrize("n_refused", [1, SEND_ATTEMPTS - 1])
def test_refusals_below_the_attempts_deliver_the_frame_once(
    error: Callable[[], Exception], n_refused: int
) -> None:
    bus = RefusingBus(lambda n: n < n_refused, error)
    c = NodeCounters()
    (f,) = frames(1)
    send_all(bus, [f], c)
    bus.shutdown()
    assert bus.sent == [f]  # once, not once per attempt
    assert bus.calls == n_refused + 1
    assert c.send_errors == n_refused
    assert c.frames_lost_on_send == 0
    assert c.as_dict()["send_errors"] == n_refused  # and it is reported


@pytest.mark.parametrize("error", [bus_error, os_error], ids=["CanOperationError", "OSError"])
def test_refusals_beyond_the_attempts_lose_the_frame_and_go_on(
    error: Callable[[], Exception],
) -> None:
    """``SEND_ATTEMPTS + 2`` refusals in a row over three frames: the first frame is
    lost after its last attempt, the second gets through on its third attempt,
    the third at once; nothing is raised."""
    n_refused = SEND_ATTEMPTS + 2
    bus = RefusingBus(lambda n: n < n_refused, error)
    c = NodeCounters()
    fs = frames(3)
    send_all(bus, fs, c)  # must not raise
    bus.shutdown()
    assert bus.sent == fs[1:]
    assert bus.calls == n_refused + 2
    assert c.send_errors == n_refused
    assert c.frames_lost_on_send == 1
    assert c.as_dict()["frames_lost_on_send"] == 1


def test_a_bus_that_always_refuses_loses_every_frame() -> None:
    bus = RefusingBus(lambda n: True)
    c = NodeCounters()
    send_all(bus, frames(3), c)
    bus.shutdown()
    assert bus.sent == []
    assert c.send_errors == 3 * SEND_ATTEMPTS
    assert c.frames_lost_on_send == 3


def test_lockstep_loop_on_refusing_buses_gives_the_inprocess_trace() -> None:
    """Plant and controller loops (threads on a virtual bus) whose sends are refused:
    every 40th call of each node from call 10 on, three times in a row (retried,
    delivered), and once ``SEND_ATTEMPTS`` times in a row on each side (a frame
    lost on send, which lockstep recovers by retransmission).  The run completes
    with the in-process trace, and the counters hold exactly the refusals."""
    scn = short("wen-5.1", 0.05)
    ref = trace(run_inprocess(scn, "sensored", CODEC), scn)

    def refuse(lost_at: int) -> Callable[[int], bool]:
        def f(n: int) -> bool:
            return (n >= 10 and n % 40 < 3) or lost_at <= n < lost_at + SEND_ATTEMPTS

        return f

    chan = f"send-errors-{os.getpid()}"
    # the lost bursts start where no short burst is (calls 40 k + 3 .. 40 k + 39)
    bus_p = RefusingBus(refuse(405), inner=can.Bus(interface="virtual", channel=chan))
    bus_c = RefusingBus(refuse(605), inner=can.Bus(interface="virtual", channel=chan))
    bus_r = can.Bus(interface="virtual", channel=chan)
    pn = make_plant_node(scn, CODEC)
    cn = make_controller_node(scn, "sensored", CODEC)
    halt = threading.Event()  # ends the controller thread should the plant loop fail
    tc = threading.Thread(
        target=controller_loop,
        args=(bus_c, cn),
        kwargs={"realtime": False, "stop": halt.is_set},
    )
    tc.start()
    try:
        for _, cmd in command_frames(scn, CODEC):
            bus_r.send(cmd)
        plant_loop(bus_p, pn, realtime=False)
        tc.join(10)
        stopped_by_itself = not tc.is_alive()  # on the scenario's stop command
        got = [cmd for _, cmd in command_frames(scn, CODEC)]
        while (m := bus_r.recv(0.2)) is not None:
            got.append(m)
    finally:
        halt.set()
        tc.join(5)
        for b in (bus_p, bus_c, bus_r):
            b.shutdown()
    assert stopped_by_itself
    assert pn.done
    assert_same_trace(ref, trace(got, scn))
    for bus, node in ((bus_p, pn), (bus_c, cn)):
        assert bus.refused > SEND_ATTEMPTS
        assert node.counters.send_errors == bus.refused
        assert node.counters.frames_lost_on_send == 1
    # the plant's lost frame (and the controller's lost duty) came back by retransmission
    assert pn.counters.retransmits > 0
