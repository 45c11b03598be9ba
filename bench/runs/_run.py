"""``bench run``: plant and controller as two OS processes over CAN, recorded.

The orchestrator starts ``bench plant`` and ``bench controller`` (and ``bench
link`` when latency is injected) as separate processes on the chosen bus,
records every frame of the bus(es) into a python-can log file, sends the
scenario's bench commands ahead of the plant, waits for the end, and derives
the per-step table, ``metrics.json``, the metadata and the plots from the
capture, exactly as ``bench analyze`` would.

:func:`run_scenario` reads as the run's steps: open the recording
(:mod:`bench.runs._recorder`), start the nodes (:mod:`bench.runs._processes`),
drive the commands (:func:`_drive`, paced by :class:`bench.runs._pacing.CommandPacer`),
stop the nodes, and score the frames (:func:`bench.runs._results.finish_run`).

With ``controller="external"`` (``bench run --controller external``) no
controller process is started: the controller under test is whatever node on
the bus answers the plant (docs/PROTOCOL.md).  The run waits for its first
valid ``PwmDuty`` up to ``dut_timeout`` seconds (:class:`DutWatch`), says on
stderr what the plant rejects while the run goes on, and is scored as any
other run.
"""

from __future__ import annotations

import gc
import json
import math
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import can

from bench import _jsonio as jsonio
from bench._errors import BenchError, CommandsLost
from bench.nodes._counters import RejectionSummary, rejection_text
from bench.nodes._loops import STALL_S, trip_text
from bench.nodes._plan import PLAN_FILE, make_plan
from controller import DesignRecord
from bench.runs._analysis import NoRowsError
from bench.runs._busfit import check_bus_rate
from bench.runs._pacing import PACE_EVERY, CommandPacer
from bench.runs._processes import (
    ended_early,
    how_ended,
    last_line,
    node_failures,
    node_roles,
    start_nodes,
    stop_nodes,
)
from bench.runs._recorder import Recording
from bench.runs._results import (
    RunResult,
    finish_run,
    realtime_warning,
    run_metadata,
    scoring_scenario,
)
from bench.scenarios._faults import lockstep_error
from bench.scenarios._schema import Scenario, write_effective
from bench.scenarios._setup import sample_period, with_position_sensor
from bench.wire._bus import BusSpec
from bench.wire._codec import Codec
from bench.wire._protocol import SHARED_RUN_FRAMES, new_run_id, unwrap

LOG_SUFFIX = {"blf": ".blf", "asc": ".asc", "log": ".log"}

__all__ = ["DUT_TIMEOUT_S", "EXTERNAL", "PACE_EVERY", "DutProcess", "DutWatch", "run_scenario"]

#: ``bench run --controller external``: the controller is a node on the bus.
EXTERNAL = "external"
#: What ended a run that no process's end explains (:func:`_drive`): the plant
#: sent no sample after its start command, or its step stopped moving.
NO_START = "no start"
NO_PROGRESS = "no progress"
#: A plant that has sent no sample this long after its start command went out
#: (the plant's own lockstep stall time, :data:`bench.nodes._loops.STALL_S`; the
#: start is sent again every second) did not start: it cannot say so itself.
START_TIMEOUT_S = STALL_S
#: A plant whose step the recorder has not seen move for this long (after the
#: controller under test's first answer) is stalled: twice the plant's own stall
#: time, so that a lockstep plant's line (the duty it waits for) comes first.
NO_PROGRESS_S = 2.0 * STALL_S
#: Default wait for the first valid duty of a controller under test (s).
DUT_TIMEOUT_S = 30.0


class _Interrupt:
    """Set by SIGINT/SIGTERM while a run is on (the run then ends at once, files kept)."""

    def __init__(self) -> None:
        self.set = False

    def __call__(self) -> bool:
        return self.set


@contextmanager
def _catch_signals() -> Iterator[_Interrupt]:
    flag = _Interrupt()
    prev = {}

    def on_signal(signum: int, frame: Any) -> None:
        flag.set = True

    for s in (signal.SIGINT, signal.SIGTERM):
        try:
            prev[s] = signal.signal(s, on_signal)
        except ValueError:
            pass  # not in the main thread
    try:
        yield flag
    finally:
        for s, h in prev.items():
            signal.signal(s, h)


def build_native_libraries() -> None:
    """Build the native node loops' library here, before the nodes start, if it is not in
    the user's cache yet (bench/nodes/native: built once per source change).

    A node builds what it lacks before it reports ready, and a first build (code
    generation and the C compiler, tens of seconds on a loaded host, longer inside
    User-Mode Linux) would then count against the node's start-up timeout. A build that
    fails is left to the nodes: each says in one line why the Python node serves.  The
    sources are hashed once per process (:func:`bench.nodes.native._native.library_path`
    keeps the answer), not on every run of a sweep.
    """
    from bench.nodes.native._native import library_path

    try:
        library_path()
    except (BenchError, OSError):  # no compiler, or an unwritable cache: the nodes say
        pass


def recorder_priority(node_args: dict[str, list[str]] | None) -> int | None:
    """The native recorder thread's ``SCHED_FIFO`` priority: one below the lower of the
    nodes' (``--rt-priority`` of the plant and the controller), so that it never delays
    a node's deadline and no normal process delays it; None when no node asked for one.

    Its work is a ``recvmmsg`` per batch of datagrams (a few microseconds), so it takes
    little of the time the nodes leave; under it, a normal thread beside two
    ``SCHED_FIFO`` nodes on 2 cores falls behind a 10 kHz pair (docs/REALTIME.md).
    """
    prios: list[int] = []
    for args in (node_args or {}).values():
        for flag, value in zip(args, args[1:], strict=False):
            if flag == "--rt-priority" and value.isdigit():
                prios.append(int(value))
    return max(1, min(prios) - 1) if prios else None


@contextmanager
def collector_paused() -> Iterator[None]:
    """Python's cyclic garbage collector off inside (as it was, after).

    A run keeps every frame it records, a Python object each (160,000 in the 4 s of
    wen-5.1 at 10 kHz), and the collector walked them all again at each of its full
    passes: 0.5 s of the bench process's 5 s, GIL held, in the demo, while its
    recorder thread, whose pace a lockstep plant waits for, needs that GIL.  The run
    itself makes no cyclic garbage (measured: 3,022 objects found once the collector
    ran again, the same after 1 s and after 4 s of a run: its start-up's), so nothing
    accumulates; what it does make is freed when the collector is back on.
    """
    was = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was:
            gc.enable()


@collector_paused()
def run_scenario(
    scn: Scenario,
    estimator: str,
    *,
    spec: BusSpec,
    out_dir: Path,
    mode: str = "lockstep",
    log_format: str = "blf",
    progress: bool = True,
    codec: Codec | None = None,
    node_args: dict[str, list[str]] | None = None,
    controller: str = "bench",
    dut_timeout: float = DUT_TIMEOUT_S,
    dut_name: str | None = None,
    check: Callable[[], object] | None = None,
    dut_process: DutProcess | None = None,
    design: DesignRecord | None = None,
) -> RunResult:
    """Run ``scn`` with ``estimator`` between two processes on ``spec``'s bus.

        The nodes read the run's plan (``plan.json``, :mod:`bench.nodes._plan`), made
    here once; ``node_args`` adds command-line options per role (``plant``,
    ``controller``, ``link``) on how a node serves it (``--engine``,
    ``--rt-priority``, ``--truth-every``, ...), never the run's settings.
        ``controller="external"``: no controller process; the controller under test
        (named ``dut_name`` in the labels) must send its first valid duty within
        ``dut_timeout`` seconds, else the run ends with a :class:`BenchError`
        naming the duty frames the bench rejected.
        ``dut_process``: the controller under test's process when the caller started
        it (``bench.run(dut=...)``): its exit before its first valid duty ends the run
        at once, with a line naming its exit status and its log.
        ``check``: a check of the run's settings that takes a while (e.g. building the
        controller, :func:`bench.scenarios._setup.build_controller_check`; ``bench run``
        builds it before any process starts, so a misfit is refused first),
        done only when a node failed to start: the controller node builds the same
        controller before its ``READY`` and fails on the same misfit, which the
        check then names in its own line (its :class:`BenchError`) in place of the
        node's exit; nothing is recorded.
        ``design``: the controller's design made by the caller (that check's
        controller, :func:`bench.scenarios._setup.checked_design`), handed to the
        controller node in the plan (:attr:`bench.nodes._plan.RunPlan.design`).
    """
    codec = codec or Codec()
    if mode == "lockstep" and (err := lockstep_error(scn.faults, scn.source)):
        raise err
    external = controller == EXTERNAL
    if external:
        estimator = EXTERNAL
    if note := check_bus_rate(scn, spec, mode=mode, external=external, codec=codec):
        print(note, file=sys.stderr, flush=True)  # above 100 % in real time: refused (raises)
    out_dir.mkdir(parents=True, exist_ok=True)
    # an earlier run's files in the same folder would mix with these (scenario.json:
    # bench run --monitor has just written this run's)
    clear_run_files(out_dir, keep=("scenario.json",))
    capture = out_dir / f"capture{LOG_SUFFIX[log_format]}"
    link = scn.latency.any
    spec_b = spec.peer() if link else spec
    if external:
        # a drive under test reads its angle from its sensor, never from the
        # recorder's PlantTruth: the plant sends PositionSensor (docs/PROTOCOL.md)
        scn = with_position_sensor(scn)
    # the exact scenario of this run (every override included), for its user
    write_effective(scn, out_dir / "scenario.json")
    # Lockstep: the plant runs no further than the commands this process has
    # sent, which follow what the recorder has seen: the recording never
    # falls so far behind that its socket overflows on a loaded machine.
    pace = PACE_EVERY if mode == "lockstep" else 0
    # the run's nonce (PlantTruth.run_id, CtrlTelemetry.run_id): another run's frames are told apart
    run_id = new_run_id()
    # the one plan every node reads (bench.nodes._plan); with a controller under
    # test the plant gives up a little after this process would (which says why)
    plan = make_plan(
        scn,
        None if external else estimator,
        mode=mode,
        plant_bus=spec,
        controller_bus=spec_b,
        run_id=run_id,
        pace_every=pace,
        dut_timeout_s=dut_timeout + 10.0 if external else 0.0,
        design=None if external else design,
    )
    plan_file = plan.write(out_dir / PLAN_FILE)
    roles = node_roles(plan, node_args)
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    procs: list[tuple[str, subprocess.Popen[str]]] = []
    ended: str | None = None
    asked: set[str] = set()
    rec = Recording(
        [spec, spec_b] if link else [spec],
        capture,
        codec,
        watch_duties=external,
        rt_priority=recorder_priority(node_args),
    )
    dut = DutWatch(rec, dut_timeout, spec_b.describe(), dut_name, dut_process) if external else None
    t_wall0 = time.perf_counter()
    start_error: str | None = None
    pacer: CommandPacer | None = None
    with _catch_signals() as interrupted:
        try:
            start_error = _bus_in_use(rec, spec, interrupted)
            rec.expect_run(run_id)
            try:
                if start_error is None:
                    build_native_libraries()
                    start_nodes(roles, plan_file, out_dir, env, procs, stop=interrupted)
            except BenchError as e:  # a node that never became ready: nothing to record
                start_error = str(e)
            if start_error is not None and check is not None:
                # a node that failed on the run's settings says less than their own check
                try:
                    check()
                except BenchError as e:
                    start_error = str(e)
            if start_error is None:
                if dut is not None:
                    dut.start()
                pacer = CommandPacer(
                    scn,
                    codec,
                    mode=mode,
                    pace_every=pace,
                    external=external,
                    schedule=plan.commands,
                )
                plant = dict(procs).get("plant")
                if plant is not None and not interrupted():
                    ended = _drive(
                        rec,
                        pacer,
                        procs,
                        plant,
                        plan.n_steps,
                        progress,
                        interrupted,
                        dut,
                        mode == "lockstep",
                    )
                shared = rec.foreign
                if progress and (ended or interrupted() or shared):
                    # said at once: stopping the nodes and scoring take a while on a loaded host
                    why = "interrupted"
                    if shared and not interrupted():
                        why = "another run's frames on this bus"
                    elif ended == "dut" and dut is not None:
                        why = dut.failure_text()
                    elif ended in (NO_START, NO_PROGRESS):
                        why = _stall_text(ended, rec.plant_step, None)
                    elif ended:
                        code = dict(procs)[ended].returncode
                        why = f"{ended} process ended ({how_ended(out_dir, ended, code)})"
                    print(
                        f"{why} at step {max(0, rec.plant_step):,}: stopping the nodes and "
                        "scoring what was recorded (Ctrl-C again to stop without scoring)",
                        file=sys.stderr,
                        flush=True,
                    )
                asked = stop_nodes(
                    procs,
                    rec.plant_bus,
                    pacer.frames,
                    link=link,
                    interrupted=interrupted() or bool(shared),
                    ended=ended,
                )
        finally:
            for _, p in procs:
                if p.poll() is None:
                    p.kill()
                    p.wait()
            rec.close()
            if pacer is not None:
                # the reports the recorder received after the plant's last period
                pacer.take(rec.recorders[-1].acks, time.monotonic())
    if start_error is not None:
        raise failed_before_recording(out_dir, start_error)
    wall = time.perf_counter() - t_wall0
    failures = node_failures(procs, asked)
    reports = _node_reports(out_dir)
    # the controller as its node built it: gains, band edges, filter corners (its report)
    design = None if external else (reports.get("controller") or {}).get("design", {})
    meta = run_metadata(
        scn, estimator, mode=mode, transport=spec.describe(), link=link, design=design
    )
    if external:
        meta["controller"] = EXTERNAL
        meta["controller_name"] = dut_name or EXTERNAL
        meta["dut_timeout_s"] = dut_timeout
        if dut is not None:
            meta["dut_first_duty_s"] = dut.first_duty_s
    meta["run_id"] = run_id
    meta["node_reports"] = reports
    meta["engine"] = (meta["node_reports"].get("plant") or {}).get("engine")  # the plant's
    # which loop served each node (python, or native: bench/nodes/native)
    meta["node_engines"] = {
        role: rep["node_engine"]
        for role, rep in meta["node_reports"].items()
        if isinstance(rep, dict) and "node_engine" in rep
    }
    meta["exit_codes"] = {role: p.returncode for role, p in procs}
    meta["recorder_frames_lost"] = rec.frames_lost
    # which recorder read the bus (native: bench/nodes/native/bn_rec.c), and why not native
    meta["recorder"] = {"engine": rec.engine, "note": rec.engine_note}
    if rec.native:
        # per bus: datagrams kept, lost, not python-can messages; its receive calls, its
        # CPU time, SCHED_FIFO granted
        meta["recorder"]["native"] = [
            {
                k: st[k]
                for k in (
                    "received",
                    "ring_lost",
                    "unread",
                    "kernel_drops",
                    "malformed",
                    "calls",
                    "cpu_ns",
                    "fifo",
                )
            }
            for st in rec.native_stats
        ]
    if rec.frames_lost:
        print(
            f"warning: the recorder lost {rec.frames_lost} frames (its receive buffer "
            + ("or its ring " if rec.engine == "native" else "")
            + "overflowed, or it had not read them when the run ended); signals.csv lacks them",
            file=sys.stderr,
            flush=True,
        )
    if interrupted():
        meta["interrupted"] = True
    if pacer is not None:
        meta["commands"] = pacer.report()
    frames = rec.frames()
    codes = dict(meta["exit_codes"])
    plant_rejects = (meta["node_reports"].get("plant") or {}).get("reject_reasons")
    if not frames and (ended or failures) and not interrupted():
        if ended == "dut" and dut is not None:
            why = dut.failure_text()
        elif ended in (NO_START, NO_PROGRESS):
            why = _stall_text(ended, rec.plant_step, plant_rejects)
        elif ended:
            why = f"{ended} process ended before the run did ({how_ended(out_dir, ended, codes[ended])})"
        else:
            why = (
                "node process failed ("
                + "; ".join(f"{r}: {last_line(out_dir, r)}" for r in failures)
                + ")"
            )
        raise failed_before_recording(out_dir, why)
    # a plant that ended before the scenario's last period (a lockstep watchdog
    # trip with a controller under test) leaves a shorter run: scored as far as it went
    short = int((reports.get("plant") or {}).get("steps", plan.n_steps)) < plan.n_steps
    shared = rec.foreign
    partial = bool(interrupted() or failures or ended or short or shared)
    # a node that died: the numbers at once, the plots left to bench analyze (seconds of matplotlib)
    plots = not ended or bool(interrupted())
    result = _score(
        frames, codec, scn, out_dir, meta, wall, capture, partial=partial, plots=plots, T_s=plan.T_s
    )
    if dut is not None:
        dut.check(rec.plant_step)  # a trip the drive loop ended before printing
        dut.plant_story(out_dir)
    if interrupted():
        return result
    line: str | None = None
    if shared:
        line = shared_bus_line(shared, spec.describe(), rec.plant_step, out_dir)
    elif ended == "dut" and dut is not None:
        line = f"{dut.failure_text()}; files in {out_dir}"
    elif ended in (NO_START, NO_PROGRESS):
        line = f"{_stall_text(ended, rec.plant_step, plant_rejects)}; files in {out_dir}"
    elif ended:
        line = (
            f"{ended} process ended before the run did ({how_ended(out_dir, ended, codes[ended])}); "
            f"files in {out_dir}"
        )
    elif failures:
        logs = "; ".join(f"{r}: {how_ended(out_dir, r, codes[r])}" for r in failures)
        line = f"node process failed ({logs}); files in {out_dir}"
    if line is not None:
        # the line of a run that ends with status 2, kept beside what it recorded
        (out_dir / "error.txt").write_text(line + "\n")
        raise BenchError(line)
    if external and pacer is not None:
        lost = pacer.verification_line()
        tripped = result.metrics.get("plant_fault", "none") not in ("none", None)
        if lost is not None and pacer.acked is not None and not tripped:
            # a trip (exit 3) is the cause of what the controller missed after it. The
            # real-time verdict is a result too: said here, as the run ends with exit 5
            # (bench run prints it after a run that returns)
            if mode == "realtime" and (warn := realtime_warning(result.metrics)):
                print(warn, file=sys.stderr, flush=True)
            raise CommandsLost(f"{lost}; files in {out_dir}")
        if lost is not None:
            print(f"warning: {lost}", file=sys.stderr, flush=True)
    return result


#: The files a run writes into its folder (besides the nodes' ``*.log``).
RUN_FILES = (
    "scenario.json",
    "plan.json",
    "capture.blf",
    "capture.asc",
    "capture.log",
    "signals.csv",
    "signals.md",
    "metrics.json",
    "meta.json",
    "run.png",
    "plant.json",
    "controller.json",
    "error.txt",
)


def clear_run_files(out_dir: Path, keep: tuple[str, ...] = ()) -> None:
    """Remove an earlier run's files (:data:`RUN_FILES`, but ``keep``) from ``out_dir``;
    nothing else."""
    for name in RUN_FILES:
        if name not in keep:
            (out_dir / name).unlink(missing_ok=True)


#: Listening before a run starts its nodes: a bus that carries a plant's or a
#: bench's frames then is another run's (a controller under test waiting
#: for its first sample may already send, and is no other run) (an active plant sends every period, a stalled
#: lockstep plant every 50 ms, PlantStatus every 100 ms of plant time).
LISTEN_S = 0.3


def _bus_in_use(rec: Recording, spec: BusSpec, interrupted: _Interrupt) -> str | None:
    """The refusal line when the bus carries another run's frames before this one starts.

    Only frames that pass their E2E check count (:attr:`Recording.bench_frames`),
    and at least :data:`SHARED_RUN_FRAMES` of them: a random frame with one of
    the identifiers passes the 8-bit CRC once in 256, while another run's plant
    sends a sample every period, and a stalled lockstep one its last 3 periods'
    frames every 50 ms (18 samples in the window).
    """
    t_end = time.monotonic() + LISTEN_S
    while time.monotonic() < t_end and not interrupted():
        time.sleep(0.02)
    n = rec.bench_frames
    if n < SHARED_RUN_FRAMES:
        return None
    return (
        f"another run is on this bus ({spec.describe()}): {n} valid plant or bench frames "
        f"(E2E-checked) in the {LISTEN_S:g} s before this run; refusing to share it "
        "(give this run its own --port or --channel)"
    )


def _stall_text(ended: str, step: int, rejects: dict[str, int] | None) -> str:
    """The line of a run whose plant did not start or stopped moving (:func:`_drive`),
    with what the plant rejected (its report; None before the nodes were stopped)."""
    if ended == NO_START:
        what = (
            f"the plant sent no sample {START_TIMEOUT_S:g} s after its start command "
            "(sent again every second in lockstep): it did not start"
        )
    else:
        what = (
            f"the plant's step has not moved for {NO_PROGRESS_S:g} s (at step {max(0, step):,}) "
            "while its process runs"
        )
    if rejects is None:
        return what
    said = rejection_text(rejects) if rejects else "nothing rejected"
    return f"{what}; the plant's frames: {said} (plant.json, reject_reasons)"


def shared_bus_line(foreign: dict[int, int], where: str, step: int, out_dir: Path) -> str:
    """One line for a run that saw another run's recorder frames on its bus."""
    runs = ", ".join(f"{rid:#06x} ({n:,} frames)" for rid, n in sorted(foreign.items()))
    return (
        f"another run shares this bus ({where}): PlantTruth/CtrlTelemetry of run {runs}; this run "
        f"stopped at step {max(0, step):,} and is not a result (both runs' controllers "
        f"saw both plants' samples; give each run its own --port or --channel); files in {out_dir}"
    )


def failed_before_recording(out_dir: Path, why: str) -> BenchError:
    """A run that failed before its first recorded frame: its folder keeps only
    ``error.txt`` (the reason) and the nodes' logs, and the error names it."""
    clear_run_files(out_dir)
    logs = sorted(p.name for p in out_dir.glob("*.log"))
    (out_dir / "error.txt").write_text(
        f"{why}\nnothing was recorded; the nodes' stderr: {', '.join(logs) or 'none'}\n"
    )
    return BenchError(f"{why}; nothing recorded, see {out_dir / 'error.txt'}")


#: The interpreter's switch interval while :func:`_drive` sends the commands of a real-time
#: run (s; a lockstep plant waits for them, and its runs were not faster with it).  This
#: thread sends them beside the recorder's, which hands every frame of the run to Python
#: (40,000 a second for a 10 kHz pair): each send gives the GIL up for its socket call and
#: waited for it back up to the default 5 ms, so that a send took 0.57 ms on average and
#: wen-5.1's ramp in real time (a command every 10 periods at 10 kHz, three frames each:
#: one frame every 0.33 ms) went out late.  0.1 ms bounds that wait to under a third of
#: it; the recorder's thread gives the GIL up only when this one asks for it.
SEND_SWITCH_INTERVAL_S = 1e-4


@contextmanager
def _switch_interval(seconds: float | None) -> Iterator[None]:
    """The interpreter's switch interval at most ``seconds`` (None: as it is) inside, the one
    before restored after."""
    before = sys.getswitchinterval()
    if seconds is not None:
        sys.setswitchinterval(min(before, seconds))
    try:
        yield
    finally:
        sys.setswitchinterval(before)


def _drive(
    rec: Recording,
    pacer: CommandPacer,
    procs: list[tuple[str, subprocess.Popen[str]]],
    plant: subprocess.Popen[str],
    steps: int,
    progress: bool,
    interrupted: _Interrupt,
    dut: DutWatch | None,
    lockstep: bool = True,
) -> str | None:
    """Send the bench commands ahead of the plant (``steps`` periods) until it is done; what
    ended the run early.

    The commands go out as :class:`CommandPacer` paces them, after the
    recorder's view of the plant's step; in real time with the switch interval at
    :data:`SEND_SWITCH_INTERVAL_S`.  With a controller under test
    (``dut``) its diagnostics go to stderr as the run goes on, and the run
    ends (``"dut"``) when it has not answered in time.
    """
    with _switch_interval(None if lockstep else SEND_SWITCH_INTERVAL_S):
        bus = rec.plant_bus
        bar = _Progress(steps) if progress else None
        t_moved, seen_step = time.monotonic(), -1
        # when the start command went out, and when the recorder last saw the step move
        # (or the controller under test answered first: the plant waited for it until then)
        t_start: float | None = None
        t_seen, last_step, waiting_dut = t_moved, -1, dut is not None and not dut.answered
        ended: str | None = None
        tel = rec.recorders[-1]  # the controller's side: its CtrlTelemetry
        while not interrupted():
            full_step = max(0, rec.plant_step)
            now = time.monotonic()
            pacer.take(tel.acks, now)
            pacer.send_due(bus, full_step, now)
            if t_start is None and pacer.sent:
                t_start = t_seen = now
            if rec.plant_step != last_step or (waiting_dut and dut is not None and dut.answered):
                t_seen, last_step = now, rec.plant_step
                waiting_dut = dut is not None and not dut.answered
            if last_step < 0 and t_start is not None and now - t_start > START_TIMEOUT_S:
                ended = NO_START
                break
            if last_step >= 0 and not waiting_dut and now - t_seen > NO_PROGRESS_S:
                ended = NO_PROGRESS
                break
            if full_step != seen_step:
                t_moved, seen_step = now, full_step
            elif pacer.pace_every and pacer.sent and time.monotonic() - t_moved > 1.0:
                # a paced plant that stopped moving may have lost the newest
                # commands (a lossy transport): the last few once more
                pacer.resend_recent(bus)
                t_moved = time.monotonic()
            if rec.plant_done or interrupted() or rec.foreign:  # another run shares the bus
                break
            if plant.poll() is not None:
                # a plant that ends by itself ends well; killed or failed, it is named at once
                ended = "plant" if plant.returncode != 0 else None
                break
            ended = ended_early(procs, lockstep=lockstep)
            if ended:
                break
            if dut is not None:
                answered = dut.answered
                if dut.check(full_step):
                    ended = "dut"
                    break
                if dut.answered and not answered:
                    pacer.resend_all(bus)  # it may have started after the first commands
            if bar is not None and (dut is None or dut.answered):
                bar.show(full_step)
            time.sleep(0.002)
        if bar is not None:
            bar.close()
        return ended


@dataclass(frozen=True)
class DutProcess:
    """The controller under test's process, started for the run, and the file of its output."""

    proc: subprocess.Popen[bytes]
    log: Path

    def exit_text(self) -> str | None:
        """None while it runs; else how it ended (``exit status 1``, ``killed by SIGKILL``)."""
        code = self.proc.poll()
        if code is None:
            return None
        if code < 0:
            try:
                return f"killed by {signal.Signals(-code).name}"
            except ValueError:
                return f"killed by signal {-code}"
        return f"exit status {code}"


class DutWatch:
    """What ``bench run --controller external`` says on stderr about the controller under test.

    - Until its first valid ``PwmDuty``: a progress line (every 5 s; in place
      on a terminal) naming the bus and the time left of ``timeout_s``, and the
      duty frames rejected so far.  When the run started its process
      (``process``) and that process has ended, the run ends at once
      (:meth:`failure_text` names its exit status and its log): nothing will answer.
    - While the run goes on: once a second, the ``PwmDuty`` frames the bench's
      codec rejected (``PwmDuty: 722 rejected (bad_crc) in the last second``),
      the growth of the plant's ``PlantStatus.late_frames``, and a plant trip
      as soon as its ``PlantStatus`` says so, by name.
    """

    def __init__(
        self,
        rec: Recording,
        timeout_s: float,
        transport: str,
        name: str | None = None,
        process: DutProcess | None = None,
    ) -> None:
        self.rec = rec
        self.process = process
        #: How its process ended before its first valid duty (None: it did not).
        self.exited: str | None = None
        self.timeout_s = timeout_s
        self.transport = transport
        self.name = name or "the controller under test"
        self.t0 = time.monotonic()
        self.line = _StatusLine()
        #: Seconds from the start to its first valid duty (None: none yet).
        self.first_duty_s: float | None = None
        self.rejects = RejectionSummary("PwmDuty")
        self.late = RejectionSummary("PlantStatus")
        self.fault = 0
        self.late_seen = 0
        self.t_late = self.t0

    def start(self) -> None:
        """The nodes are ready: ``timeout_s`` counts from now.  The nodes' start-up (a
        second or more on a loaded host, more with a native build) is not the
        controller's time to answer."""
        self.t0 = self.t_late = time.monotonic()

    @property
    def answered(self) -> bool:
        return self.first_duty_s is not None

    def _say(self, line: str) -> None:
        print(line, file=sys.stderr, flush=True)

    def check(self, plant_step: int) -> bool:
        """Print what is new; True when the controller has not answered within the timeout."""
        now = time.monotonic()
        watch = self.rec.duty_watch
        if self.first_duty_s is None:
            if watch.duties_ok:
                self.first_duty_s = now - self.t0
                self._say(f"{self.name}: first valid PwmDuty after {self.first_duty_s:.1f} s")
            elif self.process is not None and (how := self.process.exit_text()) is not None:
                self.exited = how
                return True
            elif now - self.t0 > self.timeout_s:
                return True
            elif self.line.due(now):
                rej = watch.duty_rejected
                so_far = f"; PwmDuty: {rejection_text(rej)} so far" if rej else ""
                self.line.show(
                    f"waiting for {self.name} on {self.transport}: no valid PwmDuty "
                    f"yet ({now - self.t0:.0f} s of {self.timeout_s:.0f} s){so_far}"
                )
        line = self.rejects.poll(watch.duty_rejected, now)
        if line:
            self._say(line)
        st = self.rec.recorders[0].status
        code = st.get("fault_code", 0)
        if code and code != self.fault:
            # the step of the trip's own status frame, not of the newest one
            raw = self.rec.recorders[0].fault_steps.get(code, st.get("step", 0))
            step = unwrap(raw, plant_step, 1 << 16)
            self._say(f"plant: {trip_text(code, step)}")
        self.fault = code
        late = st.get("late_frames", 0)
        if now - self.t_late >= 1.0:
            if late > self.late_seen:
                self._say(
                    f"plant: {late - self.late_seen} periods without their own valid PwmDuty "
                    "(late, missing or rejected; PlantStatus.late_frames) in the last second"
                )
            self.late_seen, self.t_late = late, now
        return False

    def plant_story(self, out_dir: Path) -> None:
        """The plant's own account of why it waited (its stall line in ``plant.log``)."""
        log = out_dir / "plant.log"
        if log.is_file():
            for line in log.read_text(errors="replace").splitlines():
                if line.startswith("plant: no valid PwmDuty"):
                    self._say(line)

    def failure_text(self) -> str:
        """The one line of a controller that never answered."""
        if self.exited is not None and self.process is not None:
            return (
                f"{self.name} ended ({self.exited}) before its first valid PwmDuty; "
                f"its output: {self.process.log}"
            )
        rej = self.rec.duty_watch.duty_rejected
        why = (
            f"PwmDuty: {rejection_text(rej)} (docs/PROTOCOL.md, what the plant rejects)"
            if rej
            else f"no PwmDuty at all: is it running on {self.transport}?"
        )
        return f"no valid PwmDuty from {self.name} in {self.timeout_s:.0f} s; {why}"


class _StatusLine:
    """A status line on stderr: rewritten in place on a terminal (at most every 0.5 s),
    a new line every 5 s in a log."""

    def __init__(self) -> None:
        self.tty = sys.stderr.isatty()
        self.t_last = -math.inf

    def due(self, now: float) -> bool:
        """True (and the clock restarted) when a line is due at ``now`` (s, any clock)."""
        if now - self.t_last < (0.5 if self.tty else 5.0):
            return False
        self.t_last = now
        return True

    def show(self, text: str) -> None:
        print(
            ("\r" if self.tty else "") + text + " ",
            end="" if self.tty else "\n",
            file=sys.stderr,
            flush=True,
        )

    def close(self) -> None:
        """End a line left open on a terminal."""
        if self.tty:
            print(file=sys.stderr)


class _Progress:
    """The progress line of a run (:class:`_StatusLine`)."""

    def __init__(self, n: int) -> None:
        self.n = n
        self.t0 = time.perf_counter()
        self.line = _StatusLine()

    def show(self, step: int) -> None:
        now = time.perf_counter()
        if not self.line.due(now):
            return
        frac = min(1.0, step / max(1, self.n))
        el = now - self.t0
        left = f"~{el / frac - el:4.0f} s left" if frac > 0.01 else "starting"
        self.line.show(
            f"  step {min(step, self.n)}/{self.n} ({100 * frac:5.1f} %), {el:5.1f} s, {left}"
        )

    def close(self) -> None:
        self.line.close()


def _node_reports(out_dir: Path) -> dict[str, Any]:
    """The counters the nodes wrote at exit (``plant.json``, ``controller.json``)."""
    reports = {}
    for role in ("plant", "controller"):
        f = out_dir / f"{role}.json"
        if f.exists():
            reports[role] = json.loads(f.read_text())
    return reports


def _partial_scoring(
    frames: Sequence[can.Message], codec: Codec, scn: Scenario, T_s: float, meta: dict[str, Any]
) -> Scenario:
    """The scenario a partial run is scored with: ``bench analyze``'s rule on its span."""
    from bench.runs._analysis import analyze_frames

    try:
        steps = analyze_frames(frames, codec, T_s=1.0, n_p=1).table["step"]
    except ValueError:
        return scn  # no complete step: nothing to score
    scored, moved = scoring_scenario(scn, float(steps[0]) * T_s, float(steps[-1]) * T_s)
    if moved:
        meta["scoring"] = moved
    return scored


def _score(
    frames: Sequence[can.Message],
    codec: Codec,
    scn: Scenario,
    out_dir: Path,
    meta: dict[str, Any],
    wall: float,
    capture: Path,
    *,
    partial: bool,
    plots: bool = True,
    T_s: float | None = None,
) -> RunResult:
    """The run's files from its frames; a ``partial`` run (interrupted, a node died) too.

    A partial run is scored by the rule ``bench analyze`` applies to its
    capture (:func:`bench.runs._results.scoring_scenario`): one that ended
    before the scenario's scoring start is scored over the second half of
    the steps it recorded, so the run and a later analysis of its capture
    give the same numbers.  One that ended before its first complete step
    keeps its capture (none without a single frame: no reader takes an
    empty log) and a ``metrics.json`` that says so.  ``T_s``: the plan's period
    (None: the scenario's).
    """
    if partial:
        scn = _partial_scoring(frames, codec, scn, T_s or sample_period(scn), meta)
    try:
        return finish_run(
            frames, codec, scn, out_dir, meta=meta, wall_s=wall, capture=capture, plots=plots
        )
    except NoRowsError as e:  # not a single plant period recorded: no table to score
        why = str(e)
    meta["capture"] = capture.name if frames else None
    if not frames:
        capture.unlink(missing_ok=True)
    metrics: dict[str, Any] = {
        "steps": 0,
        "frames_recorded": len(frames),
        "wall_s": wall,
        "unscored_reason": why,
    }
    (out_dir / "metrics.json").write_text(jsonio.dumps(metrics, indent=2) + "\n")
    (out_dir / "meta.json").write_text(json.dumps(meta, indent=2, default=str) + "\n")
    return RunResult(out_dir=out_dir, metrics=metrics, capture=capture, meta=meta)
