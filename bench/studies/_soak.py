"""Fuzzing and soak runs of the bench's nodes: nothing crashes, nothing bad is applied.

:class:`FrameFuzzer` pours frames at a node: valid frames with random signal
values (including the bench's own identifiers), corrupted copies, wrong
lengths, unknown identifiers, random payloads, duplicates, replays of old
frames and reordered bursts. :func:`fuzz_node` feeds them to a
:class:`~bench.nodes._plant_node.PlantNode` or :class:`~bench.nodes._controller_node.ControllerNode`
directly (``on_message``), advancing the node as it would run, with the
plant's ``step`` wrapped by :class:`StepGuard`, which checks every applied
duty against an oracle that is independent of the codec: the raw E2E check
of :mod:`bench.wire._e2e` and a by-hand unpacking of the ``PwmDuty`` layout.

:func:`run_soak` adds a closed loop (plant and controller in lockstep, as
:func:`bench.nodes._loops.run_inprocess`) with invalid frames injected every period
and faults injected on purpose (duty starvation for the watchdog, forged
full-scale duties for an over-current trip), each followed by a reset
command, and checks that the recorded trace has every period.
"""

from __future__ import annotations

import random
import time
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass, field
from typing import Any

import can
import cantools

from bench.nodes._controller_node import ControllerNode
from bench.nodes._plant_node import PlantNode
from bench.wire._codec import Codec
from bench.wire._e2e import crc8_j1850
from bench.wire._protocol import CMD_DISABLE, CMD_RESET, unwrap
from dbc import DBC_PATH
from plant_rt import FAULT_NONE, FAULT_OVER_CURRENT, FAULT_WATCHDOG

__all__ = [
    "FUZZ_KINDS",
    "FrameFuzzer",
    "FuzzResult",
    "SoakReport",
    "StepGuard",
    "e2e_ok",
    "fuzz_node",
    "raw_duty",
    "run_soak",
]

FUZZ_KINDS = (
    "valid",
    "corrupt",
    "bad_length",
    "unknown_id",
    "random_payload",
    "duplicate",
    "replay",
    "burst",
)
"""What :class:`FrameFuzzer` produces (``burst``: a reordered run of old frames)."""

#: Soak loop: the operator waits this many periods after a trip before the reset.
RESET_WAIT_PERIODS = 50


def e2e_ok(codec: Codec, msg: can.Message) -> bool:
    """Oracle: the frame has its DBC length and a correct E2E CRC (or carries none).

    Computed from :func:`bench.wire._e2e.crc8_j1850` and the DBC attributes, not
    through :meth:`Codec.decode`.
    """
    name = codec.name_of(msg.arbitration_id, msg.is_extended_id)
    if name is None:
        return False
    data = bytes(msg.data)
    if len(data) != codec.length(name) or msg.is_remote_frame or msg.is_error_frame:
        return False
    m = codec.message(name)
    if not any(s.name == "crc" for s in m.signals):
        return True
    data_id = int(m.dbc.attributes["E2EDataId"].value)  # type: ignore[union-attr]
    return crc8_j1850(bytes((data_id & 0xFF, data_id >> 8)) + data[1:]) == data[0]


def raw_duty(data: bytes) -> tuple[float, float, float, bool]:
    """Oracle: the duties of a ``PwmDuty`` payload, decoded by cantools alone.

    Straight from the DBC's message definition (no CRC check, no range
    check, none of :class:`~bench.wire._codec.Codec`'s fast paths), so a defect in
    the codec's decoding cannot hide itself from the fuzz test.
    """
    sig: Any = _PWM_DUTY.decode(data[:8], decode_choices=False, scaling=True)
    return (float(sig["duty_a"]), float(sig["duty_b"]), float(sig["duty_c"]), bool(sig["enable"]))


_DB = cantools.database.load_file(str(DBC_PATH))
assert isinstance(_DB, cantools.database.can.Database)
_PWM_DUTY = _DB.get_message_by_name("PwmDuty")


class StepGuard:
    """Wraps ``plant.step``: every applied duty must be in [0, 1] and come from a valid frame.

    Parameters
    ----------
    plant : object with ``step(d_a, d_b, d_c, enable)``
        Its ``step`` is replaced by the checking wrapper.
    allowed : set of tuple
        Duty triples ``(d_a, d_b, d_c)`` of frames the oracle found valid; an
        enabled step with any other triple is a violation. Callers add to it.

    Attributes
    ----------
    steps, enabled_steps : int
        Steps taken and steps with the inverter enabled.
    violations : list of str
        Every violation (the guard records instead of raising, so that the
        node under test cannot swallow the error).
    """

    def __init__(self, plant: Any, allowed: set[tuple[float, float, float]]) -> None:
        self.allowed = allowed
        self.steps = 0
        self.enabled_steps = 0
        self.violations: list[str] = []
        self._step: Callable[..., None] = plant.step
        plant.step = self.step

    def step(self, d_a: float, d_b: float, d_c: float, enable: bool = True) -> None:
        self.steps += 1
        if not (0.0 <= d_a <= 1.0 and 0.0 <= d_b <= 1.0 and 0.0 <= d_c <= 1.0):
            self.violations.append(f"duty outside [0, 1]: {(d_a, d_b, d_c)}")
        if enable:
            self.enabled_steps += 1
            if (d_a, d_b, d_c) not in self.allowed:
                self.violations.append(f"duty not from a valid frame: {(d_a, d_b, d_c)}")
        self._step(d_a, d_b, d_c, enable)


class FrameFuzzer:
    """Random frames for the bench's nodes.

    Parameters
    ----------
    codec : Codec
    seed : int
    names : sequence of str, optional
        Messages to forge valid frames of (default: every DBC message).
    weights : dict of str to float, optional
        Relative frequency of each kind in :data:`FUZZ_KINDS`.
    step_near : callable, optional
        Returns a step number that valid frames are placed near (e.g. the
        node's present period), so that some of them land in the window a
        receiver accepts; None: any counter value.
    """

    def __init__(
        self,
        codec: Codec,
        seed: int = 0,
        *,
        names: tuple[str, ...] | None = None,
        weights: dict[str, float] | None = None,
        step_near: Callable[[], int] | None = None,
    ) -> None:
        self.codec = codec
        self.rng = random.Random(seed)
        self.names = names or codec.names
        w = {k: 1.0 for k in FUZZ_KINDS}
        w.update(weights or {})
        self.kinds = [k for k in FUZZ_KINDS if w.get(k, 0.0) > 0.0]
        self.kind_w = [w[k] for k in self.kinds]
        self.step_near = step_near
        self.history: deque[can.Message] = deque(maxlen=256)
        self.known_ids = {codec.frame_id(n) for n in codec.names}
        self.crc_names = tuple(
            n for n in self.names if any(s.name == "crc" for s in codec.message(n).signals)
        )
        self.counts: dict[str, int] = {}
        self._pending: list[tuple[can.Message, str]] = []

    def valid(self, name: str | None = None) -> can.Message:
        """A correctly encoded frame with random signal values."""
        rng = self.rng
        name = name or rng.choice(self.names)
        sig: dict[str, float] = {}
        for s in self.codec.message(name).signals:
            if s.name == "crc":
                continue
            lo = float(s.minimum if s.minimum is not None else 0.0)
            hi = float(s.maximum if s.maximum is not None else 1.0)
            sig[s.name] = rng.uniform(lo, hi) if s.scale != 1 else rng.randint(int(lo), int(hi))
        if self.step_near is not None and rng.random() < 0.7:
            sig["step"] = max(0, self.step_near() + rng.randint(-20, 3))
        return self.codec.encode(name, sig)

    def _raw(self, fid: int, data: bytes, ext: bool = False) -> can.Message:
        fd = len(data) > 8
        return can.Message(arbitration_id=fid, is_extended_id=ext, is_fd=fd, data=data, check=False)

    def one(self) -> tuple[can.Message, str]:
        """The next frame and its kind."""
        if self._pending:
            return self._pending.pop()
        rng = self.rng
        kind = rng.choices(self.kinds, self.kind_w)[0]
        if kind in ("duplicate", "replay", "burst") and not self.history:
            kind = "valid"
        msg: can.Message
        if kind == "valid":
            msg = self.valid()
        elif kind == "corrupt":
            good = self.valid(rng.choice(self.crc_names) if self.crc_names else None)
            data = bytearray(good.data)
            data[rng.randrange(len(data))] ^= rng.randint(1, 255)
            msg = self._raw(good.arbitration_id, bytes(data))
        elif kind == "bad_length":
            fid = self.codec.frame_id(rng.choice(self.names))
            right = self.codec.length(self.codec.name_of(fid) or "")
            n = rng.choice([x for x in (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 64) if x != right])
            msg = self._raw(fid, rng.randbytes(n))
        elif kind == "unknown_id":
            ext = rng.random() < 0.3
            while True:
                fid = rng.getrandbits(29 if ext else 11)
                if ext or fid not in self.known_ids:
                    break
            msg = self._raw(fid, rng.randbytes(rng.choice((0, 1, 4, 8, 12, 16, 64))), ext)
        elif kind == "random_payload":
            name = rng.choice(self.names)
            msg = self._raw(self.codec.frame_id(name), rng.randbytes(self.codec.length(name)))
        elif kind == "duplicate":
            msg = self.history[-1]
        elif kind == "replay":
            msg = self.history[rng.randrange(len(self.history))]
        else:  # burst: a reordered run of recent frames
            n = min(len(self.history), rng.randint(2, 12))
            burst = list(self.history)[-n:]
            rng.shuffle(burst)
            self._pending = [(m, "burst") for m in burst[1:]]
            msg = burst[0]
        self.history.append(msg)
        self.counts[kind] = self.counts.get(kind, 0) + 1
        return msg, kind

    def __iter__(self) -> Iterator[tuple[can.Message, str]]:
        while True:
            yield self.one()


@dataclass(slots=True)
class FuzzResult:
    """What a node did with fuzzed frames.

    ``expected`` holds the oracle's counts of frames the node must reject
    for a given reason (``bad_length``, ``bad_crc``); ``counters`` the node's.
    """

    frames: int
    kinds: dict[str, int]
    counters: dict[str, Any]
    expected: dict[str, int]
    exceptions: list[str] = field(default_factory=list)
    violations: list[str] = field(default_factory=list)
    steps: int = 0
    enabled_steps: int = 0
    out_of_range_outputs: int = 0
    #: Frames given as CAN FD (the rest classic).
    fd_frames: int = 0


def _counters(node: PlantNode | ControllerNode) -> dict[str, Any]:
    c = node.counters
    d = c.as_dict()
    d["frames_seen"] = c.frames_seen
    return d


def fuzz_node(
    node: PlantNode | ControllerNode,
    frames: int,
    *,
    seed: int = 0,
    realtime: bool = False,
    weights: dict[str, float] | None = None,
    advance_every: int = 4,
) -> FuzzResult:
    """Feed ``frames`` fuzzed frames to ``node`` through ``on_message``.

    A plant node is advanced every ``advance_every`` frames (real time: always;
    lockstep: when its duty is there) with its ``step`` guarded by
    :class:`StepGuard`. A controller node's answers are checked: every
    ``PwmDuty`` it sends must pass the oracle with duties in [0, 1].
    Exceptions are caught and recorded, never raised.
    """
    codec = node.codec
    is_plant = isinstance(node, PlantNode)
    if is_plant:
        assert isinstance(node, PlantNode)
        node.realtime = realtime
        node.started = True
        near: Callable[[], int] = lambda: node.plant.k  # noqa: E731
        consumed = {codec.frame_id("PwmDuty"), codec.frame_id("BenchCommand")}
    else:
        assert isinstance(node, ControllerNode)
        node.realtime = realtime
        node.ctrl.set_enable(True)
        near = lambda: node.next_k  # noqa: E731
        consumed = {codec.frame_id("PhaseSamples"), codec.frame_id("BenchCommand")}
        if node.needs_truth:
            consumed.add(codec.frame_id("PlantTruth"))
    fz = FrameFuzzer(codec, seed, weights=weights, step_near=near)
    allowed: set[tuple[float, float, float]] = {(0.5, 0.5, 0.5)}
    guard = StepGuard(node.plant, allowed) if isinstance(node, PlantNode) else None
    duty_id = codec.frame_id("PwmDuty")
    expected = {"bad_length": 0, "bad_crc": 0}
    res = FuzzResult(frames=frames, kinds=fz.counts, counters={}, expected=expected)
    for i in range(frames):
        msg, _ = fz.one()
        res.fd_frames += msg.is_fd
        fid = msg.arbitration_id
        if fid in consumed and not msg.is_extended_id:
            name = codec.name_of(fid) or ""
            if len(msg.data) != codec.length(name):
                expected["bad_length"] += 1
            elif not e2e_ok(codec, msg):
                expected["bad_crc"] += 1
            elif fid == duty_id:
                allowed.add(raw_duty(bytes(msg.data))[:3])
        try:
            out = node.on_message(msg)
            if isinstance(node, ControllerNode):
                for m in out or ():
                    if m.arbitration_id == duty_id:
                        d = raw_duty(bytes(m.data))
                        if not e2e_ok(codec, m) or not all(0.0 <= x <= 1.0 for x in d[:3]):
                            res.out_of_range_outputs += 1
            elif i % advance_every == 0:
                if realtime:
                    node.advance_realtime()
                elif node.ready():
                    node.advance_lockstep()
                elif i % (8 * advance_every) == 0:
                    node.on_duty_timeout()
                else:
                    # a well-behaved controller's duty among the junk, so that lockstep moves
                    r = fz.rng.uniform(0.45, 0.55)
                    legit = codec.encode(
                        "PwmDuty",
                        {"duty_a": r, "duty_b": 0.5, "duty_c": 1.0 - r, "enable": 1,
                         "step": node.needed_duty()},
                    )  # fmt: skip
                    allowed.add(raw_duty(bytes(legit.data))[:3])
                    node.on_message(legit)
                    res.frames += 1
        except Exception as e:  # the point of the test: record, do not stop
            res.exceptions.append(f"{type(e).__name__}: {e}")
    if guard is not None:
        res.violations = guard.violations
        res.steps = guard.steps
        res.enabled_steps = guard.enabled_steps
    res.counters = _counters(node)
    return res


@dataclass(slots=True)
class SoakReport:
    """Figures of a soak run (docs/RELIABILITY.md quotes them)."""

    seed: int
    frames_fuzzed: int = 0
    frames_fuzzed_plant: int = 0
    frames_fuzzed_controller: int = 0
    frames_fuzzed_loop: int = 0
    #: Of the frames fuzzed, those given as CAN FD, per part (``plant``, ``controller``, ``loop``).
    frames_fd: dict[str, int] = field(default_factory=dict)
    rejected: dict[str, int] = field(default_factory=dict)
    exceptions: int = 0
    violations: int = 0
    unchecked_rejections: int = 0
    faults_injected: dict[str, int] = field(default_factory=dict)
    trips: dict[str, int] = field(default_factory=dict)
    recoveries: int = 0
    loop_periods: int = 0
    data_lost_periods: int = 0
    wall_s: float = 0.0
    notes: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """No exception, no violation, every rejection counted, every fault recovered, no loss."""
        injected = sum(self.faults_injected.values())
        return (
            self.exceptions == 0
            and self.violations == 0
            and self.unchecked_rejections == 0
            and self.data_lost_periods == 0
            and self.recoveries == injected
        )

    def as_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["ok"] = self.ok
        return d


def _merge(into: dict[str, int], add: dict[str, int]) -> None:
    for k, v in add.items():
        into[k] = into.get(k, 0) + int(v)


def _check_fuzz(rep: SoakReport, res: FuzzResult, who: str) -> None:
    rep.exceptions += len(res.exceptions)
    rep.violations += len(res.violations) + res.out_of_range_outputs
    c = res.counters
    if c["frames_seen"] != res.frames:
        rep.unchecked_rejections += abs(res.frames - c["frames_seen"])
        rep.notes.append(f"{who}: {res.frames} frames given, {c['frames_seen']} counted")
    for reason, n in res.expected.items():
        got = c["reject_reasons"].get(reason, 0)
        if got != n:
            rep.unchecked_rejections += abs(got - n)
            rep.notes.append(f"{who}: {reason}: oracle {n}, node {got}")
    _merge(rep.rejected, c["reject_reasons"])
    for e in res.exceptions[:3]:
        rep.notes.append(f"{who}: {e}")
    for v in res.violations[:3]:
        rep.notes.append(f"{who}: {v}")


def run_soak(
    frames: int,
    *,
    seed: int = 0,
    scenario: str = "wen-5.1",
    loop_periods: int = 4000,
    fault_every: int = 500,
    progress: Callable[[str], None] | None = None,
    dbc: str | None = None,
) -> SoakReport:
    """Fuzz both nodes with ``frames`` frames each, then a closed loop with faults.

    Parameters
    ----------
    frames : int
        Fuzzed frames per node (the closed loop adds its own).
    seed : int
        Seed of everything random.
    scenario : str
        Scenario the nodes are built from (sensored estimator: the fastest).
    loop_periods : int
        Periods of the closed loop.
    fault_every : int
        A fault is injected every this many periods of the loop, alternately
        duty starvation (watchdog) and forged full-scale duties (over-current).
    progress : callable, optional
        Called with a line of text per phase.
    dbc : str, optional
        DBC file (default: the bench's own).
    """
    from bench.nodes._loops import command_frames, make_controller_node, make_plant_node
    from bench.scenarios._schema import load_scenario

    t0 = time.perf_counter()
    say = progress or (lambda s: None)
    codec = Codec(dbc)
    base = load_scenario(scenario)
    rep = SoakReport(seed=seed)
    # 1. each node alone, both modes
    # the plant's share is split between its two modes (the real-time half
    # gets the odd frame), so each node gets exactly ``frames``
    for who, k, rt in (("plant", 0, True), ("plant", 1, False), ("controller", 2, True)):
        n = frames if who == "controller" else (frames + 1) // 2 if rt else frames // 2
        scn = base.with_overrides(duration=1e4, seed=seed + k)
        node: PlantNode | ControllerNode
        if who == "plant":
            node = make_plant_node(scn, codec, watchdog_rounds=5)
        else:
            node = make_controller_node(scn, "sensored", codec)
        say(f"fuzz {who} ({'real time' if rt else 'lockstep'}): {n} frames")
        res = fuzz_node(node, n, seed=seed + k, realtime=rt)
        _check_fuzz(rep, res, who)
        _merge(rep.frames_fd, {who: res.fd_frames})
        if isinstance(node, PlantNode):
            rep.frames_fuzzed_plant += n
            _merge(rep.trips, node.trips)
        else:
            rep.frames_fuzzed_controller += n
    # 2. closed loop with injected invalid frames and faults
    say(f"closed loop: {loop_periods} periods, a fault every {fault_every}")
    scn = base.with_overrides(duration=loop_periods * 1e-4 * 2, seed=seed)
    pn = make_plant_node(scn, codec, watchdog_rounds=3)
    cn = make_controller_node(scn, "sensored", codec)
    m_cmd = 1 << codec.step_bits("BenchCommand")
    allowed: set[tuple[float, float, float]] = {(0.5, 0.5, 0.5)}
    guard = StepGuard(pn.plant, allowed)
    fz = FrameFuzzer(
        codec,
        seed + 7,
        weights={"valid": 0.0, "duplicate": 2.0, "replay": 2.0, "burst": 0.5},
        step_near=lambda: pn.plant.k,
    )
    duty_id = codec.frame_id("PwmDuty")
    samples_id = codec.frame_id("PhaseSamples")
    recorded: list[can.Message] = []
    seq = 0

    def to_plant(m: can.Message) -> None:
        if m.arbitration_id == duty_id and e2e_ok(codec, m):
            allowed.add(raw_duty(bytes(m.data))[:3])
        pn.on_message(m)

    def command(cmd: int, step: int) -> None:
        nonlocal seq
        m = codec.encode(
            "BenchCommand",
            {
                "cmd": cmd,
                "seq": seq % 16,
                "speed_ref": 100.0,
                "load_torque": 0.0,
                "step": step % m_cmd,
            },
        )
        seq += 1
        to_plant(m)
        cn.on_message(m)

    for _, m in command_frames(scn, codec)[:1]:
        pn.on_message(m)
        cn.on_message(m)
    pn.apply_commands()
    out = pn.frames_now()
    phase = ""
    fault_kind = ""
    mark = 0
    enabled_mark = 0
    while pn.plant.k < loop_periods:
        k = pn.plant.k
        recorded.extend(out)
        replies: list[can.Message] = []
        try:
            for m in out:
                replies.extend(cn.on_message(m))
            # invalid and replayed frames at both nodes, every period
            for _ in range(fz.rng.randint(1, 6)):
                junk, _ = fz.one()
                rep.frames_fuzzed_loop += 1
                _merge(rep.frames_fd, {"loop": int(junk.is_fd)})
                replies.extend(cn.on_message(junk))
                to_plant(junk)
        except Exception as e:
            rep.exceptions += 1
            rep.notes.append(f"loop: {type(e).__name__}: {e}")
        if k and k % fault_every == 0 and not phase:
            fault_kind = "watchdog" if (k // fault_every) % 2 else "over_current"
            rep.faults_injected[fault_kind] = rep.faults_injected.get(fault_kind, 0) + 1
            phase, mark = "inject", k
        if phase == "inject":
            if pn.fault != FAULT_NONE:
                want = FAULT_WATCHDOG if fault_kind == "watchdog" else FAULT_OVER_CURRENT
                if pn.fault != want:
                    rep.notes.append(f"period {k}: fault {pn.fault}, expected {want}")
                # the operator disables the drive, waits, then resets
                command(CMD_DISABLE, k + 1)
                phase, mark = "tripped", k
            elif fault_kind == "watchdog":
                # the controller's duty is withheld: retransmission rounds pass
                for _ in range(pn.watchdog_rounds):
                    pn.on_duty_timeout()
            elif k - mark > 2000:
                rep.notes.append("over-current never tripped")
                phase = ""
            else:
                # a faulty controller: valid frames with full-scale duties
                replies = [
                    codec.encode(
                        "PwmDuty",
                        {"duty_a": 1.0, "duty_b": 0.0, "duty_c": 0.0, "enable": 1, "step": k + 1},
                    )
                    if m.arbitration_id == duty_id
                    else m
                    for m in replies
                ]
        elif phase == "tripped" and k - mark >= RESET_WAIT_PERIODS:
            command(CMD_RESET, k + 1)
            phase, mark, enabled_mark = "resetting", k, guard.enabled_steps
        elif phase == "resetting" and k - mark >= RESET_WAIT_PERIODS:
            if pn.fault == FAULT_NONE and guard.enabled_steps > enabled_mark:
                rep.recoveries += 1
                phase = ""
            elif pn.fault != FAULT_NONE:
                command(CMD_DISABLE, k + 1)
                phase, mark = "tripped", k  # tripped again: disable, wait, reset again
            elif k - mark > 20 * RESET_WAIT_PERIODS:
                rep.notes.append(f"no recovery after the reset at period {mark}")
                phase = ""
        recorded.extend(replies)
        for m in replies:
            to_plant(m)
        if not pn.ready():
            rep.notes.append(f"loop stalled at period {k}")
            break
        out = pn.advance_lockstep()
    rep.loop_periods = pn.plant.k
    rep.violations += len(guard.violations)
    rep.notes.extend(guard.violations[:3])
    _merge(rep.trips, pn.trips)
    _merge(rep.rejected, pn.counters.reject_reasons)
    _merge(rep.rejected, cn.counters.reject_reasons)
    # data lost: every period must have its sample frame, in order
    m_s = 1 << codec.step_bits("PhaseSamples")
    got = set()
    expect = 0
    for m in recorded:
        if m.arbitration_id == samples_id:
            d = codec.decode(m)
            if d is not None and d.ok:
                j = unwrap(int(d.signals["step"]), expect, m_s)
                got.add(j)
                expect = j
    rep.data_lost_periods = sum(1 for j in range(rep.loop_periods) if j not in got)
    rep.frames_fuzzed = (
        rep.frames_fuzzed_plant + rep.frames_fuzzed_controller + rep.frames_fuzzed_loop
    )
    rep.wall_s = time.perf_counter() - t0
    return rep
