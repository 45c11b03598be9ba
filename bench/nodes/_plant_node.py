"""The plant node: the DBC on one side, :class:`plant_rt.Plant` on the other.

The controller node (:mod:`bench.nodes._controller_node`) follows the same rules.

The nodes are written as message-in / messages-out state machines with no I/O
of their own, so exactly the same code runs

- in-process (``bench.nodes._loops.run_inprocess``: frames passed through a list, for fast
  tests and as the reference trace), and
- as OS processes on a python-can bus (``bench.nodes._loops``), in lockstep or in
  real time.

Step bookkeeping (DESIGN.md, "Timing model"):

- ``PhaseSamples.step = k``: the currents sampled at ``t = k T``.
- ``PwmDuty.step = k + 1``: the duty computed from sample ``k``; without
  injected latency it is applied during period ``k + 1``.  With a lockstep
  latency of ``N`` periods (sum of both directions) the plant applies duty
  ``t`` during period ``t + N``; periods with no duty yet run with the
  inverter disabled.
- ``BenchCommand.step = s``: both nodes apply the command just before
  they handle step ``s``, in both modes; a command that arrives after its
  step takes effect in the next period (counted in ``late_commands``).

Counters on the wire are ``step mod 2**bits``; receivers unwrap them against
the step they expect.

Fail-safe behaviour (docs/RELIABILITY.md): every frame a node receives ends in
exactly one of its counters: accepted, rejected (with a reason: the codec's
``bad_crc``, ``bad_length``, ``decode_error``, ``out_of_range``, or the node's
``stale_counter``, ``future_counter``), repeated (``repeated_counter``: an
exact repeat of an accepted counter, produced by the bench itself when it
sends commands twice or retransmits in lockstep; answered as before, counted
but not as a rejection), ignored (a DBC message the node does not consume)
or unknown (not in the DBC). Only an accepted duty frame with every duty in
[0, 1] is ever applied. The plant node trips to the safe state (all switches
open) on a protection fault (:class:`plant_rt.Protection`) or when valid duty
frames stop (watchdog), reports it with ``PlantStatus``, and stays there until
a ``reset`` or ``enable`` bench command; the controller node disables its PWM
when samples stop (real time).

A duty for period 0 answers no sample (sample 0 is answered by duty 1): it
comes from a controller that tags the duty of sample ``k`` with ``k``, which
would run the loop without its computation delay. The plant rejects it
(``wrong_step``) and trips with ``PlantStatus.fault_code`` 5 (``wrong_step``).
``PlantStatus`` also goes out every ``status_every`` periods (the DBC's
``GenMsgCycleTime``, 100 ms of plant time) while the run is on; its
``late_frames`` counts the periods without their own duty and the duty frames
rejected. docs/PROTOCOL.md is the same contract for a controller's author.

Serving a controller under test in lockstep, the plant also reads its
``CtrlTelemetry.cmd_ack`` (DBC 2.2) and runs no period whose next sample
needs a bench command the controller has not acknowledged (:meth:`PlantNode.acked`).
"""

from __future__ import annotations

import sys
import time
from collections import deque
from collections.abc import Callable

import can

from bench.nodes._counters import (
    DUTY_REPEAT_WINDOW,
    REJECT_FUTURE_COUNTER,
    REJECT_STALE_COUNTER,
    REPEATED_COUNTER,
    CommandQueue,
    NodeCounters,
)
from bench.nodes._fault_bus import NodeFaults
from bench.wire._codec import REJECT_BAD_CRC, REJECT_OUT_OF_RANGE, Codec
from bench.wire._protocol import (
    CMD_ENABLE,
    CMD_RESET,
    CMD_START,
    CMD_STOP,
    FAULT_WRONG_STEP,
    NODE_FAULT_NAMES,
    REJECT_WRONG_STEP,
    SHARED_RUN_FRAMES,
    STATE_FAULT,
    STATE_IDLE,
    STATE_RUNNING,
    seq_at_least,
    unwrap,
)
from plant_rt import (
    FAULT_NAMES,
    FAULT_NONE,
    FAULT_WATCHDOG,
    ConstantLoad,
    Plant,
    Protection,
    ProtectionPars,
    encoder_angle,
)

_SAFE_DUTY = (0.5, 0.5, 0.5, False)


def fault_name(code: int) -> str:
    """The DBC name of a ``PlantStatus.fault_code``: the machine's protections and the node's."""
    return FAULT_NAMES.get(code) or NODE_FAULT_NAMES.get(code) or str(code)


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
    protection : ProtectionPars, optional
        Trip thresholds (over-current, DC-link over-voltage, over-speed);
        None: no protection trips.
    watchdog_periods : int
        Real time: trip to the safe state when no valid duty frame has
        arrived for this many PWM periods of the plant's clock (0: off).
    watchdog_rounds : int
        Lockstep: trip when this many retransmission rounds in a row brought
        no valid duty frame, once a first one has come (0: off).
    status_every : int
        Send ``PlantStatus`` every this many periods from the start command
        (the DBC's ``GenMsgCycleTime`` in periods; 0: only on a change of
        state and at the end).
    """

    def __init__(
        self,
        codec: Codec,
        plant: Plant,
        *,
        n_steps: int,
        lockstep_delay: int = 0,
        truth_every: int = 1,
        protection: ProtectionPars | None = None,
        watchdog_periods: int = 0,
        watchdog_rounds: int = 0,
        status_every: int = 0,
    ) -> None:
        self.codec = codec
        self.plant = plant
        self.n_steps = n_steps
        self.delay = lockstep_delay
        self.truth_every = max(1, truth_every)
        #: The run's nonce, echoed in every PlantTruth (``run_id``, DBC 2.1).
        self.run_id = 0
        #: ``PlantTruth`` frames of another plant (another run_id) received, by run_id.
        self.other_plants: dict[int, int] = {}
        self.said_other_plant = False
        self.m_step = 1 << codec.step_bits("PwmDuty")
        self.m_cmd = 1 << codec.step_bits("BenchCommand")
        self.m_truth = 1 << codec.step_bits("PlantTruth")
        self.m_samples = 1 << codec.step_bits("PhaseSamples")
        self.m_status = 1 << codec.step_bits("PlantStatus")
        self.id_duty = codec.frame_id("PwmDuty")
        self.id_cmd = codec.frame_id("BenchCommand")
        self.id_samples = codec.frame_id("PhaseSamples")
        self.id_pos = codec.frame_id("PositionSensor")
        self.duties: dict[int, tuple[float, float, float, bool]] = {}
        self.latest_duty: tuple[float, float, float, bool] = _SAFE_DUTY
        self.latest_duty_step = -1
        #: Lockstep, a controller under test: the newest duty step that arrived and a
        #: [[faults]] window dropped (-1: none).  The plant waits for a dropped duty's
        #: arrival as for any other (:meth:`ready`): without that, it ran a drop
        #: window at its own pace and a controller slower than the plant lost samples.
        self.dropped_upto = -1
        #: Lockstep: the newest duty taken in its own period, and its tag.
        self.applied: tuple[tuple[float, float, float, bool], int] = (_SAFE_DUTY, -1)
        self.commands = CommandQueue(self.m_cmd)
        #: Lockstep pacing (0: off): run period k only once a bench command
        #: for step k + 1 or later has arrived. ``bench run`` sends one at least
        #: every this many periods, as far ahead as its recorder has seen, so
        #: the plant never outruns the recording (whose socket would overflow
        #: on a loaded machine) and no command is ever late.
        self.pace_every = 0
        self.cmd_horizon = -1
        self.counters = NodeCounters()
        self.started = False
        self.stopped = False
        self.realtime = False
        self.jitter: dict[str, float] | None = None
        #: Wall seconds of the stepping loop (start command to the last period).
        self.loop_s: float | None = None
        #: age (PWM periods) of the duty applied in the last period, at most 254;
        #: 255: none (before the first duty, and in the safe state after a trip).
        #: Sent in PlantTruth so the recorder measures the loop latency exactly.
        self.duty_age = 255
        self.sent: deque[list[can.Message]] = deque(maxlen=lockstep_delay + 3)
        self.protection = Protection(protection) if protection is not None else None
        self.watchdog_periods = max(0, int(watchdog_periods))
        self.watchdog_rounds = max(0, int(watchdog_rounds))
        #: Latched fault code (``PlantStatus.fault_code``); FAULT_NONE while healthy.
        self.fault = FAULT_NONE
        #: Step at which the fault was latched (-1: none).
        self.fault_step = -1
        #: Trips by fault name, and operator resets that cleared a fault.
        self.trips: dict[str, int] = {}
        self.resets = 0
        self.last_duty_k = 0
        self.rounds_waiting = 0
        self.status_every = max(0, int(status_every))
        #: ``PwmDuty`` frames not used, by reason (repeats excluded): the
        #: rejected part of ``PlantStatus.late_frames`` and of the stall message.
        self.duty_rejected: dict[str, int] = {}
        #: Whether a controller has answered at all (a duty accepted, or one for
        #: period 0 that tripped ``wrong_step``).
        self.dut_answered = False
        #: Serving a controller under test (``bench plant --dut-timeout``): the
        #: lockstep watchdog counts only from its first answer, and a lockstep
        #: trip ends the run (no duty will come: the periods cannot advance).
        self.external = False
        #: The position sensor of a sensored controller (``[sensors] encoder_counts``,
        #: DBC 2.2 ``PositionSensor``): sent every this many periods; 0: none.
        sp = plant.sensor_pars
        self.encoder_every = sp.encoder_every(plant.T_s) if sp.encoder_counts > 0 else 0
        #: ``CtrlTelemetry.cmd_ack`` of the controller (DBC 2.2): the seq of the
        #: newest command it holds with no gap, from its newest reporting
        #: telemetry; None while it has reported none (a 2.1 controller, or
        #: no telemetry): lockstep then runs ungated (:meth:`acked`).
        self.ctrl_ack: int | None = None
        self.id_tel = codec.frame_id("CtrlTelemetry")
        self._outbox: list[can.Message] = []
        #: The scenario's fault timeline (``[[faults]]``; :mod:`bench.nodes._fault_bus`).
        self.faults: NodeFaults | None = None
        #: Lockstep: PhaseSamples lost on their first sending, in order, sent again
        #: before the next sample that gets through (:mod:`bench.nodes._fault_bus`).
        self.withheld: list[can.Message] = []
        #: Real time: when each duty held by a ``delay`` in us may be applied (s, :attr:`clock`).
        self.released_at: dict[int, float] = {}
        #: The clock of the frames' receive timestamps (python-can's: seconds since the epoch).
        self.clock: Callable[[], float] = time.time
        #: Which loop served the node: ``python`` (:mod:`bench.nodes._loops`) or
        #: ``native`` (:mod:`bench.nodes.native._plant_native`).
        self.node_engine = "python"

    # -- receiving ---------------------------------------------------------
    def on_message(self, msg: can.Message) -> None:
        """Take one received frame; never raises for any frame content."""
        c = self.counters
        d = self.codec.decode(msg)
        if d is None:
            c.frames_unknown += 1
            return
        if d.name == "PwmDuty":
            if d.reason is not None:
                self._reject_duty(d.reason)
                return
            self._on_duty(d.signals, msg.timestamp)
        elif d.name == "BenchCommand":
            if d.reason is not None:
                c.reject(d.reason)
                return
            known = self.commands.add(d.signals, self.plant.k, c)
            if known is not None and known > self.cmd_horizon:
                self.cmd_horizon = known
        elif d.name == "CtrlTelemetry":
            c.frames_ignored += 1
            if d.reason is None and int(d.signals.get("cmd_ack_valid", 0)):
                a = int(d.signals["cmd_ack"])
                # the newest acknowledgement wins; an older one (a reordered frame) is dropped
                if self.ctrl_ack is None or seq_at_least(a, self.ctrl_ack):
                    self.ctrl_ack = a
        else:
            if d.name == "PlantTruth" and d.reason is None:
                rid = int(d.signals.get("run_id", 0))
                if rid != self.run_id:  # another plant (a second run) on this bus
                    seen = self.other_plants.get(rid, 0) + 1
                    self.other_plants[rid] = seen
                    if seen == SHARED_RUN_FRAMES and not self.said_other_plant:
                        self.said_other_plant = True
                        print(
                            f"plant: a second plant is on this bus: PlantTruth of run "
                            f"{rid:#06x} (this plant is run {self.run_id:#06x}); its samples "
                            "reach this run's controller",
                            file=sys.stderr,
                            flush=True,
                        )
            c.frames_ignored += 1

    def _reject_duty(self, reason: str) -> None:
        self.counters.reject(reason)
        if reason != REPEATED_COUNTER:
            self.duty_rejected[reason] = self.duty_rejected.get(reason, 0) + 1

    def _on_duty(self, s: dict[str, float], arrived: float = 0.0) -> None:
        """One valid duty frame; ``arrived``: its receive timestamp (s, the clock of
        :attr:`clock`; 0: unknown, taken as now), for a real-time ``delay`` in us."""
        c = self.counters
        k = self.plant.k
        t = unwrap(int(s["step"]), k - self.delay, self.m_step)
        if t == 0:
            # answers no sample (the first is sample 0, answered by duty 1): a
            # controller that tags the duty of sample k with k, which would run
            # the loop without its computation delay
            self._reject_duty(REJECT_WRONG_STEP)
            self.dut_answered = True
            self.trip(FAULT_WRONG_STEP)
            return
        if t > k + 1:
            # the controller answers sample k with duty k + 1 at the latest
            self._reject_duty(REJECT_FUTURE_COUNTER)
            return
        fate = None if self.faults is None else self.faults.duty_fate(t + self.delay)
        if (
            fate is None
            and self.faults is not None
            and not self.realtime
            and t >= k - self.delay
            and self.faults.answer_lost(t)
        ):
            # lockstep: the answer to a sample lost on its first sending, come with the
            # plant's resend: too late for its period, as in real time (_fault_bus)
            fate = "lost"
        if fate is not None:  # a bus fault: lost, or arrives with a bad E2E CRC
            self.dropped_upto = max(self.dropped_upto, t)  # arrived all the same
            if fate == "corrupt":
                self._reject_duty(REJECT_BAD_CRC)
            else:
                self.faults.duties_lost += 1  # type: ignore[union-attr]
            return
        if self.realtime:
            if t == self.latest_duty_step or t in self.duties:
                c.reject(REPEATED_COUNTER)
                return
            if t < self.latest_duty_step:
                self._reject_duty(REJECT_STALE_COUNTER)
                return
        else:
            needed = k - self.delay
            if t < needed - DUTY_REPEAT_WINDOW:
                self._reject_duty(REJECT_STALE_COUNTER)
                return
            if t < needed or t in self.duties:
                # already applied or already here: the answer to a retransmission
                c.reject(REPEATED_COUNTER)
                return
        d_a, d_b, d_c = float(s["duty_a"]), float(s["duty_b"]), float(s["duty_c"])
        if not (0.0 <= d_a <= 1.0 and 0.0 <= d_b <= 1.0 and 0.0 <= d_c <= 1.0):
            # the codec rejects these already (DBC range [0|1]); kept as a guard
            self._reject_duty(REJECT_OUT_OF_RANGE)
            return
        c.frames_accepted += 1
        self.dut_answered = True
        duty = (d_a, d_b, d_c, bool(s["enable"]))
        self.last_duty_k = k
        # Both modes keep the duty until its period: in real time a fast
        # controller answers sample k (duty k + 1) before period k has started,
        # and applying it then would put it one period early.
        self.duties[t] = duty
        if self.realtime and self.faults is not None and (hold := self.faults.duty_hold_s(k)):
            # a delay in us: the frame is held from its arrival (a timestamped queue)
            self.released_at[t] = (arrived or self.clock()) + hold
        if not self.realtime and t > self.latest_duty_step:
            self.latest_duty_step = t
            self.latest_duty = duty

    # -- faults ------------------------------------------------------------
    def trip(self, code: int) -> None:
        """Latch fault ``code`` (first fault wins): safe state until reset, status frame queued."""
        if self.fault != FAULT_NONE:
            return
        self.fault = code
        self.fault_step = self.plant.k
        name = fault_name(code)
        self.trips[name] = self.trips.get(name, 0) + 1
        self._outbox.append(self.status_frame(STATE_FAULT, code))

    def reset_fault(self) -> bool:
        """Operator reset: clear the latch and re-arm the watchdog; True if a fault was cleared."""
        if self.protection is not None:
            self.protection.reset()
        self.last_duty_k = self.plant.k
        self.rounds_waiting = 0
        if self.fault == FAULT_NONE:
            return False
        self.fault = FAULT_NONE
        self.fault_step = -1
        self.resets += 1
        self._outbox.append(self.status_frame(STATE_RUNNING, FAULT_NONE))
        return True

    def _check_protection(self) -> None:
        prot = self.protection
        if prot is not None and self.fault == FAULT_NONE:
            code = prot.check(*self.plant.protection_inputs())
            if code != FAULT_NONE:
                prot.reset()
                self.trip(code)

    def _flush_outbox(self, frames: list[can.Message]) -> list[can.Message]:
        if self._outbox:
            frames = [*self._outbox, *frames]
            self._outbox = []
        return frames

    def on_duty_timeout(self) -> list[can.Message]:
        """Lockstep: one retransmission round passed without the needed duty.

        Returns the frames to send (the fault status when the watchdog trips).

        The watchdog is armed by the first valid duty frame, as in real time.
        A lockstep plant's periods do not pass while it waits, so the rounds
        are wall-clock time of the bench's processes, and the wait for the
        first duty is the longest of a run: the link forwards the command
        burst, then the controller takes its first step (imports, first
        allocations), which on a loaded host (User-Mode Linux beside other
        jobs) took more than the 100 rounds; the trip then ran every later
        period in the safe state and the trace left the in-process one (at
        step 43 of the link test, where the ramp makes it visible).  Armed by
        the first duty, a controller that never answers is reported by the
        loop's stall error instead, and a trip needs a controller that went
        silent mid-run; it is reported (``plant_fault``, exit 3), never a
        silently different trace.
        """
        if self.external and not self.dut_answered:
            return self._flush_outbox([])  # waiting for the controller under test
        self.rounds_waiting += 1
        if (
            self.watchdog_rounds
            and self.started
            and self.latest_duty_step >= 0  # armed by the first valid duty
            and self.fault == FAULT_NONE
            and self.rounds_waiting >= self.watchdog_rounds
        ):
            self.trip(FAULT_WATCHDOG)
        return self._flush_outbox([])

    # -- lockstep ----------------------------------------------------------
    def needed_duty(self) -> int:
        """Tag of the duty applied in the current period (lockstep)."""
        return self.plant.k - self.delay

    def ready(self) -> bool:
        """Lockstep: whether the duty for the current period has arrived."""
        t = self.needed_duty()
        nf = self.faults
        return (
            t <= 0
            or t in self.duties
            or (
                nf is not None
                and (
                    # a dropped duty: not waited for, but a controller under test's
                    # arrival is (its pace is the run's in lockstep)
                    (
                        nf.duty_fate(self.plant.k) is not None
                        and (not self.external or self.dropped_upto >= t)
                    )
                    or nf.answer_lost(t)
                )
            )
        )

    def paced(self) -> bool:
        """Lockstep: whether pacing lets the current period run (always when off).

        Running period ``k`` ends with the commands of step ``k + 1`` (the
        plant applies them before it samples ``k + 1``, the controller before
        it computes that sample): a command for ``k + 1`` or later must be here.
        """
        return self.pace_every <= 0 or self.plant.k < self.cmd_horizon

    def needed_ack(self) -> int:
        """seq of the newest command the controller must hold before this period runs.

        Running period ``k`` sends sample ``k + 1``, which the controller
        computes after the commands of steps up to ``k + 1``: the newest of
        them the plant holds (the one pending at ``k + 1``, else the newest
        applied); -1 for none.
        """
        nxt = self.commands.pending.get(self.plant.k + 1)
        return nxt.seq if nxt is not None else self.commands.applied_seq

    def acked(self) -> bool:
        """Lockstep (DBC 2.2): whether the controller acknowledged every command
        the next sample needs (always, for a controller that does not report,
        and for the bench's own controller, whose socket is 64 MiB deep).

        Only with a controller under test: ``bench run`` then keeps at most
        :data:`bench.wire._protocol.ACK_WINDOW` commands beyond its
        acknowledgement, which the 4-bit seq comparison needs.

        With this gate a lost command cannot change a lockstep trace: the
        plant waits (and resends its frames) while the bench resends the
        command, and the controller computes no sample without it.
        """
        if self.ctrl_ack is None or self.realtime or not self.external:
            return True
        need = self.needed_ack()
        return need < 0 or seq_at_least(self.ctrl_ack, need)

    def frames_now(self) -> list[can.Message]:
        """The frames describing the plant at the current instant ``k T_s``."""
        p = self.plant
        nf = self.faults
        if nf is not None:
            nf.plant.before_period(p)  # the parameters of this instant and the next period
        s = p.sample() if nf is None else nf.plant.sample(p.sample())
        if self.fault != FAULT_NONE:
            status = STATE_FAULT
        else:
            status = STATE_RUNNING if self.started and not self.stopped else STATE_IDLE
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
        if self.encoder_every and s.k % self.encoder_every == 0:
            tr = p.truth()
            frames.append(
                self.codec.encode(
                    "PositionSensor",
                    {
                        "theta_m": encoder_angle(tr.theta_m, tr.w_m, p.sensor_pars),
                        "step": s.k % self.m_samples,
                    },
                )
            )
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
                        "duty_age": self.duty_age,
                        "step": s.k % self.m_truth,
                        "run_id": self.run_id,
                    },
                )
            )
        if nf is not None and s.k % self.truth_every == 0:
            # the true phase currents (DBC 2.4), in a run with a fault timeline only: an
            # open phase shows, and every other run keeps the 2.3 traffic frame for frame
            i_a, i_b, _ = p.currents_abc()
            frames.append(
                self.codec.encode(
                    "PlantCurrents",
                    {"i_a": i_a, "i_b": i_b, "step": s.k % self.m_truth, "run_id": self.run_id},
                )
            )
        if nf is not None:
            if not nf.sends("PhaseSamples", s.k):
                if not self.realtime:  # lockstep: sent again with the next that gets through
                    self.withheld += [m for m in frames if m.arbitration_id == self.id_samples]
                frames = [m for m in frames if m.arbitration_id != self.id_samples]
            elif self.withheld:
                frames = [*self.withheld, *frames]
                self.withheld = []
            if not nf.sends("PositionSensor", s.k):
                frames = [m for m in frames if m.arbitration_id != self.id_pos]
            to_plant, to_ctrl = nf.babble(s.k, self.codec)
            if to_plant is not None:
                self.on_message(to_plant)
            if to_ctrl is not None:
                frames.append(to_ctrl)
        self.sent.append(frames)
        return frames

    def apply_commands(self) -> None:
        for c in self.commands.due(self.plant.k):
            if c.cmd == CMD_START:
                self.started = True
                self.last_duty_k = self.plant.k
            elif c.cmd == CMD_STOP:
                self.stopped = True
            elif c.cmd in (CMD_RESET, CMD_ENABLE):
                self.reset_fault()
            self.plant.set_load(ConstantLoad(c.load_nm))

    def advance_lockstep(self) -> list[can.Message]:
        """Run the current period with its duty; return the next instant's frames."""
        t = self.needed_duty()
        if t <= 0:
            d_a, d_b, d_c, en = _SAFE_DUTY
            self.duty_age = 255
        elif t not in self.duties:  # lost to a bus fault: held, counted, watched as in real time
            # the newest duty before t: a later one may be here already (a controller that
            # answers a resent sample at once is ahead of the plant), never applied early
            held, held_step = (
                (self.latest_duty, self.latest_duty_step)
                if self.latest_duty_step < t
                else self.applied
            )
            d_a, d_b, d_c, en = held
            self.duty_age = 255 if held_step < 0 else min(254, self.plant.k - held_step)
            self.counters.late_duties += 1
            # the real-time watchdog counts from the period the last duty arrived in,
            # for a controller answering within its period the one before that duty's:
            # here from the duty's own tag, which scheduling cannot move
            if (
                self.watchdog_periods
                and self.latest_duty_step >= 0
                and self.fault == FAULT_NONE
                and t - self.latest_duty_step >= self.watchdog_periods - 1
            ):
                self.trip(FAULT_WATCHDOG)
        else:
            self.duty_age = min(254, self.plant.k - t)
            d_a, d_b, d_c, en = self.duties.pop(t)
            self.applied = ((d_a, d_b, d_c, en), t)
            for old in [s for s in self.duties if s < t]:
                del self.duties[old]
            if self.faults is not None:  # a delay fault applies an older duty
                self.faults.keep(t, (d_a, d_b, d_c, en))
                d_a, d_b, d_c, en = self.faults.delayed(self.plant.k, t, (d_a, d_b, d_c, en))
                self.duty_age = min(254, self.duty_age + self.faults.duty_shift(self.plant.k))
        if self.fault != FAULT_NONE:
            en = False
            self.duty_age = 255  # the safe state applies no duty (the DBC's 255)
        self.rounds_waiting = 0
        self.plant.step(d_a, d_b, d_c, en)
        self._check_protection()
        self.apply_commands()
        self._periodic_status()
        return self._flush_outbox(self.frames_now())

    def retransmit(self) -> list[can.Message]:
        """Frames to resend when the expected duty did not come (lossy transport)."""
        self.counters.retransmits += 1
        return [m for frames in self.sent for m in frames]

    # -- real time ---------------------------------------------------------
    def advance_realtime(self) -> list[can.Message]:
        """Run one period with the latest valid duty (real-time mode).

        The watchdog, armed by the first valid duty frame, trips when the last
        one arrived ``watchdog_periods`` or more periods ago; this period then
        already runs in the safe state.
        """
        k = self.plant.k
        shift = 0 if self.faults is None else self.faults.duty_shift(k, realtime=True)
        held = self.released_at
        now = self.clock() if held else 0.0
        due = [t for t in self.duties if t <= k - shift and held.get(t, now) <= now]
        if due:
            t = max(due)
            self.latest_duty_step = t
            self.latest_duty = self.duties[t]
            for old in [s for s in self.duties if s <= t]:  # an older one still held: passed
                del self.duties[old]
                held.pop(old, None)
        d_a, d_b, d_c, en = self.latest_duty
        self.duty_age = (
            255 if self.latest_duty_step < 0 else max(0, min(254, k - self.latest_duty_step))
        )
        expected = k - self.delay
        if self.latest_duty_step < expected:
            if self.latest_duty_step < 0:
                en = False
            else:
                self.counters.late_duties += 1
        if (
            self.watchdog_periods
            and self.latest_duty_step >= 0  # armed by the first valid duty
            and self.fault == FAULT_NONE
            and k - self.last_duty_k >= self.watchdog_periods
        ):
            self.trip(FAULT_WATCHDOG)
        if self.fault != FAULT_NONE:
            en = False
            self.duty_age = 255  # the safe state applies no duty (the DBC's 255)
        self.plant.step(d_a, d_b, d_c, en)
        self._check_protection()
        self.apply_commands()
        self._periodic_status()
        return self._flush_outbox(self.frames_now())

    def _periodic_status(self) -> None:
        """Queue ``PlantStatus`` on its cycle (plant time), while the run is on."""
        n = self.status_every
        if n and self.started and not self.stopped and self.plant.k % n == 0:
            state = STATE_FAULT if self.fault != FAULT_NONE else STATE_RUNNING
            self._outbox.append(self.status_frame(state, self.fault))

    @property
    def late_frames(self) -> int:
        """``PlantStatus.late_frames``: periods without their own duty plus duties rejected."""
        return self.counters.late_duties + sum(self.duty_rejected.values())

    def status_frame(self, state: int, fault_code: int = 0) -> can.Message:
        c = self.counters
        return self.codec.encode(
            "PlantStatus",
            {
                "state": state,
                "fault_code": fault_code,
                "overruns": min(c.overruns, 0xFFFF),
                "late_frames": min(self.late_frames, 0xFFFF),
                "step": self.plant.k % self.m_status,
            },
        )

    def report(self) -> dict[str, object]:
        """Counters and fault history, for the node's JSON report."""
        out = self.counters.as_dict()
        out.update(
            steps=self.plant.k,
            engine=self.plant.engine,
            node_engine=self.node_engine,
            jitter=self.jitter,
            loop_s=self.loop_s,
            fault=fault_name(self.fault),
            duty_rejected=dict(self.duty_rejected),
            late_frames=self.late_frames,
            fault_step=self.fault_step,
            # periods that ended beyond the flux map's checked range (Plant.out_of_range_periods)
            out_of_range_periods=self.plant.out_of_range_periods,
            # period in which the last valid duty frame arrived (the watchdog's reference)
            last_duty_arrival=self.last_duty_k,
            trips=dict(self.trips),
            resets=self.resets,
            run_id=self.run_id,
            faults=None if self.faults is None else self.faults.report(),
            other_plants={
                f"{k:#06x}": v for k, v in self.other_plants.items() if v >= SHARED_RUN_FRAMES
            },
        )
        return out

    @property
    def done(self) -> bool:
        return self.stopped or (self.n_steps > 0 and self.plant.k >= self.n_steps)
