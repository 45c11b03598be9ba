"""``bench run``: plant and controller as two OS processes over CAN, recorded.

The orchestrator starts ``bench plant`` and ``bench controller`` (and ``bench
link`` when latency is injected) as separate processes on the chosen bus,
records every frame of the bus(es) into a python-can log file, sends the
scenario's bench commands ahead of the plant, waits for the end, and derives
the per-step table, ``metrics.json``, the metadata and the plots from the
capture, exactly as ``bench analyze`` would.
"""

from __future__ import annotations

import json
import os
import platform
import select
import signal
import socket
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import can
import numpy as np

from bench._analysis import analyze_frames, write_csv
from bench._codec import Codec
from bench._errors import BenchError
from bench._loops import STATE_DONE, command_frames
from bench._metrics import compute_metrics
from bench._nodes import REPEATED_COUNTER, unwrap
from bench._scenario import Scenario, write_effective
from bench._setup import get_preset, lockstep_delay, n_steps, sample_period

LOG_SUFFIX = {"blf": ".blf", "asc": ".asc", "log": ".log"}


@dataclass(frozen=True, slots=True)
class BusSpec:
    """Where a node's bus is: a python-can interface, channel and options."""

    interface: str
    channel: str
    port: int | None = None
    bitrate: int | None = None
    data_bitrate: int | None = None

    def args(self) -> list[str]:
        a = ["--interface", self.interface, "--channel", self.channel]
        if self.port is not None:
            a += ["--port", str(self.port)]
        if self.bitrate is not None:
            a += ["--bitrate", str(self.bitrate)]
        if self.data_bitrate is not None:
            a += ["--data-bitrate", str(self.data_bitrate)]
        return a

    def open(self) -> can.BusABC:
        from bench._bus import open_bus

        kw: dict[str, Any] = {}
        if self.port is not None:
            kw["port"] = self.port
        bus = open_bus(
            self.interface,
            self.channel,
            fd=True,
            bitrate=self.bitrate,
            data_bitrate=self.data_bitrate,
            **kw,
        )
        _grow_receive_buffer(bus)
        return bus

    def peer(self) -> BusSpec:
        """The second bus of a latency link (controller side)."""
        if self.interface == "udp_multicast":
            return BusSpec(self.interface, self.channel, (self.port or 43113) + 1)
        if self.interface == "socketcan" and self.channel[-1:].isdigit():
            return BusSpec(self.interface, self.channel[:-1] + str(int(self.channel[-1]) + 1))
        return BusSpec(self.interface, self.channel + "-b", self.port)

    def describe(self) -> str:
        s = f"{self.interface}:{self.channel}"
        return s + (f" port {self.port}" if self.port is not None else "")


#: Receive buffer asked for on socket-based buses (bytes): a recorder thread that
#: is descheduled for a while must not lose frames (udp_multicast drops on
#: overflow). A lockstep plant is paced to at most the command lead (3000
#: periods, about 15,000 frames of about 1 kB in the kernel) ahead of it.
RECEIVE_BUFFER = 64 << 20
#: Lockstep pacing: a bench command (a keep-alive when nothing changes) at
#: least every this many periods; see :attr:`bench._nodes.PlantNode.pace_every`.
PACE_EVERY = 100


def _grow_receive_buffer(bus: can.BusABC) -> None:
    sock = getattr(getattr(bus, "_multicast", None), "_socket", None) or getattr(
        bus, "socket", None
    )
    if not isinstance(sock, socket.socket):
        return
    # SO_RCVBUFFORCE (root: above net.core.rmem_max) is 33 on Linux; Python does not name it
    force = getattr(socket, "SO_RCVBUFFORCE", 33 if sys.platform.startswith("linux") else None)
    for opt in (force, socket.SO_RCVBUF):
        if opt is None:
            continue
        try:
            sock.setsockopt(socket.SOL_SOCKET, opt, RECEIVE_BUFFER)
            return
        except OSError:
            continue


class Recorder(can.Listener):
    """Keeps every frame (with the index of the bus it came from) and writes the capture."""

    def __init__(self, codec: Codec, writer: can.Listener, channel: int) -> None:
        self.codec = codec
        self.writer = writer
        self.channel = channel
        self.frames: list[can.Message] = []
        self.samples_id = codec.frame_id("PhaseSamples")
        self.status_id = codec.frame_id("PlantStatus")
        self.last_raw_step = -1
        #: The plant's step from the sample counter, unwrapped here where every
        #: frame is seen in order (a poller could miss a whole counter cycle).
        self.step = -1
        self._m_step = 1 << codec.step_bits("PhaseSamples")
        self.done = threading.Event()
        self.lock = threading.Lock()

    def on_message_received(self, msg: can.Message) -> None:
        msg.channel = self.channel
        with self.lock:
            self.frames.append(msg)
            self.writer.on_message_received(msg)
        if msg.arbitration_id == self.samples_id:
            d = self.codec.decode(msg)
            if d is not None and d.reason is None:
                raw = int(d.signals["step"])
                last = self.last_raw_step
                if last < 0:
                    self.step, self.last_raw_step = raw, raw
                else:
                    ahead = (raw - last) % self._m_step
                    if ahead < self._m_step // 2:  # behind: a retransmitted old frame
                        self.step += ahead
                        self.last_raw_step = raw
        elif msg.arbitration_id == self.status_id:
            d = self.codec.decode(msg)
            if d is not None and d.reason is None and int(d.signals["state"]) == STATE_DONE:
                self.done.set()


def _drain(recorders: list[Recorder], quiet_s: float = 0.5, limit_s: float = 10.0) -> None:
    """Wait until the recorders have read what is still queued in their sockets.

    On a slow host (User-Mode Linux) the recorder thread lags the nodes by
    thousands of frames; stopping it as soon as the nodes end would lose them.
    Returns once no frame came in for ``quiet_s``, or after ``limit_s``.
    """
    t_end = time.monotonic() + limit_s
    last = -1
    while time.monotonic() < t_end:
        n = sum(len(r.frames) for r in recorders)
        if n == last:
            return
        last = n
        time.sleep(quiet_s)


@dataclass(slots=True)
class RunResult:
    out_dir: Path
    metrics: dict[str, Any]
    capture: Path
    meta: dict[str, Any] = field(default_factory=dict)


def _versions() -> dict[str, str]:
    import cantools
    import matplotlib
    import numpy
    import scipy

    return {
        "python": platform.python_version(),
        "python-can": can.__version__,
        "cantools": cantools.__version__,
        "numpy": numpy.__version__,
        "scipy": scipy.__version__,
        "matplotlib": matplotlib.__version__,
        "platform": platform.platform(),
    }


def _node_cmd(role: str, scenario_file: Path, spec: BusSpec, extra: list[str]) -> list[str]:
    return [sys.executable, "-m", "bench", role, str(scenario_file), *spec.args(), *extra]


def _scenario_args(scn: Scenario, mode: str) -> list[str]:
    return [
        "--mode",
        mode,
        "--duration",
        repr(scn.duration),
        "--delay-steps",
        str(scn.latency.duty_delay_steps),
        "--sample-delay-steps",
        str(scn.latency.sample_delay_steps),
    ]


def _wait_ready(
    proc: subprocess.Popen[str],
    role: str,
    log: Path,
    timeout: float = 60.0,
    stop: Any = lambda: False,
) -> None:
    """Wait for the node's READY line; return early when ``stop()`` (a signal came)."""
    assert proc.stdout is not None
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        if stop():
            return
        if not select.select([proc.stdout], [], [], 0.1)[0] and proc.poll() is None:
            continue
        line = proc.stdout.readline()
        if line.strip() == "READY":
            return
        if line == "" and proc.poll() is not None:
            tail = log.read_text(errors="replace").strip().splitlines()[-1:] if log.exists() else []
            raise BenchError(f"{role} process exited before it was ready: {' '.join(tail)}")
    raise BenchError(f"{role} process not ready after {timeout:.0f} s")


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
) -> RunResult:
    """Run ``scn`` with ``estimator`` between two processes on ``spec``'s bus.

    ``node_args`` adds command-line options per role (``plant``, ``controller``).
    """
    codec = codec or Codec()
    out_dir.mkdir(parents=True, exist_ok=True)
    capture = out_dir / f"capture{LOG_SUFFIX[log_format]}"
    T_s = sample_period(scn)
    n = n_steps(scn)
    link = scn.latency.any
    spec_b = spec.peer() if link else spec
    scn_args = _scenario_args(scn, mode)
    # the nodes get the exact scenario of this run (every override included)
    scn_file = write_effective(scn, out_dir / "scenario.json")
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    procs: list[tuple[str, subprocess.Popen[str]]] = []
    bus_a = spec.open()  # a bus that cannot be opened leaves no empty capture behind
    buses = [bus_a]
    if link:
        try:
            buses.append(spec_b.open())
        except BaseException:
            bus_a.shutdown()
            raise
    writer = can.Logger(str(capture))
    recorders = [Recorder(codec, writer, i + 1) for i in range(len(buses))]
    for r in recorders[1:]:
        r.lock = recorders[0].lock  # one writer: one lock, or the capture is corrupted
    notifiers = [can.Notifier(b, [r], timeout=0.05) for b, r in zip(buses, recorders, strict=True)]
    t_wall0 = time.perf_counter()
    interrupted = False
    prev_handlers = {}

    def _on_signal(signum: int, frame: Any) -> None:
        nonlocal interrupted
        interrupted = True

    for s in (signal.SIGINT, signal.SIGTERM):
        try:
            prev_handlers[s] = signal.signal(s, _on_signal)
        except ValueError:
            pass  # not in the main thread
    # Lockstep: the plant runs no further than the commands this process has
    # sent, which follow what the recorder has seen: the recording never
    # falls so far behind that its socket overflows on a loaded machine.
    pace = PACE_EVERY if mode == "lockstep" else 0
    pace_args = ["--pace-every", str(pace)] if pace else []
    try:
        extra_args = node_args or {}
        roles = [
            (
                "controller",
                spec_b,
                ["--estimator", estimator, *scn_args, *extra_args.get("controller", [])],
            ),
            (
                "plant",
                spec,
                [*scn_args, *pace_args, *extra_args.get("plant", [])],
            ),
        ]
        if link:
            lt = scn.latency
            link_args = [
                "--to", *_peer_args(spec_b), "--seed", str(scn.seed), "--mode", mode,
                "--delay-steps", str(lt.duty_delay_steps),
                "--sample-delay-steps", str(lt.sample_delay_steps),
                "--duty-delay-us", repr(lt.duty_delay_us),
                "--sample-delay-us", repr(lt.sample_delay_us),
                "--duty-jitter-us", repr(lt.duty.jitter_us),
                "--sample-jitter-us", repr(lt.sample.jitter_us),
                "--jitter-dist", lt.jitter_dist,
                "--duty-drop-prob", repr(lt.duty.drop_prob),
                "--sample-drop-prob", repr(lt.sample.drop_prob),
            ]  # fmt: skip
            roles.insert(0, ("link", spec, link_args))
        for role, sp, extra in roles:
            if interrupted:
                break
            log = out_dir / f"{role}.log"
            cmd = (
                _node_cmd(role, scn_file, sp, [*extra, "--report", str(out_dir / f"{role}.json")])
                if role != "link"
                else [sys.executable, "-m", "bench", "link", *sp.args(), *extra]
            )
            p = subprocess.Popen(
                cmd,
                stdout=subprocess.PIPE,
                stderr=log.open("w"),
                text=True,
                env=env,
                start_new_session=True,
            )
            procs.append((role, p))
            _wait_ready(p, role, log, stop=lambda: interrupted)
        # commands: sent ahead of the plant by a lead, each twice
        cmds = command_frames(scn, codec, pace_every=pace)
        # Nodes queue commands by their apply step, so sending far ahead costs
        # nothing; the recorder's view of the plant's step lags on a slow host
        # (User-Mode Linux: by thousands of frames), and a late command would
        # change the trace.
        # In real time the plant's clock runs regardless: a burst of commands
        # at the start would make its first periods late, so only a short lead.
        lead = max(3000, int(0.5 / T_s)) if mode == "lockstep" else max(20, int(0.02 / T_s))
        sent = 0
        full_step = 0
        plant = dict(procs).get("plant")
        t_last_print = 0.0
        tty = sys.stderr.isatty()
        t_moved, seen_step = time.monotonic(), -1
        ended: str | None = None
        while plant is not None and not interrupted:
            full_step = max(0, recorders[0].step)
            while sent < len(cmds) and cmds[sent][0] <= full_step + lead:
                bus_a.send(cmds[sent][1])
                bus_a.send(cmds[sent][1])
                sent += 1
            if full_step != seen_step:
                t_moved, seen_step = time.monotonic(), full_step
            elif pace and sent and time.monotonic() - t_moved > 1.0:
                # a paced plant that stopped moving may have lost the newest
                # commands (a lossy transport): the last few once more
                for _, m in cmds[max(0, sent - 8) : sent]:
                    bus_a.send(m)
                t_moved = time.monotonic()
            if recorders[0].done.is_set() or plant.poll() is not None or interrupted:
                break
            ended = _ended_early(procs)
            if ended:
                break
            now = time.perf_counter()
            if progress and now - t_last_print > (0.5 if tty else 5.0):
                t_last_print = now
                frac = min(1.0, full_step / max(1, n))
                el = now - t_wall0
                left = f"~{el / frac - el:4.0f} s left" if frac > 0.01 else "starting"
                # a terminal gets one line rewritten in place; a log gets a line every 5 s
                lead_in = "\r" if tty else ""
                print(
                    f"{lead_in}  step {min(full_step, n)}/{n} ({100 * frac:5.1f} %), "
                    f"{el:5.1f} s, {left} ",
                    end="" if tty else "\n",
                    file=sys.stderr,
                    flush=True,
                )
            time.sleep(0.002)
        if progress and tty:
            print(file=sys.stderr)
        # stop everything: the stop command is in the schedule; repeat it to be sure.
        # With latency the controller never sees the last sample, so the nodes
        # that do not end by themselves get SIGTERM (they stop cleanly on it).
        # Interrupted (SIGINT/SIGTERM): no waiting, every node gets SIGTERM at once.
        if plant is not None and not interrupted and not ended:
            bus_a.send(cmds[-1][1])
            try:
                plant.wait(timeout=30.0)
            except subprocess.TimeoutExpired:
                plant.send_signal(signal.SIGTERM)
            ctrl = dict(procs).get("controller")
            if ctrl is not None and not link:
                # it stops by itself at the stop command's step
                try:
                    ctrl.wait(timeout=10.0)
                except subprocess.TimeoutExpired:
                    pass
            time.sleep(0.2)
        for _, p in procs:
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + (2.0 if interrupted else 10.0)
        for _, p in procs:
            try:
                p.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
    finally:
        for _, p in procs:
            if p.poll() is None:
                p.kill()
                p.wait()
        _drain(recorders)
        for nt in notifiers:
            nt.stop()
        writer.stop()
        for b in buses:
            b.shutdown()
        for s, h in prev_handlers.items():
            signal.signal(s, h)
    wall = time.perf_counter() - t_wall0
    failures = {role: p.returncode for role, p in procs if p.returncode not in (0, None)}
    frames = (
        sorted((m for r in recorders for m in r.frames), key=lambda m: m.timestamp)
        if link
        else recorders[0].frames
    )
    reports = {}
    for role in ("plant", "controller"):
        f = out_dir / f"{role}.json"
        if f.exists():
            reports[role] = json.loads(f.read_text())
    meta = run_metadata(scn, estimator, mode=mode, transport=spec.describe(), link=link)
    meta["node_reports"] = reports
    meta["exit_codes"] = {role: p.returncode for role, p in procs}
    if interrupted:
        meta["interrupted"] = True
    result: RunResult | None
    try:
        result = finish_run(frames, codec, scn, out_dir, meta=meta, wall_s=wall, capture=capture)
    except ValueError:
        if not (interrupted or failures):
            raise
        result = None
    if result is None:
        # interrupted (or a node died) before the scored part: score what there is
        try:
            result = finish_run(
                frames,
                codec,
                scn.with_overrides(score_from_s=0.0),
                out_dir,
                meta=meta,
                wall_s=wall,
                capture=capture,
            )
        except ValueError:
            result = None
    if result is None:
        # stopped before the first complete step: the capture is still valid;
        # one without a single frame is not kept (no reader takes an empty log)
        meta["capture"] = capture.name if frames else None
        if not frames:
            capture.unlink(missing_ok=True)
        metrics: dict[str, Any] = {"steps": 0, "frames_recorded": len(frames), "wall_s": wall}
        (out_dir / "metrics.json").write_text(json.dumps(metrics, indent=2) + "\n")
        (out_dir / "meta.json").write_text(json.dumps(meta, indent=2, default=str) + "\n")
        result = RunResult(out_dir=out_dir, metrics=metrics, capture=capture, meta=meta)
    if ended and not interrupted:
        raise BenchError(
            f"{ended} process ended before the run did ({_last_line(out_dir, ended)}); "
            f"files in {out_dir}"
        )
    if failures and not interrupted:
        logs = "; ".join(f"{r}: {_last_line(out_dir, r)}" for r in failures)
        raise BenchError(f"node process failed ({logs}); files in {out_dir}")
    return result


def _ended_early(procs: list[tuple[str, subprocess.Popen[str]]]) -> str | None:
    """``"link"`` when the latency link ended while the plant still runs, else ``None``.

    The link is the bench's own infrastructure and never ends by itself during
    a run; without it the plant would only wait for its watchdog.  A node that
    dies (the controller) is left to the plant, as a drive would be: the
    plant's watchdog and safe state are what such a run tests.
    """
    for role, p in procs:
        if role == "link" and p.poll() is not None:
            return role
    return None


def _last_line(out_dir: Path, role: str) -> str:
    """The last line a node process wrote to its log (empty if none)."""
    f = out_dir / f"{role}.log"
    lines = f.read_text(errors="replace").strip().splitlines() if f.exists() else []
    return lines[-1] if lines else "no output"


def _peer_args(spec: BusSpec) -> list[str]:
    a = [f"{spec.interface}:{spec.channel}"]
    if spec.port is not None:
        a.append(f"--to-port={spec.port}")
    return a


def run_metadata(
    scn: Scenario, estimator: str, *, mode: str, transport: str, link: bool
) -> dict[str, Any]:
    p = get_preset(scn)
    from dataclasses import asdict

    return {
        "scenario": scn.to_dict(),
        "estimator": estimator,
        "mode": mode,
        "transport": transport,
        "latency_link": link,
        "lockstep_delay_steps": lockstep_delay(scn),
        "T_s": sample_period(scn),
        "f_sw": 1.0 / sample_period(scn),
        "preset": {
            "name": p.name,
            "motor": asdict(p.motor),
            "inverter": asdict(p.inverter),
            "f_sw": p.f_sw,
            "doc": p.doc,
        },
        "seed": scn.seed,
        "versions": _versions(),
    }


def finish_run(
    frames: list[can.Message],
    codec: Codec,
    scn: Scenario,
    out_dir: Path,
    *,
    meta: dict[str, Any],
    wall_s: float,
    capture: Path | None,
    plots: bool = True,
) -> RunResult:
    """Table, metrics, metadata and plots from a run's frames."""
    T_s = sample_period(scn)
    n_p = get_preset(scn).motor.n_p
    cap = analyze_frames(frames, codec, T_s=T_s, n_p=n_p)
    write_csv(str(out_dir / "signals.csv"), cap.table)
    m: dict[str, Any] = compute_metrics(
        cap.table,
        T_s=T_s,
        n_p=n_p,
        score_from_s=scn.score_from_s,
        thd_window_s=scn.thd_window_s,
        overshoot="speed_overshoot_rpm" in scn.paper_result,
    )
    reports = meta.get("node_reports", {})
    plant_r = reports.get("plant", {})
    ctrl_r = reports.get("controller", {})
    m["wall_s"] = wall_s
    # simulated time per wall second of the plant's stepping loop (process
    # start-up excluded); the whole run's wall time when no plant report
    loop_s = plant_r.get("loop_s") or wall_s
    m["realtime_factor"] = m["sim_s"] / loop_s if loop_s > 0 else float("nan")
    m["deadline_misses"] = int(plant_r.get("overruns", 0))
    m["late_duty_periods"] = int(plant_r.get("late_duties", 0))
    m["frames_rejected"] = int(
        cap.frames_rejected + plant_r.get("frames_rejected", 0) + ctrl_r.get("frames_rejected", 0)
    )
    reasons: dict[str, int] = dict(cap.rejected)
    repeated = 0
    for r in (plant_r, ctrl_r):
        for k, v in r.get("reject_reasons", {}).items():
            if k == REPEATED_COUNTER:
                # expected, not a fault: every command is sent twice, and a
                # retransmitted frame answers a lost one; counted on its own
                repeated += int(v)
            else:
                reasons[k] = reasons.get(k, 0) + int(v)
    m["frames_rejected_by_reason"] = reasons
    m["frames_repeated_ignored"] = repeated
    m["frames_recorded"] = cap.frames
    m["frames_unknown_id"] = cap.unknown_ids
    m["incomplete_steps"] = cap.incomplete_steps
    # periods 0 .. n - 1 of the scenario without a row: frames the recording lost
    # (or a run stopped early); the metrics above cover only the rows present
    n_run = n_steps(scn)
    present = np.unique(cap.table["step"][cap.table["step"] < n_run]).size
    m["steps_missing"] = int(n_run - present)
    m["frames_duplicate"] = cap.duplicates
    m["frames_out_of_order"] = cap.out_of_order
    m["retransmits"] = int(plant_r.get("retransmits", 0))
    m["late_commands"] = int(plant_r.get("late_commands", 0) + ctrl_r.get("late_commands", 0))
    age = cap.table["duty_age"]
    age = age[age < 255]
    if len(age):
        m["loop_latency_steps"] = {
            "median": float(np.median(age)),
            "min": float(age.min()),
            "max": float(age.max()),
        }
    if any(getattr(f, "channel", None) == 2 for f in frames[:2000]):
        from bench._analysis import measure_latency

        m["latency_measured"] = measure_latency(frames, codec)
        lt = scn.latency
        m["latency_configured"] = {
            "samples_steps": lt.sample_delay_steps,
            "duties_steps": lt.duty_delay_steps,
            "samples_us": lt.sample_delay_us,
            "duties_us": lt.duty_delay_us,
            "samples_jitter_us": lt.sample.jitter_us,
            "duties_jitter_us": lt.duty.jitter_us,
            "jitter_dist": lt.jitter_dist,
            "samples_drop_prob": lt.sample.drop_prob,
            "duties_drop_prob": lt.duty.drop_prob,
        }
    if plant_r.get("jitter"):
        m["jitter_us"] = plant_r["jitter"]
    # the first trip, from the capture; the plant's report (its latched, so
    # last, fault) only when the capture lost the status frame
    fault, fault_step = plant_fault(frames, codec)
    if fault == "none" and plant_r.get("fault") not in (None, "none"):
        fault, fault_step = str(plant_r["fault"]), int(plant_r.get("fault_step", -1))
    m["plant_fault"] = fault
    m["plant_fault_step"] = fault_step
    meta = dict(
        meta,
        scored_from_s=scn.score_from_s,
        capture=capture.name if capture else None,
        wall_s=wall_s,
    )
    (out_dir / "metrics.json").write_text(json.dumps(m, indent=2, sort_keys=True) + "\n")
    (out_dir / "meta.json").write_text(
        json.dumps(meta, indent=2, sort_keys=True, default=str) + "\n"
    )
    if plots:
        from bench._plots import plot_run

        plot_run(cap.table, out_dir, title=f"{scn.name} / {meta.get('estimator', '?')}")
    return RunResult(out_dir=out_dir, metrics=m, capture=capture or out_dir, meta=meta)


def plant_fault(frames: list[can.Message], codec: Codec) -> tuple[str, int]:
    """The plant's first protection trip in a capture: (fault name, period), or ("none", -1).

    From the ``PlantStatus`` frames the plant sends when it trips; their
    16-bit step is unwrapped against the 32-bit step of the last
    ``PlantTruth`` frame before it (the plant's own period count, whatever
    the capture's length, start, retransmissions or number of buses).
    """
    from plant_rt import FAULT_NAMES

    id_status, id_truth = codec.frame_id("PlantStatus"), codec.frame_id("PlantTruth")
    m = 1 << codec.step_bits("PlantStatus")
    last_truth: can.Message | None = None
    for f in frames:
        if f.arbitration_id == id_truth:
            last_truth = f
        elif f.arbitration_id == id_status:
            d = codec.decode(f)
            if d is None or d.reason is not None or int(d.signals["fault_code"]) == 0:
                continue
            t = codec.decode(last_truth) if last_truth is not None else None
            ref = int(t.signals["step"]) if t is not None and t.reason is None else 0
            code = int(d.signals["fault_code"])
            return FAULT_NAMES.get(code, str(code)), unwrap(int(d.signals["step"]), ref, m)
    return "none", -1


def fault_warning(m: dict[str, Any], T_s: float) -> str | None:
    """One line when the plant tripped a protection during the run."""
    fault = m.get("plant_fault", "none")
    if fault in (None, "none"):
        return None
    k = int(m.get("plant_fault_step", -1))
    return (
        f"warning: the plant tripped its {fault} protection in period {k} "
        f"(t = {k * T_s:.4f} s) and switched the inverter off (safe state, until a reset); "
        "the metrics include that part"
    )


#: Real-time runs with more late periods than this get a warning (fraction).
REALTIME_LATE_WARN = 0.01


def realtime_warning(m: dict[str, Any]) -> str | None:
    """One line when a real-time run did not keep time well enough to read as a drive's."""
    steps = max(1, int(m.get("steps", 0)))
    late = m.get("late_duty_periods", 0) / steps
    over = m.get("deadline_misses", 0) / steps
    if max(late, over) <= REALTIME_LATE_WARN:
        return None
    worst = (m.get("jitter_us") or {}).get("max", float("nan")) * 1e-3
    return (
        f"warning: real time not kept: {100 * late:.1f} % of periods ran with a late duty, "
        f"{100 * over:.1f} % started late (worst wake-up {worst:.1f} ms); the figures include "
        "this machine's scheduling, not only the controller (see README, --rt-priority)"
    )


METRIC_ROWS = (
    ("theta_err_max_deg", "deg"),
    ("theta_err_min_deg", "deg"),
    ("theta_err_mean_deg", "deg"),
    ("theta_err_abs_mean_deg", "deg"),
    ("theta_err_rms_deg", "deg"),
    ("theta_err_abs_max_rad", "rad"),
    ("speed_err_max_rpm", "rpm"),
    ("speed_track_err_max_rpm", "rpm"),
    ("speed_overshoot_rpm", "rpm"),
    ("thd_phase_a_pct", "%"),
    ("steps", ""),
    ("sim_s", "s"),
    ("wall_s", "s"),
    ("realtime_factor", "x"),
    ("deadline_misses", ""),
    ("frames_rejected", ""),
    ("retransmits", ""),
)


def format_metrics(
    m: dict[str, Any], paper: dict[str, Any] | None = None, paper_method: str | None = None
) -> str:
    """The metrics as an aligned text table, with the paper's number where it has one.

    ``paper_method``: the method the paper's numbers belong to (the
    scenario's own estimator), named in the column's heading.
    """
    paper = paper or {}
    head = f"paper ({paper_method})" if paper and paper_method else "paper"
    lines = [f"{'metric':<26}{'bench':>12}  {head}"]
    for key, unit in METRIC_ROWS:
        if key not in m:
            continue
        v = m[key]
        vs = f"{v:12.3f}" if isinstance(v, float) else f"{v:>12}"
        ps = f"{paper[key]:>8}" if key in paper else f"{'':>8}"
        lines.append(f"{key:<26}{vs}  {ps} {unit}")
    return "\n".join(lines)
