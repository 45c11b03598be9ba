"""``bench perf``: how fast the bench does its job, measured in one run.

Sections, each figure a median of several repeats inside this one process
(timings on a shared machine are noisy: compare ratios within a run, never
single absolute numbers across runs):

1. in-process (no CAN), on both engines in the same run (``python``: the
   plant and the controller in Python; ``compiled``: both in C,
   :mod:`plant_rt._engine` and :mod:`controller._engine`): the closed loop
   plant + tt-dq controller at 10 kHz with the scenario's average-model plant
   and with the switching plant of the ``drive`` profile, the plant alone per
   period, the controller alone per step, and the plant node's computation
   per period (the plant step and its frames encoded); every estimator's loop
   on the default engine, with the controller engine it ran on;
2. two processes in lockstep over the CAN transport: periods per second and
   the round trip sample -> duty on the bus;
3. real-time mode at 1, 4 and 10 kHz, with normal scheduling and under
   ``SCHED_FIFO`` (``--rt-priority``): late periods, the host stalls apart
   (number, total, longest, periods skipped; :class:`bench.nodes._clock.RealTimeClock`),
   wake-up lateness and the plant's computation per period;
4. the codec (the hot path compiled from the DBC and cantools' own) and
   ``bench analyze`` on a capture of at least 200,000 frames, written once
   with python-can from a scenario run in-process;
5. the bus-load table: the highest PWM rate the shipped DBC fits on real buses;
6. ``make demo`` as its user runs it (:func:`demo_section`): the whole command's wall
   time against issue 29's target, split into the stepping loop, the nodes' start and
   stop, and the rest (imports, checks, scoring, the figure, the files).

Every figure goes to ``perf.json``; :data:`TARGETS` (issue 14) are judged in
``verdicts``.  ``docs/BENCHMARKS.md`` is rendered from ``perf.json`` alone
(:func:`render_benchmarks`, no figure typed by hand), and so is the block of
the README's Performance section (:func:`render_readme_block`);
``tests/test_perf.py`` checks that the committed files agree.
"""

from __future__ import annotations

import cProfile
import functools
import io
import json
import math
import os
import platform
import pstats
import statistics
import tempfile
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from bench._errors import BenchError

#: SCHED_FIFO priority of the plant in the real-time section (controller one below).
RT_PRIORITY = 80
#: Fewest frames of the capture ``bench analyze`` is timed on (full run).
ANALYZE_MIN_FRAMES = 200_000
#: PWM rate of the 10 kHz figures.
F_10KHZ = 10e3
#: What ran in the ``lockstep_native`` and ``realtime_native`` figures.
NATIVE_NOTE = (
    "the native pair (--engine native: the plant node's and the controller node's loops "
    "in C, bench/nodes/native), sensored"
)
#: Speed reference of the in-process loops (rpm), and the periods run before timing.
SPEED_REF_RPM = 100.0
SETTLE_STEPS = 2000


@dataclass(frozen=True, slots=True)
class Target:
    """One target of issue 14, judged on one figure of ``perf.json``.

    Parameters
    ----------
    key : str
        Name in ``perf.json``'s ``targets`` and ``verdicts``.
    figure : str
        What is measured (one table cell).
    at_least : bool
        True: the figure must be at least ``value``; False: at most.
    value : float
        The target, in ``unit``.
    unit : str
        Unit of the figure and the target as printed.
    """

    key: str
    figure: str
    at_least: bool
    value: float
    unit: str


#: The targets of issue 14, in its order.
TARGET_LIST = (
    Target(
        "inprocess_rtf_10khz_tt_dq",
        "in-process closed loop, tt-dq, 10 kHz",
        True,
        30.0,
        "x real time",
    ),
    Target(
        "inprocess_compiled_over_python_tt_dq",
        "the same, the loop in C (the in-process native pair) against the loop in Python, "
        "both on the C cores",
        True,
        10.0,
        "x",
    ),
    Target(
        "inprocess_native_us_per_step_tt_dq",
        "in-process native pair (plant and controller stepped in C, frames in memory), "
        "tt-dq, 10 kHz, per step",
        False,
        0.8,
        "us",
    ),
    Target(
        "switching_rtf_10khz",
        "the switching inverter (drive profile), in-process, tt-dq, 10 kHz",
        True,
        10.0,
        "x real time",
    ),
    Target(
        "lockstep_periods_per_s",
        "two processes in lockstep over the default transport",
        True,
        4000.0,
        "periods/s",
    ),
    Target(
        "plant_node_us_p50_10khz",
        "plant node computation per period at 10 kHz, p50 (real-time run)",
        False,
        40.0,
        "us",
    ),
    Target(
        "realtime_missed_pct_4khz_fifo",
        "real time with `--rt-priority`, 4 kHz: periods missed",
        False,
        1.0,
        "%",
    ),
    Target(
        "realtime_missed_pct_10khz_fifo",
        "real time with `--rt-priority`, 10 kHz: periods missed",
        False,
        5.0,
        "%",
    ),
    Target(
        "realtime_missed_pct_1khz_normal",
        "real time, 1 kHz, normal scheduling: periods missed",
        False,
        0.1,
        "%",
    ),
    Target(
        "analyze_frames_per_s",
        f"`bench analyze` on a capture of at least {ANALYZE_MIN_FRAMES:,} frames: "
        "decoding it into the per-period table",
        True,
        1e6,
        "frames/s",
    ),
    Target(
        "analyze_end_to_end_frames_per_s",
        "the same, the whole command: reading the file, decoding, metrics, signals.csv (no plot)",
        True,
        1e6,
        "frames/s",
    ),
)
TARGETS = {t.key: t.value for t in TARGET_LIST}


def _median_of(fn: Callable[[], float], repeats: int) -> float:
    return statistics.median(fn() for _ in range(repeats))


def _medians_interleaved(fns: Mapping[str, Callable[[], float]], repeats: int) -> dict[str, float]:
    """The median of ``repeats`` calls of each function, the calls taken in turn.

    Taking them in turn (a, b, a, b, ...) exposes each to the same load of the
    shared machine, so their ratio is fairer than from two blocks of runs.
    """
    got: dict[str, list[float]] = {k: [] for k in fns}
    for _ in range(repeats):
        for k, fn in fns.items():
            got[k].append(fn())
    return {k: statistics.median(v) for k, v in got.items()}


def _quantile(xs: list[float], q: float) -> float:
    """``q``-quantile of a sorted, non-empty list (nearest rank)."""
    return xs[min(len(xs) - 1, int(q * (len(xs) - 1) + 0.5))]


def engines() -> tuple[str, ...]:
    """The engines this machine has: ``python``, and ``compiled`` when the plant's is built
    (the controller's follows: compiled where it is built and covers the estimator)."""
    from plant_rt import compiled_engine_missing

    return ("python",) if compiled_engine_missing() else ("python", "compiled")


# -- 1. in-process ------------------------------------------------------------------------


def _on_xue(estimator: str) -> bool:
    """The estimator's loop runs on Xue's scenario (1 kHz): a square-wave estimator without a
    speed band (the hybrids run on wen-5.1)."""
    from controller import estimator_spec

    s = estimator_spec(estimator)
    return s.family == "square" and not s.speed_band


def _loop_scenario(estimator: str, profile: str = "ideal") -> Any:
    from bench.scenarios._schema import load_scenario

    scn = load_scenario("xue-fig13" if _on_xue(estimator) else "wen-5.1")
    return scn if profile == scn.plant_profile else replace(scn, plant_profile=profile)


Duty = tuple[float, float, float, bool]


def _closed_loop(
    estimator: str, engine: str, profile: str
) -> tuple[Callable[[int, bool], None], list[Any], list[Duty]]:
    """``run(n, record)``: a fresh plant and controller stepped ``n`` periods in a closed loop.

    With ``record``, each period's measurement and applied duty are appended
    to the two lists returned (the plant-alone and controller-alone figures).
    """
    from bench.scenarios._setup import build_controller, build_plant, needs_truth
    from controller import Measurement

    scn = _loop_scenario(estimator, profile)
    plant = build_plant(scn, engine)
    ctrl = build_controller(scn, estimator, engine)
    ctrl.set_enable(True)
    ctrl.set_speed_ref(SPEED_REF_RPM * 2.0 * math.pi / 60.0)
    truth = needs_truth(estimator)
    meas: list[Any] = []
    duties: list[Duty] = []
    d: Duty = (0.5, 0.5, 0.5, False)

    def run(n: int, record: bool) -> None:
        nonlocal d
        for _ in range(n):
            s = plant.sample()
            tr = plant.truth() if truth else None
            m = Measurement(
                s.k,
                s.i_a,
                s.i_b,
                s.i_c,
                s.u_dc,
                tr.theta_e if tr else None,
                tr.w_e if tr else None,
            )
            o = ctrl.step(m)
            plant.step(*d)
            if record:
                meas.append(m)
                duties.append(d)
            d = (o.d_a, o.d_b, o.d_c, o.enable)

    return run, meas, duties


def inprocess_loop(
    estimator: str, n_steps: int, engine: str = "auto", profile: str = "ideal"
) -> float:
    """Seconds per step of plant + controller in one process, no CAN.

    The scenario's plant (``wen-5.1``, or ``xue-fig13`` for the square-wave
    estimators) with plant profile ``profile`` on ``engine``; the controller
    runs at :data:`SPEED_REF_RPM`; the first :data:`SETTLE_STEPS` periods (the
    start-up) are not timed.
    """
    run, _, _ = _closed_loop(estimator, engine, profile)
    run(SETTLE_STEPS, False)
    t0 = time.perf_counter()
    run(n_steps, False)
    return (time.perf_counter() - t0) / n_steps


def plant_and_controller_alone(profile: str, n_steps: int, repeats: int) -> dict[str, float]:
    """Seconds per period of the plant alone (each engine) and of the tt-dq controller alone
    (``controller_compiled``: its one engine, the C core).

    One closed loop (``wen-5.1``'s motor at 10 kHz, tt-dq) is recorded once;
    the plant alone is a fresh plant fed the recorded duties (``sample()`` and
    ``step()``), the controller alone a fresh controller fed the recorded
    measurements.  Both engines give the same trace bit for bit, so each does
    exactly its work inside the loop, without the other; the start-up's
    periods are replayed too but not timed.  The controller has one engine
    whatever the name (:mod:`controller._engine`): timing it under another name
    would compare the core with itself, and its Python step is the tests' oracle
    (``tests/oracle/``), not a product the bench runs, so it has no second figure.
    """
    from bench.scenarios._setup import build_controller, build_plant

    eng = engines()
    run, meas, duties = _closed_loop("tt-dq", eng[-1], profile)
    run(SETTLE_STEPS + n_steps, True)
    scn = _loop_scenario("tt-dq", profile)

    def plant_alone(e: str) -> float:
        p = build_plant(scn, e)
        for d in duties[:SETTLE_STEPS]:
            p.sample()
            p.step(*d)
        t0 = time.perf_counter()
        for d in duties[SETTLE_STEPS:]:
            p.sample()
            p.step(*d)
        return (time.perf_counter() - t0) / n_steps

    def ctrl_alone(e: str) -> float:
        ctrl = build_controller(scn, "tt-dq", e)
        ctrl.set_enable(True)
        ctrl.set_speed_ref(SPEED_REF_RPM * 2.0 * math.pi / 60.0)
        for m in meas[:SETTLE_STEPS]:
            ctrl.step(m)
        t0 = time.perf_counter()
        for m in meas[SETTLE_STEPS:]:
            ctrl.step(m)
        return (time.perf_counter() - t0) / n_steps

    fns = {f"plant_{e}": functools.partial(plant_alone, e) for e in eng}
    fns["controller_compiled"] = functools.partial(ctrl_alone, "compiled")
    return _medians_interleaved(fns, repeats)


def plant_node_compute(engine: str, periods: int, repeats: int) -> dict[str, float]:
    """The plant node's computation per period in-process (s): p50 and p99, medians of runs.

    ``wen-5.1`` with tt-dq through :func:`bench.nodes._loops.run_inprocess`:
    the plant's step and its frames encoded, as ``bench rtcheck`` measures it;
    the first tenth of the periods (the start-up) is left out.
    """
    from bench.nodes._loops import run_inprocess
    from bench.scenarios._schema import load_scenario
    from bench.scenarios._setup import sample_period
    from bench.wire._codec import Codec

    scn = load_scenario("wen-5.1")
    scn = scn.with_overrides(duration=periods * sample_period(scn))
    codec = Codec()
    p50: list[float] = []
    p99: list[float] = []
    for _ in range(repeats):
        times: list[float] = []
        run_inprocess(scn, "tt-dq", codec, plant_times=times, engine=engine)
        times = sorted(times[len(times) // 10 :])
        p50.append(_quantile(times, 0.5))
        p99.append(_quantile(times, 0.99))
    return {"p50": statistics.median(p50), "p99": statistics.median(p99)}


def profile_inprocess(estimator: str, n_steps: int, top: int = 8) -> list[str]:
    """The top entries (by own time) of a profile of the in-process loop (default engine).

    Only the stepping is profiled (after the start-up), not building the plant
    and the controller.
    """
    run, _, _ = _closed_loop(estimator, "auto", "ideal")
    run(SETTLE_STEPS, False)
    pr = cProfile.Profile()
    pr.enable()
    run(n_steps, False)
    pr.disable()
    buf = io.StringIO()
    st = pstats.Stats(pr, stream=buf)
    st.sort_stats("tottime").print_stats(top)
    root = str(Path(__file__).resolve().parent.parent.parent) + os.sep
    lines = [ln.rstrip().replace(root, "") for ln in buf.getvalue().splitlines() if ln.strip()]
    start = next((i for i, ln in enumerate(lines) if ln.lstrip().startswith("ncalls")), 0)
    return lines[start : start + top + 1]


def _per_engine(sec: dict[str, float], f_sw: float) -> dict[str, Any]:
    """Seconds per step on each engine -> us per step, real-time factor, compiled/python."""
    out: dict[str, Any] = {
        e: {"us_per_step": 1e6 * s, "rtf": 1.0 / (s * f_sw)} for e, s in sec.items()
    }
    if "compiled" in sec:
        out["compiled_over_python"] = sec["python"] / sec["compiled"]
    return out


def inprocess_section(quick: bool, repeats: int, n_steps: int) -> dict[str, Any]:
    """Section 1: every estimator on the default engine, and tt-dq on both engines."""
    from bench.scenarios._setup import build_controller
    from controller._registry import ESTIMATOR_NAMES
    from plant_rt import resolve_engine

    eng = engines()
    inproc: dict[str, Any] = {"engine_default": resolve_engine("auto")}
    for est in ESTIMATOR_NAMES:
        sec = _median_of(functools.partial(inprocess_loop, est, n_steps), repeats)
        f = 1e3 if _on_xue(est) else F_10KHZ
        ctrl_engine = build_controller(_loop_scenario(est), est, "auto").engine
        inproc[est] = {
            "us_per_step": 1e6 * sec,
            "f_sw": f,
            "rtf": 1.0 / (sec * f),
            "controller_engine": ctrl_engine,
        }
    inproc["rtf_10khz_tt_dq"] = 1.0 / (inproc["tt-dq"]["us_per_step"] * 1e-6 * F_10KHZ)
    for key, profile in (("tt_dq_10khz", "ideal"), ("switching_10khz", "drive")):
        fns = {e: functools.partial(inprocess_loop, "tt-dq", n_steps, e, profile) for e in eng}
        inproc[key] = _per_engine(_medians_interleaved(fns, repeats), F_10KHZ)
    alone: dict[str, Any] = {}
    for key, profile in (("average", "ideal"), ("switching", "drive")):
        a = plant_and_controller_alone(profile, n_steps // 2, repeats)
        row: dict[str, Any] = {e: 1e6 * a[f"plant_{e}"] for e in eng}
        if "compiled" in eng:
            row["compiled_over_python"] = a["plant_python"] / a["plant_compiled"]
        alone[key] = row
        if profile == "ideal":
            # the controller's one engine, the core (plant_and_controller_alone)
            alone["controller_tt_dq"] = {"compiled": 1e6 * a["controller_compiled"]}
    inproc["alone_us_per_period"] = alone
    periods = 1000 if quick else 4000
    node = {}
    for e in eng:
        r = plant_node_compute(e, periods, repeats)
        node[e] = {"us_p50": 1e6 * r["p50"], "us_p99": 1e6 * r["p99"]}
    inproc["plant_node_10khz"] = node
    return inproc


def inprocess_native_section(n_steps: int, repeats: int) -> dict[str, Any]:
    """The in-process native pair (:func:`bench.nodes.native._pair.run_pair`): ``wen-5.1``
    with tt-dq at 10 kHz, :data:`SETTLE_STEPS` + ``n_steps`` periods, as
    :func:`bench.nodes._loops.run_inprocess` runs it by default.

    ``us_per_step_tt_dq``: the time inside the C calls per period (the start-up's
    periods included: one call covers many periods), median of ``repeats`` runs;
    ``wall_us_per_step_tt_dq``: the whole loop's per period, with the returns to Python
    (the record buffer full, the end; the bench commands' schedule made before the
    run) and the frames handed over as one
    :class:`~bench.wire._frames.FrameArray` (no :class:`can.Message` made); its split,
    from the same runs: ``frames_us_per_step`` the frames' rows written from the
    record buffer, ``returns_us_per_step`` the rest outside C (the commands' schedule,
    the returns' Python, the nodes merged); ``returns_per_1000_steps``; ``plant_us`` and
    ``controller_us``: each unit's share per period, from one more run with the units
    timed (two clock reads more per frame and per period);
    ``python_loop_wall_us_per_step_tt_dq``: the Python loop's whole run per period on
    the same scenario (one run, the same cores).
    """
    from bench.nodes._loops import (
        INPROCESS_LEAD,
        command_frames,
        inprocess_native_unavailable,
        make_controller_node,
        make_plant_node,
        run_inprocess,
    )
    from bench.nodes.native._pair import PairRun, run_pair
    from bench.scenarios._schema import load_scenario
    from bench.scenarios._setup import sample_period
    from bench.wire._codec import Codec

    scn = load_scenario("wen-5.1")
    scn = scn.with_overrides(duration=(SETTLE_STEPS + n_steps) * sample_period(scn))
    codec = Codec()
    cmds = command_frames(scn, codec)

    def one(timed: bool) -> PairRun:
        pn = make_plant_node(scn, codec)
        cn = make_controller_node(scn, "tt-dq", codec)
        why = inprocess_native_unavailable(pn, cn, latency=False)
        if why is not None:
            raise BenchError(f"bench perf: in-process native pair: {why}")
        m = PairRun(timed=timed)
        run_pair(pn, cn, cmds, INPROCESS_LEAD, measure=m)
        return m

    runs = [one(False) for _ in range(repeats)]
    timed = one(True)
    t0 = time.perf_counter()
    run_inprocess(scn, "tt-dq", codec, loop="python")
    py_wall = time.perf_counter() - t0
    steps = runs[0].steps
    return {
        "us_per_step_tt_dq": statistics.median(1e6 * r.c_seconds / r.steps for r in runs),
        "wall_us_per_step_tt_dq": statistics.median(1e6 * r.wall_seconds / r.steps for r in runs),
        "frames_us_per_step": statistics.median(1e6 * r.frames_seconds / r.steps for r in runs),
        "returns_us_per_step": statistics.median(
            1e6 * (r.wall_seconds - r.c_seconds - r.frames_seconds) / r.steps for r in runs
        ),
        "returns_per_1000_steps": 1e3 * runs[0].calls / steps,
        "plant_us": 1e6 * timed.plant_seconds / timed.steps,
        "controller_us": 1e6 * timed.ctl_seconds / timed.steps,
        "python_loop_wall_us_per_step_tt_dq": 1e6 * py_wall / steps,
        "steps": float(steps),
    }


# -- 2. lockstep ----------------------------------------------------------------------------


def lockstep_two_process(
    duration: float, out: Path, plant_engine: str = "compiled"
) -> dict[str, Any]:
    """Two processes in lockstep over the default transport (sensored, 10 kHz).

    ``plant_engine``: the plant process's ``--engine``: ``compiled`` the Python
    node (the ``lockstep`` figures), ``native`` its loop in C (``lockstep_native``);
    the controller is the bench's Python node on its compiled core in both.

    ``steps_per_s``: periods per second of the plant's stepping loop (from the
    start command to the last period); ``wall_steps_per_s``: the same over the
    whole ``bench run``, the processes' start and stop included.  ``rtt_us_*``:
    the round trip from a period's sample to its duty, as the recorder saw them.
    """
    import can
    import numpy as np

    from bench.runs._run import run_scenario
    from bench.scenarios._schema import Profile, load_scenario
    from bench.wire._bus import BusSpec, default_transport
    from bench.wire._codec import Codec

    iface, chan, _ = default_transport()
    port = 47000 + 2 * (os.getpid() % 1000) if iface == "udp_multicast" else None
    scn = load_scenario("wen-5.1")
    scn = replace(
        scn, duration=duration, score_from_s=0.0, speed_rpm=Profile(((0.0, 0.0), (0.05, 100.0)))
    )
    res = run_scenario(
        scn,
        "sensored",
        spec=BusSpec(iface, chan, port),
        out_dir=out,
        progress=False,
        node_args={"plant": ["--engine", plant_engine], "controller": []},
    )
    m = res.metrics
    codec = Codec()
    sid, did = codec.frame_id("PhaseSamples"), codec.frame_id("PwmDuty")
    m_step = 1 << codec.step_bits("PwmDuty")
    t_s: dict[int, float] = {}
    rtt: list[float] = []
    for f in can.LogReader(str(res.capture)):
        if f.arbitration_id not in (sid, did):
            continue
        d = codec.decode(f)
        if d is None or d.reason is not None:
            continue
        if f.arbitration_id == sid:
            t_s.setdefault(int(d.signals["step"]), f.timestamp)
        else:
            k = (int(d.signals["step"]) - 1) % m_step
            if k in t_s:
                rtt.append(1e6 * (f.timestamp - t_s.pop(k)))
    arr = np.array(rtt) if rtt else np.array([math.nan])
    plant_r = res.meta.get("node_reports", {}).get("plant", {}) or {}
    loop_s = float(plant_r.get("loop_s") or m["wall_s"])
    steps_per_s = m["steps"] / loop_s
    return {
        "transport": f"{iface}",
        "engine": str(res.meta.get("engine") or "?"),
        "node_engines": dict(res.meta.get("node_engines") or {}),
        "steps_per_s": steps_per_s,
        "wall_steps_per_s": m["steps"] / m["wall_s"],
        "rtf_10khz": steps_per_s / F_10KHZ,
        "rtt_us_p50": float(np.percentile(arr, 50)),
        "rtt_us_p99": float(np.percentile(arr, 99)),
        "rtt_us_max": float(np.max(arr)),
    }


# -- 3. real time ---------------------------------------------------------------------------


def late_figures(computed: int, late: int, stalls: int, skipped: int) -> dict[str, float]:
    """A real-time run's late periods, in percent, from the plant clock's counters.

    ``computed`` periods ran, ``late`` of them started after their deadline
    (``overruns``, the wake-ups that ended a stall included), ``stalls`` host
    stalls resynchronised the clock and skipped ``skipped`` periods.

    - ``overrun_pct``: late periods of those computed;
    - ``missed_pct``: late and skipped periods of those scheduled
      (``computed + skipped``): every period not computed on time;
    - ``late_outside_stalls_pct``: late periods other than the wake-ups that
      ended a stall, of those computed: the bench's own lateness.
    """
    n = max(1, computed)
    return {
        "overrun_pct": 100.0 * late / n,
        "missed_pct": 100.0 * (late + skipped) / (n + skipped),
        "late_outside_stalls_pct": 100.0 * max(0, late - stalls) / n,
        "host_stalls": float(stalls),
        "periods_skipped": float(skipped),
    }


def realtime_run(
    f_sw: float,
    duration: float,
    out: Path,
    priority: int | None = None,
    plant_engine: str = "compiled",
) -> dict[str, Any]:
    """The plant on its wall clock at ``f_sw`` (sensored controller, default transport).

    ``plant_engine`` as for :func:`lockstep_two_process` (``realtime_native``: ``native``).

    ``priority``: run both nodes under ``SCHED_FIFO`` (``--rt-priority``);
    the result's ``policy`` says what the system granted.  ``overrun_pct``:
    periods that started late, of the periods computed; ``missed_pct``: those
    and the periods skipped by the clock's resynchronisations after host
    stalls, of the periods scheduled (every period not computed on time);
    ``late_outside_stalls_pct``: the late periods other than the wake-ups
    that ended a stall, of the periods computed.
    """
    from bench.runs._metrics import late_duty_fraction, plant_periods
    from bench.runs._run import run_scenario
    from bench.scenarios._schema import Profile, load_scenario
    from bench.wire._bus import BusSpec, default_transport

    iface, chan, _ = default_transport()
    port = 47500 + 2 * (os.getpid() % 1000) if iface == "udp_multicast" else None
    scn = load_scenario("wen-5.1")
    scn = replace(
        scn,
        f_sw=f_sw,
        duration=duration,
        score_from_s=0.0,
        speed_rpm=Profile(((0.0, 0.0), (0.05, 100.0))),
    )
    res = run_scenario(
        scn,
        "sensored",
        spec=BusSpec(iface, chan, port),
        out_dir=out,
        mode="realtime",
        progress=False,
        node_args={"plant": ["--engine", plant_engine], "controller": []}
        if priority is None
        else {
            "plant": ["--engine", plant_engine, "--rt-priority", str(priority)],
            "controller": ["--rt-priority", str(max(1, priority - 1))],
        },
    )
    m = res.metrics
    plant_r = res.meta.get("node_reports", {}).get("plant", {}) or {}
    # periods the plant ran (the table may miss a few steps whose telemetry never came)
    n = plant_periods(m)
    jit = m.get("jitter_us") or {}
    return {
        "f_sw": f_sw,
        "engine": str(res.meta.get("engine") or "?"),
        "node_engines": dict(res.meta.get("node_engines") or {}),
        "steps": float(n),
        **late_figures(
            n,
            int(m["deadline_misses"]),
            int(m.get("host_stalls", 0)),
            int(m.get("periods_skipped", 0)),
        ),
        "late_duty_pct": 100.0 * late_duty_fraction(m),
        "host_stall_ms_total": float(m.get("host_stall_ms_total", 0.0)),
        "host_stall_ms_max": float(m.get("host_stall_ms_max", 0.0)),
        "jitter_us_median": float(jit.get("median", math.nan)),
        "jitter_us_p99": float(jit.get("p99", math.nan)),
        "jitter_us_max": float(jit.get("max", math.nan)),
        "busy_us_median": float(jit.get("busy_median", math.nan)),
        "busy_us_p99": float(jit.get("busy_p99", math.nan)),
        # the native loop's busy time split (nan for the Python node): sending the
        # instant's frames, draining the socket, the step and the next frames' encoding
        "send_us_median": float(jit.get("send_median", math.nan)),
        "recv_us_median": float(jit.get("recv_median", math.nan)),
        "step_us_median": float(jit.get("step_median", math.nan)),
        "policy": str((plant_r.get("rt") or {}).get("policy", "normal")),
        # frames the recorder's socket dropped (udp_multicast: the kernel's count); -1:
        # the transport does not say
        "recorder_frames_lost": float(
            -1 if res.meta.get("recorder_frames_lost") is None else res.meta["recorder_frames_lost"]
        ),
        "recorder_engine": str((res.meta.get("recorder") or {}).get("engine", "python")),
    }


#: The figures a run scores that :func:`sensorless_realtime_score` compares.
SCORE_KEYS = ("theta_err_rms_deg", "theta_err_abs_max_deg", "theta_err_mean_deg")


def score_tolerance_deg(scn: Any) -> float:
    """How far a real-time run may score from the lockstep run and still score like it
    (deg electrical): the angle the rotor turns in one PWM period at the scenario's top
    speed.  Why: with every duty on time a real-time run applies the lockstep run's
    duties to the same plant, so the two differ only through late duties, and a duty one
    period late shifts the loop by that angle; a run that scores within it is the
    lockstep result on the drive's own clock, one that does not was changed by the late
    periods (``late_duty_pct`` says how many)."""
    from bench.scenarios._setup import get_preset, sample_period

    top_rpm = max(abs(v) for _, v in scn.speed_rpm.points)
    w_e = top_rpm * 2.0 * math.pi / 60.0 * get_preset(scn).motor.n_p
    return math.degrees(w_e * sample_period(scn))


#: Real-time runs of :func:`sensorless_realtime_score` (one with ``--quick``): the figures are
#: those of the run of median rms (on this shared machine one run's rms moved from 0.48 to
#: 2.45 deg between runs of the same code, by its late periods; the lockstep run is
#: deterministic and runs once).
SCORE_RUNS = 3


def sensorless_realtime_score(
    out: Path,
    priority: int | None = RT_PRIORITY,
    duration: float | None = None,
    realtime_runs: int = SCORE_RUNS,
) -> dict[str, Any]:
    """wen-5.1 with tt-dq at 10 kHz (the paper's rate), whole (or its first ``duration``
    seconds, ``--quick``: 1.2 s, scored from 1 s at 100 rpm), on the native pair: in real
    time with ``--rt-priority`` and in lockstep over the default transport; each run's
    position-error figures, the real-time run's late duties, and whether it scores like
    the lockstep run within :func:`score_tolerance_deg` with the angle kept
    (``realtime_native_score``; issue 29).

    The real-time run is made ``realtime_runs`` times; ``realtime`` holds the one of
    median rms (a failed run counts as the worst), ``realtime_rms_runs`` every run's rms
    (NaN: failed) and ``realtime_runs_within`` how many scored like the lockstep run."""
    from bench.runs._metrics import late_duty_fraction
    from bench.runs._run import run_scenario
    from bench.scenarios._schema import load_scenario
    from bench.scenarios._setup import sample_period
    from bench.wire._bus import BusSpec, default_transport

    iface, chan, _ = default_transport()
    scn = load_scenario("wen-5.1")
    if duration is not None:
        scn = replace(scn, duration=duration)
    runs: dict[str, dict[str, Any]] = {}
    rt_runs: list[dict[str, Any]] = []
    modes = ["lockstep"] + ["realtime"] * max(1, realtime_runs)
    for i, mode in enumerate(modes):
        port = (
            48000 + 4 * (os.getpid() % 1000) + 2 * min(i, 1) if iface == "udp_multicast" else None
        )
        rt = [] if priority is None or mode == "lockstep" else ["--rt-priority", str(priority)]
        try:
            res = run_scenario(
                scn,
                "tt-dq",
                spec=BusSpec(iface, chan, port),
                out_dir=out / (mode if i == 0 else f"{mode}{i}"),
                mode=mode,
                progress=False,
                node_args={
                    "plant": ["--engine", "native", *rt],
                    "controller": ["--engine", "native", *rt],
                },
            )
        except BenchError as e:
            if mode == "lockstep":
                raise
            # a real-time run that failed on this host (a node that missed its stop and was
            # killed, a trip before anything was scored) is this host's result: kept, said
            rt_runs.append(_failed_score_run(str(e)))
            continue
        m = res.metrics
        row = {
            **{k: math.nan if m.get(k) is None else float(m[k]) for k in SCORE_KEYS},
            "lock_lost": bool(m.get("lock_lost")),
            "late_duty_pct": 100.0 * late_duty_fraction(m),
            # bench commands the controller held only after their step: set-points applied
            # later than in lockstep, a run that differs with no late duty; and the rows
            # scored (the same window in both modes)
            "late_commands": float(
                ((res.meta.get("node_reports") or {}).get("controller") or {}).get(
                    "late_commands", 0
                )
            ),
            "commands_sent": float((res.meta.get("commands") or {}).get("commands_sent", 0)),
            "scored_steps": float(m.get("scored_steps", 0)),
            "host_stalls": float(m.get("host_stalls", 0)),
            "host_stall_ms_total": float(m.get("host_stall_ms_total", 0.0)),
            "plant_fault": str(m.get("plant_fault") or "none"),
            # -1: the transport does not say
            "recorder_frames_lost": float(
                -1
                if res.meta.get("recorder_frames_lost") is None
                else res.meta["recorder_frames_lost"]
            ),
            "node_engines": dict(res.meta.get("node_engines") or {}),
            # which recorder read the bus (native: bench/nodes/native/bn_rec.c, or python)
            "recorder_engine": str((res.meta.get("recorder") or {}).get("engine", "python")),
        }
        if mode == "lockstep":
            runs[mode] = row
        else:
            rt_runs.append(row)
    tol = score_tolerance_deg(scn)
    ref = runs["lockstep"]["theta_err_rms_deg"]
    runs["realtime"], n_within = median_score_run(rt_runs, ref, tol)
    diff = abs(runs["realtime"]["theta_err_rms_deg"] - ref)
    return {
        "scenario": "wen-5.1",
        "estimator": "tt-dq",
        "duration_s": float(scn.duration),
        "f_sw": 1.0 / sample_period(scn),
        "tolerance_deg": tol,
        "rms_diff_deg": diff,
        "scores_like_lockstep": scores_like(runs["realtime"], ref, tol),
        "realtime_rms_runs": [float(r["theta_err_rms_deg"]) for r in rt_runs],
        "realtime_runs_within": n_within,
        **runs,
    }


def scores_like(run: dict[str, Any], ref_rms: float, tol: float) -> bool:
    """Whether a real-time score run scores like the lockstep run of rms ``ref_rms``:
    within ``tol`` of it with the angle kept (a failed run, NaN, does not)."""
    return bool(abs(run["theta_err_rms_deg"] - ref_rms) <= tol and not run["lock_lost"])


def median_score_run(
    runs: list[dict[str, Any]], ref_rms: float, tol: float
) -> tuple[dict[str, Any], int]:
    """The real-time score run of median rms (a failed run or a lost angle counts as the
    worst), and how many of ``runs`` score like the lockstep run (:func:`scores_like`)."""

    def rank(r: dict[str, Any]) -> float:
        v = float(r["theta_err_rms_deg"])
        return math.inf if math.isnan(v) or r["lock_lost"] else v

    ranked = sorted(runs, key=rank)
    return ranked[len(ranked) // 2], sum(scores_like(r, ref_rms, tol) for r in runs)


def _failed_score_run(error: str) -> dict[str, Any]:
    """The real-time score run's figures when it failed: the bench's line, nothing scored."""
    return {
        **{k: math.nan for k in SCORE_KEYS},
        "lock_lost": True,
        "error": error,
        "node_engines": {},
    }


def score_lines(sc: dict[str, Any] | None) -> list[str]:
    """The sentence of docs/REALTIME.md on :func:`sensorless_realtime_score` (none for a
    ``perf.json`` written before it was measured)."""
    if not sc:
        return []
    rt, ls = sc["realtime"], sc["lockstep"]
    if "error" in rt:
        return [
            "",
            f"A sensorless run on the drive's clock against the same run in lockstep "
            f"(`realtime_native_score`): {sc['scenario']} with {sc['estimator']} at "
            f"{sc['f_sw'] / 1e3:g} kHz, both nodes native, `--rt-priority`. "
            f"**The real-time run failed on this host**: {rt['error']}. "
            f"Position error rms in lockstep {_num(ls['theta_err_rms_deg'], 'deg')}.",
        ]
    verdict = "scores like it" if sc["scores_like_lockstep"] else "**does not score like it**"
    late_cmds = rt.get("late_commands", 0.0)
    why = (
        ""
        if sc["scores_like_lockstep"]
        else f": {_num(rt['late_duty_pct'], '%')} of its periods ran with a late duty on this "
        "host, and each changes the loop: a few late in a row (tenths of a millisecond, "
        "shorter than a host stall) hold the injection's voltage and move the estimated angle "
        "by degrees (the largest error above); the limit is the host's late periods, not the "
        "model"
    )
    if late_cmds > 0:
        why += (
            f"; its controller held {late_cmds:,.0f} of the "
            f"{rt.get('commands_sent', 0.0):,.0f} bench commands only after their step: "
            "set-points applied later than in lockstep, a different run"
        )
    host = []
    if "host_stalls" in rt:
        lost = rt.get("recorder_frames_lost", -1.0)
        host = [
            "",
            f"In that real-time run: {rt['host_stalls']:.0f} host stalls "
            f"({_num(rt['host_stall_ms_total'], 'ms')} in all), plant trip: "
            f"{rt.get('plant_fault', 'none')}, frames the recorder lost: "
            + ("not said by the transport" if lost < 0 else f"{lost:,.0f}")
            + ".",
        ]
    return [
        "",
        f"A sensorless run on the drive's clock against the same run in lockstep "
        f"(`realtime_native_score`): {sc['scenario']} with {sc['estimator']} at "
        f"{sc['f_sw'] / 1e3:g} kHz, {_num(sc['duration_s'], 's')}, both nodes native, "
        "`--rt-priority`. "
        + (
            f"Real time {len(sc['realtime_rms_runs'])} times, the run of median rms below "
            f"(rms {', '.join(_num(v, 'deg') for v in sc['realtime_rms_runs'])}; "
            f"{sc['realtime_runs_within']} of {len(sc['realtime_rms_runs'])} scored like "
            "lockstep). "
            if len(sc.get("realtime_rms_runs") or []) > 1
            else ""
        )
        + f"Position error rms {_num(rt['theta_err_rms_deg'], 'deg')} in real time against "
        f"{_num(ls['theta_err_rms_deg'], 'deg')} in lockstep (max |error| "
        f"{_num(rt['theta_err_abs_max_deg'], 'deg')} against "
        f"{_num(ls['theta_err_abs_max_deg'], 'deg')}, angle "
        f"{'lost' if rt['lock_lost'] else 'kept'}): it {verdict} within "
        f"{_num(sc['tolerance_deg'], 'deg')} of rms, the angle the rotor turns in one period "
        f"at the scenario's top speed{why}.",
        *host,
    ]


def recorder_frames_lost(runs: dict[str, dict[str, Any]]) -> float:
    """Frames the recorder lost in ``runs`` (the native pair's real-time runs by rate), all
    rates together; -1 when a run's transport does not say (issue 29,
    ``realtime_native.recorder_frames_lost``)."""
    lost = [r["recorder_frames_lost"] for r in runs.values()]
    return -1.0 if any(x < 0 for x in lost) else float(sum(lost))


def rate_rows(sec: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """The per-rate entries of a real-time section (``1kHz``, ...), without its totals."""
    return {k: v for k, v in sec.items() if isinstance(v, dict)}


#: The native loop's busy time split (``realtime_native.<rate>``): the key, and what it is.
NATIVE_PARTS = (
    ("send_us_median", "send (the instant's frames out)"),
    ("recv_us_median", "receive (drain the socket, check and decode)"),
    ("step_us_median", "step (the model and the next frames' encoding)"),
)


def native_parts_lines(sec: dict[str, Any]) -> list[str]:
    """One line saying where the native plant's period goes, per rate of ``sec``
    (``realtime_native``); none for a ``perf.json`` written before the split was kept."""
    rows = [
        f"{name}: "
        + ", ".join(f"{what} {_num(r[key], 'us')}" for key, what in NATIVE_PARTS)
        + f" of the {_num(r['busy_us_median'], 'us')} p50 work"
        for name, r in rate_rows(sec).items()
        if all(math.isfinite(r.get(key, math.nan)) for key, _ in NATIVE_PARTS)
    ]
    if not rows:
        return []
    return ["", "The native plant's work per period, part by part (p50 of each part):", ""] + [
        f"- {row}" for row in rows
    ]


#: The targets of issue 29 for the native nodes, on this 2-core machine (the issue's
#: table): the native plant's own work at 10 kHz fits a tenth of the 100 us period;
#: with ``--rt-priority`` a native pair misses at most 1 % of the periods at 4 kHz and
#: 5 % at 10 kHz (where a bare C loop already wakes late in 1.5 % on this host);
#: lockstep at 20,000 periods/s (2 s of a 10 kHz run per second of wall time, for the
#: demo); and the recorder keeps every frame of a native pair.
NATIVE_TARGET_LIST = (
    Target(
        "native_busy_us_p50_10khz",
        "native plant node, work per period at 10 kHz, p50 (`realtime_native.10kHz.busy_us_median`)",
        False,
        10.0,
        "us",
    ),
    Target(
        "native_missed_pct_4khz",
        "real time, native plant, `--rt-priority`, 4 kHz: periods missed "
        "(`realtime_native.4kHz.missed_pct`)",
        False,
        1.0,
        "%",
    ),
    Target(
        "native_missed_pct_10khz",
        "real time, native plant, `--rt-priority`, 10 kHz: periods missed "
        "(`realtime_native.10kHz.missed_pct`)",
        False,
        5.0,
        "%",
    ),
    Target(
        "native_lockstep_periods_per_s",
        "lockstep, native plant (`lockstep_native.steps_per_s`)",
        True,
        20000.0,
        "periods/s",
    ),
    Target(
        "native_recorder_frames_lost",
        "frames the recorder lost beside the native pair, 1-10 kHz "
        "(`realtime_native.recorder_frames_lost`) and in the sensorless score's real-time run",
        False,
        0.0,
        "frames",
    ),
)


def _native_limit(key: str, res: dict[str, Any]) -> str:
    """What limits a missed native target, from the same run's figures."""
    if key == "native_lockstep_periods_per_s":
        ls = res["lockstep_native"]
        return (
            f"the round trip sample -> duty through two processes and the transport, "
            f"p50 {_num(ls['rtt_us_p50'], 'us')} (at most {_num(1e6 / ls['rtt_us_p50'])} "
            "periods/s one after the other)"
        )
    if key == "native_recorder_frames_lost":
        rates = float(res["realtime_native"].get("recorder_frames_lost", 0.0))
        score = ((res.get("realtime_native_score") or {}).get("realtime") or {}).get(
            "recorder_frames_lost", 0.0
        )
        where = (
            f"({rates:,.0f} frames in the rates' runs, {score:,.0f} in the sensorless "
            "score's real-time run)"
        )
        engines = {
            str(r.get("recorder_engine", "python"))
            for r in (
                *(v for v in res["realtime_native"].values() if isinstance(v, dict)),
                ((res.get("realtime_native_score") or {}).get("realtime") or {}),
            )
            if "recorder_frames_lost" in r
        }
        if engines == {"native"}:
            return (
                "the native recorder's ring was full or the kernel dropped datagrams before "
                "its SCHED_FIFO thread ran (bench/nodes/native/bn_rec.c) " + where
            )
        return (
            "the recorder's receive buffer overflowed: its Python thread, at normal "
            "priority beside the two SCHED_FIFO loops on 2 cores, fell behind " + where
        )
    if key == "native_busy_us_p50_10khz":
        r = res["realtime_native"]["10kHz"]
        split = ""
        if all(math.isfinite(r.get(key, math.nan)) for key, _ in NATIVE_PARTS):
            split = (
                f" (p50 send {_num(r['send_us_median'], 'us')}, receive "
                f"{_num(r['recv_us_median'], 'us')}, step {_num(r['step_us_median'], 'us')})"
            )
        return (
            f"the plant node's own period (receive, step, encode, send){split} on a host with "
            f"load {_num(res['machine'].get('loadavg_1min_start', math.nan))} on "
            f"{res['machine'].get('cpus')} cores; p99 {_num(r['busy_us_p99'], 'us')}; the send "
            "is the kernel's: one udp_multicast datagram per frame (python-can's wire format), "
            "each delivered to every listening socket within the send call (docs/REALTIME.md, "
            "the kernel's cost per datagram); fewer datagrams need another wire format, or a "
            "CAN adapter"
        )
    r = res["realtime_native"]["4kHz" if key.endswith("4khz") else "10kHz"]
    late = r["missed_pct"] - r["late_outside_stalls_pct"]
    if r["periods_skipped"] > 0 and late >= r["late_outside_stalls_pct"]:
        return (
            f"host stalls: {r['host_stalls']:.0f} stalls ({_num(r['host_stall_ms_total'], 'ms')} in "
            f"all, the longest {_num(r['host_stall_ms_max'], 'ms')}) skipped "
            f"{r['periods_skipped']:,.0f} periods; late outside them "
            f"{_num(r['late_outside_stalls_pct'], '%')}"
        )
    return (
        f"late wake-ups outside host stalls: {_num(r['late_outside_stalls_pct'], '%')} "
        f"(jitter p99 {_num(r['jitter_us_p99'], 'us')})"
    )


def _recorder_lost_all(res: dict[str, Any]) -> float:
    """The frames the recorder lost beside the native pair: the rates' real-time runs
    (``realtime_native.recorder_frames_lost``) and the sensorless score's real-time run,
    where measured; -1 when one of them does not say."""
    lost = [float(res["realtime_native"].get("recorder_frames_lost", -1.0))]
    score = (res.get("realtime_native_score") or {}).get("realtime") or {}
    if "recorder_frames_lost" in score:
        lost.append(float(score["recorder_frames_lost"]))
    return -1.0 if any(x < 0 for x in lost) else sum(lost)


def native_verdicts(res: dict[str, Any]) -> dict[str, dict[str, Any]] | None:
    """Each target of :data:`NATIVE_TARGET_LIST` against its figure (None: not measured)."""
    nat, ls = res.get("realtime_native"), res.get("lockstep_native")
    if nat is None or ls is None:
        return None
    figures = {
        "native_busy_us_p50_10khz": nat["10kHz"]["busy_us_median"],
        "native_missed_pct_4khz": nat["4kHz"]["missed_pct"],
        "native_missed_pct_10khz": nat["10kHz"]["missed_pct"],
        "native_lockstep_periods_per_s": ls["steps_per_s"],
        "native_recorder_frames_lost": _recorder_lost_all(res),
    }
    out = {}
    for t in NATIVE_TARGET_LIST:
        v = figures[t.key]
        unknown = t.key == "native_recorder_frames_lost" and v < 0
        met = (v >= t.value if t.at_least else v <= t.value) and not unknown
        out[t.key] = {
            "value": v,
            "target": t.value,
            "met": bool(met),
            "limit": None
            if met
            else ("not said by the transport" if unknown else _native_limit(t.key, res)),
        }
    return out


#: The markers of the native nodes' block in docs/REALTIME.md.
NATIVE_DOC_BEGIN = "<!-- perf-native:begin (written by bench perf --realtime-doc; do not edit) -->"
NATIVE_DOC_END = "<!-- perf-native:end -->"


def native_targets_table(v: dict[str, dict[str, Any]], limits: bool = True) -> list[str]:
    """Markdown rows: each native target (:func:`native_verdicts` ``v``) against its figure,
    met or missed, and (``limits``) what limits a missed one."""
    rows = []
    for t in NATIVE_TARGET_LIST:
        r = v[t.key]
        val = "n/a" if r["value"] < 0 and t.unit == "frames" else _num(r["value"], t.unit)
        row = [t.figure, val, _target_text(t), "met" if r["met"] else "**missed**"]
        rows.append([*row, r["limit"] or ""] if limits else row)
    head = ["figure", "measured", "target", "verdict"]
    return _table([*head, "limit"] if limits else head, rows)


def render_realtime_native(res: dict[str, Any], source: str = "docs/perf/perf.json") -> str:
    """The native nodes' block of docs/REALTIME.md from ``perf.json``'s ``realtime_native``
    and ``lockstep_native``, each target with its verdict and, where missed, its limit."""
    lines = [NATIVE_DOC_BEGIN, ""]
    v = native_verdicts(res)
    if v is None:
        lines += [
            f"The native nodes are not measured in `{source}` yet: `make perf` writes "
            "`realtime_native` and `lockstep_native` (issue 29).",
            "",
            NATIVE_DOC_END,
        ]
        return "\n".join(lines)
    load = res["machine"].get("loadavg_1min_start", math.nan)
    lines += [
        f"`bench perf` on this project's {res['machine'].get('cpus')}-core shared virtual machine "
        f"(load {_num(load)} at the start; every figure below is from `{source}`; "
        f"{res['realtime_native']['10kHz'].get('note', NATIVE_NOTE)}):",
        "",
    ]
    lines += native_targets_table(v)
    rows = []
    for name, r in rate_rows(res["realtime_native"]).items():
        rows.append(
            [
                name,
                str(r.get("policy", "normal")),
                _num(r["missed_pct"], "%"),
                _num(r["late_outside_stalls_pct"], "%"),
                f"{r['periods_skipped']:,.0f}",
                f"{_num(r['busy_us_median'])} / {_num(r['busy_us_p99'])} us",
                "n/a"
                if r.get("recorder_frames_lost", -1) < 0
                else f"{r['recorder_frames_lost']:,.0f}",
            ]
        )
    lines += [""]
    lines += _table(
        [
            "rate",
            "policy",
            "periods missed",
            "late outside host stalls",
            "periods skipped",
            "work p50 / p99",
            "recorder frames lost",
        ],
        rows,
    )
    lines += native_parts_lines(res["realtime_native"])
    lines += score_lines(res.get("realtime_native_score"))
    lines += ["", NATIVE_DOC_END]
    return "\n".join(lines)


def update_realtime_doc(doc: str, res: dict[str, Any]) -> str:
    """``doc`` (docs/REALTIME.md) with its native block replaced (appended when it has none)."""
    from bench.studies._rtcheck import splice_block

    return splice_block(doc, render_realtime_native(res), NATIVE_DOC_BEGIN, NATIVE_DOC_END)


# -- 4. codec and analysis ------------------------------------------------------------------


def codec_figures(repeats: int) -> dict[str, float]:
    """Microseconds per frame: the codec's encode and decode, and cantools' own on the payload."""
    from bench.wire._codec import Codec
    from bench.wire._hotcodec import compile_message

    codec = Codec()
    sig = {"i_a": 1.234, "i_b": -0.5, "u_dc": 540.0, "step": 17, "status": 1}
    msg = codec.encode("PhaseSamples", sig)
    values = {**sig, "crc": 0}
    message = codec.message("PhaseSamples")
    hot = compile_message(message)
    data = bytes(msg.data)
    n = 20000

    def per_call(fn: Callable[[], object]) -> float:
        t0 = time.perf_counter()
        for _ in range(n):
            fn()
        return (time.perf_counter() - t0) / n

    out = {
        "encode_us": 1e6
        * _median_of(lambda: per_call(lambda: codec.encode("PhaseSamples", sig)), repeats),
        "decode_us": 1e6 * _median_of(lambda: per_call(lambda: codec.decode(msg)), repeats),
        "cantools_pack_us": 1e6
        * _median_of(lambda: per_call(lambda: message.encode(values, strict=False)), repeats),
        "cantools_unpack_us": 1e6
        * _median_of(
            lambda: per_call(lambda: message.decode_simple(data, decode_choices=False)), repeats
        ),
    }
    if hot is not None:
        out["hot_pack_us"] = 1e6 * _median_of(lambda: per_call(lambda: hot.pack(values)), repeats)
        out["hot_unpack_us"] = 1e6 * _median_of(lambda: per_call(lambda: hot.unpack(data)), repeats)
    return out


def analysis_figures(repeats: int, min_frames: int, folder: Path) -> dict[str, float]:
    """``bench analyze`` on a capture of at least ``min_frames`` frames, built once.

    The capture: ``wen-5.1`` with tt-dq run in-process (its frames exactly as
    the nodes send them) long enough for ``min_frames`` frames, written as BLF
    with python-can and a ``meta.json`` naming the scenario, as a run leaves
    it.  Timed, medians of ``repeats``: reading the capture
    (:func:`bench.captures._read.read_capture`), decoding the frames read into
    the per-period table (:func:`bench.runs._analysis.analyze_frames`, the
    figure of the target) and the whole ``bench analyze`` without the plot
    (:func:`bench.captures._read.analyze_capture`: read, decode, metrics,
    ``signals.csv``).
    """
    import can

    from bench.captures._read import analyze_capture, read_capture
    from bench.nodes._loops import run_inprocess
    from bench.runs._analysis import analyze_frames
    from bench.scenarios._schema import load_scenario
    from bench.scenarios._setup import sample_period
    from bench.wire._codec import Codec

    codec = Codec()
    scn = load_scenario("wen-5.1")
    T_s = sample_period(scn)
    periods = math.ceil(1.02 * min_frames / 4)  # four frames a period, and some margin
    scn = scn.with_overrides(duration=periods * T_s)
    frames = run_inprocess(scn, "tt-dq", codec)
    t0 = time.time()
    for i, f in enumerate(frames):  # wire order, and the timestamps a recorder would give
        f.timestamp = t0 + i * T_s / 4
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "capture.blf"
    with can.BLFWriter(str(path)) as w:
        for f in frames:
            w.on_message_received(f)
    (folder / "meta.json").write_text(json.dumps({"scenario": scn.to_dict()}) + "\n")

    read: list[Any] = []

    def read_rate() -> float:
        t = time.perf_counter()
        got, _ = read_capture(path)
        dt = time.perf_counter() - t
        read[:] = got
        return len(got) / dt

    def analyze_rate() -> float:
        t = time.perf_counter()
        analyze_frames(read, codec, T_s=T_s, n_p=4)
        return len(read) / (time.perf_counter() - t)

    def whole_rate() -> float:
        t = time.perf_counter()
        analyze_capture(path, out_dir=folder / "out", codec=codec, echo=lambda s: None, plots=False)
        return len(read) / (time.perf_counter() - t)

    read_fps = _median_of(read_rate, repeats)
    return {
        "analyze_frames": float(len(read)),
        "analyze_frames_per_s": _median_of(analyze_rate, repeats),
        "capture_read_frames_per_s": read_fps,
        "analyze_end_to_end_frames_per_s": _median_of(whole_rate, repeats),
    }


def busload_limits() -> list[dict[str, Any]]:
    from bench.wire._busload import busload_table
    from bench.wire._codec import Codec

    keep = ("layout", "bus", "period_us_max", "max_rate_hz", "max_rate_hz_practical")
    return [{k: r[k] for k in keep} for r in busload_table(Codec(), rates=[1e3])]


# -- make demo (issue 29) ------------------------------------------------------------------

#: ``make demo``'s command (the Makefile's ``demo`` target and the README's first command),
#: without its ``--out``.
DEMO_COMMAND = ("run", "wen-5.1", "--estimator", "tt-dq")
#: The wall time issue 29 measured for ``make demo`` (its 4 s of wen-5.1 in lockstep,
#: Python nodes) and the factor it asks: the target is that time over the factor.
DEMO_ISSUE_S = 15.0
DEMO_FACTOR = 5.0
DEMO_TARGET_S = DEMO_ISSUE_S / DEMO_FACTOR
#: ``bench perf --quick``: the demo's command on this much of the scenario (s), so that the
#: quick run stays short (its figures are not comparable).
DEMO_QUICK_DURATION_S = 0.2
#: Timed runs of the demo's command (with the kept design): ``demo.wall_s`` is their median
#: (a single run moves by half a second with the shared machine's load).
DEMO_RUNS = 3


def demo_section(folder: Path, *, quick: bool) -> dict[str, Any]:
    """``make demo`` as its user runs it: ``bench run wen-5.1 --estimator tt-dq`` in a process
    of its own, timed from outside, :data:`DEMO_RUNS` times (one with ``--quick``); the
    figures are those of the run of median wall time (``wall_s_runs``: every run's).

    The split comes from the run's own files: ``run_s`` is its ``metrics.json``
    ``wall_s`` (the nodes started, the lockstep run, the nodes stopped, the
    recording closed), ``loop_s`` the plant's stepping loop (``plant.json``
    ``loop_s``: from the start command to the last period), so that
    ``nodes_s = run_s - loop_s`` is the nodes' start-up and stop, and
    ``outside_run_s = wall_s - run_s`` the command's own work before and after
    (imports, the scenario's checks, scoring, the figure, the files).

    ``cpu_s``: the CPU time (user and system) of the command and every process it
    started (the nodes), from the kernel's accounting of the reaped processes;
    ``cpu_floor_s = cpu_s / cpus``: the wall time no schedule of that work on this
    machine's ``cpus`` cores can beat.

    ``design_kept``: whether that run found its controller's design kept from an
    earlier one (:mod:`bench.scenarios._designs`: any run after the first with the
    same code); ``wall_s_designing``: the same command run once more with no kept
    design (``CAN_HIL_BENCH_DESIGN_CACHE=off``), as the first run after a change
    of the controller's code is.
    """
    import resource
    import subprocess
    import sys

    from bench.scenarios._designs import CACHE_ENV, load_design
    from bench.scenarios._schema import load_scenario
    from bench.scenarios._setup import controller_pars

    def command(out: Path) -> list[str]:
        cmd = [sys.executable, "-m", "bench", *DEMO_COMMAND, "--out", str(out), "--quiet"]
        return cmd + (["--duration", repr(DEMO_QUICK_DURATION_S)] if quick else [])

    pars = controller_pars(load_scenario(DEMO_COMMAND[1]), DEMO_COMMAND[3])

    def timed(out: Path, env: dict[str, str]) -> tuple[float, float, bool]:
        """The command's wall time and the CPU time of it and its processes (s), and whether
        it found its controller's design kept."""
        kept = load_design(pars) is not None
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        r = subprocess.run(command(out), capture_output=True, text=True, timeout=600, env=env)
        wall = time.perf_counter() - t0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        if r.returncode != 0:
            tail = (r.stderr.strip().splitlines() or ["no output"])[-1]
            raise BenchError(
                f"bench perf: make demo's command failed (exit {r.returncode}): {tail}"
            )
        cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
        return wall, cpu, kept

    designing, _, _ = timed(folder / "designing", {**os.environ, CACHE_ENV: "off"})
    runs = [
        (*timed(folder / f"run{i}", dict(os.environ)), folder / f"run{i}")
        for i in range(1 if quick else DEMO_RUNS)
    ]
    wall, cpu, kept, out = sorted(runs, key=lambda r: r[0])[len(runs) // 2]
    metrics = json.loads((out / "metrics.json").read_text())
    meta = json.loads((out / "meta.json").read_text())
    plant = (meta.get("node_reports") or {}).get("plant") or {}
    run_s = float(metrics["wall_s"])
    loop_s = float(plant.get("loop_s", math.nan))
    cpus = os.cpu_count() or 1
    return {
        "command": "bench " + " ".join(DEMO_COMMAND),
        "quick": quick,
        "wall_s": wall,
        "wall_s_runs": [r[0] for r in runs],
        "run_s": run_s,
        "loop_s": loop_s,
        "nodes_s": run_s - loop_s,
        "outside_run_s": wall - run_s,
        "cpu_s": cpu,
        "cpu_floor_s": cpu / cpus,
        "cpus": cpus,
        "steps": int(metrics["steps"]),
        "loop_steps_per_s": metrics["steps"] / loop_s if loop_s > 0 else math.nan,
        "node_engines": meta.get("node_engines", {}),
        "design_kept": kept,
        "wall_s_designing": designing,
        "issue_s": DEMO_ISSUE_S,
        "target_s": DEMO_TARGET_S,
        "met": wall <= DEMO_TARGET_S,
    }


def demo_lines(res: dict[str, Any]) -> list[str]:
    """The ``make demo`` section of BENCHMARKS.md (none when perf.json has no ``demo``)."""
    d = res.get("demo")
    if d is None:
        return []
    eng = ", ".join(f"{r} {e}" for r, e in sorted(d["node_engines"].items())) or "n/a"
    lines = [
        "## `make demo` (issue 29)",
        "",
        f"`{d['command']}` as its user runs it, timed from outside the process: "
        + (
            f"the run of median wall time of {len(d['wall_s_runs'])} "
            f"({', '.join(_num(w, 's') for w in d['wall_s_runs'])})"
            if len(d.get("wall_s_runs") or []) > 1
            else "one run"
        )
        + f" (`demo.wall_s`; node engines: {eng}"
        + ("; `--quick`: a short run, not comparable" if d.get("quick") else "")
        + ").",
        "",
        *_table(
            ["figure", "this run", "target"],
            [
                [
                    "`make demo`, the whole command (`demo.wall_s`)",
                    _num(d["wall_s"], "s"),
                    f"<= {_num(d['target_s'], 's')} (the issue's {_num(d['issue_s'], 's')} "
                    f"/ {_num(DEMO_FACTOR)})",
                ],
                [
                    f"the plant's stepping loop, {d['steps']:,} periods (`demo.loop_s`)",
                    f"{_num(d['loop_s'], 's')} ({_num(d['loop_steps_per_s'], 'periods/s')})",
                    "",
                ],
                [
                    "the nodes' start-up and stop, the recording closed (`demo.nodes_s`)",
                    _num(d["nodes_s"], "s"),
                    "",
                ],
                [
                    "the command's own work: imports, checks, scoring, figure, files "
                    "(`demo.outside_run_s`)",
                    _num(d["outside_run_s"], "s"),
                    "",
                ],
                *(
                    [
                        [
                            "CPU time of the command and its node processes (`demo.cpu_s`), "
                            f"over {d['cpus']} cores (`demo.cpu_floor_s`)",
                            f"{_num(d['cpu_s'], 's')}, {_num(d['cpu_floor_s'], 's')}",
                            "",
                        ]
                    ]
                    if "cpu_s" in d
                    else []
                ),
            ],
        ),
        "",
    ]
    if d["met"]:
        lines.append("The target is met in this run.")
    else:
        parts = {
            "the stepping loop": d["loop_s"],
            "the nodes' start-up and stop": d["nodes_s"],
            "the command's own work": d["outside_run_s"],
        }
        big = max(parts, key=lambda k: parts[k])
        floor = d.get("cpu_floor_s")
        lines.append(
            f"Missed: {_num(d['wall_s'], 's')} against {_num(d['target_s'], 's')}. "
            + (
                f"The command and its nodes use {_num(d['cpu_s'], 's')} of CPU, "
                f"{_num(floor, 's')} on each of the {d['cpus']} cores if they shared them "
                "perfectly: "
                + (
                    "more than the target, so no schedule of this work meets it, only less work. "
                    if floor > d["target_s"]
                    else "within the target, so the rest is waiting on one another. "
                )
                if floor is not None
                else ""
            )
            + "The largest "
            f"share is {big} ({_num(parts[big], 's')} of {_num(d['wall_s'], 's')}). The loop "
            f"alone at {_num(d['loop_steps_per_s'], 'periods/s')} "
            + (
                "leaves nothing of the target for the rest"
                if d["loop_s"] >= d["target_s"]
                else f"leaves {_num(d['target_s'] - d['loop_s'], 's')} for the rest"
            )
            + f"; it needs {_num(d['steps'] / d['target_s'], 'periods/s')} to fit the whole "
            "target by itself. In lockstep the plant runs no further than the commands "
            "`bench run` sends ahead of it, as its recorder sees the plant's step. The "
            "controller is designed once, in `bench run` before any process starts so that a "
            "misfit is one line, and handed to the controller node in plan.json; "
            + (
                f"this run found the design kept from an earlier one (without it, "
                f"{_num(d['wall_s_designing'], 's')}: scipy's import and the loops' margin "
                "searches before the nodes start). "
                if d.get("design_kept") and "wall_s_designing" in d
                else "this run made it (scipy's import and the loops' margin searches). "
            )
            + "The rest of the command's own work is Python's start and the imports, "
            "then decoding the capture, "
            "writing signals.csv and drawing run.png (matplotlib's text and axes, mostly; "
            "matplotlib and scipy.signal are imported while the nodes start). "
            "The nodes' start-up holds the 0.3 s the bench listens to the bus for another "
            "run before it starts them (a run never shares its bus), then two Python "
            "processes' imports at once on the shared cores. The machine's load average "
            f"was "
            f"{_num(res['machine'].get('loadavg_1min_start', math.nan))} on "
            f"{res['machine'].get('cpus')} cores at the start of `bench perf`."
        )
    return lines


# -- the run ----------------------------------------------------------------------------------


def run_perf(
    out_dir: Path, *, quick: bool, echo: Callable[[str], None] | None = None
) -> dict[str, Any]:
    """Measure everything; write ``perf.json`` into ``out_dir``; return the results.

    ``echo`` gets one line as each section starts (progress).
    """
    from plant_rt import compiled_engine_missing

    say = echo or (lambda s: None)
    t_start = time.perf_counter()
    out_dir.mkdir(parents=True, exist_ok=True)
    repeats = 3 if quick else 5
    n_steps = 2000 if quick else 20000
    res: dict[str, Any] = {
        "quick": quick,
        "machine": {
            "platform": platform.platform(),
            "python": platform.python_version(),
            "cpus": os.cpu_count(),
            "loadavg_1min_start": os.getloadavg()[0],
        },
        "engines": {
            "measured": list(engines()),
            "compiled_missing": compiled_engine_missing(),
            # kept for readers of perf.json: the controller's core is always built
            "controller_compiled_missing": None,
        },
        "targets": TARGETS,
    }
    say("1. in-process loops, both engines")
    res["inprocess"] = inprocess_section(quick, repeats, n_steps)
    if res["inprocess"]["rtf_10khz_tt_dq"] < TARGETS["inprocess_rtf_10khz_tt_dq"]:
        res["inprocess_profile_tt_dq"] = profile_inprocess("tt-dq", n_steps)
    say("1b. the in-process native pair")
    res["inprocess_native"] = inprocess_native_section(n_steps, repeats)
    with tempfile.TemporaryDirectory() as tmp:
        tmpd = Path(tmp)
        say("2. the transport's send cost, and two processes in lockstep")
        from bench.studies._rtcheck import send_cost_us

        res["transport_send_us"] = send_cost_us(500 if quick else 2000)
        runs = [
            lockstep_two_process(0.2 if quick else 1.0, tmpd / f"ls{i}")
            for i in range(1 if quick else 3)
        ]
        res["lockstep"] = {
            k: (
                statistics.median(r[k] for r in runs)
                if isinstance(runs[0][k], float)
                else runs[0][k]
            )
            for k in runs[0]
        }
        rt: dict[str, Any] = {}
        fifo: dict[str, Any] = {}
        for f in (1e3, 4e3, 10e3):
            dur = 0.3 if quick else {1e3: 5.0, 4e3: 3.0, 10e3: 2.0}[f]
            name = f"{f / 1e3:g}kHz"
            say(f"3. real time at {name}, normal scheduling and SCHED_FIFO")
            rt[name] = realtime_run(f, dur, tmpd / f"rt{int(f)}")
            fifo[name] = realtime_run(f, dur, tmpd / f"rtf{int(f)}", priority=RT_PRIORITY)
        res["realtime"] = rt
        # the same with both nodes under SCHED_FIFO (bench run --rt-priority)
        res["realtime_fifo"] = fifo
        say("3b. the native plant node: lockstep, and real time with SCHED_FIFO")
        res["lockstep_native"] = {
            **lockstep_two_process(0.2 if quick else 1.0, tmpd / "lsn", plant_engine="native"),
            "note": NATIVE_NOTE,
        }
        nat: dict[str, Any] = {}
        for f in (1e3, 4e3, 10e3):
            dur = 0.3 if quick else {1e3: 5.0, 4e3: 3.0, 10e3: 2.0}[f]
            name = f"{f / 1e3:g}kHz"
            r = realtime_run(
                f, dur, tmpd / f"rtn{int(f)}", priority=RT_PRIORITY, plant_engine="native"
            )
            nat[name] = {**r, "note": NATIVE_NOTE}
        res["realtime_native"] = {**nat, "recorder_frames_lost": recorder_frames_lost(nat)}
        say("3c. a sensorless run on the native pair: real time against lockstep")
        res["realtime_native_score"] = sensorless_realtime_score(
            tmpd / "score",
            duration=1.2 if quick else None,
            realtime_runs=1 if quick else SCORE_RUNS,
        )
        say("4. codec, and bench analyze on a large capture")
        res["codec"] = {
            **codec_figures(repeats),
            **analysis_figures(3, 20_000 if quick else ANALYZE_MIN_FRAMES, tmpd / "analyze"),
        }
        say("6. make demo, as its user runs it")
        res["demo"] = demo_section(tmpd / "demo", quick=quick)
    res["busload"] = busload_limits()
    res["verdicts"] = verdicts(res)
    res["wall_s"] = time.perf_counter() - t_start
    res["machine"]["loadavg_1min_end"] = os.getloadavg()[0]
    (out_dir / "perf.json").write_text(json.dumps(res, indent=2, default=float) + "\n")
    return res


def _fastest(row: dict[str, Any]) -> tuple[str, dict[str, Any]]:
    """The compiled engine's entry when it was measured, else the Python engine's."""
    e = "compiled" if "compiled" in row else "python"
    return e, row[e]


def _fifo_config(res: dict[str, Any], name: str) -> str:
    pol = res["realtime_fifo"][name].get("policy", "normal")
    return f"--rt-priority {RT_PRIORITY}" + ("" if pol == "fifo" else " (refused: normal)")


def _loop_ratio(nat: dict[str, Any] | None) -> tuple[float, str]:
    """The frame loop in Python over the in-process native pair's whole loop, per period,
    wen-5.1 with tt-dq, the same cores, one ``bench perf`` run."""
    if not nat:
        return math.nan, "not measured"
    ratio = nat["python_loop_wall_us_per_step_tt_dq"] / nat["wall_us_per_step_tt_dq"]
    return float(ratio), "wen-5.1, the whole loop per period, same run"


def verdicts(res: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """Each target of :data:`TARGET_LIST` against its figure, and the configuration measured."""
    inp = res["inprocess"]
    e_loop, loop = _fastest(inp["tt_dq_10khz"])
    e_sw, sw = _fastest(inp["switching_10khz"])
    ls = res["lockstep"]
    figures: dict[str, tuple[float, str]] = {
        "inprocess_rtf_10khz_tt_dq": (loop["rtf"], f"{e_loop} engine"),
        # the models have one engine each, their C cores (the controller's Python step is
        # the tests' oracle): what is compiled or Python is the loop around them
        "inprocess_compiled_over_python_tt_dq": _loop_ratio(res.get("inprocess_native")),
        "inprocess_native_us_per_step_tt_dq": (
            float(res.get("inprocess_native", {}).get("us_per_step_tt_dq", math.nan)),
            "wen-5.1, time inside the C calls" if "inprocess_native" in res else "not measured",
        ),
        "switching_rtf_10khz": (sw["rtf"], f"{e_sw} engine"),
        "lockstep_periods_per_s": (ls["steps_per_s"], f"{ls['transport']}, {ls.get('engine')}"),
        "plant_node_us_p50_10khz": (
            res["realtime_fifo"]["10kHz"]["busy_us_median"],
            _fifo_config(res, "10kHz"),
        ),
        "realtime_missed_pct_4khz_fifo": (
            res["realtime_fifo"]["4kHz"]["missed_pct"],
            _fifo_config(res, "4kHz"),
        ),
        "realtime_missed_pct_10khz_fifo": (
            res["realtime_fifo"]["10kHz"]["missed_pct"],
            _fifo_config(res, "10kHz"),
        ),
        "realtime_missed_pct_1khz_normal": (
            res["realtime"]["1kHz"]["missed_pct"],
            "normal scheduling",
        ),
        "analyze_frames_per_s": (
            res["codec"]["analyze_frames_per_s"],
            f"{res['codec']['analyze_frames']:,.0f} frames",
        ),
        "analyze_end_to_end_frames_per_s": (
            res["codec"]["analyze_end_to_end_frames_per_s"],
            f"{res['codec']['analyze_frames']:,.0f} frames, BLF",
        ),
    }
    out = {}
    for t in TARGET_LIST:
        val, how = figures[t.key]
        met = val >= t.value if t.at_least else val <= t.value
        out[t.key] = {"value": val, "target": t.value, "met": bool(met), "config": how}
    return out


# -- text: the console, docs/BENCHMARKS.md and the README block --------------------------------


def _num(v: float, unit: str = "") -> str:
    """A figure as printed everywhere: three significant digits, thousands separated."""
    if not math.isfinite(v):
        return "n/a"
    a = abs(v)
    if a >= 1000:
        s = f"{v:,.0f}"
    elif a >= 100:
        s = f"{v:.0f}"
    elif a >= 10:
        s = f"{v:.1f}"
    elif a >= 1:
        s = f"{v:.2f}"
    else:
        s = f"{v:.3f}" if a >= 0.01 or a == 0 else f"{v:.2g}"
    if not unit:
        return s
    return s + unit if unit.startswith("x") else f"{s} {unit}"


def _target_text(t: Target) -> str:
    return f"{'>=' if t.at_least else '<='} {_num(t.value, t.unit)}"


def _table(head: list[str], rows: list[list[str]]) -> list[str]:
    return [
        "| " + " | ".join(head) + " |",
        "|" + "|".join("---" for _ in head) + "|",
        *["| " + " | ".join(r) + " |" for r in rows],
    ]


def targets_table(res: dict[str, Any]) -> list[str]:
    """Markdown rows: every target of issue 14 against its figure, met or missed."""
    rows = []
    for t in TARGET_LIST:
        v = res["verdicts"][t.key]
        rows.append(
            [
                t.figure,
                _num(v["value"], t.unit),
                _target_text(t),
                "met" if v["met"] else "**missed**",
                v["config"],
            ]
        )
    return _table(["figure", "measured", "target", "", "measured with"], rows)


def _engine_rows(res: dict[str, Any]) -> list[list[str]]:
    inp = res["inprocess"]
    eng = res["engines"]["measured"]

    def row(label: str, vals: dict[str, float], unit: str, ratio: float | None) -> list[str]:
        cells = [_num(vals[e], unit) if e in vals else "n/a" for e in ("python", "compiled")]
        return [label, *cells, _num(ratio, "x") if ratio is not None else ""]

    out = []
    for key, label in (
        ("tt_dq_10khz", "closed loop plant + tt-dq controller, average model, 10 kHz"),
        ("switching_10khz", "closed loop plant + tt-dq controller, switching plant, 10 kHz"),
    ):
        r = inp[key]
        us = {e: r[e]["us_per_step"] for e in eng}
        rtf = {e: r[e]["rtf"] for e in eng}
        ratio = r.get("compiled_over_python")
        out.append([label + ": per step", *row("", us, "us", ratio)[1:]])
        out.append([label + ": real-time factor", *row("", rtf, "x", None)[1:]])
    alone = inp["alone_us_per_period"]
    for key, label in (("average", "average model"), ("switching", "switching plant")):
        a = alone[key]
        out.append(
            row(
                f"plant alone per period, {label}",
                {e: a[e] for e in eng},
                "us",
                a.get("compiled_over_python"),
            )
        )
    c = alone["controller_tt_dq"]
    # one engine, the core, whatever the name: no Python figure to set beside it (an older
    # perf.json's was the Python step, now the tests' oracle, not a product engine)
    out.append(
        [
            "tt-dq controller alone per step, 10 kHz (one engine: the C core)",
            "n/a",
            _num(c["compiled"], "us"),
            "",
        ]
    )
    node = inp["plant_node_10khz"]
    out.append(
        row(
            "plant node per period, in-process, 10 kHz: p50 (step and frames encoded)",
            {e: node[e]["us_p50"] for e in eng},
            "us",
            None,
        )
    )
    out.append(
        row("the same, p99", {e: node[e]["us_p99"] for e in eng}, "us", None),
    )
    return out


def figures_sections(res: dict[str, Any]) -> list[str]:
    """The Markdown of every figure of ``perf.json``, by section."""
    inp = res["inprocess"]
    lines = ["### 1. In-process (no CAN)", ""]
    lines += _table(
        ["figure", "python engine", "compiled engine", "compiled / python"], _engine_rows(res)
    )
    lines += [
        "",
        f"Every estimator's closed loop on the default engine (plant {inp['engine_default']}; "
        "the controller's engine is compiled where the compiled controller covers the "
        "estimator, else Python):",
        "",
    ]
    rows = [
        [
            est,
            str(r.get("controller_engine", "python")),
            _num(r["us_per_step"], "us"),
            _num(r["f_sw"] / 1e3, "kHz"),
            _num(r["rtf"], "x"),
        ]
        for est, r in inp.items()
        if isinstance(r, dict) and "f_sw" in r
    ]
    lines += _table(
        ["estimator", "controller engine", "per step", "PWM rate", "real-time factor"], rows
    )
    nat = res.get("inprocess_native")
    if nat is not None:
        lines += [
            "",
            "The in-process native pair (`bench.nodes.native._pair`: the plant unit and the "
            "controller unit stepped in C for many periods per call, the frames passed in "
            "memory; what `bench suite --inprocess`, the sweeps and in-process runs use by "
            f"default), wen-5.1 with tt-dq at 10 kHz, {_num(nat['steps'])} periods:",
            "",
        ]
        lines += _table(
            ["figure", "per step"],
            [
                ["inside the C calls", _num(nat["us_per_step_tt_dq"], "us")],
                ["of which the plant unit (units timed)", _num(nat["plant_us"], "us")],
                ["of which the controller unit (units timed)", _num(nat["controller_us"], "us")],
                [
                    "the whole loop, the frames handed over as one array "
                    f"({_num(nat['returns_per_1000_steps'])} returns per 1,000 steps)"
                    if "frames_us_per_step" in nat
                    else "the whole loop, frames made Python objects "
                    f"({_num(nat['returns_per_1000_steps'])} returns per 1,000 steps)",
                    _num(nat["wall_us_per_step_tt_dq"], "us"),
                ],
                *(
                    [
                        [
                            "of which the frames' rows written from the record buffer",
                            _num(nat["frames_us_per_step"], "us"),
                        ],
                        [
                            "of which Python at the returns (commands fed, nodes built)",
                            _num(nat["returns_us_per_step"], "us"),
                        ],
                    ]
                    if "frames_us_per_step" in nat
                    else []
                ),
                [
                    'the Python loop on the same cores (`run_inprocess(..., loop="python")`)',
                    _num(nat["python_loop_wall_us_per_step_tt_dq"], "us"),
                ],
            ],
        )
    ls = res["lockstep"]
    lines += [
        "",
        f"### 2. Two processes in lockstep over {ls['transport']} "
        f"(plant engine {ls.get('engine')})",
        "",
    ]
    lines += _table(
        [
            "periods/s",
            "the same over the whole run",
            "real-time factor at 10 kHz",
            "round trip p50",
            "p99",
            "max",
            "sending one period's plant frames p50 / p99",
        ],
        [
            [
                _num(ls["steps_per_s"]),
                _num(ls["wall_steps_per_s"]),
                _num(ls["rtf_10khz"], "x"),
                _num(ls["rtt_us_p50"], "us"),
                _num(ls["rtt_us_p99"], "us"),
                _num(ls["rtt_us_max"], "us"),
                f"{_num(res['transport_send_us']['median'])} / "
                f"{_num(res['transport_send_us']['p99'])} us",
            ]
        ],
    )
    lines += [
        "",
        "Periods/s: the plant's stepping loop, from the start command to its last period; "
        "the whole run adds the processes' start and stop.",
    ]
    if (lsn := res.get("lockstep_native")) is not None:
        lines += [
            "",
            f"Lockstep, {lsn['note']}: {_num(lsn['steps_per_s'])} periods/s, "
            f"round trip p50 {_num(lsn['rtt_us_p50'], 'us')}.",
        ]
    lines += ["", "### 3. Real time (plant on its wall clock, sensored controller)", ""]
    rows = []
    sections = [("normal", res["realtime"]), ("SCHED_FIFO", res["realtime_fifo"])]
    if "realtime_native" in res:  # the native plant node (measured since it exists)
        sections.append(("SCHED_FIFO, native plant", res["realtime_native"]))
    for label, sec in sections:
        for name, r in rate_rows(sec).items():
            got = r.get("policy", "normal")
            want_fifo = label.startswith("SCHED_FIFO")
            tag = label if (got == "fifo") == want_fifo else f"{label} refused"
            rows.append(
                [
                    name,
                    tag,
                    _num(r["steps"]),
                    _num(r["missed_pct"], "%"),
                    _num(r["overrun_pct"], "%"),
                    _num(r["late_outside_stalls_pct"], "%"),
                    _num(r["late_duty_pct"], "%"),
                    f"{r['host_stalls']:.0f} / {_num(r['host_stall_ms_total'], 'ms')} / "
                    f"{_num(r['host_stall_ms_max'], 'ms')}"
                    if r["host_stalls"]
                    else "none",
                    f"{r['periods_skipped']:,.0f}",
                    f"{_num(r['jitter_us_median'])} / {_num(r['jitter_us_p99'])} / "
                    f"{_num(r['jitter_us_max'])} us",
                    f"{_num(r['busy_us_median'])} / {_num(r['busy_us_p99'])} of "
                    f"{_num(1e6 / r['f_sw'])} us",
                ]
            )
    lines += _table(
        [
            "rate",
            "scheduling",
            "periods computed",
            "missed (late or skipped)",
            "late",
            "late outside stalls",
            "late duties",
            "host stalls: n / total / longest",
            "periods skipped",
            "wake-up late p50 / p99 / max",
            "computation p50 / p99",
        ],
        rows,
    )
    if "realtime_native" in res:
        lines += native_parts_lines(res["realtime_native"])
    c = res["codec"]
    lines += ["", "### 4. Codec and analysis", ""]
    rows = [
        ["codec encode, `PhaseSamples` (clip, pack, CRC, frame)", _num(c["encode_us"], "us/frame")],
        [
            "codec decode, `PhaseSamples` (unpack, CRC, range check)",
            _num(c["decode_us"], "us/frame"),
        ],
    ]
    if "hot_pack_us" in c:
        rows += [
            [
                "payload pack: hot path / cantools",
                f"{_num(c['hot_pack_us'])} / {_num(c['cantools_pack_us'])} us",
            ],
            [
                "payload unpack: hot path / cantools",
                f"{_num(c['hot_unpack_us'])} / {_num(c['cantools_unpack_us'])} us",
            ],
        ]
    rows += [
        ["capture analysed (BLF written with python-can)", _num(c["analyze_frames"], "frames")],
        ["reading it (python-can's BLF reader)", _num(c["capture_read_frames_per_s"], "frames/s")],
        [
            "decoding it into the per-period table (`analyze_frames`)",
            _num(c["analyze_frames_per_s"], "frames/s"),
        ],
        [
            "`bench analyze` end to end (read, decode, metrics, CSV; no plot)",
            _num(c["analyze_end_to_end_frames_per_s"], "frames/s"),
        ],
    ]
    lines += _table(["figure", "measured"], rows)
    lines += [
        "",
        "### 5. Bus load: highest PWM rate the shipped DBC fits (worst-case stuffing)",
        "",
    ]
    rows = [
        [
            r["layout"],
            r["bus"],
            _num(r["period_us_max"], "us"),
            _num(r["max_rate_hz"] / 1e3, "kHz"),
            _num(r["max_rate_hz_practical"] / 1e3, "kHz"),
        ]
        for r in res["busload"]
    ]
    lines += _table(
        ["frames every period", "bus", "wire time per period", "at 100 % load", "at 80 % load"],
        rows,
    )
    return lines


def _missed_reasons(res: dict[str, Any]) -> list[str]:
    """One paragraph per missed target: what limits it, every number from ``res``."""
    v = res["verdicts"]
    inp = res["inprocess"]
    out: list[str] = []
    alone = inp["alone_us_per_period"]
    e_loop, loop = _fastest(inp["tt_dq_10khz"])
    ctrl_us = alone["controller_tt_dq"]["compiled"]  # one engine, the core
    plant_us = alone["average"].get(e_loop, math.nan)
    rest_us = loop["us_per_step"] - plant_us - ctrl_us
    load = res["machine"].get("loadavg_1min_start", math.nan)
    if not v["inprocess_rtf_10khz_tt_dq"]["met"]:
        need = 1e6 / (F_10KHZ * TARGETS["inprocess_rtf_10khz_tt_dq"])
        out.append(
            f"- **In-process closed loop.** The target asks for at most {_num(need, 'us')} per "
            f"step; the loop takes {_num(loop['us_per_step'], 'us')} on the {e_loop} engine: "
            f"the plant alone {_num(plant_us, 'us')} per period (its `sample()` and `step()` "
            f"as Python calls them, the model's step inside), the tt-dq controller alone "
            f"{_num(ctrl_us, 'us')} per step, and the loop's own Python the remaining "
            f"{_num(rest_us, 'us')}: a `Measurement` and the duties built every period and "
            "the calls between the two. On the compiled engine what is left is Python's cost "
            "per call and per object around the two C steps, not the models' arithmetic. "
            "The figures are wall-clock times on a shared two-core machine (one-minute load "
            f"average {_num(load)} at the start of this run): other work on the cores "
            "lengthens every one of them."
        )
    if not v["inprocess_compiled_over_python_tt_dq"]["met"] and "compiled" in inp["tt_dq_10khz"]:
        py = inp["tt_dq_10khz"]["python"]["us_per_step"]
        out.append(
            f"- **Compiled against Python.** The compiled engine runs the plant "
            f"{_num(alone['average'].get('compiled_over_python', math.nan), 'x')} faster "
            f"than Python, the loop only {_num(inp['tt_dq_10khz']['compiled_over_python'], 'x')}; "
            "the controller has one engine on both, its C core (its Python step is the "
            "tests' oracle, `tests/oracle/`, not an engine the bench runs, and not timed "
            "here): what is Python on both engines is the same on both and bounds the "
            "ratio. That "
            f"is the loop's own Python ({_num(rest_us, 'us')} per step on the compiled "
            f"engine; with it alone the bound is {_num(py / rest_us, 'x')}, the Python loop "
            f"of {_num(py, 'us')} over it) and the Python of the plant's `sample()` and "
            "`step()` around its C step, which the plant-alone figure "
            f"({_num(plant_us, 'us')}) includes: a `Sample` built every period, the "
            "states copied back from the core. The models' arithmetic is no longer what "
            "the loop spends."
        )
    nat = res.get("inprocess_native")
    if nat is not None and not v["inprocess_native_us_per_step_tt_dq"]["met"]:
        us = nat["us_per_step_tt_dq"]
        rest = us - nat["plant_us"] - nat["controller_us"]
        out.append(
            f"- **In-process native pair.** The pair spends {_num(us, 'us')} per step inside "
            f"C against the target's {_num(TARGETS['inprocess_native_us_per_step_tt_dq'], 'us')}. "
            f"With the units timed, the plant unit takes {_num(nat['plant_us'], 'us')} per "
            "period (the model's step with its PWM sub-intervals, the commands, and the "
            f"instant's frames encoded with their CRC) and the controller unit "
            f"{_num(nat['controller_us'], 'us')} (the frames decoded and checked, the tt-dq "
            f"core's step, the duty and telemetry encoded); the pair's own hand-over about "
            f"{_num(rest, 'us')}. No Python runs per period "
            f"({_num(nat['returns_per_1000_steps'])} returns per 1,000 steps): what is "
            "left is the two cores' arithmetic, which must stay the same bits. On wen-5.1 "
            "the plant takes two RK4 steps per period, eight stages in one chain (each "
            "stage's currents wait for the last one's square root and two divisions), "
            "and seven of the eight stages and the sensors' angle each need a cosine and "
            "sine from libm; the controller four more (its estimator's angle, the "
            "estimate, the output angle, the injection's phase). Beside them the frames' "
            "E2E CRC (a byte at a time through a table) and the encoding. The figures are "
            "wall-clock times on a shared two-core machine (one-minute load average "
            f"{_num(load)} at the start of this run): other work on the cores lengthens "
            "every one of them."
        )
    if not v["switching_rtf_10khz"]["met"]:
        e_sw, sw = _fastest(inp["switching_10khz"])
        sw_plant = alone["switching"].get(e_sw, math.nan)
        c_sw = ctrl_us
        out.append(
            f"- **Switching plant.** The loop takes {_num(sw['us_per_step'], 'us')} per step on "
            f"the {e_sw} engine, of which the switching plant alone {_num(sw_plant, 'us')} "
            f"(its carrier timeline and sub-intervals) and the controller {_num(c_sw, 'us')}; "
            f"the loop's own Python the remaining "
            f"{_num(sw['us_per_step'] - sw_plant - c_sw, 'us')}."
        )
    ls = res["lockstep"]
    if not v["lockstep_periods_per_s"]["met"]:
        budget = 1e6 / TARGETS["lockstep_periods_per_s"]
        e_n = "compiled" if "compiled" in inp["plant_node_10khz"] else "python"
        nodes_us = inp["plant_node_10khz"][e_n]["us_p50"] + ctrl_us
        text = (
            f"- **Two-process lockstep.** The target leaves {_num(budget, 'us')} per period for "
            f"everything; the sample -> duty round trip on the bus alone has a median of "
            f"{_num(ls['rtt_us_p50'], 'us')}, of which the two nodes' computation in-process "
            f"(the plant node's step and encoding, the controller's step) is about "
            f"{_num(nodes_us, 'us')}. The rest is the transport: every period is one round "
            f"trip through {ls['transport']} and python-can in both processes, and the "
            "recorder, a third process, receives every frame too; the three share two cores."
        )
        if ls["transport"] == "udp_multicast":
            text += (
                " On udp_multicast each frame is packed with msgpack, sent on a socket, "
                "and every process wakes from `select` and unpacks every frame of the bus, "
                "its own included; SocketCAN (vcan or a real interface) spares a node its "
                "own frames."
            )
        out.append(text)
    fifo10 = res["realtime_fifo"]["10kHz"]
    if not v["plant_node_us_p50_10khz"]["met"]:
        node = inp["plant_node_10khz"]
        e_n = "compiled" if "compiled" in node else "python"
        out.append(
            f"- **Plant node computation at 10 kHz.** In the real-time run the plant node "
            f"takes {_num(fifo10['busy_us_median'], 'us')} per period (median, from its "
            "wake-up to its next wait). In-process, without a bus, the same node's step and "
            f"frame encoding take {_num(node[e_n]['us_p50'], 'us')} ({e_n} engine): the rest is "
            "the transport, sending the period's frames and receiving and decoding every "
            "frame on the bus through python-can; sending one period's two frames alone "
            f"takes {_num(res['transport_send_us']['median'], 'us')} (median) on "
            f"{ls['transport']}."
        )
    for key, sec, name, label in (
        ("realtime_missed_pct_4khz_fifo", "realtime_fifo", "4kHz", "4 kHz with `--rt-priority`"),
        ("realtime_missed_pct_10khz_fifo", "realtime_fifo", "10kHz", "10 kHz with `--rt-priority`"),
        ("realtime_missed_pct_1khz_normal", "realtime", "1kHz", "1 kHz, normal scheduling"),
    ):
        if v[key]["met"]:
            continue
        r = res[sec][name]
        T_us = 1e6 / r["f_sw"]
        stalls = (
            f"{r['host_stalls']:.0f} host stalls (longest {_num(r['host_stall_ms_max'], 'ms')}, "
            f"{_num(r['host_stall_ms_total'], 'ms')} in all) skipped "
            f"{r['periods_skipped']:,.0f} periods"
            if r["host_stalls"]
            else "there was no host stall"
        )
        text = (
            f"- **Real time, {label}.** {_num(r['missed_pct'], '%')} of the periods were "
            f"missed: {_num(r['late_outside_stalls_pct'], '%')} started late outside host "
            f"stalls, and {stalls}. "
        )
        if r["host_stalls"] and r["late_outside_stalls_pct"] <= TARGETS[key]:
            text += (
                "Outside the stalls the plant kept the target: the host's stalls, counted "
                "apart, are what misses it. "
            )
        if r["busy_us_median"] > T_us:
            text += (
                f"The plant's computation per period ({_num(r['busy_us_median'], 'us')} "
                f"median) exceeds the {_num(T_us, 'us')} period: the plant falls behind its "
                "clock by itself, and what the clock counts as stalls here is that backlog "
                "reaching the stall threshold, not the host. The computation is mostly the "
                "transport (see the plant node above)."
            )
        if ls["rtt_us_p50"] > T_us:
            text += (
                f" The controller's answer also missed its period in "
                f"{_num(r['late_duty_pct'], '%')} of the periods: the sample -> duty round trip "
                f"through the transport (median {_num(ls['rtt_us_p50'], 'us')} in lockstep) "
                "is longer than the period."
            )
        elif r["busy_us_p99"] > T_us:
            text += (
                f"The plant's computation fits the {_num(T_us, 'us')} period at the median "
                f"({_num(r['busy_us_median'], 'us')}) but not at the 99th percentile "
                f"({_num(r['busy_us_p99'], 'us')}): every slow period makes the next late. "
                "The computation is measured on the wall clock, so it includes the time the "
                "plant was preempted: on this shared two-core virtual machine the controller, "
                "the recorder and other work compete for the same cores"
                + (
                    ", and under normal scheduling any of them may run before the plant."
                    if r.get("policy") != "fifo"
                    else "."
                )
            )
        else:
            text += (
                f"The plant's computation fits the {_num(T_us, 'us')} period "
                f"({_num(r['busy_us_median'], 'us')} median, {_num(r['busy_us_p99'], 'us')} "
                f"p99); the worst wake-up was {_num(r['jitter_us_max'] / 1e3, 'ms')} late: the "
                "missed periods are the times this shared virtual machine did not run the "
                "plant at its deadline (docs/REALTIME.md: a core of its own, `isolcpus`, "
                "PREEMPT_RT)."
            )
        out.append(text)
    c = res["codec"]
    if not v["analyze_frames_per_s"]["met"]:
        out.append(
            f"- **Analysis, decoding.** Decoding the capture runs at "
            f"{_num(c['analyze_frames_per_s'])} frames/s, vectorised with numpy over the "
            "whole capture once the frames are in memory; what is left per frame is "
            "reading each python-can message object's fields."
        )
    if not v["analyze_end_to_end_frames_per_s"]["met"]:
        n = c["analyze_frames"]
        t_all = n / c["analyze_end_to_end_frames_per_s"]
        t_read = n / c["capture_read_frames_per_s"]
        t_dec = n / c["analyze_frames_per_s"]
        out.append(
            f"- **Analysis, the whole command.** Of its {_num(t_all, 's')} on this capture, "
            f"reading the BLF file takes {_num(t_read, 's')} (python-can's reader, "
            f"{_num(c['capture_read_frames_per_s'])} frames/s: it inflates the file and "
            "builds one Python message object per frame), decoding "
            f"{_num(t_dec, 's')}, and the metrics and writing `signals.csv` and the JSON "
            f"files the remaining {_num(max(0.0, t_all - t_read - t_dec), 's')}."
            + (
                " The reader alone is below the target: meeting it needs a BLF reader that "
                "fills arrays instead of building message objects."
                if c["capture_read_frames_per_s"] < TARGETS["analyze_end_to_end_frames_per_s"]
                else ""
            )
        )
    return out


#: Text of docs/BENCHMARKS.md that is not a figure (it holds no number).
_DOC_HEAD = """\
# Benchmarks

<!-- Written by `bench perf --doc` from docs/perf/perf.json: do not edit; rerun `make perf`.
     tests/test_perf.py checks that this page is the rendering of that file. -->

Produced by

```sh
make perf    # = .venv/bin/bench perf --out docs/perf --doc docs/BENCHMARKS.md --readme README.md
```

which measures everything in one run, writes [`docs/perf/perf.json`](perf/perf.json) and
renders this page from it (every figure below comes from that file; `bench perf
--from-json docs/perf/perf.json --doc docs/BENCHMARKS.md` renders it again without
measuring).  `bench perf --quick` runs the same sections briefly; the tests use it and
check only that every figure is there.  Each figure is a median of several runs inside
the one process; the machine is shared, so timings vary between runs: compare the ratios
measured in the same run.
"""

_DOC_DEFINITIONS = """\
Real-time terms (`bench/nodes/_clock.py`): a period is *late* when the plant woke up after
its deadline; a wake-up later than the stall threshold is a *host stall*: the clock
resynchronises instead of running the missed periods back to back, and those periods are
*skipped* (never computed).  *Missed* counts every period not computed on time, late or
skipped, of the periods scheduled: the targets are judged on it.  *Late outside stalls*
leaves out the wake-ups that ended a stall: the bench's own lateness.  *Late duties*: the
controller's answer missed its period.  *Computation*: the plant node's work per period,
from its wake-up to its next wait (send the instant's frames, receive and decode
everything on the bus, step the model, encode the next frames).
"""

_DOC_BUSLOAD = """\
The bus load is the physical limit a real bus sets whatever the computer: the two-frame
loop of a real drive on classic CAN fits the rate of the "control" rows, which is why the
Xue scenarios at their low PWM rate are the ones to run against real hardware.
"""


def render_benchmarks(res: dict[str, Any]) -> str:
    """``docs/BENCHMARKS.md``: every figure of ``perf.json``, the targets, what limits them."""
    m = res["machine"]
    missing = "; ".join(
        w
        for w in (
            res["engines"].get("compiled_missing"),
            res["engines"].get("controller_compiled_missing"),
        )
        if w
    )
    lines = [
        _DOC_HEAD,
        f"Machine of this run: {m['cpus']} cores, `{m['platform']}`, Python {m['python']}; "
        f"transport {res['lockstep']['transport']}; engines (plant and controller) measured: "
        f"{', '.join(res['engines']['measured'])}"
        + (f" ({missing})" if missing else "")
        + f". The run took {_num(res.get('wall_s', math.nan) / 60.0, 'min')}; the machine's "
        f"one-minute load average was {_num(m.get('loadavg_1min_start', math.nan))} at its "
        f"start and {_num(m.get('loadavg_1min_end', math.nan))} at its end (this run's own "
        "processes included)"
        + (" (`--quick`: short runs, figures not comparable)." if res.get("quick") else "."),
        "",
        "## Targets (issue 14)",
        "",
        *targets_table(res),
        "",
        "## What limits the missed targets",
        "",
    ]
    reasons = _missed_reasons(res)
    lines += reasons if reasons else ["Every target is met in this run."]
    lines += ["", *demo_lines(res)] if "demo" in res else []
    lines += ["", "## All figures", "", _DOC_DEFINITIONS, *figures_sections(res), "", _DOC_BUSLOAD]
    if res.get("inprocess_profile_tt_dq"):
        lines += [
            "## Profile of the in-process tt-dq loop (default engine, top entries by own time)",
            "",
            "```",
            *res["inprocess_profile_tt_dq"],
            "```",
            "",
        ]
    return "\n".join(lines).rstrip() + "\n"


#: The markers of the generated block in the README's Performance section.
README_BEGIN = (
    "<!-- perf:begin (written by bench perf --readme from docs/perf/perf.json; do not edit) -->"
)
README_END = "<!-- perf:end -->"


def render_readme_block(res: dict[str, Any]) -> str:
    """The README's block: the targets of the last ``make perf``, the native pair's (the
    default engine) first, then the in-process, Python-node and analysis ones."""
    v = native_verdicts(res)
    native = (
        []
        if v is None
        else [
            "The native pair (`--engine native`, the default: each node's whole loop in C; "
            "what limits a missed target: [docs/REALTIME.md](docs/REALTIME.md)):",
            "",
            *native_targets_table(v, limits=False),
            "",
            "In process, the Python plant node (`bench plant --engine python`, beside the "
            "native controller node) and the analysis:",
            "",
        ]
    )
    return "\n".join(
        [
            README_BEGIN,
            "",
            *native,
            *targets_table(res),
            "",
            README_END,
        ]
    )


def update_readme(text: str, res: dict[str, Any]) -> str:
    """``text`` with its perf block replaced; a README without the markers is an error."""
    if README_BEGIN not in text or README_END not in text:
        raise ValueError("no perf block (the markers of bench perf --readme) in this README")
    head, _, rest = text.partition(README_BEGIN)
    _, _, tail = rest.partition(README_END)
    return head + render_readme_block(res) + tail


def format_perf(res: dict[str, Any]) -> str:
    """The console output: the targets, then every figure (the page's Markdown tables)."""
    demo = ["", *demo_lines(res)] if "demo" in res else []
    return "\n".join(["targets:", *targets_table(res), *demo, "", *figures_sections(res)])
