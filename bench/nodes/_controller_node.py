"""The controller node: the DBC on one side, :class:`controller.Controller` on the other.

One sample in, one duty (and telemetry) out, strictly in step order; the
step bookkeeping and the counters follow the plant node's rules
(:mod:`bench.nodes._plant_node`).
"""

from __future__ import annotations

from typing import Any

import can

from bench.nodes._counters import (
    REJECT_FUTURE_COUNTER,
    REJECT_STALE_COUNTER,
    REPEATED_COUNTER,
    CommandQueue,
    NodeCounters,
)
from bench.wire._codec import Codec
from bench.wire._protocol import (
    CMD_DISABLE,
    CMD_ENABLE,
    CMD_RESET,
    CMD_START,
    CMD_STOP,
    RPM_PER_RAD_S,
    lockstep_sample_lead,
    unwrap,
)
from controller import Controller, ControlOutput, HybridEstimator, Measurement


def controller_design(ctrl: Controller) -> dict[str, Any]:
    """What a run's scoring needs of the controller as its node built it (the node's report,
    ``design``), so that the run never builds the controller again:

    - ``gains``: every gain, bandwidth, filter corner and delay (:meth:`Controller.gains`,
      ``meta.json``'s ``controller_gains``);
    - ``injection``: the HF injection's ``w_h`` (rad/s, rotating) or ``R`` (PWM periods
      per square-wave period), both None for an estimator that injects nothing;
    - ``band_edges``: a hybrid estimator's band on the true speed (rad/s,
      :attr:`controller.TransitionBand.edges`), else None;
    - ``speed_loop``: the speed PI's ``k_t``, ``k_p``, ``k_i``, the speed filter ``w_f``
      and the bandwidth ``alpha_s`` (a hybrid run's expected hand-over speed).
    """
    est = ctrl.estimator
    edges: list[float] | None = None
    hf: object = est
    if isinstance(est, HybridEstimator):
        edges, hf = [float(e) for e in est.band.edges], est.hf
    w_h, R = getattr(hf, "w_h", None), getattr(hf, "R", None)
    pi = ctrl.pi_w
    return {
        "gains": ctrl.gains(),
        "injection": {
            "w_h": None if w_h is None else float(w_h),
            "R": int(R) if R else None,
        },
        "band_edges": edges,
        "speed_loop": {
            "k_t": float(pi.k_t),
            "k_p": float(pi.k_p),
            "k_i": float(pi.k_i),
            "w_f": float(ctrl.w_f),
            "alpha_s": float(ctrl.alpha_s),
        },
    }


class ControllerNode:
    """The controller behind the DBC: one sample in, one duty (+ telemetry) out.

    Samples are processed strictly in step order; a sample that arrives
    twice gets the cached answer again (the plant retransmits when a frame
    was lost), a sample from the future waits for the missing ones.  In
    lockstep with a known ``lockstep_delay``, a sample further ahead than the
    plant can be (:func:`bench.wire._protocol.lockstep_sample_lead`) is
    rejected (``future_counter``): it is not the plant's, and held it would
    take the place of the genuine sample of its step.

    Parameters
    ----------
    needs_truth : bool
        The sensored baseline waits for ``PlantTruth`` of the same step.
    lockstep_delay : int, optional
        The plan's ``lockstep_delay`` (:attr:`bench.nodes._plan.RunPlan.lockstep_delay`),
        which bounds how far ahead a lockstep sample can be; None (a node not made
        from a run's plan): the unwrap window, as in real time.
    truth_may_lead : bool
        The plan has a fault timeline: its lockstep plant sends ``PlantTruth``
        while it withholds the samples a fault loses and runs on without their
        answers (:mod:`bench.nodes._fault_bus`), so a truth may lead by the
        length of such a window and keeps the unwrap window's bound.
    """

    def __init__(
        self,
        codec: Codec,
        controller: Controller,
        *,
        needs_truth: bool = False,
        lockstep_delay: int | None = None,
        truth_may_lead: bool = False,
    ) -> None:
        self.codec = codec
        self.ctrl = controller
        self.needs_truth = needs_truth
        self.lockstep_delay = lockstep_delay
        self.truth_may_lead = truth_may_lead
        self.m_step = 1 << codec.step_bits("PhaseSamples")
        self.m_cmd = 1 << codec.step_bits("BenchCommand")
        self.m_tel = 1 << codec.step_bits("CtrlTelemetry")
        #: The run's nonce, sent in every CtrlTelemetry (``run_id``, DBC 2.1).
        self.run_id = 0
        self.m_truth = 1 << codec.step_bits("PlantTruth")
        self.next_k = 0
        self.samples: dict[int, dict[str, float]] = {}
        self.truth: dict[int, dict[str, float]] = {}
        self.answers: dict[int, list[can.Message]] = {}
        self.commands = CommandQueue(self.m_cmd)
        self.counters = NodeCounters()
        self.stopped = False
        self.realtime = False
        #: Valid samples taken (the loop's watchdog watches it move).
        self.samples_accepted = 0
        #: Times the PWM was disabled because samples stopped (real time).
        self.sample_timeouts = 0
        #: True from a sample timeout until a reset/enable command.
        self.faulted = False
        #: Which loop ran the periods: "python" (:func:`bench.nodes._loops.controller_loop`)
        #: or "native" (:mod:`bench.nodes.native.controller_node`).
        self.node_engine = "python"
        #: The native real-time loop's command frames held until a duty was out: held,
        #: the most at once, handed over at once by a full ring (None: not that loop).
        self.commands_held: dict[str, int] | None = None
        #: The newest output, whose telemetry is sent again when the command
        #: acknowledgement moves (``CtrlTelemetry.cmd_ack``, DBC 2.2).
        self.last_output: ControlOutput | None = None

    def on_message(self, msg: can.Message) -> list[can.Message]:
        """Take one received frame; return the frames to send. Never raises for any content."""
        c = self.counters
        d = self.codec.decode(msg)
        if d is None:
            c.frames_unknown += 1
            return []
        name = d.name
        if name not in ("PhaseSamples", "BenchCommand") and not (
            name == "PlantTruth" and self.needs_truth
        ):
            c.frames_ignored += 1
            return []
        if d.reason is not None:
            c.reject(d.reason)
            return []
        if name == "BenchCommand":
            # In both modes a command takes effect at its step (the sample of
            # that step), as in the plant: the bench sends commands ahead of
            # time, and applied on arrival a stop would end the controller
            # (and a set-point change reach it) that much early.
            before = self.commands.ack_seq
            self.commands.add(d.signals, self.next_k, c)
            if self.commands.ack_seq != before and self.last_output is not None:
                # DBC 2.2: the acknowledgement moved; say so at once (a lockstep
                # plant may be waiting for it, with no sample left to answer)
                return [self._telemetry(self.last_output)]
            return []
        if name == "PhaseSamples":
            k = unwrap(int(d.signals["step"]), self.next_k, self.m_step)
            if k < self.next_k:
                cached = self.answers.get(k)
                if cached is None:
                    c.reject(REJECT_STALE_COUNTER)
                    return []
                c.reject(REPEATED_COUNTER)
                last = self.last_output
                if last is not None and last.k == k:
                    # the same duty; the telemetry with the acknowledgement held now
                    return [cached[0], self._telemetry(last)]
                return list(cached)
            lead = self.sample_lead()
            if lead is not None and k > self.next_k + lead:
                c.reject(REJECT_FUTURE_COUNTER)
                return []
            if k in self.samples:
                c.reject(REPEATED_COUNTER)
                return []
            c.frames_accepted += 1
            self.samples_accepted += 1
            if self.realtime and k > self.next_k:
                # real time: never wait for the past, skip to the newest sample
                self.samples = {s: v for s, v in self.samples.items() if s >= k}
                self.next_k = k
            self.samples[k] = d.signals
        else:  # PlantTruth, sensored baseline
            k = unwrap(int(d.signals["step"]), self.next_k, self.m_truth)
            if k < self.next_k or k in self.truth:
                c.reject(REPEATED_COUNTER)
                return []
            lead = self.truth_lead()
            if k > self.next_k + (self.m_step if lead is None else lead):
                c.reject(REJECT_FUTURE_COUNTER)
                return []
            c.frames_accepted += 1
            self.truth[k] = d.signals
        return self._run_ready()

    def sample_lead(self) -> int | None:
        """The most steps a sample may be ahead of :attr:`next_k`: in lockstep with a known
        delay :func:`~bench.wire._protocol.lockstep_sample_lead`; else None (the unwrap window)."""
        if self.realtime or self.lockstep_delay is None:
            return None
        return lockstep_sample_lead(self.lockstep_delay)

    def truth_lead(self) -> int | None:
        """The same for ``PlantTruth`` (None: one sample counter range, ``m_step``)."""
        return None if self.truth_may_lead else self.sample_lead()

    def sample_timeout(self) -> None:
        """Samples stopped (real time): disable the PWM until a reset or enable command.

        When the stop command is due with the very sample that did not come
        (the plant's last one, lost on the way), the run is over: stop.
        """
        if any(
            c.cmd == CMD_STOP and c.apply_step <= self.next_k
            for c in self.commands.pending.values()
        ):
            self.stopped = True
        if not self.faulted:
            self.faulted = True
            self.sample_timeouts += 1
            self.ctrl.set_enable(False)

    def _apply_commands(self, step: int) -> None:
        for c in self.commands.due(step):
            if c.cmd in (CMD_START, CMD_ENABLE, CMD_RESET):
                self.faulted = False
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
            self.last_output = o
            frames = self.encode_output(o)
            self.answers[k] = frames
            self.answers.pop(k - 8, None)
            out.extend(frames)
            self.next_k = k + 1
        return out

    def report(self) -> dict[str, object]:
        """Counters, for the node's JSON report; the controller's ``engine`` (``compiled``: its
        one engine, the core, whatever the name) and ``engine_note`` (None, kept for the
        readers of the report: it said why a controller ran in Python); the
        loop that ran the periods (``node_engine``: ``python`` or ``native``); its
        design as built (``design``, :func:`controller_design`)."""
        out = self.counters.as_dict()
        out.update(steps=self.next_k, sample_timeouts=self.sample_timeouts)
        out.update(engine=self.ctrl.engine, engine_note=None)
        out["node_engine"] = self.node_engine
        if self.commands_held is not None:
            out["commands_held"] = dict(self.commands_held)
        out["design"] = controller_design(self.ctrl)
        return out

    def _telemetry(self, o: ControlOutput) -> can.Message:
        """``CtrlTelemetry`` of output ``o`` with the command acknowledgement held now."""
        ack = self.commands.ack_seq
        return self.codec.encode(
            "CtrlTelemetry",
            {
                "theta_hat": o.theta_hat,
                "w_hat": o.w_hat,
                "err": o.err,
                "mode": o.mode,
                "step": o.k % self.m_tel,
                "run_id": self.run_id,
                "cmd_ack_valid": 1 if ack >= 0 else 0,
                "cmd_ack": max(0, ack),
            },
        )

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
            self._telemetry(o),
        ]
