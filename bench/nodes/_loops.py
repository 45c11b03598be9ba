"""The nodes' main loops on a python-can bus, and the in-process loop.

``plant_loop`` and ``controller_loop`` drive a :class:`~bench.nodes._plant_node.PlantNode`
or :class:`~bench.nodes._controller_node.ControllerNode` from a :class:`can.BusABC`; they are
what ``bench plant`` and ``bench controller`` run as processes, and what the
``virtual``-bus tests run as threads.  ``run_inprocess`` passes the same
frames between the same nodes without any bus: the reference trace.
"""

from __future__ import annotations

import math
import os
import sys
import time
from collections.abc import Callable, Sequence

import can

from bench._errors import BenchError
from bench.nodes._clock import RealTimeClock
from bench.nodes._controller_node import ControllerNode
from bench.nodes._counters import feed_steps
from bench.nodes._plan import RunPlan
from bench.nodes._plant_node import PlantNode
from bench.nodes._plant_text import (
    LAST_ANSWER_S,
    RETRANSMIT_S,
    STATE_DONE,
    PlantDiagnostics,
    stall_text,
    tripped_text,
)
from bench.nodes._plant_text import trip_text as trip_text  # where the run and tests look
from bench.nodes._rt import no_gc
from bench.nodes._send import send_all
from bench.scenarios._faults import Fault
from bench.scenarios._schema import Scenario
from bench.scenarios._setup import (
    ENGINE_ENV,
    NATIVE,
    PlannedCommand,
    build_controller,
    build_plant,
    command_schedule,
    lockstep_delay,
    n_steps,
    needs_truth,
    sample_period,
    with_keepalives,
)
from bench.wire._codec import Codec
from controller import Controller
from plant_rt import FAULT_WATCHDOG, Plant, ProtectionPars

STATE_RUN = 1

#: Lockstep: give up when nothing arrives for this long.
STALL_S = 20.0
#: Real-time plant watchdog: trip after this many PWM periods without a valid duty ...
WATCHDOG_PERIODS = 10
#: ... but never after less than this (a general-purpose OS deschedules a process for ms).
WATCHDOG_MIN_S = 0.02
#: Lockstep plant watchdog: trip after this many retransmission rounds without a duty (5 s).
WATCHDOG_ROUNDS = 100
#: Real-time controller: disable the PWM when no valid sample came for this long.
SAMPLE_TIMEOUT_S = 0.05


def watchdog_periods(T_s: float, watchdog_s: float | None = None) -> int:
    """Real-time watchdog in PWM periods: ``watchdog_s`` if given, else the defaults."""
    if watchdog_s is not None:
        return max(1, math.ceil(watchdog_s / T_s - 1e-9))
    return max(WATCHDOG_PERIODS, math.ceil(WATCHDOG_MIN_S / T_s - 1e-9))


def make_plant_node(
    scn: Scenario,
    codec: Codec,
    *,
    truth_every: int = 1,
    protection: ProtectionPars | None = None,
    watchdog_s: float | None = None,
    watchdog_rounds: int = WATCHDOG_ROUNDS,
    engine: str = "auto",
) -> PlantNode:
    """The plant node of a scenario, with protection and watchdogs (:func:`plant_node`)."""
    return plant_node(
        build_plant(scn, engine),
        n_steps(scn),
        lockstep_delay(scn),
        codec,
        truth_every=truth_every,
        protection=protection,
        watchdog_s=watchdog_s,
        watchdog_rounds=watchdog_rounds,
        faults=tuple(scn.faults),
        seed=scn.seed,
    )


def plant_node(
    plant: Plant,
    steps: int,
    delay: int,
    codec: Codec,
    *,
    truth_every: int = 1,
    protection: ProtectionPars | None = None,
    watchdog_s: float | None = None,
    watchdog_rounds: int = WATCHDOG_ROUNDS,
    faults: tuple[Fault, ...] = (),
    seed: int = 0,
) -> PlantNode:
    """The node of ``plant`` (a run's plan: ``plan.plant.build(engine)``), running
    ``steps`` periods with ``delay`` periods of lockstep latency.

    ``protection`` defaults to :meth:`ProtectionPars.from_preset` of the
    plant's motor and inverter; ``watchdog_s`` to :func:`watchdog_periods`' default.
    """
    cycle_ms = codec.message("PlantStatus").cycle_time or 0
    if protection is None:
        protection = ProtectionPars.from_preset(plant.motor, plant.inverter)
    node = PlantNode(
        codec,
        plant,
        n_steps=steps,
        lockstep_delay=delay,
        truth_every=truth_every,
        protection=protection,
        watchdog_periods=watchdog_periods(plant.T_s, watchdog_s),
        watchdog_rounds=watchdog_rounds,
        status_every=max(1, round(cycle_ms * 1e-3 / plant.T_s)) if cycle_ms else 0,
    )
    if faults:  # the scenario's [[faults]]; ``seed`` seeds their random streams
        from bench.nodes._fault_bus import NodeFaults

        node.faults = NodeFaults(faults, plant, seed)
    return node


def make_controller_node(
    scn: Scenario, estimator: str, codec: Codec, engine: str | None = None
) -> ControllerNode:
    """``engine``: the controller's (:func:`~bench.scenarios._setup.build_controller`'s)."""
    return ControllerNode(
        codec, build_controller(scn, estimator, engine), needs_truth=needs_truth(estimator)
    )


def controller_node(plan: RunPlan, codec: Codec) -> ControllerNode:
    """The controller node of a run's plan (its controller as built, :attr:`RunPlan.controller`).

    The engine is :data:`bench.scenarios._setup.ENGINE_ENV`'s (``--engine``), else auto;
    ``native`` (the node's loop in C) builds the controller as auto does.
    """
    if plan.controller is None:
        raise BenchError(f"plan of {plan.scenario}: it has no controller of the bench's")
    engine = os.environ.get(ENGINE_ENV) or "auto"
    if engine == NATIVE:
        engine = "auto"
    try:
        ctrl = Controller(plan.controller, engine, design=plan.design)
    except TypeError as e:
        raise BenchError(f"plan of {plan.scenario}: estimator options: {e}") from None
    if ctrl.design_refused:
        print(
            f"plan of {plan.scenario}: field 'design': {ctrl.design_refused} than its field "
            "'controller'; designed for 'controller' here",
            file=sys.stderr,
            flush=True,
        )
    return ControllerNode(
        codec,
        ctrl,
        needs_truth=plan.needs_truth,
        lockstep_delay=plan.lockstep_delay,
        truth_may_lead=bool(plan.faults),
    )


def command_frames(
    scn: Scenario,
    codec: Codec,
    pace_every: int = 0,
    schedule: Sequence[PlannedCommand] | None = None,
) -> list[tuple[int, can.Message]]:
    """The scenario's bench commands as frames, with their apply steps.

    ``schedule``: the commands as planned (a run's plan, :attr:`RunPlan.commands`);
    None: :func:`bench.scenarios._setup.command_schedule` of ``scn``.

    ``pace_every > 0`` adds a keep-alive (``cmd`` 0, the references already
    in force, so nothing changes) at every multiple of ``pace_every`` that
    has no command of its own: the pace tokens of a paced lockstep plant
    (:attr:`bench.nodes._plant_node.PlantNode.pace_every`).
    """
    m = 1 << codec.step_bits("BenchCommand")
    plan = with_keepalives(
        list(schedule) if schedule is not None else command_schedule(scn), pace_every
    )
    out = []
    for i, c in enumerate(plan):
        msg = codec.encode(
            "BenchCommand",
            {
                "cmd": c.cmd,
                "seq": i % 16,
                "speed_ref": c.speed_ref_rpm,
                "load_torque": c.load_nm,
                "step": c.apply_step % m,
            },
        )
        out.append((c.apply_step, msg))
    return out


#: In-process loop: the commands are handed to the nodes this many periods
#: ahead of the plant, as ``bench run`` paces them on a bus.  All at once
#: would not do: the 16-bit ``BenchCommand.step`` wraps after 65,536 periods
#: (6.5 s at 10 kHz) and the nodes keep at most ``MAX_PENDING_COMMANDS``.
INPROCESS_LEAD = 1000


#: :func:`run_inprocess`'s ``loop`` choices.
INPROCESS_LOOPS = ("auto", "python", "native")


def inprocess_native_unavailable(
    pn: PlantNode, cn: ControllerNode, *, latency: bool, steps: list[int] | None = None
) -> str | None:
    """Why the in-process loop of these nodes cannot run in C (one line), or None.

    :func:`bench.nodes.native._pair.pair_unavailable` (``steps``: the commands' apply
    steps, fed :data:`INPROCESS_LEAD` ahead), and the library's build (no C compiler, a
    failed build) as a reason rather than an error.
    """
    try:
        from bench.nodes.native._pair import pair_unavailable

        return pair_unavailable(pn, cn, latency=latency, steps=steps, lead=INPROCESS_LEAD)
    except (BenchError, OSError) as e:
        return str(e)


def run_inprocess(
    scn: Scenario,
    estimator: str,
    codec: Codec,
    *,
    plant_times: list[float] | None = None,
    engine: str = "auto",
    observe: Callable[[Controller], None] | None = None,
    loop: str = "auto",
) -> Sequence[can.Message]:
    """Run a scenario in lockstep in this process; return every frame in wire order.

    The frames are the same objects the CAN nodes would send (same DBC
    encoding, so the same quantization), passed by hand; injected lockstep
    latency goes through the same :class:`~bench.nodes._link.LockstepLink` logic
    the link process runs.  ``plant_times`` (when given) gets the plant node's
    computation of every period (s): the plant step and its frames encoded.
    ``engine`` is the plant's (:class:`plant_rt.Plant`).  ``observe`` (when given) is
    called with the controller after every period it answered, to record a state no
    frame carries (the controller's engine is then Python, where the estimator's
    states live; both engines give the same trace, ``tests/test_controller_engine.py``).

    ``loop``: ``auto`` (the default) runs the loop in C, both nodes stepped for many
    periods per call (:func:`bench.nodes.native._pair.run_pair`, the same frames bit
    for bit, returned as one :class:`bench.wire._frames.FrameArray`: a
    :class:`can.Message` is made only where one is asked for), wherever both nodes can serve natively and neither ``plant_times`` nor
    ``observe`` asks for Python between periods, else the Python loop below;
    ``python`` asks for the Python loop, ``native`` for the C one (:class:`BenchError`
    naming why not, when it cannot serve).
    """
    from bench.nodes._link import LockstepLink
    from bench.scenarios._faults import lockstep_error

    if loop not in INPROCESS_LOOPS:
        raise BenchError(f"run_inprocess: loop {loop!r}: one of {', '.join(INPROCESS_LOOPS)}")
    if err := lockstep_error(scn.faults, scn.source):
        raise err
    pn = make_plant_node(scn, codec, engine=engine)
    cn = make_controller_node(scn, estimator, codec, "python" if observe else None)
    lt = scn.latency
    cmds = command_frames(scn, codec)
    if loop != "python":
        why = inprocess_native_unavailable(
            pn,
            cn,
            latency=bool(lt.sample_delay_steps or lt.duty_delay_steps),
            steps=[s for s, _ in cmds],
        )
        if why is None and (plant_times is not None or observe is not None):
            why = "plant_times and observe are Python's between periods"
        if why is None:
            from bench.nodes.native._pair import run_pair

            return run_pair(pn, cn, cmds, INPROCESS_LEAD)
        if loop == "native":
            raise BenchError(f"in-process native pair: {why}")
    link = (
        LockstepLink(codec, sample_delay=lt.sample_delay_steps, duty_delay=lt.duty_delay_steps)
        if lt.sample_delay_steps or lt.duty_delay_steps
        else None
    )
    frames: list[can.Message] = []
    sent = 0
    at = feed_steps([s for s, _ in cmds], INPROCESS_LEAD)

    def feed(k: int) -> None:
        """Hand the nodes the commands fed after the answers of plant step ``k`` (-1: before
        the run), as ``bench run`` paces them."""
        nonlocal sent
        while sent < len(cmds) and at[sent] <= k:
            m = cmds[sent][1]
            frames.append(m)
            pn.on_message(m)
            cn.on_message(m)
            sent += 1

    feed(-1)
    pn.apply_commands()
    out = pn.frames_now()
    while True:
        frames.extend(out)
        to_plant: list[can.Message] = []
        to_ctrl = out
        if link is not None:
            to_ctrl = []
            for m in out:
                to_b, to_a = link.from_a(m)
                to_ctrl.extend(to_b)
                to_plant.extend(to_a)
        replies: list[can.Message] = []
        for m in to_ctrl:
            replies.extend(cn.on_message(m))
        if observe is not None and replies:
            observe(cn.ctrl)
        frames.extend(replies)
        if link is None:
            to_plant = replies
        else:
            for m in replies:
                _, to_a = link.from_b(m)
                to_plant.extend(to_a)
        for m in to_plant:
            pn.on_message(m)
        if pn.done:
            break
        if not pn.ready():
            raise RuntimeError(f"in-process loop stalled at step {pn.plant.k}")
        feed(pn.plant.k)
        if plant_times is None:
            out = pn.advance_lockstep()
        else:
            t0 = time.perf_counter()
            out = pn.advance_lockstep()
            plant_times.append(time.perf_counter() - t0)
    return frames


def plant_loop(
    bus: can.BusABC,
    node: PlantNode,
    *,
    realtime: bool,
    on_ready: Callable[[], None] | None = None,
    stop: Callable[[], bool] = lambda: False,
    watchdog_s: float = STALL_S,
    dut_timeout_s: float = 0.0,
) -> None:
    """Serve the plant on ``bus`` until the scenario's end or a stop command.

    ``dut_timeout_s > 0``: the controller is a device under test, not the
    bench's own (``bench run --controller external``): the plant waits up to
    that long for its first answer (lockstep: no watchdog meanwhile; real
    time: sample 0 is resent until then and the clock starts after it), and
    in lockstep a watchdog trip ends the run.  Rejected duty frames and a
    trip are reported on stderr as they happen (:class:`PlantDiagnostics`).
    """
    node.realtime = realtime
    node.external = dut_timeout_s > 0
    names = ["PwmDuty", "BenchCommand"]
    if node.external and not realtime:
        names.append("CtrlTelemetry")  # its cmd_ack gates the periods (DBC 2.2)
    ids = {node.codec.frame_id(n) for n in names}
    if on_ready:
        on_ready()
    if not _wait_for_start(bus, node, ids, stop):
        return
    frames = node.frames_now()
    diag = PlantDiagnostics(node)
    t_loop = time.perf_counter()
    try:
        if realtime:
            if node.external:
                if not _wait_first_answer(bus, node, ids, frames, stop, dut_timeout_s, diag):
                    return
                frames = []  # sample 0 is out; the clock starts with period 0
                t_loop = time.perf_counter()  # waiting for the first answer is start-up
            _serve_realtime(bus, node, ids, frames, stop=stop, diag=diag)
        else:
            _serve_lockstep(
                bus,
                node,
                ids,
                frames,
                stop=stop,
                watchdog_s=watchdog_s,
                first_s=dut_timeout_s,
                diag=diag,
            )
    finally:
        node.loop_s = time.perf_counter() - t_loop
        diag.poll(force=True)
    send_all(bus, [node.status_frame(STATE_DONE, node.fault)], node.counters)


def _wait_first_answer(
    bus: can.BusABC,
    node: PlantNode,
    ids: set[int],
    frames: list[can.Message],
    stop: Callable[[], bool],
    limit_s: float,
    diag: PlantDiagnostics,
) -> bool:
    """Real time with a controller under test: resend sample 0 until it answers (False: stopped)."""
    t0 = time.monotonic()
    t_sent = -1.0
    while not node.dut_answered:
        if stop():
            return False
        now = time.monotonic()
        if now - t0 > limit_s:
            raise BenchError(f"plant: {stall_text(node, limit_s)}")
        if now - t_sent >= RETRANSMIT_S:
            send_all(bus, frames, node.counters)
            t_sent = now
        msg = bus.recv(RETRANSMIT_S / 5)
        if msg is not None and msg.arbitration_id in ids:
            node.on_message(msg)
        diag.poll()
    return True


def _wait_for_start(
    bus: can.BusABC, node: PlantNode, ids: set[int], stop: Callable[[], bool]
) -> bool:
    """Feed the node its frames until the start command has been applied (False: stopped)."""
    t_idle = time.monotonic()
    while not node.started:
        if stop():
            return False
        msg = bus.recv(0.05)
        if msg is not None and msg.arbitration_id in ids:
            node.on_message(msg)
            node.apply_commands()
        if time.monotonic() - t_idle > 3600.0:
            raise BenchError("plant: no start command within an hour")
    return True


def _serve_realtime(
    bus: can.BusABC,
    node: PlantNode,
    ids: set[int],
    frames: list[can.Message],
    *,
    stop: Callable[[], bool],
    diag: PlantDiagnostics | None = None,
) -> None:
    """Real time: one period per tick of the plant's own clock, with the newest duty.

    Each instant's frames leave at that instant (the deadline), so the
    controller has one period to answer, as in a drive; the plant then runs
    the period with the newest duty meant for it.  A host stall resynchronises
    the clock instead of a catch-up burst (:class:`bench.nodes._clock.RealTimeClock`).
    The clock's overruns, stalls and jitter statistics go to the node's report.
    """
    clock = RealTimeClock(node.plant.T_s)
    with no_gc():
        clock.start()
        while not node.done and not stop():
            send_all(bus, frames, node.counters)
            while (msg := bus.recv(0.0)) is not None:
                if msg.arbitration_id in ids:
                    node.on_message(msg)
            frames = node.advance_realtime()
            if diag is not None:
                diag.poll()
            clock.wait()
        send_all(bus, frames, node.counters)
    node.counters.overruns = clock.overruns
    st = clock.stats()
    node.jitter = {
        "n": float(st.n),
        "median": 1e6 * st.median,
        "p99": 1e6 * st.p99,
        "max": 1e6 * st.max,
        "busy_median": 1e6 * st.busy_median,
        "busy_p99": 1e6 * st.busy_p99,
        "busy_max": 1e6 * st.busy_max,
        "stalls": float(st.stalls),
        "stall_total": 1e6 * st.stall_total,
        "stall_max": 1e6 * st.stall_max,
        "skipped": float(st.skipped),
    }


def _serve_lockstep(
    bus: can.BusABC,
    node: PlantNode,
    ids: set[int],
    frames: list[can.Message],
    *,
    stop: Callable[[], bool],
    watchdog_s: float,
    first_s: float = 0.0,
    diag: PlantDiagnostics | None = None,
) -> None:
    """Lockstep: a period runs once its duty (and, when paced, its bench command) has come.

    While it waits, the recent frames are resent every :data:`RETRANSMIT_S`
    (a lost frame on a lossy transport); after ``watchdog_s`` without
    progress (``first_s``, when given, before the controller's first answer)
    the plant gives up with a message naming what it waited for and what
    was rejected (:func:`stall_text`).
    """
    send_all(bus, frames, node.counters)
    last_progress = time.monotonic()
    t_wait = last_progress

    def no_duty() -> None:
        nonlocal t_wait
        now = time.monotonic()
        limit = first_s if first_s > 0 and not node.dut_answered else watchdog_s
        if diag is not None:
            diag.poll()
        if now - last_progress > limit:
            raise BenchError(f"plant: {stall_text(node, limit)}")
        if now - t_wait >= RETRANSMIT_S:
            send_all(bus, node.on_duty_timeout(), node.counters)
            if node.external and node.fault == FAULT_WATCHDOG:
                # no duty will come: the run cannot go on (bench run: exit 3)
                print(f"plant: {tripped_text(node, last_progress, now)}", file=sys.stderr)
                raise _RunOver
            send_all(bus, node.retransmit(), node.counters)
            t_wait = now

    def no_command() -> None:
        if time.monotonic() - last_progress > watchdog_s:
            raise BenchError(
                f"plant: no bench command for step {node.plant.k} in {watchdog_s:.0f} s "
                "(paced by bench run: has its recorder stopped?)"
            )

    t_ack = time.monotonic()

    def no_ack() -> None:
        # the controller has not acknowledged a command the next sample needs:
        # our frames again (its answer to a repeated sample carries its newest
        # acknowledgement), while bench run resends the commands it lacks
        nonlocal t_ack
        now = time.monotonic()
        if now - last_progress > watchdog_s:
            raise BenchError(
                f"plant: the controller has not acknowledged BenchCommand seq "
                f"{node.needed_ack()} (needed for sample {node.plant.k + 1}) in "
                f"{watchdog_s:.0f} s; its newest CtrlTelemetry.cmd_ack is {node.ctrl_ack}"
            )
        if now - t_ack >= RETRANSMIT_S:
            send_all(bus, node.retransmit(), node.counters)
            t_ack = now

    while not node.done and not stop():
        t_wait = time.monotonic()
        try:
            if not _receive_until(bus, node, ids, node.ready, stop, no_duty):
                break
        except _RunOver:
            break
        # paced by bench run: not ahead of the commands (and so of its recorder)
        if not _receive_until(bus, node, ids, node.paced, stop, no_command):
            break
        # a controller under test that reports (DBC 2.2): not before it holds the commands
        t_ack = time.monotonic()
        if not _receive_until(bus, node, ids, node.acked, stop, no_ack):
            break
        send_all(bus, node.advance_lockstep(), node.counters)
        last_progress = time.monotonic()
        if diag is not None:
            diag.poll()
    if node.external and node.done and not stop():
        _last_answer(bus, node, ids, stop)


def _last_answer(bus: can.BusABC, node: PlantNode, ids: set[int], stop: Callable[[], bool]) -> None:
    """Resend the last frames until the answer to the last sample has come (or a while).

    The recorder's last rows need the controller's telemetry of the last
    samples; without this a controller whose socket dropped the last sample
    would leave them out, and a lossy run would have fewer rows than a clean one.
    """
    want = node.plant.k + 1 - node.delay
    t_end = time.monotonic() + LAST_ANSWER_S
    t_sent = 0.0

    def answered() -> bool:
        return want in node.duties or time.monotonic() > t_end

    def again() -> None:
        nonlocal t_sent
        if time.monotonic() - t_sent >= RETRANSMIT_S:
            send_all(bus, node.retransmit(), node.counters)
            t_sent = time.monotonic()

    t_sent = time.monotonic()
    _receive_until(bus, node, ids, answered, stop, again)


class _RunOver(Exception):
    """A lockstep plant serving a controller under test tripped its watchdog: end the run."""


def _receive_until(
    bus: can.BusABC,
    node: PlantNode,
    ids: set[int],
    done: Callable[[], bool],
    stop: Callable[[], bool],
    quiet: Callable[[], None],
) -> bool:
    """Feed the node its frames until ``done()`` (True) or ``stop()`` (False).

    ``quiet()`` runs after each ``RETRANSMIT_S`` without a frame, and at
    least every ``RETRANSMIT_S`` while frames come that do not make ``done()``
    (a controller answering with frames the node rejects); it may raise.
    """
    t_quiet = time.monotonic()
    while not done():
        if stop():
            return False
        msg = bus.recv(RETRANSMIT_S)
        if msg is not None:
            if msg.arbitration_id in ids:
                node.on_message(msg)
            now = time.monotonic()
            if now - t_quiet < RETRANSMIT_S:
                continue
        quiet()
        t_quiet = time.monotonic()
    return True


def controller_loop(
    bus: can.BusABC,
    node: ControllerNode,
    *,
    realtime: bool,
    on_ready: Callable[[], None] | None = None,
    stop: Callable[[], bool] = lambda: False,
    idle_s: float = 3600.0,
    sample_timeout_s: float = SAMPLE_TIMEOUT_S,
) -> None:
    """Serve the controller on ``bus`` until a stop command (or ``idle_s`` of silence).

    Real time: when no valid sample arrived for ``sample_timeout_s`` after the
    first one, the controller disables its PWM (:meth:`ControllerNode.sample_timeout`)
    until a reset or enable command.
    """
    node.realtime = realtime
    names = ["PhaseSamples", "BenchCommand"]
    if node.needs_truth:
        names.append("PlantTruth")
    ids = {node.codec.frame_id(n) for n in names}
    if on_ready:
        on_ready()
    last = time.monotonic()
    seen = node.samples_accepted
    t_sample = last
    poll = min(0.05, sample_timeout_s / 4) if realtime else 0.05
    with no_gc(realtime):
        while not node.stopped and not stop():
            msg = bus.recv(poll)
            now = time.monotonic()
            if realtime:
                if node.samples_accepted != seen:
                    seen = node.samples_accepted
                    t_sample = now
                elif seen and now - t_sample > sample_timeout_s:
                    node.sample_timeout()
            if msg is None:
                if now - last > idle_s:
                    return
                continue
            if msg.arbitration_id not in ids:
                continue
            last = now
            out = node.on_message(msg)
            if out:
                send_all(bus, out, node.counters)


def period_s(scn: Scenario) -> float:
    return sample_period(scn)
