"""``bench rerun``: a recorded capture through an estimator, offline.

The sample frames of a capture (``PhaseSamples``) are fed, in capture order,
into a :class:`~bench.nodes._controller_node.ControllerNode` built for the chosen estimator,
together with the recorded bench commands (applied at their steps exactly as
the live controller applied them) and, for the sensored baseline, the
recorded ``PlantTruth``.  The node's ``CtrlTelemetry`` is then scored against
the recorded truth with the same table and metrics a live run uses.

Open loop: the duties the rerun controller computes are not applied to
anything.  The currents in the capture respond to the duties of the
controller that was recorded, including its HF injection.  Consequences:

- the estimator (and settings) that produced the capture reproduces its
  logged estimate bit for bit: the controller is deterministic and sees the
  same decoded (DBC-quantized) inputs at the same steps;
- another estimator of the same injection family with the same settings
  demodulates currents that respond to an injection of its own kind: a fair
  comparison of demodulators and observers on identical data (its own
  closed loop would only differ in the fundamental-frequency regulation);
- an estimator of another family (rotating vs. square-wave injection) sees
  currents that respond to an injection it did not make; its score says how
  it copes with foreign signals, not how it performs.

For a two-bus capture (latency link) the controller's view is the
controller-side bus (channel 2).  Gaps in the samples are skipped (the node
restarts counting at the next recorded step); a capture that starts mid-run
starts the controller fresh at its first step (its state at that time is
not in the capture, so no reproduction is expected there).
"""

from __future__ import annotations

import bisect
import json
import math
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import can
import numpy as np

from bench import _jsonio as jsonio
from bench._errors import CaptureError
from bench.captures._read import (
    capture_scenario,
    incomplete_warning,
    read_capture_counted,
    scoring_scenario,
    skipped_warning,
)
from bench.captures._replay import (
    channel_tag,
)
from bench.runs._analysis import analyze_frames, signals_doc, write_csv
from bench.wire._batch_decode import decode_batch
from bench.wire._codec import Codec

__all__ = ["RerunResult", "injection_note", "rerun_capture"]


@dataclass(slots=True)
class RerunResult:
    """Scores and bookkeeping of a rerun (``report`` is what ``rerun.json`` holds)."""

    out_dir: Path
    metrics: dict[str, Any]
    report: dict[str, Any] = field(default_factory=dict)
    files: list[str] = field(default_factory=list)
    paper_result: dict[str, Any] = field(default_factory=dict)
    #: The method ``paper_result`` belongs to (the scenario's own estimator).
    paper_method: str | None = None
    #: The control period of the capture's scenario (s), for the warning lines.
    T_s: float = 0.0


def injection_note(estimator: str, recorded: str | None) -> str:
    """What the comparison of ``estimator`` on a capture of ``recorded`` means."""
    from bench.scenarios._setup import needs_truth
    from controller._registry import injection_family

    fam = injection_family(estimator)
    truth = needs_truth(estimator)
    if recorded is None:
        return (
            "open loop on a capture of an unknown controller: the currents respond to the "
            f"injection that controller applied, not to the {fam} injection of {estimator}"
        )
    rec_fam = injection_family(recorded)
    if estimator == recorded and truth:
        return (
            f"same estimator as recorded ({recorded}, no injection): it reads the recorded "
            "truth angle; the logged estimate is reproduced"
        )
    if estimator == recorded:
        return (
            f"same estimator as recorded ({recorded}): the currents respond to its own "
            "injection; with the same settings its logged estimate is reproduced"
        )
    if truth:
        return (
            f"the sensored baseline reads the recorded truth angle; the currents respond to "
            f"the {rec_fam} injection of {recorded}"
        )
    if fam == rec_fam:
        return (
            f"open loop: the currents respond to the injection of {recorded}, not of "
            f"{estimator}; both use the {fam} injection with the same scenario settings, so "
            f"{estimator} demodulates the response to an injection of its own kind: a fair "
            "comparison on identical data (the fundamental currents follow the recorded "
            "controller's regulation, not this one's)"
        )
    return (
        f"not like for like: the currents respond to the {rec_fam} injection of {recorded}, "
        f"not to the {fam} injection {estimator} would apply; its score shows how it copes "
        "with foreign signals, not how it performs in its own loop"
    )


def _controller_view(
    frames: list[can.Message], truth_id: int | None
) -> tuple[list[can.Message], str]:
    """The frames the controller saw: bus 2 of a two-bus capture, else all."""
    tags = {channel_tag(f.channel) for f in frames[:5000]}
    if {1, 2} <= tags:
        view = [f for f in frames if channel_tag(f.channel) == 2]
        if truth_id is not None and not any(f.arbitration_id == truth_id for f in view[:5000]):
            return frames, "both buses (the controller-side bus carries no truth)"
        return view, "controller-side bus (channel 2)"
    return frames, "the whole capture (one bus)"


def rerun_capture(
    path: Path,
    estimator: str,
    *,
    scenario: str | None = None,
    out_dir: Path | None = None,
    codec: Codec | None = None,
    plots: bool = True,
    echo: Callable[[str], None] | None = None,
) -> RerunResult:
    """Feed a capture's samples into ``estimator``'s controller and score its estimate.

    Parameters
    ----------
    path : Path
        Capture (any python-can format) or run folder.
    estimator : str
        Estimator name (``controller._registry.ESTIMATOR_NAMES``).
    scenario : str, optional
        Scenario name or file; default from ``meta.json`` beside the capture.
    out_dir : Path, optional
        Default: ``rerun-ESTIMATOR`` beside the capture.

    Writes ``signals.csv`` (the rerun's estimate against the recorded truth),
    ``metrics.json``, ``rerun.json`` (reproduction check, recorded metrics,
    what the comparison means) and ``run.png``.
    """
    from bench.nodes._loops import make_controller_node
    from bench.runs._metrics import compute_metrics
    from bench.scenarios._setup import (
        check_estimator_fits,
        check_estimator_name,
        get_preset,
        sample_period,
    )
    from bench.scenarios._setup import needs_truth as reads_truth
    from controller._registry import ESTIMATOR_NAMES, UnknownEstimatorError, check_estimator

    check_estimator_name(estimator)
    codec = codec or Codec()
    say = echo or (lambda s: print(s, file=sys.stderr))
    got = read_capture_counted(path)
    frames, problem = got.frames, got.problem
    scn, meta = capture_scenario(path, scenario)
    if note := check_estimator_fits(scn, estimator):  # a misfit is one line, as for ``bench run``
        say(note)
    if problem:
        say(incomplete_warning(path, problem, len(frames)))
    if got.lines_skipped:
        say(skipped_warning(path, got.lines_skipped))
    recorded = meta.get("estimator") if isinstance(meta.get("estimator"), str) else None
    if recorded is not None and recorded not in ESTIMATOR_NAMES:
        try:  # a plug-in that still loads is known too
            check_estimator(recorded)
        except UnknownEstimatorError:
            recorded = None
    mode = str(meta.get("mode", "lockstep"))
    T_s = sample_period(scn)
    n_p = get_preset(scn).motor.n_p
    needs_truth = reads_truth(estimator)
    view, view_name = _controller_view(
        frames, codec.frame_id("PlantTruth") if needs_truth else None
    )

    # full step of every valid sample (and truth) frame of the view, by position
    dec = decode_batch(view, codec)
    from bench.runs._analysis import _full_steps

    wide = [
        (dec.messages[n].index, dec.messages[n].signals["step"].astype(np.int64))
        for n in ("PlantTruth", "CtrlTelemetry")
        if n in dec.messages and len(dec.messages[n].index)
    ]
    anchor = None
    if wide:
        a_idx = np.concatenate([w[0] for w in wide])
        a_st = np.concatenate([w[1] for w in wide])
        o = np.argsort(a_idx, kind="stable")
        anchor = (a_idx[o], a_st[o])
    sb = dec.messages.get("PhaseSamples")
    if sb is None or len(sb.index) == 0:
        raise CaptureError(f"{path}: no valid PhaseSamples frame to rerun")
    s_steps = _full_steps(
        "PhaseSamples",
        sb.signals["step"].astype(np.int64),
        sb.index,
        codec.step_bits("PhaseSamples"),
        anchor,
    )
    step_of = dict(zip(sb.index.tolist(), s_steps.tolist(), strict=True))
    present = set(step_of.values())
    if needs_truth:
        tb = dec.messages.get("PlantTruth")
        t_steps = set(tb.signals["step"].astype(np.int64).tolist()) if tb is not None else set()
        present &= t_steps
        if not present:
            raise CaptureError(f"{path}: sensored rerun needs PlantTruth with the samples")
    present_sorted = sorted(present)

    node = make_controller_node(scn, estimator, codec)
    node.run_id = _recorded_run_id(frames, codec)  # its telemetry as the recorded run's
    node.realtime = mode == "realtime"
    k_first = present_sorted[0]
    node.next_k = k_first
    ids = {codec.frame_id("PhaseSamples"), codec.frame_id("BenchCommand")}
    if needs_truth:
        ids.add(codec.frame_id("PlantTruth"))
    cmd_id = codec.frame_id("BenchCommand")
    saw_command = False
    started_without_command = False
    gap_steps = 0
    outputs_after: dict[int, list[can.Message]] = {}
    for i, f in enumerate(view):
        if node.stopped:
            break
        if f.arbitration_id not in ids or f.is_extended_id:
            continue
        if f.arbitration_id == cmd_id:
            saw_command = True
        k = step_of.get(i)
        if k is not None and not saw_command and not started_without_command:
            # a capture without bench commands before its first sample: run anyway
            node.ctrl.set_enable(True)
            started_without_command = True
        if k is not None and not node.realtime:
            nk = node.next_k
            if k > nk and nk not in present:
                j = bisect.bisect_left(present_sorted, nk)
                nxt = present_sorted[j] if j < len(present_sorted) else k
                gap_steps += nxt - nk
                for stale in [s for s in node.samples if s < nxt]:
                    del node.samples[stale]
                node.next_k = nxt
        out = node.on_message(f)
        if out:
            outputs_after[id(f)] = out
    n_out = sum(len(v) for v in outputs_after.values())
    if n_out == 0:
        raise CaptureError(f"{path}: the controller produced no output from this capture")

    # the capture with the recorded controller outputs replaced by the rerun's
    tele_id, duty_id = codec.frame_id("CtrlTelemetry"), codec.frame_id("PwmDuty")
    replaced: list[can.Message] = []
    for f in frames:
        if f.arbitration_id in (tele_id, duty_id) and not f.is_extended_id:
            continue
        replaced.append(f)
        made = outputs_after.get(id(f))
        if made:
            replaced.extend(made)
    try:
        new = analyze_frames(replaced, codec, T_s=T_s, n_p=n_p)
        old = analyze_frames(frames, codec, T_s=T_s, n_p=n_p)
    except ValueError as e:
        raise CaptureError(f"{path}: {e}") from None

    # bit-for-bit check: rerun telemetry payloads against the recorded ones, by step
    def tele_by_step(msgs: list[can.Message]) -> dict[int, bytes]:
        by_step: dict[int, bytes] = {}
        for m in msgs:
            if m.arbitration_id != tele_id or m.is_extended_id:
                continue
            d = codec.decode(m)
            if d is None or d.reason is not None:
                continue
            by_step.setdefault(int(d.signals["step"]), bytes(m.data))
        return by_step

    rec_tele = tele_by_step(frames)
    new_tele = tele_by_step([o for v in outputs_after.values() for o in v])
    common = sorted(set(rec_tele) & set(new_tele))
    differ = [k for k in common if rec_tele[k] != new_tele[k]]

    def score(table: dict[str, np.ndarray], score_from_s: float) -> dict[str, Any]:
        return dict(
            compute_metrics(
                table,
                T_s=T_s,
                n_p=n_p,
                score_from_s=score_from_s,
                thd_window_s=scn.thd_window_s,
                overshoot="speed_overshoot_rpm" in scn.paper_result,
            )
        )

    t = new.table["t"]
    scored, moved = scoring_scenario(scn, float(t[0]), float(t[-1]))
    if moved:
        say(moved)
    score_from = scored.score_from_s
    try:
        m_new = score(new.table, score_from)
    except ValueError as e:
        raise CaptureError(f"{path}: {e}") from None
    m_old: dict[str, Any] | None
    try:
        m_old = score(old.table, score_from)
    except ValueError:
        m_old = None
    m_new["rerun_steps"] = len(new_tele)
    m_new["estimate_steps_compared"] = len(common)
    m_new["estimate_steps_identical"] = len(common) - len(differ)
    m_new["sample_gap_steps"] = gap_steps
    m_new["frames_rejected"] = new.frames_rejected
    m_new["frames_unknown_id"] = new.unknown_ids
    m_new["frames_duplicate"] = new.duplicates
    m_new["frames_copies"] = new.copies
    m_new["frames_out_of_order"] = new.out_of_order
    if problem:
        m_new["capture_truncated"] = True
        m_new["capture_read_error"] = problem
    reproduced = bool(common) and not differ and len(common) == len(rec_tele)
    th_diff = math.nan
    if common:
        a = new.table["theta_hat"]
        b = old.table["theta_hat"]
        sa, sb_ = new.table["step"], old.table["step"]
        both, ia, ib = np.intersect1d(sa, sb_, return_indices=True)
        if len(both):
            d = (a[ia] - b[ib] + np.pi) % (2 * np.pi) - np.pi
            th_diff = float(np.degrees(np.max(np.abs(d))))
    report: dict[str, Any] = {
        "capture": str(path),
        "estimator": estimator,
        "recorded_estimator": recorded,
        "recorded_mode": mode,
        "scenario": scn.name,
        "controller_view": view_name,
        "open_loop": True,
        "comparison": injection_note(estimator, recorded),
        "first_step": k_first,
        "scored_from_s": score_from,
        "scoring_window_moved": moved,
        "started_without_command": started_without_command,
        "sample_gap_steps": gap_steps,
        "estimate": {
            "steps_compared": len(common),
            "steps_identical": len(common) - len(differ),
            "first_differing_step": differ[0] if differ else None,
            "reproduces_recorded_bit_for_bit": reproduced,
            "max_theta_hat_difference_deg": th_diff,
        },
        "metrics": m_new,
        "recorded_metrics": m_old,
        "capture_read_error": problem,
    }
    dest = out_dir or (
        (path if path.is_dir() else path.parent) / f"rerun-{estimator.replace(':', '-')}"
    )
    dest.mkdir(parents=True, exist_ok=True)
    write_csv(str(dest / "signals.csv"), new.table)
    (dest / "signals.md").write_text(signals_doc())
    (dest / "metrics.json").write_text(jsonio.dumps(m_new, indent=2, sort_keys=True) + "\n")
    (dest / "rerun.json").write_text(
        json.dumps(report, indent=2, sort_keys=True, default=str) + "\n"
    )
    if plots:
        from bench.runs._plots import plot_run
        from bench.runs._results import fundamental_corner_hz

        plot_run(
            new.table,
            dest,
            title=f"{scn.name} / rerun {estimator} on {recorded or '?'}",
            metrics=m_new,
            scored_from_s=scn.score_from_s,
            f_split_hz=fundamental_corner_hz(scn, estimator, new.table),
            paper=scn.paper,
        )
    say(
        f"rerun: {estimator} on {len(new_tele)} recorded steps ({view_name}); "
        + (
            f"estimate identical to the recorded one at {len(common) - len(differ)}/{len(common)} steps"
            if common
            else "no recorded estimate to compare"
        )
    )
    files = ["signals.csv", "signals.md", "metrics.json", "rerun.json"] + (
        ["run.png"] if plots else []
    )
    return RerunResult(
        out_dir=dest,
        metrics=m_new,
        report=report,
        files=files,
        paper_result=dict(scn.paper_result),
        paper_method=scn.estimator,
        T_s=T_s,
    )


def _recorded_run_id(frames: list[can.Message], codec: Codec) -> int:
    """The run_id of most of the capture's valid ``PlantTruth`` frames (0 without any)."""
    truth_id = codec.frame_id("PlantTruth")
    counts: dict[int, int] = {}
    for m in frames:
        if m.arbitration_id == truth_id and not m.is_extended_id:
            d = codec.decode(m)
            if d is not None and d.reason is None:
                rid = int(d.signals.get("run_id", 0))
                counts[rid] = counts.get(rid, 0) + 1
    return max(counts, key=lambda r: counts[r]) if counts else 0
