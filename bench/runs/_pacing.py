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
(``PhaseSamples.step``, unwrapped; this run's ``PlantTruth.step`` while a fault
loses the samples: :attr:`bench.runs._recorder.Recording.plant_step`); in real
time with the bench's own controller, the plant's step on its clock since the
host first saw it when that is further (the host's view lags by what its
recorder has yet to decode, up to a second on a loaded host, and a command sent
after its step changes the run).  In lockstep it also sends a keep-alive
(``cmd`` 0) at least every :data:`PACE_EVERY` periods: a paced plant
(``bench plant --pace-every``) runs no period beyond the newest command it
holds, so it never outruns the host's recorder.  ``bench run`` uses it with
the bench's own controller and with a controller under test alike; a host of
one's own can use it as it is (docs/PROTOCOL.md, "Bench commands and pacing")::

    pacer = CommandPacer(scenario, codec, mode="lockstep")
    while not done:
        pacer.send_due(bus, plant_step)   # plant_step: newest PhaseSamples.step seen
    pacer.send_stop(bus)

Every command's arrival is verifiable (DBC 2.2): ``BenchCommand.seq`` counts
distinct commands, and a controller reports in ``CtrlTelemetry.cmd_ack`` the
seq of the newest command it holds with no gap before it.  With such a
controller the pacer keeps at most :data:`bench.wire._protocol.ACK_WINDOW`
commands beyond the acknowledged one and resends the unacknowledged ones
every :data:`RESEND_S` while the acknowledgement does not move
(:meth:`CommandPacer.on_telemetry`, :meth:`CommandPacer.send_due`).  It also
counts, from each telemetry's step, the commands the controller had not
received by their step (:attr:`CommandPacer.late`: applied late, a result in
real time; in lockstep the plant's gate makes it impossible after the first
reporting telemetry) and, at the end, those it never acknowledged.  For a
controller that does not report (2.1, or no telemetry) nothing of this can be
verified: :meth:`CommandPacer.verification_line` says so.
"""

from __future__ import annotations

import bisect
import collections
from collections.abc import Sequence

import can

from bench.nodes._counters import MAX_PENDING_COMMANDS
from bench.nodes._loops import command_frames
from bench.scenarios._schema import Scenario
from bench.scenarios._setup import PACE_EVERY, PlannedCommand, sample_period
from bench.wire._codec import Codec
from bench.wire._protocol import ACK_WINDOW, SEQ_MODULUS

__all__ = [
    "AGAIN_S",
    "COMMAND_BURST",
    "PACE_EVERY",
    "REALTIME_AHEAD_S",
    "RESEND_S",
    "CommandPacer",
    "command_lead",
]


#: Datagrams a receive buffer of Linux's default size (``net.core.rmem_default``,
#: 212,992 bytes) holds of python-can's udp_multicast frames: 256, measured with a
#: ``BenchCommand`` (160 bytes of msgpack, about 830 bytes of kernel accounting
#: each).  A controller under test opens its bus with that default.
DEFAULT_SOCKET_FRAMES = 256
#: Commands sent ahead of the plant's step at most, for a controller that does
#: not acknowledge them: two copies each may fill a quarter of a default receive
#: buffer (:data:`DEFAULT_SOCKET_FRAMES` / 4 / 2), the rest being left to the
#: plant's frames (four per period with the recorder frames, plus its resends of
#: 3 periods) and to a reader that falls behind.  One command per period over a
#: whole ramp then reaches the controller 32 at a time, never 1,579 frames in a burst.
COMMAND_BURST = DEFAULT_SOCKET_FRAMES // 4 // 2
#: Real time with the bench's own controller: commands go out this far ahead of their
#: step (s).  The bench's process sends them at normal priority beside its recorder,
#: which decodes every frame of a 10 kHz pair in Python, on the 2 cores of the two
#: ``SCHED_FIFO`` nodes that each command frame wakes: there a send took 0.57 ms (three
#: per command), 500-600 commands/s, while wen-5.1's ramp needs 1,000/s for 0.5 s; with
#: 20 ms ahead the ramp reached the nodes up to a second late, a different run
#: (docs/REALTIME.md).  The bench's nodes open the bus with
#: :data:`bench.wire._bus.RECEIVE_BUFFER` and queue
#: :data:`bench.nodes._counters.MAX_PENDING_COMMANDS`: they hold what this sends ahead
#: (:attr:`CommandPacer.window`: a quarter of that).
REALTIME_AHEAD_S = 0.5
#: Telemetry frames without an acknowledgement after which a controller under test
#: counts as one that does not report (2.1), and the commands go on without it: a
#: 2.2 controller holds the start before its first sample (the plant sends sample 0
#: only after the start, and ``bench run`` resends every command at the first
#: answer), so it reports from its first or second telemetry; ten leaves room for
#: a few lost frames, and costs a 2.1 controller ten periods of its first commands.
SILENT_REPORTS = 10
#: Resend the commands beyond the acknowledged one when the acknowledgement has
#: not moved for this long (s): the plant's own resend interval
#: (:data:`bench.nodes._loops.RETRANSMIT_S`), so a lost command costs one round.
RESEND_S = 0.05
#: Each command goes out twice at once and a third time this long after (s): a
#: node whose receive buffer overflowed (a process descheduled on a loaded host
#: misses a burst of frames) loses both copies of one sending together, while a
#: copy a resend interval later finds its socket drained.  A controller that does
#: not acknowledge (the bench's own, a 2.1 one) has no other way to get a lost
#: command back; the nodes take the copies as repeats (same ``seq``).
AGAIN_S = RESEND_S


def command_lead(T_s: float, mode: str) -> int:
    """How many periods ahead of the plant's step the commands are sent.

    Lockstep: 0.5 s of plant time and at least 3000 periods (a host's view
    of the plant's step lags on a slow machine, by thousands of frames under
    User-Mode Linux, and a late command would change the trace); the plant
    is paced, so it cannot run away.  Real time: 20 ms and at least 20
    periods (the plant's clock runs regardless; a short lead keeps the first
    periods free of a burst); with the bench's own controller
    :class:`CommandPacer` sends :data:`REALTIME_AHEAD_S` ahead, a burst at a time.
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
    external : bool
        A controller under test: its acknowledgements are followed, with at most
        :data:`ACK_WINDOW` commands beyond the newest acknowledged one; in lockstep
        also at most that many beyond the plant's step (else :data:`COMMAND_BURST`),
        the bound the plant's acknowledgement gate needs to compare 4-bit seq
        (:meth:`bench.nodes._plant_node.PlantNode.acked`).
    schedule : sequence of PlannedCommand, optional
        The commands (a run's plan: :attr:`bench.nodes._plan.RunPlan.commands`);
        default: the scenario's.
    """

    def __init__(
        self,
        scn: Scenario,
        codec: Codec,
        *,
        mode: str,
        pace_every: int | None = None,
        external: bool = False,
        schedule: Sequence[PlannedCommand] | None = None,
    ) -> None:
        if pace_every is None:
            pace_every = PACE_EVERY if mode == "lockstep" else 0
        self.pace_every = pace_every
        #: (apply step, frame) of every command, in order; the last one is the stop.
        self.frames: list[tuple[int, can.Message]] = command_frames(
            scn, codec, pace_every, schedule
        )
        #: Periods ahead of the plant's step a command is sent (:func:`command_lead`).
        self.lead = command_lead(sample_period(scn), mode)
        #: How many of :attr:`frames` have been sent.
        self.sent = 0
        self._steps = [k for k, _ in self.frames]
        #: Commands sent beyond the plant's step at most.
        self.window = ACK_WINDOW if external and mode == "lockstep" else COMMAND_BURST
        #: Real time with the bench's own controller: the plant's step is read from its
        #: clock (:meth:`plant_step_at`), not only from the host's lagging view, and the
        #: commands go :data:`REALTIME_AHEAD_S` ahead, :data:`COMMAND_BURST` per call.
        self._clock = mode == "realtime" and not external
        self._T_s = sample_period(scn)
        if self._clock:
            self.lead = max(self.lead, int(REALTIME_AHEAD_S / self._T_s))
            self.window = MAX_PENDING_COMMANDS // 4
        #: Whether acknowledgements are followed: only within :data:`ACK_WINDOW`,
        #: i.e. for a controller under test, can a 4-bit seq name one command.
        self.external = external
        #: Index (in :attr:`frames`) of the newest command the controller acknowledged
        #: (-1: none); None while it has reported nothing (DBC 2.1 or no telemetry).
        self.acked: int | None = None
        #: Telemetry frames that reported an acknowledgement / that did not.
        self.reports = 0
        self.silent_reports = 0
        #: Indexes of the commands the controller held only after their step.
        self.late: set[int] = set()
        #: Rounds of resent unacknowledged commands.
        self.resends = 0
        self._t_ack = 0.0
        self._n_taken = 0
        #: (step, when) the host first saw the plant's step; None before.
        self._first_seen: tuple[int, float] | None = None
        #: (when, index) of the commands to send a third time (:data:`AGAIN_S`).
        self._again: collections.deque[tuple[float, int]] = collections.deque()

    def take(self, acks: list[tuple[int, int, int]], now: float) -> None:
        """Take the ``CtrlTelemetry`` reports of ``acks`` not taken yet (a recorder's
        :attr:`bench.runs._recorder.Recorder.acks`, which only grows).

        Called as the run goes and once more after the nodes stopped: a recorder
        that lags the plant (thousands of frames on a slow host) still holds the
        reports of the last commands when the plant's last period is seen.
        """
        while self._n_taken < len(acks):
            self.on_telemetry(*acks[self._n_taken], now)
            self._n_taken += 1

    def on_telemetry(self, step: int, valid: int, ack: int, now: float) -> None:
        """Take one ``CtrlTelemetry`` (its full step, ``cmd_ack_valid``, ``cmd_ack``)."""
        if not self.external:
            return
        if not valid:
            self.silent_reports += 1
            return
        self.reports += 1
        base = -1 if self.acked is None else self.acked
        # the acknowledged index: the one with seq ``ack`` at or after base (window < 8)
        i = base + (ack - base) % SEQ_MODULUS
        if i >= self.sent:
            return  # not a command sent yet: garbage, or another run's
        if self.acked is None or i > self.acked:
            self.acked = i
            self._t_ack = now
        # commands up to this telemetry's step that the controller did not yet hold
        j = max(self.acked, max(self.late, default=-1)) + 1
        while j < self.sent and self.frames[j][0] <= step:
            self.late.add(j)
            j += 1

    def send_due(self, bus: can.BusABC, plant_step: int, now: float | None = None) -> int:
        """Send (twice each) the commands that apply up to ``plant_step + lead``; how many.

        At most :data:`COMMAND_BURST` beyond the plant's step; with a controller
        that acknowledges, at most :data:`ACK_WINDOW` beyond its acknowledgement,
        and the ones beyond it again every :data:`RESEND_S` while it does not move.
        """
        n = 0
        step = self.plant_step_at(plant_step, now)
        limit = step + self.lead
        cap = self._first_beyond(step) + self.window
        if self._clock:
            cap = min(cap, self.sent + COMMAND_BURST)  # no burst of a whole lead at once
        if self.acked is None:
            if self.external and self.silent_reports < SILENT_REPORTS:
                cap = min(cap, ACK_WINDOW)  # until it says whether it acknowledges
                if now is not None and self.sent and now - self._t_ack > RESEND_S:
                    # a controller under test that opened its bus after the first
                    # commands (a slow start) gets them before it answers
                    if self._t_ack:
                        for _, m in self.frames[: self.sent]:
                            bus.send(m)
                        self.resends += 1
                    self._t_ack = now
        else:
            cap = min(cap, self.acked + 1 + ACK_WINDOW)
            if now is not None and self.sent > self.acked + 1 and now - self._t_ack > RESEND_S:
                for _, m in self.frames[self.acked + 1 : self.sent]:
                    bus.send(m)
                self.resends += 1
                self._t_ack = now
        while self._again and now is not None and self._again[0][0] <= now:
            bus.send(self.frames[self._again.popleft()[1]][1])
        while (
            self.sent < len(self.frames) and self.frames[self.sent][0] <= limit and self.sent < cap
        ):
            msg = self.frames[self.sent][1]
            bus.send(msg)
            bus.send(msg)
            if now is not None:
                self._again.append((now + AGAIN_S, self.sent))
            self.sent += 1
            n += 1
        if n and now is not None and self.acked is not None and self.sent == self.acked + 1 + n:
            self._t_ack = now  # the resend clock starts with the first unacknowledged command
        return n

    def plant_step_at(self, plant_step: int, now: float | None) -> int:
        """The plant's step the commands are sent after: ``plant_step`` (the host's view);
        in real time with the bench's own controller, the step the plant's clock has
        reached by ``now`` when that is further: the step the host first saw (0 before
        the plant's first sample: the first call sends the start) plus the periods
        since.  It is ahead of the plant by the periods host stalls skipped
        (bench/nodes/_clock.py) and by the plant's start after the first call, behind
        it by the host's lag at that first sight (nothing yet to decode): a command
        goes out that much early (it carries its step, a node queues it), never late
        because the host's recorder lags later in the run."""
        step = max(0, plant_step)
        if not self._clock or now is None or plant_step < 0:
            return step
        if self._first_seen is None:
            self._first_seen = (plant_step, now)
        s0, t0 = self._first_seen
        return max(step, s0 + int((now - t0) / self._T_s))

    def _first_beyond(self, step: int) -> int:
        """Index of the first command that applies after ``step``."""
        return bisect.bisect_right(self._steps, step)

    @property
    def unacknowledged(self) -> int:
        """Commands sent that the controller never acknowledged (0 when it does not report).

        The stop, which applies after the plant's last period, changes no period
        of the run: a controller that ends before its acknowledgement reaches the
        recorder is not counted here (:attr:`stop_unacknowledged` says so).
        """
        if self.acked is None or not self.frames:
            return 0
        end = self.frames[-1][0]
        return sum(1 for k, _ in self.frames[self.acked + 1 : self.sent] if k < end)

    @property
    def stop_unacknowledged(self) -> bool:
        """The stop was sent and the controller's reports never acknowledged it."""
        return (
            self.acked is not None
            and bool(self.frames)
            and self.sent == len(self.frames)
            and self.acked < self.sent - 1
        )

    def verification_line(self) -> str | None:
        """The line on what could not be verified or went wrong; None when all is well."""
        if self.acked is None:
            return (
                "the controller reported no command acknowledgement (CtrlTelemetry.cmd_ack_valid, "
                "DBC 2.2): the bench cannot verify that it received its BenchCommand frames"
            )
        if self.late or self.unacknowledged:
            return (
                f"the controller held {len(self.late)} of {self.sent} BenchCommand(s) only after "
                f"their step and never acknowledged {self.unacknowledged} "
                "(CtrlTelemetry.cmd_ack): its set-points were not those of the scenario"
            )
        return None

    def report(self) -> dict[str, object]:
        """For ``meta.json``: ``commands_sent``, ``_late``, ``_unacknowledged``, ``_verified``."""
        return {
            "commands_sent": self.sent,
            "commands_verified": self.acked is not None,
            "commands_late": len(self.late),
            "commands_unacknowledged": self.unacknowledged,
            "command_resends": self.resends,
            "stop_unacknowledged": self.stop_unacknowledged,
        }

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
