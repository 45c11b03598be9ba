"""Sending a scenario's bench commands ahead of the plant: the pacing every host uses.

A scenario's commands (start, set-point and load changes, stop) are
``BenchCommand`` frames that carry the period they apply in
(:func:`bench.nodes._loops.command_frames`), so they may be sent early; the
nodes queue them by that step.  They must not all be sent at once: the
16-bit ``BenchCommand.step`` wraps after 65,536 periods, a node holds at most
:data:`bench.nodes._counters.MAX_PENDING_COMMANDS`, and a burst at the start
of a real-time run makes the plant's first periods late.  :class:`CommandPacer`
sends each command (twice, same ``seq``) once the plant is within
:attr:`CommandPacer.lead` periods of it, as the host sees the plant's step
(``PhaseSamples.step``, unwrapped).  In lockstep it also sends a keep-alive
(``cmd`` 0) at least every :data:`PACE_EVERY` periods: a paced plant
(``bench plant --pace-every``) runs no period beyond the newest command it
holds, so it never outruns the host's recorder.  ``bench run`` uses it with
the bench's own controller and with a controller under test alike; a host of
one's own can use it as it is (docs/PROTOCOL.md, "Bench commands and pacing")::

    pacer = CommandPacer(scenario, codec, mode="lockstep")
    while not done:
        pacer.send_due(bus, plant_step)   # plant_step: newest PhaseSamples.step seen
    pacer.send_stop(bus)
"""

from __future__ import annotations

import can

from bench.nodes._loops import command_frames
from bench.scenarios._schema import Scenario
from bench.scenarios._setup import sample_period
from bench.wire._codec import Codec

__all__ = ["PACE_EVERY", "CommandPacer", "command_lead"]

#: Lockstep pacing: a bench command (a keep-alive when nothing changes) at
#: least every this many periods; see :attr:`bench.nodes._plant_node.PlantNode.pace_every`.
PACE_EVERY = 100


def command_lead(T_s: float, mode: str) -> int:
    """How many periods ahead of the plant's step the commands are sent.

    Lockstep: 0.5 s of plant time and at least 3000 periods (a host's view
    of the plant's step lags on a slow machine, by thousands of frames under
    User-Mode Linux, and a late command would change the trace); the plant
    is paced, so it cannot run away.  Real time: 20 ms and at least 20
    periods (the plant's clock runs regardless; a short lead keeps the first
    periods free of a burst).
    """
    if mode == "lockstep":
        return max(3000, int(0.5 / T_s))
    return max(20, int(0.02 / T_s))


class CommandPacer:
    """The scenario's bench commands, sent ahead of the plant as it advances.

    Parameters
    ----------
    scn : Scenario
    codec : Codec
    mode : str
        ``"lockstep"`` or ``"realtime"``.
    pace_every : int, optional
        Keep-alive spacing in periods; default :data:`PACE_EVERY` in lockstep, 0 in
        real time.  It must match the plant's ``--pace-every``.
    """

    def __init__(
        self, scn: Scenario, codec: Codec, *, mode: str, pace_every: int | None = None
    ) -> None:
        if pace_every is None:
            pace_every = PACE_EVERY if mode == "lockstep" else 0
        self.pace_every = pace_every
        #: (apply step, frame) of every command, in order; the last one is the stop.
        self.frames: list[tuple[int, can.Message]] = command_frames(scn, codec, pace_every)
        #: Periods ahead of the plant's step a command is sent (:func:`command_lead`).
        self.lead = command_lead(sample_period(scn), mode)
        #: How many of :attr:`frames` have been sent.
        self.sent = 0

    def send_due(self, bus: can.BusABC, plant_step: int) -> int:
        """Send (twice each) the commands that apply up to ``plant_step + lead``; how many."""
        n = 0
        limit = max(0, plant_step) + self.lead
        while self.sent < len(self.frames) and self.frames[self.sent][0] <= limit:
            msg = self.frames[self.sent][1]
            bus.send(msg)
            bus.send(msg)
            self.sent += 1
            n += 1
        return n

    def resend_recent(self, bus: can.BusABC, n: int = 8) -> None:
        """Send the newest ``n`` commands sent once more (a paced plant that stopped moving
        on a lossy transport may have lost them; a node ignores the repeats)."""
        for _, m in self.frames[max(0, self.sent - n) : self.sent]:
            bus.send(m)

    def resend_all(self, bus: can.BusABC) -> None:
        """Every command sent so far once more: for a controller that joined after them
        (``bench run --controller external`` does this at its first valid duty; the plant
        ignores the repeats, the controller applies what is past due at its next sample)."""
        for _, m in self.frames[: self.sent]:
            bus.send(m)

    def send_stop(self, bus: can.BusABC) -> None:
        """The last command (the stop) once more."""
        if self.frames:
            bus.send(self.frames[-1][1])
