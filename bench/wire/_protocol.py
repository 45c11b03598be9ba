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

#: ``BenchCommand.speed_ref`` is in rpm (mechanical); the scenarios in rad/s.
RPM_PER_RAD_S = 60.0 / (2.0 * math.pi)


def unwrap(raw: int, expected: int, modulus: int) -> int:
    """The step nearest ``expected`` whose value mod ``modulus`` is ``raw``."""
    half = modulus // 2
    d = (raw - expected + half) % modulus - half
    return expected + d
