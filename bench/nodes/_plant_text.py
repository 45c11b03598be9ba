"""What a plant node says on stderr, and the lockstep constants both plant loops share.

The Python plant loop (:mod:`bench.nodes._loops`) and the native one
(:mod:`bench.nodes.native._plant_native`) print the same lines from here; the
module imports neither loop, so the native modules (and the in-process native
pair the Python loop's module runs) depend on it without a circle.
"""

from __future__ import annotations

import sys
import time

from bench.nodes._counters import RejectionSummary, rejection_text
from bench.nodes._plant_node import PlantNode, fault_name
from bench.wire._protocol import STATE_IDLE

__all__ = [
    "LAST_ANSWER_S",
    "RETRANSMIT_S",
    "STATE_DONE",
    "PlantDiagnostics",
    "stall_text",
    "trip_text",
    "tripped_text",
]

#: ``PlantStatus.state`` of the plant's last frame: the run is over, the plant idle.
STATE_DONE = STATE_IDLE

#: Lockstep: resend the recent frames when the expected duty has not come in this time.
RETRANSMIT_S = 0.05

#: Lockstep with a controller under test: how long the plant waits, resending, for
#: the answer to its last sample (the controller may have lost it; no period follows
#: that would make the plant resend it otherwise).
LAST_ANSWER_S = 2.0


class PlantDiagnostics:
    """What a running plant says on stderr, for the author of the controller on the bus.

    Once a second, the ``PwmDuty`` frames rejected in that second
    (``PwmDuty: 722 rejected (bad_crc) in the last second``), and a trip as
    soon as it happens, with what the controller did wrong for ``wrong_step``.
    """

    def __init__(self, node: PlantNode) -> None:
        self.node = node
        self.summary = RejectionSummary("PwmDuty")
        self.fault = node.fault
        self.t_check = 0.0

    def poll(self, force: bool = False) -> None:
        now = time.monotonic()
        if not force and now - self.t_check < 0.1:
            return
        self.t_check = now
        node = self.node
        if node.fault != self.fault:
            self.fault = node.fault
            if node.fault:
                print(f"plant: {trip_text(node.fault, node.fault_step)}", file=sys.stderr)
        line = self.summary.poll(node.duty_rejected, now, force)
        if line:
            print(f"plant: {line}", file=sys.stderr, flush=True)


def trip_text(code: int, step: int) -> str:
    """One line on a trip: its fault name, period, and for ``wrong_step`` the remedy."""
    name = fault_name(code)
    s = f"tripped {name} in period {step}, inverter off until a reset"
    if name == "wrong_step":
        s += (
            ": a PwmDuty came with step 0, which answers no sample; the duty computed from "
            "PhaseSamples step k must carry step k + 1 (docs/PROTOCOL.md, step numbering)"
        )
    elif name == "watchdog":
        s += ": no valid PwmDuty for too long"
    return s


def tripped_text(node: PlantNode, last_progress_s: float, now_s: float | None = None) -> str:
    """The line of a lockstep plant whose watchdog tripped while it waited for a controller
    under test: :func:`stall_text` with the time waited since its last progress
    (``last_progress_s`` on ``time.monotonic()``'s clock, ``CLOCK_MONOTONIC``, the clock of
    the native loop's ``bn_now_ns``), never the give-up limit, which it has not reached."""
    now = time.monotonic() if now_s is None else now_s
    return stall_text(node, now - last_progress_s)


def stall_text(node: PlantNode, waited_s: float) -> str:
    """Why a lockstep plant waits: the duty it needs, what came instead, what was rejected."""
    need = node.needed_duty()
    # a trip's line gives the time waited, often under a second: in ms there
    waited = f"{waited_s:.0f} s" if waited_s >= 1.0 else f"{waited_s * 1e3:.0f} ms"
    s = f"no valid PwmDuty for step {need} (the answer to sample {need - 1}) in {waited}"
    later = sorted(t for t in node.duties if t > need)
    if later:
        # the plant sent sample need - 1 (and resent it): whether the controller's
        # socket lost it or the controller passed it over, the bus does not say
        s += (
            f"; PwmDuty for later steps came ({', '.join(map(str, later[:4]))}): sample "
            f"{need - 1}, sent and resent every {RETRANSMIT_S * 1e3:.0f} ms, was lost in transit "
            f"(the controller's receive buffer) or the controller skipped sample {need - 1}"
        )
    if node.duty_rejected:
        s += f"; PwmDuty: {rejection_text(node.duty_rejected)} since the start"
    if not node.dut_answered and not node.duty_rejected:
        s += " (is a controller running on this bus?)"
    return s
