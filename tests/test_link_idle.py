"""When the latency link stops by itself, and what ``bench run`` does when it does.

The link is started before the nodes; on a slow host (User-Mode Linux) a
Python node takes tens of seconds to start, so the link's idle time may only
count once traffic has begun.  ``bench run`` stops at once, naming the link,
when the link ends during a run, instead of waiting for the plant's watchdog;
a controller that dies is left to the plant's watchdog, which is what such a
run tests.
"""

from __future__ import annotations

import subprocess
import sys
import threading
import time
import uuid

import can

from bench.nodes._link import LockstepLink, link_loop
from bench.runs._processes import ended_early
from bench.wire._codec import Codec

CODEC = Codec()


def _frame(k: int) -> can.Message:
    return CODEC.encode(
        "BenchCommand", {"cmd": 1, "seq": k % 16, "step": k, "speed_ref": 0.0, "load_torque": 0.0}
    )


def test_link_waits_for_first_traffic_then_stops_when_idle() -> None:
    chan = uuid.uuid4().hex
    a, b = (can.Bus(interface="virtual", channel=f"{chan}-{s}") for s in "ab")
    node_a = can.Bus(interface="virtual", channel=f"{chan}-a")
    node_b = can.Bus(interface="virtual", channel=f"{chan}-b")
    logic = LockstepLink(CODEC, sample_delay=0, duty_delay=0)
    sent: dict[str, int] = {}
    why: list[str] = []
    t = threading.Thread(
        target=lambda: why.append(link_loop(a, b, logic, idle_s=0.2, sent=sent)), daemon=True
    )
    try:
        t.start()
        time.sleep(0.6)  # three idle times without any traffic: still there
        assert t.is_alive()
        node_a.send(_frame(5))  # a command passes from A to B at once
        got = node_b.recv(2.0)
        assert got is not None and got.arbitration_id == CODEC.frame_id("BenchCommand")
        t.join(5.0)  # then 0.2 s of silence ends it
        assert not t.is_alive()
        assert why == ["idle"] and sent["a_to_b"] == 1
    finally:
        for bus in (a, b, node_a, node_b):
            bus.shutdown()


def test_link_stops_on_request_before_any_traffic() -> None:
    chan = uuid.uuid4().hex
    a, b = (can.Bus(interface="virtual", channel=f"{chan}-{s}") for s in "ab")
    stop = threading.Event()
    why: list[str] = []
    logic = LockstepLink(CODEC, sample_delay=1, duty_delay=1)
    t = threading.Thread(
        target=lambda: why.append(link_loop(a, b, logic, idle_s=0.05, stop=stop.is_set)),
        daemon=True,
    )
    try:
        t.start()
        time.sleep(0.3)
        assert t.is_alive()
        stop.set()
        t.join(5.0)
        assert why == ["stopped"]
    finally:
        a.shutdown()
        b.shutdown()


def _proc(code: str) -> subprocess.Popen[str]:
    return subprocess.Popen([sys.executable, "-c", code], text=True)


def test_a_link_that_ends_during_the_run_is_named() -> None:
    running = _proc("import time; time.sleep(30)")
    done_ok, failed = _proc("pass"), _proc("raise SystemExit(3)")
    try:
        for p in (done_ok, failed):
            p.wait(10.0)
        assert ended_early([("link", running), ("plant", running)]) is None
        # the link never ends by itself during a run, whatever its exit code
        assert ended_early([("link", done_ok), ("plant", running)]) == "link"
        assert ended_early([("link", failed), ("plant", running)]) == "link"
        # a dead controller is the plant's to handle (watchdog, safe state)
        assert ended_early([("controller", failed), ("plant", running)]) is None
    finally:
        running.kill()
        running.wait()
