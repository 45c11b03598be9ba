"""Per-run plots: ``run.png``, read like a scope, and custom figures of ``signals.csv``.

:func:`plot_run` (:func:`run_figure`) draws, top to bottom:

- a zoom: the true and estimated electrical angle over the last electrical
  periods of the time window (as the papers' figures show them: Wen Fig. 14,
  Xue Fig. 13); its span is shaded on the panels below;
- on one shared time axis (a cursor runs through all of them):

  - the position error, scaled to the scored rows (the start-up transient is
    tens of degrees, the scored error a fraction of one), with the paper's
    bound where the scenario has one and a small inset of the same time axis
    at full scale;
  - the true, estimated and reference mechanical speed;
  - the phase-A current: with an injection the raw sample and its
    fundamental (the true rotor frame's ``i_d``, ``i_q`` through the
    zero-phase low-pass of :func:`bench.runs._metrics.lowpass_zero_phase`
    below the injection, turned back with the true angle), without one the
    sample alone; scaled to the current outside the start-up pulses;
  - the load torque on the shaft, the commanded load and the
    electromagnetic torque.

The shared panels shade the controller's start-up phases (``mode`` 1 align,
2 polarity test, each at least :data:`MIN_SPAN` of the axis wide so a 9 ms
test stays visible; 3 run unshaded; 4 fault) and mark the scoring start, a
protection trip, a lost lock, and each load step (a line) or ramp (a band).
A real-time run's periods with a late duty (:func:`late_duty_rows`: a
``duty_age`` above the run's usual one, an older duty held) and its host stalls (an instant
in simulated time: the periods a stall skipped were never computed) are
marked on them too, and the metrics box gives their share and number with the
periods the recording lacks (``steps_missing``).  When the recording lost the
run's tail (the plant ran further than the last recorded period), the time
axis runs on to the plant's last period (a time window's: to the window's end)
and the end of the recorded data is marked.
A row whose controller was disabled (``mode`` 0: before the start, the last
row after the stop) or whose estimate is missing (an empty cell: the
controller's telemetry stopped) draws no estimate: a gap. Legends and the
metrics box sit right of the panels, never over a trace. The metrics are the
whole run's (``metrics.json``) or, for a time window, recomputed from the
window's scored rows; the box says which. The title names the scenario, the
controller (``meta.json``'s ``controller`` when it names one, its
``estimator`` otherwise), the paper's figure to compare with, and the run's
variations (:func:`run_variations`: plant profile, countermeasures, injected
delay, the controller's model errors, a time window).

:func:`plot_signals` is ``bench plot RUN_DIR --signals a,b``: one panel per
column of ``signals.csv``, with its unit, over a chosen time window.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from bench.runs._metrics import METRIC_LABELS

Array = npt.NDArray[np.float64]

#: Controller modes (``CtrlTelemetry.mode`` in ``dbc/bench.dbc``) shaded on the
#: time panels: mode code, label, colour.
PHASES = ((1, "align", "tab:olive"), (2, "polarity test", "tab:orange"), (4, "fault", "tab:red"))
#: Opacity of each phase's shading: the short polarity test darker, so it stands out at
#: the end of the align phase it follows.
PHASE_ALPHA = {1: 0.25, 2: 0.6, 4: 0.3}
#: Electrical periods shown in the angle zoom.
ANGLE_PERIODS = 3.0
#: Narrowest shaded span, as a fraction of the time axis: 0.4 % is about 3 pixels of the
#: 1300-pixel figure's panels, the least an eye finds without looking for it.
MIN_SPAN = 0.004
#: Changes of the commanded load closer than this (s) are one ramp (:func:`load_events`): a
#: ramp reaches the plant as a staircase at the scenario's reference rate (a step every
#: 1 ms at the default 1 kHz), while the papers' load steps are seconds apart.
LOAD_GAP_S = 0.05
#: ``duty_age`` of a period without any duty (``PlantTruth.duty_age``'s "none", the DBC).
NO_DUTY_AGE = 255
#: The panels of :func:`run_figure` (each axes' label), top to bottom; all but the
#: first share the time axis.
PANELS = ("angle", "error", "speed", "current", "load")


def controller_label(meta: dict[str, Any]) -> str:
    """Who controlled a run, from its ``meta.json``, for titles and headings: the
    estimator of the bench's own controller, or ``external controller`` (with the name
    given by ``--dut-name``) for a controller under test."""
    if meta.get("controller") == "external":
        name = meta.get("controller_name")
        return (
            f"external controller {name}" if name and name != "external" else "external controller"
        )
    return str(meta.get("estimator") or "?")


def paper_figure(paper: str) -> str | None:
    """``"Wen et al. 2023, Fig. 14"`` from a scenario's ``paper`` field; None without a figure."""
    m = re.search(r"Fig\.\s*\d+", paper or "")
    if m is None:
        return None
    who = paper.split(",")[0].strip()
    return f"{who}, {m.group(0)}"


def run_variations(meta: dict[str, Any], window: tuple[float, float] | None = None) -> list[str]:
    """What sets a run apart from its scenario as shipped, from its ``meta.json``: the
    plant profile, the countermeasures, the injected delay, the controller's model errors,
    an own ``[motor]``, real time, and the plotted time window."""
    from bench.scenarios._setup import countermeasures_text

    scn = meta.get("scenario") or {}
    out: list[str] = []
    plant = (meta.get("plant") or {}).get("profile") or scn.get("plant_profile")
    if plant:
        out.append(f"{plant} plant")
    if "countermeasures" in meta:
        out.append(f"countermeasures: {countermeasures_text(meta['countermeasures'])}")
    delay = int(meta.get("lockstep_delay_steps") or 0)
    if delay:
        out.append(f"delay +{delay} period{'s' if delay != 1 else ''}")
    lat = scn.get("latency") or {}
    us = float(lat.get("duty_delay_us") or 0.0) + float(lat.get("sample_delay_us") or 0.0)
    if us:
        out.append(f"latency {us:g} us")
    if lat.get("jitter_us"):
        out.append(f"jitter {float(lat['jitter_us']):g} us")
    if lat.get("drop_prob"):
        out.append(f"drop {float(lat['drop_prob']):g}")
    errs = [f"{k} x{float(v):g}" for k, v in (scn.get("controller_model") or {}).items()
            if float(v) != 1.0]  # fmt: skip
    if errs:
        out.append("model " + ", ".join(errs))
    if scn.get("motor"):
        out.append("own [motor]")
    if meta.get("mode") == "realtime":
        out.append("real time")
    if window is not None:
        out.append(f"window {window[0]:g}-{window[1]:g} s")
    return out


def paper_bounds(paper_result: dict[str, Any] | None) -> tuple[list[float], str]:
    """The paper's bounds on the position error (deg) and their legend text, from a
    scenario's ``paper_result``: its largest and smallest error (Wen's tables), or +- its
    largest |error| (Xue's bounds, in rad); none without either."""
    pr = paper_result or {}
    if "theta_err_max_deg" in pr or "theta_err_min_deg" in pr:
        vals = [float(pr[k]) for k in ("theta_err_min_deg", "theta_err_max_deg") if k in pr]
        return vals, "paper's range " + " .. ".join(f"{v:+g}" for v in vals) + " deg"
    if "theta_err_abs_max_rad" in pr:
        b = float(pr["theta_err_abs_max_rad"])
        return [-math.degrees(b), math.degrees(b)], f"paper's bound |dtheta| <= {b:g} rad"
    if "theta_err_abs_max_deg" in pr:
        b = float(pr["theta_err_abs_max_deg"])
        return [-b, b], f"paper's bound |dtheta| <= {b:g} deg"
    return [], ""


def _spans(mask: npt.NDArray[np.bool_], t: Array) -> list[tuple[float, float]]:
    """Contiguous runs of ``mask`` as (t_start, t_end) pairs."""
    if not np.any(mask):
        return []
    m = mask.astype(np.int8)
    edges = np.flatnonzero(np.diff(np.concatenate(([0], m, [0]))))
    dt = float(t[1] - t[0]) if len(t) > 1 else 0.0
    return [
        (float(t[a]), float(t[b - 1]) + dt) for a, b in zip(edges[::2], edges[1::2], strict=True)
    ]


def load_events(t: Array, load: Array) -> tuple[list[float], list[tuple[float, float]]]:
    """Load steps (the time of a lone change) and ramps (the span of a run of changes) of a
    load column: changes less than :data:`LOAD_GAP_S` apart are one ramp, the staircase
    a ramp becomes at the scenario's reference rate."""
    if len(t) < 2:
        return [], []
    x = np.nan_to_num(np.asarray(load, dtype=float))
    k = np.flatnonzero(np.abs(np.diff(x)) > 1e-9) + 1
    steps: list[float] = []
    ramps: list[tuple[float, float]] = []
    if not len(k):
        return steps, ramps
    groups = np.split(k, np.flatnonzero(np.diff(t[k]) > LOAD_GAP_S) + 1)
    for g in groups:
        if len(g) == 1:
            steps.append(float(t[g[0]]))
        else:
            ramps.append((float(t[g[0]]), float(t[g[-1]])))
    return steps, ramps


def fundamental_a(table: dict[str, Array], T_s: float, f_c: float) -> Array:
    """Phase-A fundamental current: ``i_d``, ``i_q`` low-passed at ``f_c`` (Hz), back to phase A."""
    from bench.runs._metrics import lowpass_zero_phase

    i_d = lowpass_zero_phase(table["i_d"], T_s, f_c)
    i_q = lowpass_zero_phase(table["i_q"], T_s, f_c)
    th = table["theta_e"]
    out: Array = i_d * np.cos(th) - i_q * np.sin(th)
    return out


def late_duty_rows(table: dict[str, Array]) -> npt.NDArray[np.bool_]:
    """Periods that ran with a late duty: a ``duty_age`` (the DBC: the applied duty's age,
    0 without injected latency, N with N periods of it) above the run's usual one, its
    median (``loop_latency_steps``); the periods without any duty (255) left out.  A
    lockstep run, whose every duty has its set age, has none."""
    if "duty_age" not in table or not len(table["duty_age"]):
        return np.zeros(len(table["t"]), dtype=bool)
    age = np.asarray(table["duty_age"], dtype=float)
    ok = np.isfinite(age) & (age < NO_DUTY_AGE)
    if not np.any(ok):
        return np.zeros(len(age), dtype=bool)
    out: npt.NDArray[np.bool_] = ok & (age > float(np.median(age[ok])))
    return out


def _markers(ax: Any, t: Array, table: dict[str, Array], m: dict[str, Any], T_s: float,
             t0: float, legend: bool, loads: tuple[list[float], list[tuple[float, float]]],
             stalls: list[float] | None = None, t_end: float | None = None,
             ) -> None:  # fmt: skip
    """Phases shaded, scoring start, load events, late duties, host stalls, trip, lost lock
    and the end of the recorded data (``t_end``: when the recording lost the run's tail)
    on one time panel."""
    t_lo, t_hi = (float(t[0]), float(t[-1])) if len(t) else (0.0, 1.0)
    w_min = MIN_SPAN * max(t_hi - t_lo, T_s)
    late = late_duty_rows(table)
    n_late = int(np.count_nonzero(late))
    for i, (a, b) in enumerate(_spans(late, t)):
        if b - a < w_min:
            a, b = a - 0.5 * (w_min - (b - a)), b + 0.5 * (w_min - (b - a))
        ax.axvspan(a, b, color="tab:pink", alpha=0.35, lw=0, gid="late_duty",
                   label=f"late duty held ({n_late} periods)" if legend and i == 0
                   else None)  # fmt: skip
    for i, s in enumerate(stalls or []):
        ax.axvspan(s - 0.5 * w_min, s + 0.5 * w_min, color="0.15", alpha=0.5, lw=0,
                   gid="host_stall",
                   label=f"host stall ({len(stalls or [])} located; the periods it\n"
                   "skipped were not computed: an instant here)"
                   if legend and i == 0 else None)  # fmt: skip
    if t_end is not None:
        ax.axvline(t_end, color="k", lw=1.5, ls=(0, (1, 1)), gid="recorded_end",
                   label="end of the recorded data\n(the recorder lost the rest)" if legend
                   else None)  # fmt: skip
    if "mode" in table:
        for code, label, colour in PHASES:
            spans = _spans(table["mode"] == code, t)
            for i, (a, b) in enumerate(spans):
                dur = b - a
                if b - a < w_min:  # widened to be seen; the label keeps the true length
                    a, b = a - 0.5 * (w_min - dur), b + 0.5 * (w_min - dur)
                ms = f" ({1e3 * sum(y - x for x, y in spans):.0f} ms)" if code != 4 else ""
                ax.axvspan(a, b, color=colour, alpha=PHASE_ALPHA[code], lw=0, gid=f"phase{code}",
                           label=label + ms if legend and i == 0 else None)  # fmt: skip
    if t_lo <= t0 <= t_hi:
        ax.axvline(t0, color="k", ls=":", lw=1.0, label="scoring start" if legend else None)
    steps, ramps = loads
    for i, s in enumerate(steps):
        ax.axvline(s, color="tab:brown", ls="-.", lw=1.0,
                   label="load step" if legend and i == 0 else None)  # fmt: skip
    for i, (a, b) in enumerate(ramps):
        ax.axvspan(a, b, color="tab:brown", alpha=0.12, lw=0,
                   label="load ramp" if legend and i == 0 else None)  # fmt: skip
    if "fault_active" in table:  # the [[faults]] windows, and each detection
        for i, (a, b) in enumerate(_spans(table["fault_active"] > 0, t)):
            ax.axvspan(a, max(b, a + w_min), facecolor="none", edgecolor="tab:red", hatch="//",
                       alpha=0.35, lw=0, gid="fault",
                       label="fault active" if legend and i == 0 else None)  # fmt: skip
        seen = False
        for f in m.get("faults") or []:
            at = f.get("detected_at_s")
            if at is not None and t_lo <= float(at) <= t_hi:
                ax.axvline(float(at), color="tab:orange", lw=1.2, ls=(0, (4, 1)),
                           label="fault detected" if legend and not seen else None)  # fmt: skip
                seen = True
    k = int(m.get("plant_fault_step", -1) or -1)
    if m.get("plant_fault") not in (None, "none") and k >= 0 and t_lo <= k * T_s <= t_hi:
        ax.axvline(k * T_s, color="tab:red", lw=1.5,
                   label=f"trip: {m['plant_fault']}" if legend else None)  # fmt: skip
    lost = m.get("lock_lost_at_s")
    if m.get("lock_lost") and lost is not None and t_lo <= float(lost) <= t_hi:
        ax.axvline(float(lost), color="tab:purple", lw=1.5, ls="--",
                   label="lock lost" if legend else None)  # fmt: skip


def _fmt(v: Any, spec: str) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    return format(v, spec)


def metrics_text(m: dict[str, Any]) -> str:
    """The key metrics of a run, one per line (the figure's text box): the errors, and
    where not zero what makes a run less than a drive's (late duties, host stalls,
    periods the recording lacks), a trip, a lost lock and the faults' reactions."""
    from bench.runs._metrics import late_duty_fraction

    lines = [
        f"{METRIC_LABELS['theta_err_abs_max_deg']} "
        f"{_fmt(m.get('theta_err_abs_max_deg'), '.2f')} deg "
        f"({_fmt(m.get('theta_err_abs_max_rad'), '.3f')} rad)",
        f"dtheta {_fmt(m.get('theta_err_min_deg'), '+.2f')} .. "
        f"{_fmt(m.get('theta_err_max_deg'), '+.2f')} deg",
        f"mean {_fmt(m.get('theta_err_mean_deg'), '+.2f')}, "
        f"|mean| {_fmt(m.get('theta_err_abs_mean_deg'), '.2f')}, "
        f"rms {_fmt(m.get('theta_err_rms_deg'), '.2f')} deg",
        f"speed error max {_fmt(m.get('speed_err_max_rpm'), '.1f')} rpm",
    ]
    if "thd_phase_a_pct" in m:
        lines.append(f"THD i_a {_fmt(m['thd_phase_a_pct'], '.2g')} %")
    if m.get("late_duty_periods"):
        lines.append(f"late duty {100 * late_duty_fraction(m):.1f} % of periods")
    if m.get("host_stalls"):
        lines.append(f"host stalls {int(m['host_stalls'])}, "
                     f"longest {_fmt(m.get('host_stall_ms_max'), '.1f')} ms")  # fmt: skip
        lines.append(f"  periods skipped {int(m.get('periods_skipped', 0))}")
    if m.get("steps_missing"):
        lines.append(f"steps_missing {int(m['steps_missing'])} (not recorded)")
    if m.get("plant_fault") not in (None, "none"):
        lines.append(f"TRIP: {m['plant_fault']} (not a scenario result)")
    if m.get("lock_lost"):
        lines.append(f"LOCK LOST at {_fmt(m.get('lock_lost_at_s'), '.3f')} s")
    for f in m.get("faults") or []:
        seen = (
            f"{f['detected_by']} +{_fmt(f.get('reaction_ms'), '.1f')} ms"
            if f.get("detected_by")
            else "not detected"
        )
        met = "" if f.get("met") is None else (", met" if f["met"] else ", MISSED")
        lines.append(f"fault {f['kind']} @ {f['at_s']:g} s: {seen}{met}")
    return "\n".join(lines)


def estimate_rows(table: dict[str, Array]) -> npt.NDArray[np.bool_]:
    """Rows with an estimate: the controller enabled (``mode`` not 0) and its telemetry
    present (no empty cell)."""
    ok = np.isfinite(table["theta_hat"]) & np.isfinite(table["w_hat_rpm"])
    if "theta_err_deg" in table:
        ok &= np.isfinite(table["theta_err_deg"])
    if "mode" in table:
        ok &= np.isfinite(table["mode"]) & (table["mode"] != 0)
    out: npt.NDArray[np.bool_] = ok
    return out


def window_metrics(
    table: dict[str, Array], T_s: float, n_p: int | None, scored_from_s: float
) -> tuple[dict[str, Any], str]:
    """The metrics of a time window's scored rows (:func:`bench.runs._metrics.compute_metrics`
    over the rows with an estimate), and the box's heading. A window before the scoring
    start is scored over all its rows, and says so."""
    from bench.runs._metrics import compute_metrics

    ok = estimate_rows(table)
    part = {k: v[ok] for k, v in table.items()}
    t = part["t"]
    if len(t) < 2:
        return {}, "window: no estimate to score"
    t0 = max(scored_from_s, float(t[0]))
    head = f"window {float(table['t'][0]):g}-{float(table['t'][-1]):g} s, scored from {t0:g} s"
    if t0 >= float(t[-1]):
        t0 = float(t[0])
        head = (f"window {float(table['t'][0]):g}-{float(table['t'][-1]):g} s, all rows "
                f"(before the run's scoring start, {scored_from_s:g} s)")  # fmt: skip
    try:
        m = compute_metrics(part, T_s=T_s, n_p=n_p or 4, score_from_s=t0)
    except ValueError:
        return {}, "window: no estimate to score"
    return m, head


def _nanrange(x: Array) -> tuple[float, float] | None:
    x = x[np.isfinite(x)]
    if not len(x):
        return None
    return float(np.min(x)), float(np.max(x))


def run_figure(
    table: dict[str, Array],
    *,
    title: str = "",
    metrics: dict[str, Any] | None = None,
    scored_from_s: float = 0.0,
    f_split_hz: float | None = None,
    paper: str = "",
    paper_result: dict[str, Any] | None = None,
    n_p: int | None = None,
    meta: dict[str, Any] | None = None,
    window: tuple[float, float] | None = None,
    stalls: list[float] | None = None,
    recorded_end_s: float | None = None,
) -> Any:
    """The figure of :func:`plot_run` (a matplotlib ``Figure``; the caller closes it).

    ``table`` holds the rows to draw (a time window's, when ``window`` names it:
    its start and end, s, as asked for); ``metrics`` the whole run's.
    ``recorded_end_s``: where the whole run's recorded data end (its last row's
    period's end; default the table's), so that a window reaching past them marks
    a lost tail as the whole run's figure does and runs on to the window's end or
    the plant's last period. ``meta`` (a ``meta.json``) gives the title, the paper,
    its bounds and the run's variations where ``title``, ``paper`` and ``paper_result``
    are not given; with a controller under test (``meta["controller"]`` external) no
    paper's bound is drawn (the paper's numbers are its method's, not this controller's).
    ``stalls``: the host stalls' instants (s, :func:`bench.runs._results.host_stall_times`).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    meta = meta or {}
    scn = meta.get("scenario") or {}
    title = title or f"{scn.get('name', 'run')} / {controller_label(meta)}"
    paper = paper or str(scn.get("paper", ""))
    if paper_result is None:
        paper_result = scn.get("paper_result") or {}
    if meta.get("controller") == "external":
        paper_result = {}  # another method's numbers: neither its band nor its y range
    m_run = metrics or {}
    t = table["t"]
    T_s = float(t[1] - t[0]) if len(t) > 1 else 1.0
    t_lo, t_hi = (float(t[0]), float(t[-1]) + T_s) if len(t) else (0.0, 1.0)
    # the plant ran further than the recording goes: the axis runs on to its last period
    # (or the window's end), when the rows drawn reach the end of the recorded data
    t_rec_end: float | None = None
    plant_steps = (meta.get("node_reports") or {}).get("plant", {}).get("steps")
    rec_end = t_hi if recorded_end_s is None else float(recorded_end_s)
    w_hi = math.inf if window is None else float(window[1])
    if (
        plant_steps
        and len(t)
        and abs(t_hi - rec_end) < 0.5 * T_s
        and min(int(plant_steps) * T_s, w_hi) > rec_end + 0.5 * T_s
    ):
        t_rec_end, t_hi = rec_end, min(int(plant_steps) * T_s, w_hi)
    est = estimate_rows(table)
    nan = np.full(len(t), np.nan)
    theta_hat = np.where(est, table["theta_hat"], nan)
    w_hat = np.where(est, table["w_hat_rpm"], nan)
    err = np.where(est, table["theta_err_deg"], nan)
    scored = est & (t >= scored_from_s)
    if np.count_nonzero(scored) < 2:  # a window before the scoring start: all of it
        scored = est.copy()
    if window is not None:
        m_box, head = window_metrics(table, T_s, n_p, scored_from_s)
        for k in ("plant_fault", "plant_fault_step"):
            if k in m_run:
                m_box[k] = m_run[k]
    else:
        m_box, head = m_run, f"whole run, scored from {scored_from_s:g} s"
    loads = load_events(t, table["load_ref_nm"]) if "load_ref_nm" in table else ([], [])

    def marks(ax: Any, legend: bool = False) -> None:
        _markers(ax, t, table, m_run, T_s, scored_from_s, legend=legend, loads=loads,
                 stalls=stalls, t_end=t_rec_end)  # fmt: skip

    fig = plt.figure(figsize=(12, 14.5))
    gs = fig.add_gridspec(5, 1, height_ratios=(0.9, 1.4, 1.0, 1.0, 0.7), hspace=0.32)
    fig.subplots_adjust(left=0.08, right=0.72, top=0.93, bottom=0.05)
    ax_ang = fig.add_subplot(gs[0], label="angle")
    ax_err = fig.add_subplot(gs[1], label="error")
    ax_spd = fig.add_subplot(gs[2], sharex=ax_err, label="speed")
    ax_cur = fig.add_subplot(gs[3], sharex=ax_err, label="current")
    ax_load = fig.add_subplot(gs[4], sharex=ax_err, label="load")
    shared = (ax_err, ax_spd, ax_cur, ax_load)
    outside = {"loc": "upper left", "bbox_to_anchor": (1.01, 1.0), "fontsize": 8,
               "borderaxespad": 0.0}  # fmt: skip

    # angle zoom: the last electrical periods of the window's scored rows
    sel = scored if np.any(scored) else np.ones(len(t), dtype=bool)
    t_end = float(t[sel][-1]) if np.any(sel) else t_hi
    tail = sel & (t >= t_end - 0.1)
    w_e = abs(float(np.nanmean(table["w_m_rpm"][tail]))) if np.any(tail) else 0.0
    f_e = w_e / 60.0 * (n_p or _pole_pairs(table, sel))
    span = min(ANGLE_PERIODS / f_e, 0.5) if f_e > 0.5 else 0.5
    span = min(span, max(t_end - t_lo, T_s))
    zoom = (t >= t_end - span) & (t <= t_end)
    ax_ang.plot(t[zoom], table["theta_e"][zoom], lw=1.0, label=r"$\theta_e$ (true)")
    ax_ang.plot(t[zoom], theta_hat[zoom], lw=1.0, ls="--",
                label=r"$\hat\theta_e$ (estimated)")  # fmt: skip
    ax_ang.set_ylabel("electrical angle (rad)")
    ax_ang.set_xlabel("time (s)", fontsize=8)
    shade_zoom = span < 0.5 * (t_hi - t_lo)  # else it would grey most of the window
    where = "shaded grey on the time axis below" if shade_zoom else "the end of the time axis below"
    ax_ang.set_title(f"zoom: angle over {float(t_end - span):.3f}-{t_end:.3f} s ({where})",
                     fontsize=9, loc="left")  # fmt: skip
    ax_ang.legend(**outside)

    # position error: scaled to the scored rows and the paper's bound; full scale inset
    ax_err.plot(t, err, lw=0.6, color="tab:red", label=r"$\Delta\theta$")
    ax_err.axhline(0.0, color="k", lw=0.5)
    bounds, bound_text = paper_bounds(paper_result)
    method = scn.get("estimator")
    for i, b in enumerate(bounds):
        text = bound_text + (f"\n(for {method})" if method else "")
        ax_err.axhline(b, color="tab:green", ls="--", lw=1.0, gid="paper_bound",
                       label=text if i == 0 else None)  # fmt: skip
    rng = _nanrange(err[scored]) or (-1.0, 1.0)
    lo, hi = min([rng[0], *bounds]), max([rng[1], *bounds])
    pad = max(0.1 * (hi - lo), 0.05)
    ax_err.set_ylim(lo - pad, hi + pad + 0.6 * (hi - lo + 2 * pad))  # room for the inset
    ax_err.set_ylabel(r"$\Delta\theta$ (deg, electrical)")
    ax_err.set_title("position error, scaled to the scored rows (inset: full scale)",
                     fontsize=9, loc="left")  # fmt: skip
    marks(ax_err)
    inset = ax_err.inset_axes((0.6, 0.65, 0.38, 0.27))
    inset.plot(t, err, lw=0.4, color="tab:red")
    marks(inset)
    inset.set_xlim(t_lo, t_hi)
    inset.set_title("full scale, same time axis", fontsize=7)
    inset.tick_params(labelsize=6)
    ax_err.legend(**outside)
    ax_err.text(1.01, 0.0, f"{head}\n" + metrics_text(m_box), transform=ax_err.transAxes,
                va="bottom", ha="left", fontsize=7.5, family="monospace",
                bbox={"boxstyle": "round", "fc": "white", "alpha": 0.9})  # fmt: skip

    # speed
    ax_spd.plot(t, table["w_m_rpm"], lw=0.8, label="true")
    ax_spd.plot(t, w_hat, lw=0.8, ls="--", label="estimated")
    ax_spd.plot(t, table["w_ref_rpm"], lw=0.8, color="k", alpha=0.5, label="reference")
    ax_spd.set_ylabel("mechanical speed (rpm)")
    marks(ax_spd, legend=True)
    if shade_zoom:
        ax_spd.axvspan(t_end - span, t_end, color="0.5", alpha=0.15, lw=0, label="angle zoom")
    ax_spd.legend(**outside)

    # current: scaled to the current outside the start-up pulses (align, polarity test)
    injected = f_split_hz is not None
    ax_cur.plot(t, table["i_a"], lw=0.4 if injected else 0.7, color="0.6" if injected else "tab:blue",
                label="sample (with injection)" if injected else "sample")  # fmt: skip
    if injected and len(t) > 30 and np.all(np.isfinite(table["i_d"])) \
            and np.all(np.isfinite(table["i_q"])):  # fmt: skip
        ax_cur.plot(t, fundamental_a(table, T_s, float(f_split_hz or 0.0)), lw=0.9,
                    color="tab:blue",
                    label=f"fundamental (d-q low-pass {f_split_hz:.0f} Hz)")  # fmt: skip
    # with a fault timeline, every phase's true current (PlantCurrents): an open phase shows
    trues = ("i_a_true", "i_b_true", "i_c_true")
    with_true = bool(
        "fault_active" in table
        and np.any(table["fault_active"] > 0)
        and all(c in table and np.any(np.isfinite(table[c])) for c in trues)
    )
    if with_true:
        for c, colour in zip(trues, ("tab:cyan", "tab:green", "tab:red"), strict=True):
            ax_cur.plot(t, table[c], lw=0.5, color=colour, alpha=0.8, label=f"true $i_{c[2]}$")
    marks(ax_cur)
    running = np.ones(len(t), dtype=bool)
    if "mode" in table:
        running = ~np.isin(table["mode"], (1, 2))
    k_trip = int(m_run.get("plant_fault_step", -1) or -1)
    if m_run.get("plant_fault") not in (None, "none") and k_trip >= 0:
        running &= t < k_trip * T_s  # the trip's current is the protection's, not the run's
    if not np.any(running):
        running = np.ones(len(t), dtype=bool)
    r = _nanrange(np.abs(table["i_a"][running]))
    if with_true and r is not None:
        r_true = _nanrange(np.abs(np.concatenate([table[c][running] for c in trues])))
        if r_true is not None:
            r = (r[0], max(r[1], r_true[1]))
    if r is not None and r[1] > 0.0:
        ax_cur.set_ylim(-1.2 * r[1], 1.2 * r[1])
    ax_cur.set_ylabel(r"$i_a$ (A)" if not with_true else "phase currents (A)")
    ax_cur.set_title("phase-A current" + (" and every phase's true current" if with_true else "")
                     + ", scaled outside the start-up pulses", fontsize=9,
                     loc="left")  # fmt: skip
    ax_cur.legend(**outside)

    # torque: the load on the shaft, the commanded load, the machine's torque
    if "tau_e" in table:
        tau_e, what = table["tau_e"], "electromagnetic torque"
        if injected and len(t) > 30 and np.all(np.isfinite(tau_e)):
            from bench.runs._metrics import lowpass_zero_phase

            # the injection's torque ripple would hide the load; its fundamental part
            tau_e = lowpass_zero_phase(tau_e, T_s, float(f_split_hz or 0.0))
            what += f" (low-pass {f_split_hz:.0f} Hz)"
        ax_load.plot(t, tau_e, lw=0.8, color="tab:cyan", label=what)
    if "tau_L" in table:
        ax_load.plot(t, table["tau_L"], lw=1.6, color="tab:brown", label="load torque",
                     zorder=3)  # fmt: skip
    if "load_ref_nm" in table:
        ax_load.plot(t, table["load_ref_nm"], lw=1.0, ls=":", color="k",
                     label="load commanded", zorder=4)  # fmt: skip
    marks(ax_load)
    ax_load.set_ylabel("torque (N m)")
    ax_load.set_xlabel("time (s)" if t_rec_end is None else
                       f"time (s): the recorded data end at {t_rec_end:.3f} s, the plant ran to "
                       f"{t_hi:.3f} s (the recorder lost the rest)")  # fmt: skip
    ax_load.legend(**outside)

    for a in shared:
        if shade_zoom and a is not ax_spd:
            a.axvspan(t_end - span, t_end, color="0.5", alpha=0.15, lw=0)
        a.grid(alpha=0.3)
    ax_ang.grid(alpha=0.3)
    ax_err.set_xlim(t_lo, t_hi)
    for a in shared[:-1]:
        a.tick_params(labelbottom=False)
    fig_ref = paper_figure(paper)
    head1 = title + (f"  (compare: {fig_ref})" if fig_ref else "")
    var = run_variations(meta, window)
    fig.suptitle(head1 + ("\n" + " | ".join(var) if var else ""), fontsize=11)
    return fig


def plot_run(
    table: dict[str, Array],
    out_dir: Path,
    *,
    title: str = "",
    metrics: dict[str, Any] | None = None,
    scored_from_s: float = 0.0,
    f_split_hz: float | None = None,
    paper: str = "",
    paper_result: dict[str, Any] | None = None,
    n_p: int | None = None,
    meta: dict[str, Any] | None = None,
    window: tuple[float, float] | None = None,
    name: str = "run.png",
    stalls: list[float] | None = None,
    recorded_end_s: float | None = None,
) -> Path:
    """The run's figure (see the module's docstring, :func:`run_figure`) to
    ``out_dir / name``; ``f_split_hz``: the fundamental's low-pass corner (None: no
    injection, the sample is the fundamental)."""
    import matplotlib.pyplot as plt

    fig = run_figure(table, title=title, metrics=metrics, scored_from_s=scored_from_s,
                     f_split_hz=f_split_hz, paper=paper, paper_result=paper_result, n_p=n_p,
                     meta=meta, window=window, stalls=stalls,
                     recorded_end_s=recorded_end_s)  # fmt: skip
    path = out_dir / name
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _pole_pairs(table: dict[str, Array], sel: npt.NDArray[np.bool_]) -> float:
    """Pole pairs from the table itself: electrical angle advance over mechanical speed."""
    th = np.unwrap(table["theta_e"][sel])
    t = table["t"][sel]
    w = table["w_m_rpm"][sel] * (2 * math.pi / 60.0)
    turned = float(np.trapezoid(w, t)) if len(t) > 1 else 0.0
    if abs(turned) < 1e-3:
        return 4.0
    return max(1.0, round(abs(float(th[-1] - th[0]) / turned)))


def plot_signals(
    table: dict[str, Array],
    signals: list[str],
    path: Path,
    *,
    t_from: float | None = None,
    t_to: float | None = None,
    title: str = "",
    units: dict[str, str] | None = None,
) -> Path:
    """One panel per column of ``signals`` over ``[t_from, t_to]`` (s), to ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = table["t"]
    sel = np.ones_like(t, dtype=bool)
    if t_from is not None:
        sel &= t >= t_from
    if t_to is not None:
        sel &= t <= t_to
    fig, axes = plt.subplots(len(signals), 1, figsize=(10, 1.0 + 2.2 * len(signals)),
                             sharex=True, squeeze=False)  # fmt: skip
    for ax, s in zip(axes[:, 0], signals, strict=True):
        ax.plot(t[sel], table[s][sel], lw=0.7)
        ax.set_ylabel(s, fontsize=9)
        ax.set_title((units or {}).get(s, ""), fontsize=8, loc="left")
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("time (s)")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
