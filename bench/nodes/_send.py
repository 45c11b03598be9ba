"""Sending a node's frames on a bus: a refused send is counted and retried, never fatal."""

from __future__ import annotations

import time

import can

from bench.nodes._counters import NodeCounters

#: A frame the bus refuses (buffer full, bus-off) is tried this many times in all.
SEND_ATTEMPTS = 5


def send_all(bus: can.BusABC, frames: list[can.Message], counters: NodeCounters) -> None:
    """Send ``frames``; a refused send (buffer full, bus-off) is counted and retried.

    After :data:`SEND_ATTEMPTS` refusals the frame is counted as lost and the
    node goes on (lockstep recovers it by retransmission; real time by the
    next period's frame); a send error is never fatal.
    """
    for f in frames:
        for attempt in range(SEND_ATTEMPTS):
            try:
                bus.send(f)
                break
            except (can.CanError, OSError):
                counters.send_errors += 1
                if attempt == SEND_ATTEMPTS - 1:
                    counters.frames_lost_on_send += 1
                else:
                    time.sleep(0.0005 * (attempt + 1))
