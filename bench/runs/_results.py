"""A run's files from its frames: table, metrics, metadata, plots, and the printed summary.

:func:`finish_run` is the one path from frames to files, used by a live run
(:mod:`bench.runs._run`) and by ``bench analyze`` of a capture alike, so both
give the same files.  :func:`format_metrics` is the table a run prints beside
the paper's number; :func:`fault_warning` and :func:`realtime_warning` are
the warning lines that go with it.
"""

from __future__ import annotations

import json
import math
import platform
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import can
import numpy as np

from bench import _jsonio as jsonio
from bench._errors import (
    EXIT_FAULT_EXPECTATION,
    EXIT_LOCK_LOST,
    EXIT_MODEL_RANGE,
    EXIT_NOT_SCORED,
    EXIT_PLANT_TRIPPED,
)
from bench.nodes._counters import REPEATED_COUNTER
from bench.runs._analysis import analyze_frames, signals_doc, write_csv
from bench.runs._metrics import (
    BAND_QUANTITIES,
    BANDS,
    SpeedLoop,
    band_metrics,
    compute_metrics,
    fault_metrics,
    late_duty_fraction,
    plant_periods,
    split_corner_hz,
)
from bench.scenarios._schema import Scenario
from bench.scenarios._setup import (
    countermeasures,
    get_preset,
    lockstep_delay,
    n_steps,
    plant_setup,
    sample_period,
)
from bench.wire._codec import Codec
from bench.wire._frames import FrameArray, with_ids
from bench.wire._protocol import unwrap
from plant_rt import FLUX_RANGE


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


def run_metadata(
    scn: Scenario,
    estimator: str,
    *,
    mode: str,
    transport: str,
    link: bool,
    design: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The run's ``meta.json`` before its results (docs/RUNS.md).

    ``design``: the controller as its node built it (the node's report,
    :func:`bench.nodes._controller_node.controller_design`); its gains are
    recorded as they are.  None (an in-process run, a test): the controller is
    built here to learn them.
    """
    return {
        "scenario": scn.to_dict(),
        "estimator": estimator,
        "mode": mode,
        "transport": transport,
        "latency_link": link,
        "lockstep_delay_steps": lockstep_delay(scn),
        **plant_record(scn),
        "seed": scn.seed,
        # every gain, bandwidth, filter corner and delay the controller uses
        # (controller.Controller.gains); none for an external controller
        "controller": "external" if estimator == "external" else "bench",
        "controller_gains": {}
        if estimator == "external"
        else _controller_gains(scn, estimator, design),
        # the scenario's [estimator_options] this estimator does not take, and the note on them
        "estimator_options_left_out": [] if estimator == "external" else _left_out(scn, estimator),
        # the drive's countermeasures the bench's controller runs (None: a controller under test)
        "countermeasures": None if estimator == "external" else countermeasures(scn),
        "versions": _versions(),
    }


def plant_record(scn: Scenario) -> dict[str, Any]:
    """What ``meta.json`` records of the plant a scenario builds (docs/RUNS.md).

    ``T_s``, ``f_sw``, ``u_dc`` and ``motor`` as built (the preset's with the
    scenario's ``[motor]``, ``[magnetics]``, ``[inverter]`` and ``f_sw`` in
    place); ``preset``: the same values with the preset's reasoning (``doc``)
    and, under ``replaced``, the preset's own values the scenario replaced;
    ``plant``: the profile as built.  ``bench analyze`` records it again for
    the scenario it analyses with.
    """
    from dataclasses import asdict

    p, prof = plant_setup(scn)
    motor = asdict(p.motor)  # as built: the preset's with [motor] and [magnetics] in place
    inverter = asdict(prof.inverter)  # as built: the profile's with [inverter] in place
    f_sw = 1.0 / sample_period(scn)
    return {
        "T_s": sample_period(scn),
        "f_sw": f_sw,
        "u_dc": prof.inverter.u_dc,
        "motor": motor,
        "preset": {
            "name": p.name,
            "motor": motor,
            "inverter": inverter,
            "f_sw": f_sw,
            "doc": p.doc,
            "replaced": _replaced_preset_values(
                p.name, {"motor": motor, "inverter": inverter, "f_sw": f_sw}
            ),
        },
        "plant": {
            "profile": prof.name,
            "inverter": inverter,
            "sensors": asdict(prof.sensors),
            "saturation": prof.saturation,
            "cross_saturation": prof.cross_saturation,
            "doc": prof.doc,
        },
    }


def _replaced_preset_values(name: str, run: dict[str, Any]) -> dict[str, Any]:
    """The shipped preset's own values that differ from the run's, by dotted key
    (``motor.R_s``, ``inverter.u_dc``, ``f_sw``)."""
    from dataclasses import asdict

    from plant_rt import PRESETS

    shipped = PRESETS[name]
    own = {
        "motor": asdict(shipped.motor),
        "inverter": asdict(shipped.inverter),
        "f_sw": shipped.f_sw,
    }

    def flat(d: Any, prefix: str = "") -> dict[str, Any]:
        if not isinstance(d, dict):
            return {prefix: d}
        out: dict[str, Any] = {}
        for k, v in d.items():
            out.update(flat(v, f"{prefix}.{k}" if prefix else str(k)))
        return out

    mine, theirs = flat(run), flat(own)
    return {k: v for k, v in theirs.items() if mine.get(k, v) != v}


def _left_out(scn: Scenario, estimator: str) -> list[str]:
    from bench.scenarios._setup import left_out_options

    try:
        return left_out_options(scn, estimator)
    except ValueError:  # an estimator that cannot be loaded: said elsewhere
        return []


def _controller_gains(
    scn: Scenario, estimator: str, design: dict[str, Any] | None
) -> dict[str, float]:
    from bench.scenarios._setup import build_controller

    if design is not None:
        return dict(design.get("gains") or {})
    try:
        return build_controller(scn, estimator).gains()
    except (ValueError, TypeError):  # an estimator that does not fit: said elsewhere
        return {}


def scoring_scenario(scn: Scenario, t_first: float, t_end: float) -> tuple[Scenario, str | None]:
    """The scenario to score a capture spanning ``t_first`` .. ``t_end`` (s) with, and what changed.

    A live run shorter than its scenario's scoring start is scored over its
    second half (:meth:`Scenario.with_overrides` with its ``duration``).  A
    capture whose span ends at or before ``score_from_s`` is scored the same
    way, from the middle of its span, with the scenario's duration set to the
    span's end, so that a capture of a shortened run scores as the live run
    did and the ``meta.json`` written with it scores the same again.
    """
    if scn.score_from_s < t_end:
        return scn, None
    t_end = round(t_end, 9)
    start = round(t_first + (t_end - t_first) / 2, 9)
    out = scn.with_overrides(duration=max(t_end, 1e-3), score_from_s=start)
    return out, (
        f"capture ends at {t_end:g} s, not after the scenario's scoring start "
        f"({scn.score_from_s:g} s): scoring its second half, from {start:g} s "
        "(as a run of that duration is scored)"
    )


def finish_run(
    frames: Sequence[can.Message],
    codec: Codec,
    scn: Scenario,
    out_dir: Path,
    *,
    meta: dict[str, Any],
    wall_s: float,
    capture: Path | None,
    plots: bool = True,
    overshoot: bool | None = None,
) -> RunResult:
    """Table, metrics, metadata and plots from a run's frames.

    ``overshoot``: whether the metrics hold ``speed_overshoot_rpm`` (None: where
    the scenario's paper reports one; a sweep asks for it at every point).
    """
    T_s = sample_period(scn)
    n_p = get_preset(scn).motor.n_p
    run_id = meta.get("run_id")
    cap = analyze_frames(frames, codec, T_s=T_s, n_p=n_p, run_id=run_id)
    cap.table["fault_active"] = fault_active(cap.table["step"], scn, T_s)
    write_csv(str(out_dir / "signals.csv"), cap.table)
    (out_dir / "signals.md").write_text(signals_doc(codec))
    m: dict[str, Any] = compute_metrics(
        cap.table,
        T_s=T_s,
        n_p=n_p,
        score_from_s=scn.score_from_s,
        thd_window_s=scn.thd_window_s,
        overshoot=("speed_overshoot_rpm" in scn.paper_result) if overshoot is None else overshoot,
    )
    reports = meta.get("node_reports", {})
    # the controller as its node built it (its report), when the run had one
    design = (reports.get("controller") or {}).get("design")
    m.update(hybrid_band_metrics(cap.table, scn, str(meta.get("estimator", "")), design))
    plant_r = reports.get("plant", {})
    ctrl_r = reports.get("controller", {})
    m["wall_s"] = wall_s
    # simulated time per wall second of the plant's stepping loop (process
    # start-up excluded); the whole run's wall time when no plant report
    loop_s = plant_r.get("loop_s") or wall_s
    m["realtime_factor"] = m["sim_s"] / loop_s if loop_s > 0 else float("nan")
    m["plant_periods"] = int(plant_r.get("steps", 0))
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
    # recorder frames failing their E2E check or range: never scored (DBC 2.1)
    m["frames_rejected_recorded"] = cap.frames_rejected
    m["run_id"] = cap.run_id
    # recorder frames of another run (another PlantTruth/CtrlTelemetry run_id): never scored
    m["frames_foreign"] = cap.frames_foreign
    m["frames_foreign_by_message"] = dict(cap.foreign)
    m["frames_unknown_id"] = cap.unknown_ids
    m["incomplete_steps"] = cap.incomplete_steps
    m["steps_without_telemetry"] = cap.steps_without_telemetry
    # periods 0 .. n - 1 of the scenario without a row: frames the recording lost
    # (or a run stopped early); the metrics above cover only the rows present
    n_run = n_steps(scn)
    present = np.unique(cap.table["step"][cap.table["step"] < n_run]).size
    m["steps_missing"] = int(n_run - present)
    m["frames_duplicate"] = cap.duplicates
    m["frames_copies"] = cap.copies
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
        from bench.runs._analysis import measure_latency

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
        jit = plant_r["jitter"]
        m["jitter_us"] = jit
        # host stalls, apart from the late periods (bench/nodes/_clock.py): the
        # periods that passed during a stall were skipped, not computed
        m["host_stalls"] = int(jit.get("stalls", 0))
        m["host_stall_ms_total"] = 1e-3 * float(jit.get("stall_total", 0.0))
        m["host_stall_ms_max"] = 1e-3 * float(jit.get("stall_max", 0.0))
        m["periods_skipped"] = int(jit.get("skipped", 0))
        # where they were (the capture's gaps): a run folder without its capture keeps them
        m["host_stall_at_s"] = host_stall_times(frames, codec, T_s) if m["host_stalls"] else []
    # the first trip, from the capture; the plant's report (its latched, so
    # last, fault) only when the capture lost the status frame
    fault, fault_step = plant_fault(frames, codec)
    if fault == "none" and plant_r.get("fault") not in (None, "none"):
        fault, fault_step = str(plant_r["fault"]), int(plant_r.get("fault_step", -1))
    m["plant_fault"] = fault
    m["plant_fault_step"] = fault_step
    # time the plant's current spent beyond its flux map's checked range (its report;
    # None for a capture analysed without one)
    n_out = plant_r.get("out_of_range_periods")
    m["plant_out_of_range_s"] = None if n_out is None else int(n_out) * T_s
    m["faults"] = fault_metrics(
        cap.table,
        [
            (f.kind, f.at_s, f.end_s(m["sim_s"]), f.expect)
            for f in scn.faults
            if f.at_s < m["sim_s"]
        ],
        T_s=T_s,
        plant_fault=fault,
        plant_fault_step=fault_step,
    )
    # the plant's own counters as it sent them (PlantStatus), e.g. for a capture
    # of a controller under test analysed without the node's report
    status = plant_status_counters(frames, codec)
    if status is not None:
        m["plant_status_late_frames"] = status["late_frames"]
        m["plant_status_overruns"] = status["overruns"]
        if not plant_r:
            m["deadline_misses"] = status["overruns"]
    meta = dict(
        meta,
        scored_from_s=scn.score_from_s,
        capture=capture.name if capture else None,
        wall_s=wall_s,
    )
    # the DBC of the run (a capture analysed later keeps the one it was recorded with)
    meta.setdefault("dbc_version", codec.version)
    (out_dir / "metrics.json").write_text(jsonio.dumps(m, indent=2, sort_keys=True) + "\n")
    (out_dir / "meta.json").write_text(
        json.dumps(meta, indent=2, sort_keys=True, default=str) + "\n"
    )
    if plots:
        from bench.runs._plots import plot_run

        plot_run(
            cap.table,
            out_dir,
            meta=meta,  # title, paper, its bound and the run's variations
            metrics=m,
            stalls=m.get("host_stall_at_s"),
            scored_from_s=scn.score_from_s,
            f_split_hz=fundamental_corner_hz(
                scn, str(meta.get("estimator", "")), cap.table, design
            ),
            n_p=n_p,
        )
    return RunResult(out_dir=out_dir, metrics=m, capture=capture or out_dir, meta=meta)


@dataclass(frozen=True, slots=True)
class Injection:
    """An estimator's HF injection as a node reports it (``design.injection``):
    ``w_h`` (rad/s, rotating) or ``R`` (PWM periods per square-wave period)."""

    w_h: float | None = None
    R: int | None = None


def fundamental_corner_hz(
    scn: Scenario,
    estimator: str,
    table: dict[str, Any],
    design: dict[str, Any] | None = None,
) -> float | None:
    """Corner (Hz) of the low-pass that gives ``run.png`` the fundamental current:
    :func:`bench.runs._metrics.split_corner_hz` of the estimator's injection up to the
    run's top speed; None when the estimator injects nothing (the raw current is the
    fundamental) or is not a built-in one.

    ``design``: the controller as its node reported it (``injection``); None
    (a capture without the report): the controller is built to learn it.
    """
    from bench.scenarios._setup import build_controller

    hf: Any
    if design is not None:
        hf = Injection(**(design.get("injection") or {}))
    else:
        try:
            est = build_controller(scn, estimator).estimator
        except Exception:  # an external or unfitting controller: no injection known
            return None
        hf = getattr(est, "hf", est)
    n_p = get_preset(scn).motor.n_p
    w_top = (
        float(np.max(np.abs(table["w_m_rpm"]))) * math.pi / 30.0 * n_p if len(table["t"]) else 0.0
    )
    try:
        return split_corner_hz(injection_floor_hz(hf, sample_period(scn), w_top))
    except ValueError:
        return None


def injection_floor_hz(hf: Any, T_s: float, w_top: float) -> float:
    """Lowest frequency (Hz) of an injection estimator's HF current in the true rotor frame,
    wherever it injects (true electrical speed up to ``w_top`` rad/s).

    Rotating injection (``w_h``, rad/s): the positive and negative sequences sit
    at ``+/-(w_h - w_e)`` in the rotor frame, lowest at the top speed. Square wave
    (``R`` PWM periods per injection period): along the estimated d axis, which
    turns with the rotor, so ``1 / (R T_s)`` at any speed (half the PWM rate).
    """
    w_h = getattr(hf, "w_h", None)
    if w_h is not None:
        return (float(w_h) - w_top) / (2.0 * math.pi)
    R = getattr(hf, "R", None)
    if R:
        return 1.0 / (int(R) * T_s)
    raise ValueError(
        f"{type(hf).__name__}: neither a rotating (w_h) nor a square-wave (R) injection"
    )


def hybrid_band_metrics(
    table: dict[str, Any],
    scn: Scenario,
    estimator: str,
    design: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The per-band metrics of a hybrid estimator's run (:func:`bench.runs._metrics.band_metrics`);
    ``{}`` for any other estimator.

    Everything comes from the controller the run used: as its node reported it
    (``design``, :func:`bench.nodes._controller_node.controller_design`), or,
    without that report (a capture, an in-process sweep), built again from the
    scenario (:func:`bench.scenarios._setup.build_controller`): the band's
    edges on the true speed (:attr:`controller.TransitionBand.edges`), the
    injection's lowest rotor-frame frequency (:func:`injection_floor_hz`, up to
    the band's upper edge: no injection above it) for the separation's corner,
    the speed PI's gains and filter for the hand-overs' expected speed. The
    mechanics and the loss are the plant's: its ``J``, ``b`` and ``R_s``, not the
    controller's model of them.
    """
    from bench._errors import BenchError
    from bench.nodes._controller_node import controller_design
    from controller import UnknownEstimatorError, estimator_spec

    try:
        if not estimator_spec(estimator).speed_band:
            return {}
    except UnknownEstimatorError:
        return {}
    if design is None:
        from bench.scenarios._setup import build_controller

        try:
            design = controller_design(build_controller(scn, estimator))
        except (BenchError, ValueError, TypeError):  # an estimator that does not fit
            return {}
    if not design.get("band_edges"):
        return {}
    T_s = sample_period(scn)
    lo, hi = (float(e) for e in design["band_edges"])
    f_c = split_corner_hz(injection_floor_hz(Injection(**design["injection"]), T_s, hi))
    motor = plant_setup(scn)[0].motor
    sl = design["speed_loop"]
    loop = SpeedLoop(sl["k_t"], sl["k_p"], sl["k_i"], sl["w_f"], motor.J, motor.b, sl["alpha_s"])
    edges = (lo, hi)
    return band_metrics(
        table,
        T_s=T_s,
        n_p=motor.n_p,
        edges=edges,
        R_s=motor.R_s,
        f_c=f_c,
        loop=loop,
        score_from_s=scn.score_from_s,
    )


def plant_fault(frames: Sequence[can.Message], codec: Codec) -> tuple[str, int]:
    """The plant's first protection trip in a capture: (fault name, period), or ("none", -1).

    From the ``PlantStatus`` frames the plant sends when it trips; their
    16-bit step is unwrapped against the 32-bit step of the last
    ``PlantTruth`` frame before it (the plant's own period count, whatever
    the capture's length, start, retransmissions or number of buses).
    """
    from bench.nodes._plant_node import fault_name

    id_status, id_truth = codec.frame_id("PlantStatus"), codec.frame_id("PlantTruth")
    m = 1 << codec.step_bits("PlantStatus")
    last_truth: can.Message | None = None
    for f in with_ids(frames, (id_status, id_truth)):
        if f.arbitration_id == id_truth:
            last_truth = f
        elif f.arbitration_id == id_status:
            d = codec.decode(f)
            if d is None or d.reason is not None or int(d.signals["fault_code"]) == 0:
                continue
            t = codec.decode(last_truth) if last_truth is not None else None
            ref = int(t.signals["step"]) if t is not None and t.reason is None else 0
            code = int(d.signals["fault_code"])
            return fault_name(code), unwrap(int(d.signals["step"]), ref, m)
    return "none", -1


def plant_status_counters(frames: Sequence[can.Message], codec: Codec) -> dict[str, int] | None:
    """The counters of the capture's last valid ``PlantStatus`` (None: the capture has none).

    ``late_frames`` (periods without their own duty plus duties rejected) and
    ``overruns`` (real-time deadlines missed) count from the plant's start, so
    the last frame holds the run's totals (saturated at 65535).
    """
    id_status = codec.frame_id("PlantStatus")
    for f in reversed(with_ids(frames, (id_status,))):
        if f.arbitration_id == id_status:
            d = codec.decode(f)
            if d is not None and d.reason is None:
                return {k: int(v) for k, v in d.signals.items() if k != "crc"}
    return None


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


def lock_warning(m: dict[str, Any]) -> str | None:
    """One line when the estimator lost the rotor angle (``lock_lost`` in the metrics)."""
    if not m.get("lock_lost"):
        return None
    return (
        f"warning: the estimator lost the rotor angle at t = {m.get('lock_lost_at_s', 0.0):.4f} s "
        "(|dtheta| above 90 deg electrical for more than 50 ms after the scoring start); "
        "the metrics are not a scenario result"
    )


def model_range_warning(m: dict[str, Any]) -> str | None:
    """One line when the plant's current left its flux map's checked range."""
    t = m.get("plant_out_of_range_s")
    if not t:
        return None
    return (
        f"warning: the plant's current was beyond its flux map's checked range "
        f"(|i_s| > {FLUX_RANGE:g} i_max) for {t:.4f} s: the motor model was identified on "
        "no machine there (the plant stays finite on its continuation); the metrics are not "
        "a scenario result"
    )


def telemetry_warning(m: dict[str, Any]) -> str | None:
    """One line for rows without the controller's telemetry, and for metrics left null."""
    parts = []
    n = int(m.get("steps_without_telemetry") or 0)
    if n:
        parts.append(
            f"{n:,} of {int(m.get('steps', 0)):,} periods have no CtrlTelemetry (the controller "
            "sent none, died, or the frame was lost): their estimate is empty in signals.csv "
            "and their position error is not scored"
        )
    if m.get("unscored_reason"):
        parts.append(f"metrics left null: {m['unscored_reason']}")
    if not parts:
        return None
    return f"warning: {'; '.join(parts)}"


def missing_rows_warning(m: dict[str, Any], meta: dict[str, Any]) -> str | None:
    """One line for periods of the run without a row in ``signals.csv`` (``steps_missing``);
    none for a run that Ctrl-C interrupted (its end is said already)."""
    missing = int(m.get("steps_missing", 0) or 0)
    if not missing or meta.get("interrupted"):
        return None
    return (
        f"warning: {missing} periods of the run have no row in signals.csv (the run ended "
        "early, or frames the recording lost); the metrics cover the rows present"
    )


def run_warnings(m: dict[str, Any], meta: dict[str, Any], status_lines: list[str]) -> list[str]:
    """Every warning line ``bench run`` prints, in its order: real time not kept (a
    real-time run), recorded frames not scored, ``status_lines`` (those of its exit
    status), rows missing.  The command line and :attr:`bench.Run.warnings` both take
    them from here."""
    lines = []
    if meta.get("mode") == "realtime" and (w := realtime_warning(m)):
        lines.append(w)
    if w := frames_warning(m):
        lines.append(w)
    lines += status_lines
    if w := missing_rows_warning(m, meta):
        lines.append(w)
    return lines


def frames_warning(m: dict[str, Any]) -> str | None:
    """One line for recorded frames that were not scored: bad ones and another run's."""
    parts = []
    bad = int(m.get("frames_rejected_recorded", 0))
    if bad:
        parts.append(
            f"{bad:,} recorded frames failed their check (E2E CRC, length, range or counter)"
        )
    foreign = int(m.get("frames_foreign", 0))
    if foreign:
        by = ", ".join(f"{k} {v:,}" for k, v in (m.get("frames_foreign_by_message") or {}).items())
        parts.append(f"{foreign:,} recorder frames of another run ({by})")
    if not parts:
        return None
    return f"warning: {'; '.join(parts)}: not scored"


def fault_active(step: Any, scn: Scenario, T_s: float) -> Any:
    """``signals.csv`` ``fault_active``: how many faults of the timeline cover each period."""
    k = np.asarray(step, dtype=float)
    out = np.zeros(len(k))
    for f in scn.faults:
        k0, k1 = f.periods(T_s)
        out += (k >= k0) & (k < (math.inf if k1 is None else k1))
    return out


def outcome(m: dict[str, Any], T_s: float) -> tuple[int, list[str]]:
    """The exit status of a finished run or analysis and its warning lines.

    3 when the plant tripped a protection, 8 when not one period was scored
    (``scored_steps`` 0: a controller disabled throughout, nothing recorded), 4 when
    the estimator lost the rotor angle, 7 when the plant's current left its flux
    map's checked range (``plant_out_of_range_s``), 0 otherwise (DESIGN.md).  A trip
    comes first: an estimator whose inverter was switched off loses the angle as a
    consequence, and a controller that sees a trip may disable itself; a lost angle
    comes before the range, whose runaway it causes.  A run with
    fault expectations (``[[faults]]`` ``expect``) exits 6 when one was missed
    and 0 when every one held, even when what held was a trip (the lines
    still say what happened).
    """
    lines = [
        w
        for w in (
            fault_warning(m, T_s),
            lock_warning(m),
            model_range_warning(m),
            telemetry_warning(m),
        )
        if w
    ]
    expected = [f for f in m.get("faults") or [] if f.get("expect") is not None]
    missed = [f for f in expected if not f.get("met")]
    for f in missed:
        lines.append(
            f"warning: fault {f['kind']} at {f['at_s']:g} s: expected {f['expect']}, got "
            + (
                f"{f['detected_by']} after {f['reaction_ms']:.1f} ms"
                if f.get("detected_by")
                else "no detection"
            )
            + ("" if f.get("lock_kept") is not False else ", rotor angle lost")
        )
    if missed:
        return EXIT_FAULT_EXPECTATION, lines
    if expected:
        return 0, lines
    if m.get("plant_fault", "none") not in ("none", None):
        return EXIT_PLANT_TRIPPED, lines
    if m.get("scored_steps", m.get("steps")) == 0:
        return EXIT_NOT_SCORED, lines
    if m.get("lock_lost"):
        return EXIT_LOCK_LOST, lines
    if m.get("plant_out_of_range_s"):
        return EXIT_MODEL_RANGE, lines
    return 0, lines


#: Real-time runs with more late periods than this get a warning (fraction).
REALTIME_LATE_WARN = 0.01


def host_stall_times(frames: Sequence[can.Message], codec: Codec, T_s: float) -> list[float]:
    """Where a real-time plant met its host stalls, in simulated time (s): the periods after
    which its ``PlantTruth`` frames stopped for longer than a stall (:func:`bench.nodes._clock.
    default_stall_s`) beyond their usual spacing.  The periods a stall skipped were never
    computed (bench/nodes/_clock.py), so in simulated time a stall is an instant."""
    from bench.nodes._clock import default_stall_s

    truth = with_ids(frames, (codec.frame_id("PlantTruth"),))
    if isinstance(truth, FrameArray):
        ts = np.asarray(truth.rows["timestamp"], dtype=float)
    else:
        truth = [f for f in truth if f.arbitration_id == codec.frame_id("PlantTruth")]
        ts = np.fromiter((f.timestamp for f in truth), dtype=float, count=len(truth))
    if len(ts) < 3:
        return []
    dt = np.diff(ts)
    gaps = np.flatnonzero(dt > float(np.median(dt)) + default_stall_s(T_s)) + 1
    out: list[float] = []
    for i in gaps:
        d = codec.decode(truth[int(i) : int(i) + 1][0])  # one frame made, not all
        if d is not None and d.reason is None:
            out.append(int(d.signals["step"]) * T_s)
    return out


def realtime_warning(m: dict[str, Any]) -> str | None:
    """One line when a real-time run did not keep time well enough to read as a drive's."""
    steps = plant_periods(m)
    late = late_duty_fraction(m)
    over = m.get("deadline_misses", 0) / steps
    if max(late, over) <= REALTIME_LATE_WARN:
        return None
    worst = (m.get("jitter_us") or {}).get("max", float("nan")) * 1e-3
    stalls = int(m.get("host_stalls", 0))
    host = (
        f"; {stalls} host stalls (longest {m.get('host_stall_ms_max', 0.0):.1f} ms, "
        f"{int(m.get('periods_skipped', 0))} periods skipped)"
        if stalls
        else ""
    )
    return (
        f"warning: real time not kept: {100 * late:.1f} % of periods ran with a late duty, "
        f"{100 * over:.1f} % started late (worst wake-up {worst:.1f} ms){host}; the figures "
        "include this machine's scheduling, not only the controller (see docs/USAGE.md, --rt-priority)"
    )


METRIC_ROWS = (
    ("theta_err_max_deg", "deg"),
    ("theta_err_min_deg", "deg"),
    ("theta_err_mean_deg", "deg"),
    ("theta_err_abs_mean_deg", "deg"),
    ("theta_err_rms_deg", "deg"),
    ("theta_err_abs_max_deg", "deg"),
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

#: What the rows measured by a clock measure (the last column): the run's wall time and
#: the plant loop's speed are not one span, so ``sim_s / wall_s`` is not ``realtime_factor``.
CLOCK_LABELS = {
    "wall_s": "wall time of the whole run: node start-up and stop included",
    "realtime_factor": "sim_s per wall second of the plant's loop alone (start-up excluded)",
}

#: Units of the per-band quantities (``band_<band>_<quantity>``).
_BAND_UNITS = {
    "steps": "",
    "theta_err_abs_max_deg": "deg",
    "theta_err_abs_mean_deg": "deg",
    "speed_err_max_rpm": "rpm",
    "injection_loss_w": "W",
    "torque_ripple_rms_nm": "N m",
}
#: Rows of a hybrid estimator's run, after :data:`METRIC_ROWS`.
BAND_ROWS = (
    ("band_lo_rpm", "rpm"),
    ("band_hi_rpm", "rpm"),
    *((f"band_{b}_{q}", _BAND_UNITS[q]) for b in BANDS for q in BAND_QUANTITIES),
    ("handover_dip_max_pct", "%"),
)


def format_metrics(
    m: dict[str, Any],
    paper: dict[str, Any] | None = None,
    paper_method: str | None = None,
    estimator: str | None = None,
    column: str = "bench",
) -> str:
    """The metrics as an aligned text table, with the paper's number where it has one.

    ``column``: the heading of the run's column (a controller under test: its
    ``--dut-name``, at most 12 characters).

    ``paper_method``: the method the paper's numbers belong to (the
    scenario's own estimator), named in the column's heading.  ``estimator``:
    the run's; when it is another, the paper's column is left out (its
    numbers are not this method's) and a last line says where they apply.
    A scenario without the paper's numbers (a user's own) has no paper
    column.  The last column says what an error row measures
    (:data:`bench.runs._metrics.METRIC_LABELS`: which ones keep their sign) and which
    span a timed row covers (:data:`CLOCK_LABELS`).  A paper number compared with
    another metric than its key's (:data:`bench.runs._metrics.PAPER_COMPARED_AS`:
    Wen's "dtheta avg" is a mean |dtheta|) stands on that metric's row.
    """
    from bench.runs._metrics import METRIC_LABELS, PAPER_COMPARED_AS

    paper = paper or {}
    paper = {
        **{PAPER_COMPARED_AS[k]: v for k, v in paper.items() if k in PAPER_COMPARED_AS},
        **{k: v for k, v in paper.items() if k not in PAPER_COMPARED_AS},
    }
    note = ""
    if paper and paper_method and estimator and estimator != paper_method:
        note = f"\n(the paper's numbers are for {paper_method}; this run is {estimator})"
        paper = {}
    head = f"paper ({paper_method})" if paper_method else "paper"
    rows = [(k, u) for k, u in (*METRIC_ROWS, *BAND_ROWS) if k in m]
    wk = max([26, *(len(k) + 1 for k, _ in rows)])
    lines = [f"{'metric':<{wk}}{column[:12]:>12}" + (f"  {head}" if paper else "")]
    for key, unit in rows:
        v = m[key]
        vs = f"{v:12.3f}" if isinstance(v, float) else f"{'-' if v is None else v:>12}"
        ps = (f"  {paper[key]:>8}" if key in paper else f"  {'':>8}") if paper else ""
        label = METRIC_LABELS.get(key) or CLOCK_LABELS.get(key, "")
        lines.append(f"{key:<{wk}}{vs}{ps} {unit:<4}{f' {label}' if label else ''}".rstrip())
    return "\n".join(lines) + note
