"""Codes and counters of the wire protocol, shared by every node and the analysis.

The numeric codes are the DBC's value tables (``dbc/bench.dbc``):
``BenchCommand.cmd`` and ``PlantStatus.state`` / ``PhaseSamples.status``.
Step counters travel as ``step mod 2**bits`` and are unwrapped against the
step the receiver expects (:func:`unwrap`).
"""

from __future__ import annotations

import math

#: ``BenchCommand.cmd`` codes.
CMD_NONE, CMD_START, CMD_STOP, CMD_RESET, CMD_ENABLE, CMD_DISABLE = 0, 1, 2, 3, 4, 5
#: Plant states (DBC value table of ``PlantStatus.state`` and ``PhaseSamples.status``).
STATE_IDLE, STATE_RUNNING, STATE_FAULT = 0, 1, 2

#: ``PlantStatus.fault_code`` of a protocol fault the plant node latches (the
#: machine's own protections, 1..4, are :data:`plant_rt.FAULT_NAMES`): a
#: ``PwmDuty`` for period 0, which answers no sample, so a controller that
#: tags the duty computed from sample ``k`` with ``k`` instead of ``k + 1``.
FAULT_WRONG_STEP = 5
#: Names of the node's own fault codes (DBC value table of ``fault_code``).
NODE_FAULT_NAMES = {FAULT_WRONG_STEP: "wrong_step"}
#: Reason under which the plant counts a ``PwmDuty`` for period 0.
REJECT_WRONG_STEP = "wrong_step"

#: ``BenchCommand.speed_ref`` is in rpm (mechanical); the scenarios in rad/s.
RPM_PER_RAD_S = 60.0 / (2.0 * math.pi)


#: Valid recorder frames of one foreign ``run_id`` that make it another run on
#: the bus: a random frame passes the 8-bit CRC once in 256 with a random
#: run_id, while another run sends its truth every period.
SHARED_RUN_FRAMES = 8


def new_run_id() -> int:
    """A random run nonce, 1..65535 (``PlantTruth.run_id``; 0 means unknown)."""
    import secrets

    return secrets.randbelow(0xFFFF) + 1


def unwrap(raw: int, expected: int, modulus: int) -> int:
    """The step nearest ``expected`` whose value mod ``modulus`` is ``raw``."""
    half = modulus // 2
    d = (raw - expected + half) % modulus - half
    return expected + d


def lockstep_sample_lead(delay: int) -> int:
    """The most steps a genuine ``PhaseSamples`` (or ``PlantTruth``) can be ahead of the
    next step of a lockstep controller whose plant runs with ``delay`` periods of lockstep
    latency (the plan's ``lockstep_delay``: sample plus duty delay of the link).

    The controller's next step ``n`` says that the newest duty it has sent is tagged
    ``n`` (the answer to sample ``n - 1``).  A lockstep plant runs period ``p`` only
    with the duty tagged ``p - delay`` (periods with ``p - delay <= 0`` need none), so
    with duties up to ``n`` it can run up to period ``n + delay``, which ends with the
    sample of instant ``n + delay + 1``; its next period needs duty ``n + 1``, which the
    controller has not computed.  A latency link only holds samples back (it releases
    sample ``j`` once the plant's bus carried ``j + N_s``), and a retransmission resends
    older frames.  So a genuine sample is at most ``delay + 1`` steps ahead; samples
    arrive in the plant's order, so one that far ahead follows a loss the plant's
    retransmission fills.  Anything further is not the plant's: a random frame that
    passed the 8-bit E2E CRC (one in 256 do) with a counter in the unwrap window
    (:data:`bench.nodes._counters.REJECT_FUTURE_COUNTER`, as AUTOSAR E2E's
    MaxDeltaCounter).  Real time keeps the unwrap window: after a gap the controller
    skips ahead to the newest sample.
    """
    return delay + 1


#: How far a controller's answer (``PwmDuty`` tagged ``t``, which answers sample
#: ``t - 1``; ``CtrlTelemetry`` of step ``k``, which answers sample ``k``) may be ahead
#: of the newest plant step (``PhaseSamples``, ``PlantTruth``) before it in a capture,
#: in the step of the sample it answers: 0.  A controller answers a sample only after
#: it received it, and the recorder's sockets stamp every frame on receipt in the
#: kernel (``SO_TIMESTAMPNS``; SocketCAN alike), so the capture, merged by those
#: stamps, holds the sample (on the controller's bus, and earlier on the plant's)
#: before the answer, whichever of the two sockets of a latency link it reads.
ANSWER_LEAD = 0
#: How far a ``PhaseSamples`` may be ahead of the newest plant step before it in a
#: capture: 1.  A plant sends the frames of instant ``k`` (sample, then truth) after
#: those of instant ``k - 1``, and resends only older ones.  (For this and
#: :data:`ANSWER_LEAD`: when the recorder lost the frames before a genuine frame, or
#: recorded neighbours out of order, the plant's next frame after it vouches for it
#: instead, with the same lead: :mod:`bench.runs._analysis`.)
PLANT_LEAD = 1


#: ``BenchCommand.seq`` counts distinct commands (keep-alives included) modulo this.
SEQ_MODULUS = 16
#: Commands the host may have sent beyond the newest one the controller
#: acknowledged (``CtrlTelemetry.cmd_ack``): fewer than half the seq range, so
#: any two seq a receiver compares are less than half a cycle apart and
#: :func:`seq_at_least` is exact (serial-number arithmetic, as RFC 1982).
ACK_WINDOW = SEQ_MODULUS // 2 - 1


def seq_at_least(a: int, b: int) -> bool:
    """Whether seq ``a`` is ``b`` or newer, for seq less than half a cycle apart."""
    return (a - b) % SEQ_MODULUS < SEQ_MODULUS // 2
