"""What every node counts, and the bench-command queue both nodes share.

Every frame a node receives ends in exactly one of its counters (see
:mod:`bench.nodes._plant_node`): accepted, rejected with a reason, repeated,
ignored or unknown.  Bench commands are queued by the step they apply at
(:class:`CommandQueue`), so they may arrive early and in any order.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field

from bench.wire._protocol import SEQ_MODULUS, unwrap

#: A counter that is older than the receiver accepts (replayed or very late frame).
REJECT_STALE_COUNTER = "stale_counter"
#: A counter ahead of anything the sender can have produced yet.
REJECT_FUTURE_COUNTER = "future_counter"
#: An exact repeat of an accepted counter: counted, not a rejection (see module doc).
REPEATED_COUNTER = "repeated_counter"
#: More pending bench commands than this are refused (a flood of forged frames).
REJECT_QUEUE_FULL = "queue_full"
MAX_PENDING_COMMANDS = 4096
_FAR = 1 << 62
#: Lockstep: a duty answered from the controller's cache may be this many periods old.
DUTY_REPEAT_WINDOW = 16


@dataclass(slots=True)
class Command:
    """A decoded bench command, with its full (unwrapped) step."""

    apply_step: int
    cmd: int
    speed_ref_rpm: float
    load_nm: float
    seq: int = 0


@dataclass(slots=True)
class NodeCounters:
    """What a node counts; reported in the run's metrics."""

    frames_rejected: int = 0
    reject_reasons: dict[str, int] = field(default_factory=dict)
    duplicates: int = 0
    late_commands: int = 0
    retransmits: int = 0
    overruns: int = 0
    late_duties: int = 0
    missing_duties: int = 0
    frames_accepted: int = 0
    frames_ignored: int = 0
    frames_unknown: int = 0
    send_errors: int = 0
    frames_lost_on_send: int = 0

    def reject(self, reason: str, n: int = 1) -> None:
        """Count ``n`` frames that are not used, under ``reason``.

        ``repeated_counter`` goes to ``duplicates`` (and the per-reason
        counts); every other reason to ``frames_rejected``.
        """
        if n <= 0:
            return
        self.reject_reasons[reason] = self.reject_reasons.get(reason, 0) + n
        if reason == REPEATED_COUNTER:
            self.duplicates += n
        else:
            self.frames_rejected += n

    @property
    def frames_seen(self) -> int:
        """Every frame given to the node, whatever became of it."""
        return (
            self.frames_accepted
            + self.frames_rejected
            + self.duplicates
            + self.frames_ignored
            + self.frames_unknown
        )

    def as_dict(self) -> dict[str, object]:
        """The counters as a JSON-ready dict (the node reports)."""
        return {
            "frames_accepted": self.frames_accepted,
            "frames_rejected": self.frames_rejected,
            "reject_reasons": dict(self.reject_reasons),
            "duplicates": self.duplicates,
            "frames_ignored": self.frames_ignored,
            "frames_unknown": self.frames_unknown,
            "late_commands": self.late_commands,
            "retransmits": self.retransmits,
            "overruns": self.overruns,
            "late_duties": self.late_duties,
            "send_errors": self.send_errors,
            "frames_lost_on_send": self.frames_lost_on_send,
        }


class CommandQueue:
    """Bench commands ordered by apply step, de-duplicated by apply step and seq.

    It also follows ``BenchCommand.seq``, which counts distinct commands in
    step order (DBC 2.2): :attr:`ack_seq` is the seq of the newest command
    held with every earlier one (no gap), what a controller reports in
    ``CtrlTelemetry.cmd_ack``.  The first command of a run (``start``) has
    seq 0.  A command at or before the step of that newest gap-free command
    is a copy of one already held (one command per step, seq in step
    order): a repeat, never a late command, however long after it comes.
    """

    def __init__(self, modulus: int) -> None:
        self.modulus = modulus
        self.pending: dict[int, Command] = {}
        self.applied_upto = -1
        self.recent: deque[tuple[int, int]] = deque(maxlen=64)
        self.next_step = _FAR
        #: seq of the newest command held with no gap before it (-1: none yet).
        self.ack_seq = -1
        #: its apply step (-1: none yet).
        self.ack_step = -1
        #: commands held beyond a gap: seq -> apply step.
        self.ahead: dict[int, int] = {}
        #: seq of the newest command applied (-1: none).
        self.applied_seq = -1
        #: Frames taken, new or late (each put its key in :attr:`recent`): a native
        #: node drops the copies of the last ones before they reach Python (bn.h).
        self.taken = 0

    def _follow_seq(self, seq: int, step: int) -> bool:
        """Record a new command's seq; True when it extended the gap-free run."""
        nxt = (self.ack_seq + 1) % SEQ_MODULUS
        if (seq - nxt) % SEQ_MODULUS >= SEQ_MODULUS // 2:
            return False  # older than the gap-free run: nothing to record
        self.ahead[seq] = step
        moved = False
        while nxt in self.ahead:
            self.ack_step = self.ahead.pop(nxt)
            self.ack_seq = nxt
            nxt = (nxt + 1) % SEQ_MODULUS
            moved = True
        return moved

    def add(self, sig: dict[str, float], now: int, counters: NodeCounters) -> int | None:
        """Queue a command; its unwrapped apply step if it is known now (new or a repeat)."""
        s = unwrap(int(sig["step"]), now, self.modulus)
        if s < 0:
            # no command of a run applies before its start (step 0): a replay of
            # another (longer) run's, whose set-points would apply here as late
            counters.reject(REJECT_STALE_COUNTER)
            return None
        seq = int(sig["seq"])
        key = (s, seq)
        if key in self.recent or (0 <= s <= self.ack_step):
            counters.reject(REPEATED_COUNTER)
            return s
        if s <= self.applied_upto:
            if s < self.applied_upto - self.modulus // 4:
                counters.reject(REJECT_STALE_COUNTER)
                return None
            counters.late_commands += 1
            self.recent.append(key)
            self.taken += 1
            self._follow_seq(seq, s)
            # late: at the next call of due() (the next period the node handles;
            # a plant waiting for its start asks for step 0 again and again, and
            # a start moved to step 1 never came due), after any other late
            # command already waiting (arrival order, so a newer set-point wins)
            s = self.applied_upto
            while s in self.pending:
                s += 1
        elif s in self.pending:
            counters.reject(REPEATED_COUNTER)
            return s
        else:
            self.recent.append(key)
            self.taken += 1
            self._follow_seq(seq, s)
        if len(self.pending) >= MAX_PENDING_COMMANDS:
            counters.reject(REJECT_QUEUE_FULL)
            return None
        counters.frames_accepted += 1
        self.next_step = min(self.next_step, s)
        self.pending[s] = Command(
            s, int(sig["cmd"]), float(sig["speed_ref"]), float(sig["load_torque"]), seq
        )
        return s

    def due(self, step: int) -> list[Command]:
        if step > self.applied_upto:
            self.applied_upto = step
        if not self.pending or self.next_step > step:
            return []
        out = [c for s, c in sorted(self.pending.items()) if s <= step]
        for c in out:
            del self.pending[c.apply_step]
            self.applied_seq = c.seq
        self.next_step = min(self.pending) if self.pending else _FAR
        return out


def rejection_text(counts: dict[str, int]) -> str:
    """``"722 rejected (bad_crc)"``, or with several reasons ``"730 rejected (bad_crc 722, ...)"``."""
    n = sum(counts.values())
    if len(counts) == 1:
        return f"{n} rejected ({next(iter(counts))})"
    return f"{n} rejected ({', '.join(f'{k} {v}' for k, v in sorted(counts.items()))})"


class RejectionSummary:
    """Lines for stderr on the frames of one message rejected since the last line.

    A running node or ``bench run`` calls :meth:`poll` with the running counts
    by reason as often as it likes; at most once per ``every_s`` it returns
    ``"PwmDuty: 722 rejected (bad_crc) in the last second"`` (nothing when no
    frame was rejected in that time).
    """

    def __init__(self, message: str, every_s: float = 1.0) -> None:
        self.message = message
        self.every_s = every_s
        self.t_last: float | None = None
        self.seen: dict[str, int] = {}

    def poll(self, counts: dict[str, int], now: float, force: bool = False) -> str | None:
        """The line on what was rejected since the last one (``force``: even before a second)."""
        if self.t_last is None:
            self.t_last = now
        if now - self.t_last < self.every_s and not force:
            return None
        new = {k: v - self.seen.get(k, 0) for k, v in counts.items() if v > self.seen.get(k, 0)}
        span = now - self.t_last
        self.t_last = now
        self.seen = dict(counts)
        if not new:
            return None
        when = "in the last second" if span < 1.5 * self.every_s else f"in the last {span:.0f} s"
        return f"{self.message}: {rejection_text(new)} {when}"


def feed_steps(steps: Sequence[int], lead: int) -> list[int]:
    """The plant step after whose answers the in-process loop feeds each command (apply
    steps ``steps``, in the schedule's order); -1: before the run.

    A command is fed once the plant is within ``lead`` periods of its step, in the
    schedule's order (never before an earlier one); those within ``lead`` of step 0 go
    before the run.  The Python loop (:func:`bench.nodes._loops.run_inprocess`) and the
    native pair (:mod:`bench.nodes.native._pair`) both feed by it.
    """
    out = []
    k = -1
    for s in steps:
        k = max(k, s - lead) if s > lead or k >= 0 else -1
        out.append(k)
    return out
