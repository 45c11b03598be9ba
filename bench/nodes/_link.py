"""The latency link: a gateway between two buses with delay, jitter and drop.

Like ``cangw``, but it delays what it forwards.  Side A is the plant's bus,
side B the controller's.  It forwards ``PhaseSamples``, ``PositionSensor`` and ``PlantTruth``
from A to B, ``PwmDuty`` from B to A, and ``BenchCommand`` from A to B at
once (the bench sends its commands on the plant's side; forwarding them both
ways would echo them forever on a bus that delivers a node's own frames back
to it, as udp_multicast does).

Lockstep (deterministic): delays are whole PWM periods, counted in the
plant's sample frames seen on A.  Sample ``j`` is released to B when A has
carried sample ``j + N_s``; duty ``t`` (the answer to sample ``t - 1``, which
B received when A carried sample ``t - 1 + N_s``) is released to A when A
carries sample ``t - 1 + N_s + N_d``.  Release points follow from the
frames' own step counters, never from arrival times, so the trace is the
same however the processes are scheduled.  A dropped
frame is recovered by the plant's retransmission: a repeated sample on A
makes the link repeat what it has already released.

Real time: each frame is released ``delay + jitter`` microseconds after it
was received, never before (a negative draw is clipped to no delay; absolute
times, a heap ordered by release time; frames of one direction may overtake
each other when the jitter exceeds their spacing, as on a real gateway with
queues).  ``BenchCommand`` frames pass at once, never jittered nor dropped,
in both modes.

Per direction: the sample direction (``PhaseSamples`` and ``PlantTruth``,
A to B) and the duty direction (``PwmDuty``, B to A) each have their own
delay, jitter and drop probability.  One seed serves the link; each direction
draws its drops and its jitter from random streams of its own derived from
the seed (:func:`direction_rng`), so the settings or the traffic of one
direction never change the draws of the other.
"""

from __future__ import annotations

import heapq
import random
import select
import time
from collections import deque
from collections.abc import Callable
from typing import TYPE_CHECKING, TypeVar

import can

from bench.nodes._send import send_all
from bench.wire._codec import Codec
from bench.wire._protocol import unwrap

if TYPE_CHECKING:
    from bench.nodes._plan import LinkPlan


def direction_rng(seed: int, direction: str, kind: str) -> random.Random:
    """The random stream of one direction (``"samples"``, ``"duties"``) and use
    (``"drop"``, ``"jitter"``) of a link seeded with ``seed``.

    Seeded from a string (hashed with SHA-512 by :class:`random.Random`), so
    the streams of one seed are unrelated to each other and do not depend on
    ``PYTHONHASHSEED``.
    """
    return random.Random(f"bench-link/{direction}/{kind}/{seed}")


def _resolve(shared: float, own: float | None) -> float:
    return shared if own is None else own


def link_logic(lp: LinkPlan, mode: str, codec: Codec) -> LockstepLink | RealtimeLink:
    """The link logic of ``mode`` (``"lockstep"`` or ``"realtime"``) that injects ``lp``:
    the one construction ``bench link`` makes from its options and from a run's plan."""
    if mode == "lockstep":
        return LockstepLink(
            codec,
            sample_delay=lp.sample_delay_steps,
            duty_delay=lp.duty_delay_steps,
            seed=lp.seed,
            sample_drop_prob=lp.sample_drop_prob,
            duty_drop_prob=lp.duty_drop_prob,
        )
    return RealtimeLink(
        codec,
        sample_delay_us=lp.sample_delay_us,
        duty_delay_us=lp.duty_delay_us,
        jitter_dist=lp.jitter_dist,
        seed=lp.seed,
        sample_jitter_us=lp.sample_jitter_us,
        duty_jitter_us=lp.duty_jitter_us,
        sample_drop_prob=lp.sample_drop_prob,
        duty_drop_prob=lp.duty_drop_prob,
    )


class LockstepLink:
    """Period-counting link logic (no I/O): frames in, frames out per side.

    Parameters
    ----------
    codec : Codec
        The DBC codec (frame IDs, step counters).
    sample_delay, duty_delay : int
        Fixed delay of the sample (A to B) and duty (B to A) directions,
        whole PWM periods.
    drop_prob : float
        Drop probability per frame, both directions.
    seed : int
        Seed of the drop streams (one per direction, :func:`direction_rng`).
    sample_drop_prob, duty_drop_prob : float or None
        Drop probability of one direction; ``None``: ``drop_prob``.
    """

    def __init__(
        self,
        codec: Codec,
        *,
        sample_delay: int,
        duty_delay: int,
        drop_prob: float = 0.0,
        seed: int = 0,
        sample_drop_prob: float | None = None,
        duty_drop_prob: float | None = None,
    ) -> None:
        self.codec = codec
        self.n_s = sample_delay
        self.n_d = duty_delay
        self.p_s = _resolve(drop_prob, sample_drop_prob)
        self.p_d = _resolve(drop_prob, duty_drop_prob)
        self.rng_s = direction_rng(seed, "samples", "drop")
        self.rng_d = direction_rng(seed, "duties", "drop")
        self.m = 1 << codec.step_bits("PhaseSamples")
        self.id_samples = codec.frame_id("PhaseSamples")
        self.id_truth = codec.frame_id("PlantTruth")
        self.id_pos = codec.frame_id("PositionSensor")
        self.id_duty = codec.frame_id("PwmDuty")
        self.id_cmd = codec.frame_id("BenchCommand")
        self.latest_a = -1
        self.held_b: deque[tuple[int, can.Message]] = deque()
        self.held_a: deque[tuple[int, can.Message]] = deque()
        self.released_b: dict[int, list[can.Message]] = {}
        self.released_a: deque[can.Message] = deque(maxlen=4)
        #: Periods a repeat can reach back: the plant resends its last ``delay + 3``
        #: periods (``delay`` = ``sample_delay + duty_delay``), and a little more.
        self.keep = self.n_s + self.n_d + 8
        #: Steps of the duties held or released, the last ``keep``: a duty seen again (the
        #: controller answering a repeated sample from its cache) is not forwarded;
        #: the plant's repeat of its newest sample brings it :attr:`released_a`.
        #: A duty first seen after later ones (its first copy lost) is new.
        self.duty_seen: set[int] = set()
        self.dropped_samples = 0
        self.dropped_duties = 0

    @property
    def dropped(self) -> int:
        """Frames dropped on purpose, both directions."""
        return self.dropped_samples + self.dropped_duties

    def _release(self) -> tuple[list[can.Message], list[can.Message]]:
        to_b: list[can.Message] = []
        to_a: list[can.Message] = []
        while self.held_b and self.held_b[0][0] <= self.latest_a - self.n_s:
            j, m = self.held_b.popleft()
            self.released_b.setdefault(j, []).append(m)
            self.released_b = _window(self.released_b, j, self.keep)
            if self.p_s and self.rng_s.random() < self.p_s:
                self.dropped_samples += 1
            else:
                to_b.append(m)
        while self.held_a and self.held_a[0][0] <= self.latest_a:
            _, m = self.held_a.popleft()
            self.released_a.append(m)
            if self.p_d and self.rng_d.random() < self.p_d:
                self.dropped_duties += 1
            else:
                to_a.append(m)
        return to_b, to_a

    def _seen(self, j: int, fid: int) -> bool:
        """Whether a frame ``fid`` of period ``j`` is held or was released."""
        return any(m.arbitration_id == fid for m in self.released_b.get(j, ())) or any(
            s == j and m.arbitration_id == fid for s, m in self.held_b
        )

    def from_a(self, msg: can.Message) -> tuple[list[can.Message], list[can.Message]]:
        """A frame seen on A: (frames for B, frames for A).

        A sample of a new period moves the link's period on; every frame is held
        in period order until its period is ``sample_delay`` periods old.  A frame
        already held or released is a repeat (the plant resends its last periods
        when the duty it needs does not come): a repeated sample resends what
        was released to B for its period (sample and truth), and the repeat of
        the newest one, which ends each of the plant's rounds, the duties last
        released to A, so a frame lost on either side comes again.  Nothing is
        sent twice for one repeat: on a loaded host a link that answered each
        repeated sample with every duty, and forwarded the controller's cached
        answers again, fell behind its input, each round of the waiting plant
        added to the backlog, and a run stalled for seconds (thousands of
        copies of one duty on vcan inside User-Mode Linux).  A frame of
        an earlier period that this link never saw (its first copy was lost on
        the way in) is new, held in its place: the controller takes its samples
        (and the sensored one its truth) in order and waits for it.  Which frame
        was seen is asked per frame identifier: a period whose truth came but
        whose sample was lost is still waiting for that sample.
        """
        fid = msg.arbitration_id
        if fid == self.id_cmd:
            return [msg], []
        if fid not in (self.id_samples, self.id_truth, self.id_pos):
            return [], []
        d = self.codec.decode(msg)
        if d is None or d.reason is not None:
            return [], []
        j = unwrap(int(d.signals["step"]) % self.m, max(self.latest_a, 0), self.m)
        is_sample = fid == self.id_samples
        if is_sample and j > self.latest_a:
            self.latest_a = j
        elif self._seen(j, fid):
            if not is_sample:
                return [], []  # resent with its period's sample
            again_b = list(self.released_b.get(j, [])) if j <= self.latest_a - self.n_s else []
            # the duties once per round: the round ends with the plant's newest sample
            return again_b, list(self.released_a) if j == self.latest_a else []
        elif j <= self.latest_a - self.keep:  # older than the window released_b keeps
            return [], []
        self.held_b = _in_order(self.held_b, j, msg)
        return self._release()

    def from_b(self, msg: can.Message) -> tuple[list[can.Message], list[can.Message]]:
        """A frame seen on B: (frames for B, frames for A)."""
        fid = msg.arbitration_id
        if fid != self.id_duty:
            return [], []
        d = self.codec.decode(msg)
        if d is None or d.reason is not None:
            return [], []
        t = unwrap(int(d.signals["step"]), max(self.latest_a, 0) + 1, self.m)
        if t in self.duty_seen or t <= max(self.latest_a, 0) - self.keep:
            return [], []  # seen: held, or released (resent from released_a when lost)
        self.duty_seen.add(t)
        self.duty_seen = _window(self.duty_seen, t, self.keep)
        # duty t answers sample t - 1, which B saw when A carried sample t - 1 + N_s
        self.held_a = _in_order(self.held_a, t - 1 + self.n_s + self.n_d, msg)
        return self._release()


_Periods = TypeVar("_Periods", dict[int, list[can.Message]], set[int])


def _window(c: _Periods, newest: int, keep: int) -> _Periods:
    """``c`` (keyed by period) without the periods ``keep`` or more before ``newest``, once
    it holds twice that many (each insert amortised O(1)); else ``c`` itself."""
    if len(c) <= 2 * keep:
        return c
    if isinstance(c, dict):
        return {s: v for s, v in c.items() if s > newest - keep}
    return {s for s in c if s > newest - keep}


def _in_order(
    q: deque[tuple[int, can.Message]], key: int, msg: can.Message
) -> deque[tuple[int, can.Message]]:
    """``q`` with ``(key, msg)`` held in key order (after those of ``key`` held): at the
    end as a rule, in its place for a frame whose first copy was lost."""
    if not q or q[-1][0] <= key:
        q.append((key, msg))
        return q
    return deque(sorted([*q, (key, msg)], key=lambda x: x[0]))


class _Way:
    """One direction of a :class:`RealtimeLink` (delays in seconds)."""

    __slots__ = ("delay", "dist", "drop_prob", "dropped", "jit", "rng_drop", "rng_jit", "side")

    def __init__(
        self,
        side: str,
        delay: float,
        jit: float,
        dist: str,
        drop_prob: float,
        rng_drop: random.Random,
        rng_jit: random.Random,
    ) -> None:
        self.side = side
        self.delay = delay
        self.jit = jit
        self.dist = dist
        self.drop_prob = drop_prob
        self.rng_drop = rng_drop
        self.rng_jit = rng_jit
        self.dropped = 0

    def hold(self) -> float | None:
        """How long to hold a frame, s (>= 0); ``None``: drop it."""
        if self.drop_prob and self.rng_drop.random() < self.drop_prob:
            self.dropped += 1
            return None
        if not self.jit:
            return self.delay
        if self.dist == "uniform":
            j = self.rng_jit.uniform(-self.jit, self.jit)
        else:
            j = self.rng_jit.gauss(0.0, self.jit)
        d = self.delay + j
        return d if d > 0.0 else 0.0


class RealtimeLink:
    """Time-based link logic: frames get a release time; :meth:`due` pops them.

    Parameters
    ----------
    codec : Codec
        The DBC codec (frame IDs).
    sample_delay_us, duty_delay_us : float
        Fixed delay of the sample (A to B) and duty (B to A) directions, us.
    jitter_us : float
        Jitter, both directions, us: standard deviation (``"normal"``) or
        half-width (``"uniform"``).  The delay is ``max(0, delay + jitter)``.
    jitter_dist : str
        ``"normal"`` or ``"uniform"``.
    drop_prob : float
        Drop probability per frame, both directions.
    seed : int
        Seed of the random streams (two per direction, :func:`direction_rng`).
    clock : callable
        Time in seconds (monotonic).
    sample_jitter_us, duty_jitter_us, sample_drop_prob, duty_drop_prob : float or None
        One direction's jitter or drop probability; ``None``: the shared one.
    """

    def __init__(
        self,
        codec: Codec,
        *,
        sample_delay_us: float,
        duty_delay_us: float,
        jitter_us: float = 0.0,
        jitter_dist: str = "normal",
        drop_prob: float = 0.0,
        seed: int = 0,
        clock: Callable[[], float] = time.perf_counter,
        sample_jitter_us: float | None = None,
        duty_jitter_us: float | None = None,
        sample_drop_prob: float | None = None,
        duty_drop_prob: float | None = None,
    ) -> None:
        self.codec = codec
        self.samples = _Way(
            "b",
            sample_delay_us * 1e-6,
            _resolve(jitter_us, sample_jitter_us) * 1e-6,
            jitter_dist,
            _resolve(drop_prob, sample_drop_prob),
            direction_rng(seed, "samples", "drop"),
            direction_rng(seed, "samples", "jitter"),
        )
        self.duties = _Way(
            "a",
            duty_delay_us * 1e-6,
            _resolve(jitter_us, duty_jitter_us) * 1e-6,
            jitter_dist,
            _resolve(drop_prob, duty_drop_prob),
            direction_rng(seed, "duties", "drop"),
            direction_rng(seed, "duties", "jitter"),
        )
        self.clock = clock
        self.heap: list[tuple[float, int, str, can.Message]] = []
        self.n = 0
        self.forward_a = {
            codec.frame_id(n) for n in ("PhaseSamples", "PlantTruth", "PositionSensor")
        }
        self.id_duty = codec.frame_id("PwmDuty")
        self.id_cmd = codec.frame_id("BenchCommand")

    @property
    def dropped_samples(self) -> int:
        """Sample-direction frames (A to B) dropped on purpose."""
        return self.samples.dropped

    @property
    def dropped_duties(self) -> int:
        """Duty-direction frames (B to A) dropped on purpose."""
        return self.duties.dropped

    @property
    def dropped(self) -> int:
        """Frames dropped on purpose, both directions."""
        return self.samples.dropped + self.duties.dropped

    def _push(self, hold: float, side: str, msg: can.Message) -> None:
        self.n += 1
        heapq.heappush(self.heap, (self.clock() + hold, self.n, side, msg))

    def from_a(self, msg: can.Message) -> None:
        """A frame seen on A (the plant's bus)."""
        if msg.arbitration_id in self.forward_a:
            hold = self.samples.hold()
            if hold is not None:
                self._push(hold, "b", msg)
        elif msg.arbitration_id == self.id_cmd:
            self._push(0.0, "b", msg)

    def from_b(self, msg: can.Message) -> None:
        """A frame seen on B (the controller's bus)."""
        if msg.arbitration_id == self.id_duty:
            hold = self.duties.hold()
            if hold is not None:
                self._push(hold, "a", msg)

    def next_time(self) -> float | None:
        return self.heap[0][0] if self.heap else None

    def due(self) -> list[tuple[str, can.Message]]:
        now = self.clock()
        out = []
        while self.heap and self.heap[0][0] <= now:
            _, _, side, msg = heapq.heappop(self.heap)
            out.append((side, msg))
        return out


def link_loop(
    bus_a: can.BusABC,
    bus_b: can.BusABC,
    logic: LockstepLink | RealtimeLink,
    *,
    on_ready: Callable[[], None] | None = None,
    stop: Callable[[], bool] = lambda: False,
    idle_s: float = 3600.0,
    sent: dict[str, int] | None = None,
) -> str:
    """Run a link between two buses until ``stop()`` or ``idle_s`` without traffic.

    The idle time counts from the last frame received, and only once traffic
    has begun: a link started ahead of its nodes waits for them however long
    they take to start (on a slow host, tens of seconds per Python process).
    Returns why it ended: ``"stopped"`` or ``"idle"``.

    ``sent``, when given, counts the frames forwarded (keys ``a_to_b``, ``b_to_a``)
    and the sends a bus refused (``send_errors``, ``frames_lost_on_send``).
    """
    count = sent if sent is not None else {}
    count.setdefault("a_to_b", 0)
    count.setdefault("b_to_a", 0)
    # a send the bus refuses (queue full, bus-off) is retried and counted, never fatal
    from bench.nodes._counters import NodeCounters

    counters = NodeCounters()
    if on_ready:
        on_ready()
    fds: list[int] | None
    try:
        fds = [bus_a.fileno(), bus_b.fileno()]
        if min(fds) < 0:
            fds = None
    except (NotImplementedError, AttributeError):
        fds = None
    last: float | None = None  # no traffic yet
    while not stop():
        got = False
        for side, bus in (("a", bus_a), ("b", bus_b)):
            while (msg := bus.recv(0.0)) is not None:
                got = True
                msg = _copy(msg)
                if isinstance(logic, LockstepLink):
                    to_b, to_a = logic.from_a(msg) if side == "a" else logic.from_b(msg)
                    send_all(bus_b, to_b, counters)
                    send_all(bus_a, to_a, counters)
                    count["a_to_b"] += len(to_b)
                    count["b_to_a"] += len(to_a)
                elif side == "a":
                    logic.from_a(msg)
                else:
                    logic.from_b(msg)
        wait = 0.05
        if isinstance(logic, RealtimeLink):
            for side, m in logic.due():
                send_all(bus_a if side == "a" else bus_b, [m], counters)
                count["b_to_a" if side == "a" else "a_to_b"] += 1
            nt = logic.next_time()
            if nt is not None:
                wait = max(0.0, min(wait, nt - logic.clock()))
        if counters.send_errors:
            count["send_errors"] = counters.send_errors
            count["frames_lost_on_send"] = counters.frames_lost_on_send
        if got:
            last = time.monotonic()
            continue
        if last is not None and time.monotonic() - last > idle_s:
            return "idle"
        if fds is not None:
            select.select(fds, [], [], wait)
        else:
            time.sleep(min(wait, 0.0002))
    return "stopped"


def _copy(msg: can.Message) -> can.Message:
    return can.Message(
        arbitration_id=msg.arbitration_id,
        is_extended_id=msg.is_extended_id,
        data=bytes(msg.data),
        is_fd=msg.is_fd,
        bitrate_switch=msg.bitrate_switch,
        dlc=msg.dlc,
    )
