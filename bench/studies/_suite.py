"""``bench suite``: every shipped scenario with every estimator that applies, and the sweeps.

The shipped scenarios are the papers' (Wen Tables 5-8, Xue Figs. 13-18) and
the full speed range's (``wide-speed-wen``, ``wide-speed-xue``: the hybrid
estimators, whose goals the report checks beside the papers' claims).

Each shipped scenario lists the estimators it is run with (``estimators`` in
its TOML: the three rotating-injection demodulators and the sensored zero
line for Wen, the square-wave estimator with and without CIC and the
sensored zero line for Xue).  Each (scenario, estimator) pair is a lockstep
run between two processes over the CAN transport of
:func:`bench.wire._bus.default_transport` (:func:`bench.runs._run.run_scenario`), each
run on a UDP port of its own so parallel runs do not hear each other.  The
sweeps of :mod:`bench.studies._sweep` run in-process.

Parallelism.  Each run is already three busy processes (recorder, plant,
controller), so two runs at a time on a 2-core machine gain little: on the
development machine four 1.5 s ``wen-5.1`` runs took 48.0 s one at a time and
44.2 s two at a time (``concurrent.futures`` with 2 spawned workers), so two
workers is the default; ``--jobs 1`` runs one at a time.  The in-process
sweep points are single-threaded and gain about twice from two workers.
On SocketCAN (one shared ``vcan0``) runs are not isolated from each other,
so the suite runs them one at a time there.

Plants.  Every scenario runs on three plants (``--plants``): ``ideal``, the
papers' plant as shipped; ``drive``, the ``drive`` profile (switching
inverter with dead time and device drops, 12-bit ADC with offsets and gain
mismatch, cross-saturation: :mod:`plant_rt._profiles`) with the drive's
countermeasures on (dead-time compensation, cross-saturation angle
compensation, offset calibration: :mod:`controller._compensation`); and
``drive-nocomp``, the same plant with every countermeasure off, to show how
far each method degrades without them (:func:`plant_variant`).

Files.  The full run folders (capture, ``signals.csv``, node logs) go to
``runs_dir``; the suite's output folder receives only ``report.md``,
``summary.json``, the sweep plots and per run ``metrics.json``, ``meta.json``
and a downscaled ``run.png``, so it can be committed.
"""

from __future__ import annotations

import io
import math
import os
import random
import shutil
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Protocol

from bench._errors import BenchError
from bench.scenarios._schema import SHIPPED, Scenario, load_scenario
from bench.studies._accel_ff import AccelFfJob
from bench.studies._cic import CicJob
from bench.studies._extras import path_name, run_extras
from bench.studies._plants import PLANTS, plant_variant
from controller._registry import ESTIMATOR_NAMES

#: Simulated seconds of a run in ``--quick`` mode (smoke test, not comparable with the papers):
#: wen-5.1's start-up and ramp end at 0.8 s, the scored window is the last 0.2 s or more.
QUICK_DURATION_S = 1.6


@dataclass(frozen=True, slots=True)
class Smoke:
    """What ``bench suite paper --quick`` runs when no scenario or estimator is chosen.

    One run over CAN per estimator family and paper (Wen's rotating
    injection, Xue's square wave, the hybrid of the full speed range), on
    the ideal plant, cut to :data:`QUICK_DURATION_S`; and one sweep (speed,
    its quick values, the three rotating demodulators, in-process), so every
    path of the suite (runs over the bus, sweep points, claims, report) runs
    once: 3 runs and 9 sweep points, instead of every shipped scenario,
    estimator, plant and sweep cut short.  Its measured time is in
    README.md ("Results").
    """

    scenarios: tuple[str, ...] = ("wen-5.1", "xue-fig13", "wide-speed-xue")
    #: each listed by one of the scenarios only: one run per scenario
    estimators: tuple[str, ...] = ("tt-dq", "square-wave", "hybrid-square-wave")
    plants: tuple[str, ...] = ("ideal",)
    sweeps: tuple[str, ...] = ("speed",)


SMOKE = Smoke()
#: Relative cost of a step over a bus versus in-process (for the time-left estimate only).
BUS_STEP_COST = 6.0
#: Fixed cost of a run (process start, analysis, plots), in in-process steps.
RUN_OVERHEAD_STEPS = 15000.0
#: Width of the per-run plot copied into the suite's output folder (pixels).
PNG_WIDTH = 760
#: The error of a job that did not run to its end (the suite was interrupted).
UNFINISHED = "not finished: the suite was interrupted"

#: Metrics of a run kept in ``summary.json``.
SUMMARY_METRICS = (
    "theta_err_max_deg",
    "theta_err_min_deg",
    "theta_err_mean_deg",
    "theta_err_abs_mean_deg",
    "theta_err_abs_max_deg",
    "theta_err_abs_max_rad",
    "theta_err_rms_deg",
    "speed_err_max_rpm",
    "speed_track_err_max_rpm",
    "speed_overshoot_rpm",
    "thd_phase_a_pct",
    "steps",
    "sim_s",
    "wall_s",
    "deadline_misses",
    "frames_rejected",
    "lock_lost",
    "lock_lost_at_s",
)

#: ... and those of a hybrid estimator's run: every metric whose name starts so.
BAND_METRIC_PREFIXES = (
    "band_",
    "handover_",
    "theta_err_steady_",
    "theta_err_transient_",
    "steady_settle_",
)


def run_subdir(plant: str, scenario: str, estimator: str) -> str:
    """Where a run's files go under a runs or report folder: ``scenario/estimator`` on
    the ideal plant, ``plant/scenario/estimator`` on the others."""
    est = path_name(estimator)
    return f"{scenario}/{est}" if plant == "ideal" else f"{plant}/{scenario}/{est}"


class Job(Protocol):
    @property
    def label(self) -> str: ...

    @property
    def cost(self) -> float: ...

    def __call__(self) -> dict[str, Any]: ...


def quick_scenario(scn: Scenario, duration: float = QUICK_DURATION_S) -> Scenario:
    """``scn`` cut to ``duration`` s; a THD window past the end moves to the scored part."""
    d = min(scn.duration, duration)
    thd = scn.thd_window_s
    if thd is not None and thd[1] > d:
        thd = (min(scn.score_from_s, d - 0.2), d)
    return replace(scn, duration=d, thd_window_s=thd, score_from_s=min(scn.score_from_s, d - 0.2))


@dataclass(frozen=True, slots=True)
class RunJob:
    """One (scenario, estimator) run, over a bus or in-process (picklable).

    ``transport`` is ``(interface, channel, port)`` for a two-process run
    over CAN, or None for an in-process run (the reference trace, used by
    the quick test of the suite).
    """

    scenario: Scenario
    estimator: str
    run_dir: Path
    transport: tuple[str, str, int | None] | None
    plant: str = "ideal"

    @property
    def label(self) -> str:
        where = "" if self.plant == "ideal" else f" ({self.plant})"
        return f"{self.scenario.name}/{self.estimator}{where}"

    @property
    def cost(self) -> float:
        from bench.scenarios._setup import n_steps

        k = BUS_STEP_COST if self.transport is not None else 1.0
        return k * n_steps(self.scenario) + RUN_OVERHEAD_STEPS

    def __call__(self) -> dict[str, Any]:
        t0 = time.perf_counter()
        try:
            metrics, meta = self._run()
        except Exception as e:  # one failing run must not end the suite
            return {"error": f"{type(e).__name__}: {e}", "wall_s": time.perf_counter() - t0}
        if meta.get("interrupted"):  # a signal reached the run: its numbers are not a result
            return {"error": UNFINISHED, "wall_s": time.perf_counter() - t0}
        gains = meta.get("controller_gains") or {}
        # the report's figures of the run and its small plot, made here in the worker: in
        # the suite's process they took 0.2 s of CPU per run (0.5 to 0.8 s of wall time at
        # a load of 14 on two cores), during which a signal waited (run_suite)
        extras = run_extras(self.run_dir / "signals.csv", self.scenario)
        png = self.run_dir / "run.png"
        return {
            "metrics": metrics,
            "gains": gains,
            "extras": extras,
            "png": small_png(png) if png.exists() else None,
            "wall_s": time.perf_counter() - t0,
        }

    def _run(self) -> tuple[dict[str, Any], dict[str, Any]]:
        from bench.runs._local import run_local
        from bench.runs._run import run_scenario
        from bench.wire._bus import BusSpec
        from bench.wire._codec import Codec

        codec = Codec()
        if self.transport is None:
            res = run_local(self.scenario, self.estimator, self.run_dir, codec=codec)
            return res.metrics, res.meta
        iface, chan, port = self.transport
        res = run_scenario(
            self.scenario,
            self.estimator,
            spec=BusSpec(iface, chan, port),
            out_dir=self.run_dir,
            progress=False,
            codec=codec,
        )
        return res.metrics, res.meta


def _call(job: Job) -> dict[str, Any]:
    return job()


class Progress:
    """One status line on stderr: runs done, the current runs, elapsed and time left.

    The time left scales the elapsed time by the remaining share of the
    jobs' costs (simulated steps, a bus step counted ``BUS_STEP_COST``
    times), so it adapts to the machine as runs finish.
    """

    def __init__(self, total_cost: float, n: int, *, stream: Any = None, enabled: bool = True):
        self.total = total_cost
        self.n = n
        self.done_cost = 0.0
        self.done = 0
        self.t0 = time.perf_counter()
        self.stream = stream or sys.stderr
        self.enabled = enabled
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.last = 0.0

    def finished(self, job: Job, ok: bool) -> None:
        self.done += 1
        self.done_cost += job.cost
        if self.enabled and not self.tty:
            print(
                f"[{self.done}/{self.n}] {job.label} {'done' if ok else 'FAILED'}  {self._times()}",
                file=self.stream,
                flush=True,
            )

    def _times(self) -> str:
        el = time.perf_counter() - self.t0
        if self.done_cost > 0:
            left = el * (self.total - self.done_cost) / self.done_cost
            return f"{_mmss(el)} elapsed, ~{_mmss(left)} left"
        return f"{_mmss(el)} elapsed"

    def show(self, running: Sequence[str]) -> None:
        now = time.perf_counter()
        if not (self.enabled and self.tty) or now - self.last < 0.5:
            return
        self.last = now
        cur = f"running: {', '.join(running)} | " if running else ""
        line = f"[{self.done}/{self.n}] {cur}{self._times()}"
        print(f"\r{line[:150]:<150}", end="", file=self.stream, flush=True)

    def close(self) -> None:
        if self.enabled and self.tty:
            print(file=self.stream, flush=True)


def _mmss(s: float) -> str:
    if not math.isfinite(s):
        return "?"
    s = max(0.0, s)
    return f"{int(s // 60)}:{int(s % 60):02d}"


def run_jobs(
    jobs: Sequence[Job],
    *,
    workers: int = 2,
    progress: bool = True,
    on_done: Callable[[Job, dict[str, Any]], None] | None = None,
) -> list[dict[str, Any]]:
    """Run ``jobs`` (longest first) on ``workers`` processes; results in ``jobs`` order.

    The jobs run in worker processes even with one worker, so that the command's
    own process only waits and reacts to signals at once
    (:mod:`bench.studies._executors`).  A job that did not finish (SIGINT or
    SIGTERM stopped the batch) has ``{"error": UNFINISHED}``.
    """
    # the same engine as bench sweep: a process pool that resubmits the
    # unfinished runs of a worker that died (bench.studies._executors)
    from bench.studies._executors import LOST, execute

    order = sorted(range(len(jobs)), key=lambda i: -jobs[i].cost)
    results: list[dict[str, Any] | None] = [None] * len(jobs)
    prog = Progress(sum(j.cost for j in jobs), len(jobs), enabled=progress)

    def _done(k: int, res: dict[str, Any]) -> None:
        i = order[k]
        if res.get("error") == LOST:
            res = {"error": f"worker died: {res.get('why', '')}", "wall_s": math.nan}
        results[i] = res
        prog.finished(jobs[i], "error" not in res)
        if on_done is not None:
            on_done(jobs[i], res)
        prog.show([])

    try:
        execute([jobs[i] for i in order], _call, _done, workers=max(1, workers))
    finally:
        prog.close()
    return [r if r is not None else {"error": UNFINISHED} for r in results]


def suite_transport(interface: str | None = None, channel: str | None = None) -> tuple[str, str]:
    """The transport of the suite's runs: the given one or the default."""
    if interface is None:
        from bench.wire._bus import default_transport

        iface, chan, _ = default_transport()
        return iface, chan
    from bench._errors import InterfaceError
    from bench.wire._bus import default_channel

    chan2 = channel or default_channel(interface)
    if chan2 is None:
        raise InterfaceError(f"--interface {interface}: give --channel")
    return interface, chan2


def paper_jobs(
    runs_dir: Path,
    *,
    scenarios: Sequence[str] = SHIPPED,
    estimators: Sequence[str] | None = None,
    quick: bool = False,
    transport: tuple[str, str] | None = None,
    plants: Sequence[str] = ("ideal",),
) -> list[RunJob]:
    """One job per plant, shipped scenario and estimator it lists (``estimators`` filters)."""
    base_port = 40000 + 4 * random.Random(os.getpid()).randrange(3000)
    jobs: list[RunJob] = []
    for plant in plants:
        for name in scenarios:
            scn = plant_variant(load_scenario(name), plant)
            if quick:
                scn = quick_scenario(scn)
            # a plug-in no scenario lists runs on every scenario chosen
            extra = [
                e for e in estimators or () if e not in ESTIMATOR_NAMES and e not in scn.estimators
            ]
            for est in (*scn.estimators, *extra):
                if estimators is not None and est not in estimators:
                    continue
                tr: tuple[str, str, int | None] | None = None
                if transport is not None:
                    port = base_port + 4 * len(jobs) if transport[0] == "udp_multicast" else None
                    tr = (transport[0], transport[1], port)
                run_dir = runs_dir / run_subdir(plant, scn.name, est)
                jobs.append(RunJob(scn, est, run_dir, tr, plant))
    return jobs


def unmatched_estimators(scenarios: Sequence[str], estimators: Sequence[str]) -> str | None:
    """Which of ``estimators`` none of ``scenarios`` lists, and what they list (None: all listed)."""
    listed = {name: load_scenario(name).estimators for name in scenarios}
    missing = [
        e
        for e in estimators
        if e in ESTIMATOR_NAMES and not any(e in ests for ests in listed.values())
    ]
    if not missing:
        return None
    what = "; ".join(f"{name} lists {', '.join(ests)}" for name, ests in listed.items())
    return f"--estimators {', '.join(missing)}: not an estimator of the scenarios chosen ({what})"


def small_png(src: Path, width: int = PNG_WIDTH) -> bytes:
    """A PNG scaled to ``width`` pixels and reduced to a 64-colour palette, as bytes."""
    from PIL import Image

    with Image.open(src) as im:
        w, h = im.size
        im2 = im.convert("RGB")
        if w > width:
            im2 = im2.resize((width, max(1, round(h * width / w))), Image.Resampling.LANCZOS)
        im2 = im2.quantize(colors=64)
        buf = io.BytesIO()
        im2.save(buf, format="PNG", optimize=True)
        return buf.getvalue()


def export_run(job: RunJob, out_dir: Path, png: bytes | None = None) -> Path:
    """Copy a run's small files (metrics, metadata, and ``png``, its plot made small by the
    worker, :func:`small_png`) under ``out_dir``."""
    dst = out_dir / "runs" / run_subdir(job.plant, job.scenario.name, job.estimator)
    if dst.is_dir():  # an earlier run's files (--overwrite, --update): none of them is kept
        shutil.rmtree(dst)
    dst.mkdir(parents=True, exist_ok=True)
    for name in ("metrics.json", "meta.json"):
        if (job.run_dir / name).exists():
            shutil.copyfile(job.run_dir / name, dst / name)
    if png is not None:
        (dst / "run.png").write_bytes(png)
    return dst


def run_record(job: RunJob, res: dict[str, Any], out_dir: Path) -> dict[str, Any]:
    """The entry of ``summary.json`` for one run."""
    scn = job.scenario
    rec: dict[str, Any] = {
        "scenario": scn.name,
        "estimator": job.estimator,
        "plant": job.plant,
        "paper": scn.paper,
        "description": scn.description,
        "duration_s": scn.duration,
        "score_from_s": scn.score_from_s,
        "paper_result": dict(scn.paper_result),
        "transport": "in-process" if job.transport is None else f"{job.transport[0]} lockstep",
        "wall_s": res.get("wall_s", math.nan),
        "files": f"runs/{run_subdir(job.plant, scn.name, job.estimator)}",
    }
    if "error" in res:
        rec["error"] = res["error"]
        rec["metrics"] = {}
    else:
        m = res["metrics"]
        rec["metrics"] = {k: m[k] for k in SUMMARY_METRICS if k in m}
        # a hybrid estimator's per-band figures and hand-overs (bench.runs._metrics.band_metrics)
        rec["metrics"].update({k: v for k, v in m.items() if k.startswith(BAND_METRIC_PREFIXES)})
        extras = res.get("extras")
        rec.update(extras if extras is not None else run_extras(job.run_dir / "signals.csv", scn))
        if res.get("gains"):
            rec["gains"] = res["gains"]
    return rec


@dataclass(frozen=True, slots=True)
class SuiteOptions:
    """What ``bench suite paper`` runs and where it writes."""

    out_dir: Path
    runs_dir: Path
    scenarios: tuple[str, ...] = SHIPPED
    estimators: tuple[str, ...] | None = None
    plants: tuple[str, ...] = PLANTS
    quick: bool = False
    sweeps: tuple[str, ...] = ()
    sweep_quick: bool = False
    inprocess: bool = False
    workers: int = 2
    interface: str | None = None
    channel: str | None = None
    progress: bool = True
    #: ``bench suite paper --update``: the summary already in ``out_dir``, whose records
    #: of the runs not chosen now are kept (:func:`merge_update`)
    keep: dict[str, Any] | None = None


def run_key(rec: dict[str, Any]) -> tuple[str, str, str]:
    """What names a run in ``summary.json``: scenario, estimator, plant."""
    return (rec["scenario"], rec["estimator"], rec.get("plant", "ideal"))


def check_update(keep: dict[str, Any], opt: SuiteOptions, where: Path) -> None:
    """A suite is updated only by runs made as its own were (transport, ``--quick``), so
    that its records stay comparable; a :class:`BenchError` names the difference."""
    info = keep.get("suite") or {}
    was = info.get("transport")
    now = "in-process" if opt.inprocess else "a bus"
    if (was == "in-process") != opt.inprocess:
        raise BenchError(
            f"--update: {where}: its runs were made {'in-process' if was == 'in-process' else f'over {was}'}, "
            f"these would be made {now}; give the same transport ({'--inprocess' if was == 'in-process' else 'no --inprocess'})"
        )
    if bool(info.get("quick")) != opt.quick:
        raise BenchError(
            f"--update: {where}: suite.quick is {bool(info.get('quick'))}; give "
            f"{'--quick' if info.get('quick') else 'no --quick'} so the runs are cut alike"
        )


def merge_update(
    keep: dict[str, Any],
    records: list[dict[str, Any]],
    sweeps: dict[str, Any],
    cic: dict[str, Any],
    accel_ff: dict[str, dict[str, Any]],
    info: dict[str, Any],
) -> tuple[list[dict[str, Any]], dict[str, Any], dict[str, Any], dict[str, Any], dict[str, Any]]:
    """The kept summary with the parts run now in place of theirs (``--update``).

    A run's record replaces the kept one of the same scenario, estimator and
    plant in its place (a new one is appended); every other record is kept as
    it was.  A sweep, the CIC study of a plant and the ``accel_ff`` runs of a
    plant and scenario replace theirs likewise.  The suite information is
    the kept one, with this command and its runs added to ``updates``.
    """
    new = {run_key(r): r for r in records}
    runs = [new.pop(run_key(r), r) for r in keep.get("runs", [])]
    runs.extend(new.values())
    sw = {**keep.get("sweeps", {}), **sweeps}
    cc = {**keep.get("cic", {}), **cic}
    ff = {p: dict(v) for p, v in keep.get("accel_ff", {}).items()}
    for plant, per in accel_ff.items():
        ff.setdefault(plant, {}).update(per)
    kept_info = dict(keep.get("suite") or {})
    upd = {
        "command": info["command"],
        "runs": [list(run_key(r)) for r in records],
        "sweeps": list(sweeps),
        "wall_s": info["wall_s"],
    }
    kept_info["updates"] = [*kept_info.get("updates", []), upd]
    for k in ("interrupted", "finished"):
        if k in info:
            kept_info[k] = info[k]
    return runs, sw, cc, ff, kept_info


def run_suite(opt: SuiteOptions) -> dict[str, Any]:
    """Run the suite, write ``report.md``, ``summary.json`` and plots; return the summary.

    Each run's small files go to ``out_dir`` as it finishes.  Stopped by
    SIGINT/SIGTERM (under :func:`bench.studies._executors.catch_signals`),
    it writes ``summary.json`` and ``report.md`` of what finished, without the
    sweep plots, and the summary's ``suite.interrupted`` is set.
    """
    from bench.studies._executors import interrupted
    from bench.studies._report import build_summary, write_report
    from bench.studies._sweep import collect, plot_sweeps, sweep_jobs

    t0 = time.perf_counter()
    transport = None if opt.inprocess else suite_transport(opt.interface, opt.channel)
    workers = opt.workers
    note = ""
    if transport is not None and transport[0] != "udp_multicast" and workers > 1:
        workers = 1
        note = f"{transport[0]} {transport[1]} is shared by every run: runs one at a time"
        print(f"suite: {note}", file=sys.stderr)
    runs = paper_jobs(
        opt.runs_dir,
        scenarios=opt.scenarios,
        estimators=opt.estimators,
        quick=opt.quick,
        transport=transport,
        plants=opt.plants,
    )
    sweeps = sweep_jobs(opt.sweeps, quick=opt.sweep_quick) if opt.sweeps else []
    cic = cic_jobs(opt)
    ff = ff_jobs(opt)
    why = None if opt.estimators is None else unmatched_estimators(opt.scenarios, opt.estimators)
    if not (runs or sweeps):
        raise BenchError(
            f"{why or 'no scenario with an estimator and no sweep'}; nothing left to run"
        )
    if why:
        print(f"suite: {why}; skipped", file=sys.stderr)
    opt.out_dir.mkdir(parents=True, exist_ok=True)
    if opt.progress:
        where = "in-process" if transport is None else f"{transport[0]} {transport[1]}"
        print(
            f"suite: {len(runs)} runs ({where}, lockstep), {len(sweeps)} sweep points "
            f"(in-process), {workers} worker(s); full runs in {opt.runs_dir}",
            file=sys.stderr,
        )
    jobs: list[Job] = [*runs, *sweeps, *cic, *ff]
    finished: dict[int, dict[str, Any]] = {}  # id(run job) -> its summary record

    def on_done(job: Job, res: dict[str, Any]) -> None:
        # a run's small files and its record the moment it ends: kept whatever comes next
        if isinstance(job, RunJob):
            if "error" not in res:
                export_run(job, opt.out_dir, res.pop("png", None))
            elif opt.keep is not None:  # its record says the run failed: no older files beside it
                shutil.rmtree(
                    opt.out_dir / "runs" / run_subdir(job.plant, job.scenario.name, job.estimator),
                    ignore_errors=True,
                )
            finished[id(job)] = run_record(job, res, opt.out_dir)

    results = run_jobs(jobs, workers=workers, progress=opt.progress, on_done=on_done)
    stopped = interrupted()
    # interrupted: the runs and sweep points that finished, nothing invented for the others
    records = [finished[id(job)] for job in runs if id(job) in finished]
    done_sweeps = [
        (job, res)
        for job, res in zip(sweeps, results[len(runs) : len(runs) + len(sweeps)], strict=True)
        if res.get("error") != UNFINISHED
    ]
    n0 = len(runs) + len(sweeps)
    cic_summary = {
        job.plant: res
        for job, res in zip(cic, results[n0 : n0 + len(cic)], strict=True)
        if res.get("error") != UNFINISHED
    }
    ff_summary: dict[str, dict[str, Any]] = {}
    for fjob, res in zip(ff, results[n0 + len(cic) :], strict=True):
        if res.get("error") != UNFINISHED:
            ff_summary.setdefault(fjob.plant, {})[fjob.scenario] = res
    sweep_summary: dict[str, Any] = {}
    if done_sweeps:
        sweep_summary = collect(
            [j for j, _ in done_sweeps], [r for _, r in done_sweeps], quick=opt.sweep_quick
        )
        if not stopped:  # plots take seconds of matplotlib: not within the time a signal allows
            plot_sweeps(sweep_summary, opt.out_dir / "sweeps")
    info = {
        "command": " ".join(["bench", *sys.argv[1:]]) if sys.argv[0].endswith("bench") else "",
        "transport": "in-process" if transport is None else f"{transport[0]} {transport[1]}",
        "mode": "lockstep",
        "quick": opt.quick,
        "plants": list(opt.plants),
        "sweep_quick": opt.sweep_quick,
        "workers": workers,
        "wall_s": time.perf_counter() - t0,
        "note": note,
        "runs_dir": str(opt.runs_dir),
    }
    fin = {
        "runs": len(records),
        "runs_planned": len(runs),
        "sweep_points": len(done_sweeps),
        "sweep_points_planned": len(sweeps),
    }
    if stopped:
        info["interrupted"] = True
        info["finished"] = fin
    if opt.keep is not None:
        records, sweep_summary, cic_summary, ff_summary, info = merge_update(
            opt.keep, records, sweep_summary, cic_summary, ff_summary, info
        )
    summary = build_summary(records, sweep_summary, info, cic_summary, ff_summary)
    write_report(summary, opt.out_dir)
    if stopped:
        _mark_interrupted(opt.out_dir / "report.md", fin)
    return summary


def cic_jobs(opt: SuiteOptions) -> list[CicJob]:
    """The quadrature-signal study of Xue's CIC claim (:mod:`bench.studies._cic`), one job
    per plant, when the suite runs its scenario with both square-wave estimators (not in
    ``--quick``, whose runs are cut short)."""
    from bench.studies._cic import SCENARIO, WITH_CIC, WITHOUT_CIC

    if opt.quick or SCENARIO not in opt.scenarios:
        return []
    if opt.estimators is not None and not {WITH_CIC, WITHOUT_CIC} <= set(opt.estimators):
        return []
    return [CicJob(plant) for plant in opt.plants]


def ff_jobs(opt: SuiteOptions) -> list[AccelFfJob]:
    """Tables 6-8 with tt-dq's ``accel_ff`` (:mod:`bench.studies._accel_ff`) on the ideal and
    the drive plant, when the suite runs those scenarios with tt-dq (not in ``--quick``)."""
    from bench.studies._accel_ff import ESTIMATOR, SCENARIOS, accel_ff_jobs

    if opt.quick or not set(SCENARIOS) <= set(opt.scenarios):
        return []
    if opt.estimators is not None and ESTIMATOR not in opt.estimators:
        return []
    return accel_ff_jobs(opt.runs_dir, opt.plants)


def _mark_interrupted(report: Path, fin: dict[str, int]) -> None:
    """Say at the top of ``report.md`` that it holds only the part that finished."""
    text = report.read_text(encoding="utf-8")
    head, sep, rest = text.partition("\n\n")
    line = (
        f"**Interrupted: {fin['runs']} of {fin['runs_planned']} runs and {fin['sweep_points']} "
        f"of {fin['sweep_points_planned']} sweep points finished; this report holds only "
        "those (no sweep plots).**"
    )
    report.write_text(f"{head}{sep}{line}\n\n{rest}", encoding="utf-8")
