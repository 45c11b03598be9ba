"""Plant and controller nodes: the DBC on one side, the pure libraries on the other.

The nodes are written as message-in / messages-out state machines with no I/O
of their own, so exactly the same code runs

- in-process (``bench._inprocess``: frames passed through a list, for fast
  tests and as the reference trace), and
- as OS processes on a python-can bus (``bench._proc``), in lockstep or in
  real time.

Step bookkeeping (DESIGN.md, "Timing model"):

- ``PhaseSamples.step = k``: the currents sampled at ``t = k T``.
- ``PwmDuty.step = k + 1``: the duty computed from sample ``k``; without
  injected latency it is applied during period ``k + 1``.  With a lockstep
  latency of ``N`` periods (sum of both directions) the plant applies duty
  ``t`` during period ``t + N``; periods with no duty yet run with the
  inverter disabled.
- ``BenchCommand.step = s``: both nodes apply the command just before
  they handle step ``s`` (lockstep), or on receipt (real time).

Counters on the wire are ``step mod 2**bits``; receivers unwrap them against
the step they expect.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import can

from bench._codec import Codec
from controller import Controller, ControlOutput, Measurement
from plant_rt import ConstantLoad, Plant

CMD_NONE, CMD_START, CMD_STOP, CMD_RESET, CMD_ENABLE, CMD_DISABLE = 0, 1, 2, 3, 4, 5

RPM_PER_RAD_S = 60.0 / (2.0 * math.pi)


def unwrap(raw: int, expected: int, modulus: int) -> int:
    """The step nearest ``expected`` whose value mod ``modulus`` is ``raw``."""
    half = modulus // 2
    d = (raw - expected + half) % modulus - half
    return expected + d


@dataclass(slots=True)
class Command:
    """A decoded bench command, with its full (unwrapped) step."""

    apply_step: int
    cmd: int
    speed_ref_rpm: float
    load_nm: float


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

    def reject(self, reason: str) -> None:
        self.frames_rejected += 1
        self.reject_reasons[reason] = self.reject_reasons.get(reason, 0) + 1


class _CommandQueue:
    """Bench commands ordered by apply step, de-duplicated by apply step."""

    def __init__(self, modulus: int) -> None:
        self.modulus = modulus
        self.pending: dict[int, Command] = {}
        self.applied_upto = -1

    def add(self, sig: dict[str, float], now: int, counters: NodeCounters) -> None:
        s = unwrap(int(sig["step"]), now, self.modulus)
        if s <= self.applied_upto:
            if s in self.pending or s < self.applied_upto - self.modulus // 4:
                return
            counters.late_commands += 1
            s = self.applied_upto + 1
        if s in self.pending:
            counters.duplicates += 1
            return
        self.pending[s] = Command(
            s, int(sig["cmd"]), float(sig["speed_ref"]), float(sig["load_torque"])
        )

    def due(self, step: int) -> list[Command]:
        out = [c for s, c in sorted(self.pending.items()) if s <= step]
        for c in out:
            del self.pending[c.apply_step]
        self.applied_upto = max(self.applied_upto, step)
        return out


class PlantNode:
    """The plant behind the DBC.

    Parameters
    ----------
    codec : Codec
    plant : Plant
    n_steps : int
        Periods to run before reporting completion (0: until stopped).
    lockstep_delay : int
        Total injected latency in whole periods (lockstep only).
    truth_every : int
        Send ``PlantTruth`` every this many periods (1 on virtual transports;
        more on a real bus, see the CAN budget).
    """

    def __init__(
        self,
        codec: Codec,
        plant: Plant,
        *,
        n_steps: int,
        lockstep_delay: int = 0,
        truth_every: int = 1,
    ) -> None:
        self.codec = codec
        self.plant = plant
        self.n_steps = n_steps
        self.delay = lockstep_delay
        self.truth_every = max(1, truth_every)
        self.m_step = 1 << codec.step_bits("PwmDuty")
        self.m_cmd = 1 << codec.step_bits("BenchCommand")
        self.m_truth = 1 << codec.step_bits("PlantTruth")
        self.m_samples = 1 << codec.step_bits("PhaseSamples")
        self.duties: dict[int, tuple[float, float, float, bool]] = {}
        self.latest_duty: tuple[float, float, float, bool] = (0.5, 0.5, 0.5, False)
        self.latest_duty_step = -1
        self.commands = _CommandQueue(self.m_cmd)
        self.counters = NodeCounters()
        self.started = False
        self.stopped = False
        self.jitter: dict[str, float] | None = None
        self.sent: deque[list[can.Message]] = deque(maxlen=lockstep_delay + 3)

    # -- receiving ---------------------------------------------------------
    def on_message(self, msg: can.Message) -> None:
        d = self.codec.decode(msg)
        if d is None:
            return
        if d.reason is not None:
            if d.name in ("PwmDuty", "BenchCommand"):
                self.counters.reject(d.reason)
            return
        k = self.plant.k
        if d.name == "PwmDuty":
            s = d.signals
            t = unwrap(int(s["step"]), k - self.delay, self.m_step)
            if t in self.duties or t <= self.latest_duty_step - 2 * self.m_step // 4:
                self.counters.duplicates += 1
                return
            duty = (float(s["duty_a"]), float(s["duty_b"]), float(s["duty_c"]), bool(s["enable"]))
            self.duties[t] = duty
            if t > self.latest_duty_step:
                self.latest_duty_step = t
                self.latest_duty = duty
        elif d.name == "BenchCommand":
            self.commands.add(d.signals, k, self.counters)

    # -- lockstep ----------------------------------------------------------
    def needed_duty(self) -> int:
        """Tag of the duty applied in the current period (lockstep)."""
        return self.plant.k - self.delay

    def ready(self) -> bool:
        """Lockstep: whether the duty for the current period has arrived."""
        t = self.needed_duty()
        return t <= 0 or t in self.duties

    def frames_now(self) -> list[can.Message]:
        """The frames describing the plant at the current instant ``k T``."""
        p = self.plant
        s = p.sample()
        status = 1 if self.started and not self.stopped else 0
        frames = [
            self.codec.encode(
                "PhaseSamples",
                {
                    "i_a": s.i_a,
                    "i_b": s.i_b,
                    "u_dc": s.u_dc,
                    "step": s.k % self.m_samples,
                    "status": status,
                },
            )
        ]
        if s.k % self.truth_every == 0:
            tr = p.truth()
            frames.append(
                self.codec.encode(
                    "PlantTruth",
                    {
                        "theta_e": tr.theta_e,
                        "w_m": tr.w_m,
                        "tau_e": tr.tau_e,
                        "tau_L": tr.tau_L,
                        "step": s.k % self.m_truth,
                    },
                )
            )
        self.sent.append(frames)
        return frames

    def apply_commands(self) -> None:
        for c in self.commands.due(self.plant.k):
            if c.cmd == CMD_START:
                self.started = True
            elif c.cmd == CMD_STOP:
                self.stopped = True
            self.plant.set_load(ConstantLoad(c.load_nm))

    def advance_lockstep(self) -> list[can.Message]:
        """Run the current period with its duty; return the next instant's frames."""
        t = self.needed_duty()
        if t <= 0:
            d_a, d_b, d_c, en = 0.5, 0.5, 0.5, False
        else:
            d_a, d_b, d_c, en = self.duties.pop(t)
            for old in [s for s in self.duties if s < t]:
                del self.duties[old]
        self.plant.step(d_a, d_b, d_c, en)
        self.apply_commands()
        return self.frames_now()

    def retransmit(self) -> list[can.Message]:
        """Frames to resend when the expected duty did not come (lossy transport)."""
        self.counters.retransmits += 1
        return [m for frames in self.sent for m in frames]

    # -- real time ---------------------------------------------------------
    def advance_realtime(self) -> list[can.Message]:
        """Run one period with the latest valid duty (real-time mode)."""
        d_a, d_b, d_c, en = self.latest_duty
        expected = self.plant.k - self.delay
        if self.latest_duty_step < expected:
            if self.latest_duty_step < 0:
                en = False
            else:
                self.counters.late_duties += 1
        self.plant.step(d_a, d_b, d_c, en)
        self.duties.clear()
        self.apply_commands()
        return self.frames_now()

    def status_frame(self, state: int, fault_code: int = 0) -> can.Message:
        c = self.counters
        return self.codec.encode(
            "PlantStatus",
            {
                "state": state,
                "fault_code": fault_code,
                "overruns": min(c.overruns, 0xFFFF),
                "late_frames": min(c.late_duties, 0xFFFF),
                "step": self.plant.k % (1 << self.codec.step_bits("PlantStatus")),
            },
        )

    @property
    def done(self) -> bool:
        return self.stopped or (self.n_steps > 0 and self.plant.k >= self.n_steps)


class ControllerNode:
    """The controller behind the DBC: one sample in, one duty (+ telemetry) out.

    Samples are processed strictly in step order; a sample that arrives
    twice gets the cached answer again (the plant retransmits when a frame
    was lost), a sample from the future waits for the missing ones.

    Parameters
    ----------
    needs_truth : bool
        The sensored baseline waits for ``PlantTruth`` of the same step.
    """

    def __init__(self, codec: Codec, controller: Controller, *, needs_truth: bool = False) -> None:
        self.codec = codec
        self.ctrl = controller
        self.needs_truth = needs_truth
        self.m_step = 1 << codec.step_bits("PhaseSamples")
        self.m_cmd = 1 << codec.step_bits("BenchCommand")
        self.m_tel = 1 << codec.step_bits("CtrlTelemetry")
        self.m_truth = 1 << codec.step_bits("PlantTruth")
        self.next_k = 0
        self.samples: dict[int, dict[str, float]] = {}
        self.truth: dict[int, dict[str, float]] = {}
        self.answers: dict[int, list[can.Message]] = {}
        self.commands = _CommandQueue(self.m_cmd)
        self.counters = NodeCounters()
        self.stopped = False
        self.realtime = False

    def on_message(self, msg: can.Message) -> list[can.Message]:
        d = self.codec.decode(msg)
        if d is None:
            return []
        if d.reason is not None:
            if d.name in ("PhaseSamples", "BenchCommand"):
                self.counters.reject(d.reason)
            return []
        if d.name == "BenchCommand":
            self.commands.add(d.signals, self.next_k, self.counters)
            if self.realtime:
                self._apply_commands(self.next_k + self.m_cmd)
            return []
        if d.name == "PhaseSamples":
            k = unwrap(int(d.signals["step"]), self.next_k, self.m_step)
            if k < self.next_k:
                self.counters.duplicates += 1
                return list(self.answers.get(k, []))
            if self.realtime and k > self.next_k:
                # real time: never wait for the past, skip to the newest sample
                self.samples = {s: v for s, v in self.samples.items() if s >= k}
                self.next_k = k
            self.samples[k] = d.signals
        elif d.name == "PlantTruth" and self.needs_truth:
            k = unwrap(int(d.signals["step"]), self.next_k, self.m_truth)
            if k >= self.next_k:
                self.truth[k] = d.signals
        else:
            return []
        return self._run_ready()

    def _apply_commands(self, step: int) -> None:
        for c in self.commands.due(step):
            if c.cmd in (CMD_START, CMD_ENABLE, CMD_RESET):
                self.ctrl.set_enable(True)
            elif c.cmd in (CMD_STOP, CMD_DISABLE):
                self.ctrl.set_enable(False)
                if c.cmd == CMD_STOP:
                    self.stopped = True
            self.ctrl.set_speed_ref(c.speed_ref_rpm / RPM_PER_RAD_S)

    def _run_ready(self) -> list[can.Message]:
        out: list[can.Message] = []
        while self.next_k in self.samples and (not self.needs_truth or self.next_k in self.truth):
            k = self.next_k
            s = self.samples.pop(k)
            tr = self.truth.pop(k, None)
            self._apply_commands(k)
            theta = w_e = None
            if tr is not None:
                theta = float(tr["theta_e"])
                w_e = float(tr["w_m"]) * self.ctrl.pars.motor.n_p
            i_a, i_b = float(s["i_a"]), float(s["i_b"])
            m = Measurement(k, i_a, i_b, -i_a - i_b, float(s["u_dc"]), theta, w_e)
            o = self.ctrl.step(m)
            frames = self.encode_output(o)
            self.answers[k] = frames
            self.answers.pop(k - 8, None)
            out.extend(frames)
            self.next_k = k + 1
        return out

    def encode_output(self, o: ControlOutput) -> list[can.Message]:
        return [
            self.codec.encode(
                "PwmDuty",
                {
                    "duty_a": o.d_a,
                    "duty_b": o.d_b,
                    "duty_c": o.d_c,
                    "enable": 1 if o.enable else 0,
                    "step": (o.k + 1) % self.m_step,
                },
            ),
            self.codec.encode(
                "CtrlTelemetry",
                {
                    "theta_hat": o.theta_hat,
                    "w_hat": o.w_hat,
                    "err": o.err,
                    "mode": o.mode,
                    "step": o.k % self.m_tel,
                },
            ),
        ]
