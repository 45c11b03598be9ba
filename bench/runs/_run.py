"""``bench run``: plant and controller as two OS processes over CAN, recorded.

The orchestrator starts ``bench plant`` and ``bench controller`` (and ``bench
link`` when latency is injected) as separate processes on the chosen bus,
records every frame of the bus(es) into a python-can log file, sends the
scenario's bench commands ahead of the plant, waits for the end, and derives
the per-step table, ``metrics.json``, the metadata and the plots from the
capture, exactly as ``bench analyze`` would.

:func:`run_scenario` reads as the run's steps: open the recording
(:mod:`bench.runs._recorder`), start the nodes (:mod:`bench.runs._processes`),
drive the commands (:func:`_drive`), stop the nodes, and score the frames
(:func:`bench.runs._results.finish_run`).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import can

from bench import _jsonio as jsonio
from bench._errors import BenchError
from bench.nodes._loops import command_frames
from bench.runs._processes import (
    ended_early,
    how_ended,
    node_failures,
    node_roles,
    start_nodes,
    stop_nodes,
)
from bench.runs._recorder import Recording
from bench.runs._results import RunResult, finish_run, run_metadata, scoring_scenario
from bench.scenarios._schema import Scenario, write_effective
from bench.scenarios._setup import n_steps, sample_period
from bench.wire._bus import BusSpec
from bench.wire._codec import Codec

LOG_SUFFIX = {"blf": ".blf", "asc": ".asc", "log": ".log"}

#: Lockstep pacing: a bench command (a keep-alive when nothing changes) at
#: least every this many periods; see :attr:`bench.nodes._plant_node.PlantNode.pace_every`.
PACE_EVERY = 100


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
    link = scn.latency.any
    spec_b = spec.peer() if link else spec
    # the nodes get the exact scenario of this run (every override included)
    scn_file = write_effective(scn, out_dir / "scenario.json")
    # Lockstep: the plant runs no further than the commands this process has
    # sent, which follow what the recorder has seen: the recording never
    # falls so far behind that its socket overflows on a loaded machine.
    pace = PACE_EVERY if mode == "lockstep" else 0
    roles = node_roles(scn, estimator, spec, spec_b, mode=mode, pace=pace, node_args=node_args)
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    procs: list[tuple[str, subprocess.Popen[str]]] = []
    ended: str | None = None
    asked: set[str] = set()
    rec = Recording([spec, spec_b] if link else [spec], capture, codec)
    t_wall0 = time.perf_counter()
    with _catch_signals() as interrupted:
        try:
            start_nodes(roles, scn_file, out_dir, env, procs, stop=interrupted)
            cmds = command_frames(scn, codec, pace_every=pace)
            plant = dict(procs).get("plant")
            if plant is not None and not interrupted():
                ended = _drive(rec, cmds, procs, plant, scn, mode, pace, progress, interrupted)
            if progress and (ended or interrupted()):
                # said at once: stopping the nodes and scoring take a while on a loaded host
                why = "interrupted"
                if ended:
                    code = dict(procs)[ended].returncode
                    why = f"{ended} process ended ({how_ended(out_dir, ended, code)})"
                print(
                    f"{why} at step {max(0, rec.plant_step):,}: stopping the nodes and scoring "
                    "what was recorded (Ctrl-C again to stop without scoring)",
                    file=sys.stderr,
                    flush=True,
                )
            asked = stop_nodes(
                procs, rec.plant_bus, cmds, link=link, interrupted=interrupted(), ended=ended
            )
        finally:
            for _, p in procs:
                if p.poll() is None:
                    p.kill()
                    p.wait()
            rec.close()
    wall = time.perf_counter() - t_wall0
    failures = node_failures(procs, asked)
    meta = run_metadata(scn, estimator, mode=mode, transport=spec.describe(), link=link)
    meta["node_reports"] = _node_reports(out_dir)
    meta["engine"] = (meta["node_reports"].get("plant") or {}).get("engine")  # the plant's
    meta["exit_codes"] = {role: p.returncode for role, p in procs}
    if interrupted():
        meta["interrupted"] = True
    frames = rec.frames()
    partial = bool(interrupted() or failures or ended)
    # a node that died: the numbers at once, the plots left to bench analyze (seconds of matplotlib)
    plots = not ended or bool(interrupted())
    result = _score(frames, codec, scn, out_dir, meta, wall, capture, partial=partial, plots=plots)
    codes = dict(meta["exit_codes"])
    if ended and not interrupted():
        raise BenchError(
            f"{ended} process ended before the run did ({how_ended(out_dir, ended, codes[ended])}); "
            f"files in {out_dir}"
        )
    if failures and not interrupted():
        logs = "; ".join(f"{r}: {how_ended(out_dir, r, codes[r])}" for r in failures)
        raise BenchError(f"node process failed ({logs}); files in {out_dir}")
    return result


def _drive(
    rec: Recording,
    cmds: list[tuple[int, can.Message]],
    procs: list[tuple[str, subprocess.Popen[str]]],
    plant: subprocess.Popen[str],
    scn: Scenario,
    mode: str,
    pace: int,
    progress: bool,
    interrupted: _Interrupt,
) -> str | None:
    """Send the bench commands ahead of the plant until it is done; the role that ended early.

    Nodes queue commands by their apply step, so sending far ahead costs
    nothing; the recorder's view of the plant's step lags on a slow host
    (User-Mode Linux: by thousands of frames), and a late command would
    change the trace.  In real time the plant's clock runs regardless: a
    burst of commands at the start would make its first periods late, so
    only a short lead.  Each command is sent twice.
    """
    T_s = sample_period(scn)
    lead = max(3000, int(0.5 / T_s)) if mode == "lockstep" else max(20, int(0.02 / T_s))
    bus = rec.plant_bus
    bar = _Progress(n_steps(scn)) if progress else None
    sent = 0
    t_moved, seen_step = time.monotonic(), -1
    ended: str | None = None
    while not interrupted():
        full_step = max(0, rec.plant_step)
        while sent < len(cmds) and cmds[sent][0] <= full_step + lead:
            bus.send(cmds[sent][1])
            bus.send(cmds[sent][1])
            sent += 1
        if full_step != seen_step:
            t_moved, seen_step = time.monotonic(), full_step
        elif pace and sent and time.monotonic() - t_moved > 1.0:
            # a paced plant that stopped moving may have lost the newest
            # commands (a lossy transport): the last few once more
            for _, m in cmds[max(0, sent - 8) : sent]:
                bus.send(m)
            t_moved = time.monotonic()
        if rec.plant_done or interrupted():
            break
        if plant.poll() is not None:
            # a plant that ends by itself ends well; killed or failed, it is named at once
            ended = "plant" if plant.returncode != 0 else None
            break
        ended = ended_early(procs, lockstep=mode == "lockstep")
        if ended:
            break
        if bar is not None:
            bar.show(full_step)
        time.sleep(0.002)
    if bar is not None:
        bar.close()
    return ended


class _Progress:
    """The progress line on stderr: rewritten in place on a terminal, every 5 s in a log."""

    def __init__(self, n: int) -> None:
        self.n = n
        self.tty = sys.stderr.isatty()
        self.t0 = time.perf_counter()
        self.t_last = 0.0

    def show(self, step: int) -> None:
        now = time.perf_counter()
        if now - self.t_last <= (0.5 if self.tty else 5.0):
            return
        self.t_last = now
        frac = min(1.0, step / max(1, self.n))
        el = now - self.t0
        left = f"~{el / frac - el:4.0f} s left" if frac > 0.01 else "starting"
        lead_in = "\r" if self.tty else ""
        print(
            f"{lead_in}  step {min(step, self.n)}/{self.n} ({100 * frac:5.1f} %), "
            f"{el:5.1f} s, {left} ",
            end="" if self.tty else "\n",
            file=sys.stderr,
            flush=True,
        )

    def close(self) -> None:
        if self.tty:
            print(file=sys.stderr)


def _node_reports(out_dir: Path) -> dict[str, Any]:
    """The counters the nodes wrote at exit (``plant.json``, ``controller.json``)."""
    reports = {}
    for role in ("plant", "controller"):
        f = out_dir / f"{role}.json"
        if f.exists():
            reports[role] = json.loads(f.read_text())
    return reports


def _partial_scoring(
    frames: list[can.Message], codec: Codec, scn: Scenario, meta: dict[str, Any]
) -> Scenario:
    """The scenario a partial run is scored with: ``bench analyze``'s rule on its span."""
    from bench.runs._analysis import analyze_frames

    try:
        steps = analyze_frames(frames, codec, T_s=1.0, n_p=1).table["step"]
    except ValueError:
        return scn  # no complete step: nothing to score
    T_s = sample_period(scn)
    scored, moved = scoring_scenario(scn, float(steps[0]) * T_s, float(steps[-1]) * T_s)
    if moved:
        meta["scoring"] = moved
    return scored


def _score(
    frames: list[can.Message],
    codec: Codec,
    scn: Scenario,
    out_dir: Path,
    meta: dict[str, Any],
    wall: float,
    capture: Path,
    *,
    partial: bool,
    plots: bool = True,
) -> RunResult:
    """The run's files from its frames; a ``partial`` run (interrupted, a node died) too.

    A partial run is scored by the rule ``bench analyze`` applies to its
    capture (:func:`bench.runs._results.scoring_scenario`): one that ended
    before the scenario's scoring start is scored over the second half of
    the steps it recorded, so the run and a later analysis of its capture
    give the same numbers.  One that ended before its first complete step
    keeps its capture (none without a single frame: no reader takes an
    empty log) and a ``metrics.json`` that says so.
    """
    if partial:
        scn = _partial_scoring(frames, codec, scn, meta)
    try:
        return finish_run(
            frames, codec, scn, out_dir, meta=meta, wall_s=wall, capture=capture, plots=plots
        )
    except ValueError:
        if not partial:
            raise
    meta["capture"] = capture.name if frames else None
    if not frames:
        capture.unlink(missing_ok=True)
    metrics: dict[str, Any] = {"steps": 0, "frames_recorded": len(frames), "wall_s": wall}
    (out_dir / "metrics.json").write_text(jsonio.dumps(metrics, indent=2) + "\n")
    (out_dir / "meta.json").write_text(json.dumps(meta, indent=2, default=str) + "\n")
    return RunResult(out_dir=out_dir, metrics=metrics, capture=capture, meta=meta)
