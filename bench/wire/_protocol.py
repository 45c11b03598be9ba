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
