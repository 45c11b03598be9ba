"""Per-run plots: ``run.png``, read at a glance, and custom figures of ``signals.csv``.

:func:`plot_run` draws, top to bottom:

- the true and estimated electrical angle over the last electrical periods
  of the run (as the papers' figures show them: Wen Fig. 14, Xue Fig. 13);
- the position error over the scored window, scaled to it, with a small
  inset of the whole run (the start-up transient is tens of degrees, the
  scored error a fraction of one);
- the true, estimated and reference mechanical speed;
- the raw phase-A current (with the injection) and its fundamental: the
  true rotor frame's ``i_d``, ``i_q`` through the zero-phase low-pass of
  :func:`bench.runs._metrics.lowpass_zero_phase` below the injection, turned
  back with the true angle.

The full-run panels shade the controller's start-up phases (``mode`` 1
align, 2 polarity test; 3 run unshaded; 4 fault) and mark the scoring
start, a protection trip and a lost lock.  A text box gives the key
metrics; the title names the scenario, the controller (``meta.json``'s
``controller`` when it names one, its ``estimator`` otherwise) and the
paper's figure to compare with.

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
#: full-run panels: mode code, label, colour.
PHASES = ((1, "align", "tab:olive"), (2, "polarity test", "tab:orange"), (4, "fault", "tab:red"))
#: Electrical periods shown in the angle panel.
ANGLE_PERIODS = 3.0


def controller_label(meta: dict[str, Any]) -> str:
    """Who controlled a run, from its ``meta.json``, for titles and headings: the
    estimator of the bench's own controller, or ``external controller`` (with the name
    given by ``--dut-name``) for a controller under test."""
    if meta.get("controller") == "external":
        name = meta.get("controller_name")
        return f"external controller {name}" if name and name != "external" else "external controller"
    return str(meta.get("estimator") or "?")


def paper_figure(paper: str) -> str | None:
    """``"Wen et al. 2023, Fig. 14"`` from a scenario's ``paper`` field; None without a figure."""
    m = re.search(r"Fig\.\s*\d+", paper or "")
    if m is None:
        return None
    who = paper.split(",")[0].strip()
    return f"{who}, {m.group(0)}"


def _spans(mask: npt.NDArray[np.bool_], t: Array) -> list[tuple[float, float]]:
    """Contiguous runs of ``mask`` as (t_start, t_end) pairs."""
    if not np.any(mask):
        return []
    m = mask.astype(np.int8)
    edges = np.flatnonzero(np.diff(np.concatenate(([0], m, [0]))))
    dt = float(t[1] - t[0]) if len(t) > 1 else 0.0
    return [(float(t[a]), float(t[b - 1]) + dt) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def fundamental_a(table: dict[str, Array], T_s: float, f_c: float) -> Array:
    """Phase-A fundamental current: ``i_d``, ``i_q`` low-passed at ``f_c`` (Hz), back to phase A."""
    from bench.runs._metrics import lowpass_zero_phase

    i_d = lowpass_zero_phase(table["i_d"], T_s, f_c)
    i_q = lowpass_zero_phase(table["i_q"], T_s, f_c)
    th = table["theta_e"]
    out: Array = i_d * np.cos(th) - i_q * np.sin(th)
    return out


def _markers(ax: Any, t: Array, table: dict[str, Array], m: dict[str, Any], T_s: float,
             t0: float, legend: bool) -> None:  # fmt: skip
    """Phases shaded, scoring start, trip and lost lock on one full-run panel."""
    if "mode" in table:
        for code, label, colour in PHASES:
            for i, (a, b) in enumerate(_spans(table["mode"] == code, t)):
                ax.axvspan(a, b, color=colour, alpha=0.15, lw=0,
                           label=label if legend and i == 0 else None)  # fmt: skip
    ax.axvline(t0, color="k", ls=":", lw=1.0, label="scoring start" if legend else None)
    k = int(m.get("plant_fault_step", -1) or -1)
    if m.get("plant_fault") not in (None, "none") and k >= 0:
        ax.axvline(k * T_s, color="tab:red", lw=1.5,
                   label=f"trip: {m['plant_fault']}" if legend else None)  # fmt: skip
    if m.get("lock_lost") and m.get("lock_lost_at_s") is not None:
        ax.axvline(float(m["lock_lost_at_s"]), color="tab:purple", lw=1.5, ls="--",
                   label="lock lost" if legend else None)  # fmt: skip


def _fmt(v: Any, spec: str) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    return format(v, spec)


def metrics_text(m: dict[str, Any]) -> str:
    """The key metrics of a run, one per line (the figure's text box)."""
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
        lines.append(f"THD i_a {_fmt(m['thd_phase_a_pct'], '.1f')} %")
    if m.get("plant_fault") not in (None, "none"):
        lines.append(f"TRIP: {m['plant_fault']} (not a scenario result)")
    if m.get("lock_lost"):
        lines.append(f"LOCK LOST at {_fmt(m.get('lock_lost_at_s'), '.3f')} s")
    return "\n".join(lines)


def plot_run(
    table: dict[str, Array],
    out_dir: Path,
    *,
    title: str,
    metrics: dict[str, Any] | None = None,
    scored_from_s: float = 0.0,
    f_split_hz: float | None = None,
    paper: str = "",
    n_p: int | None = None,
    name: str = "run.png",
) -> Path:
    """The run's figure (see the module's docstring); ``f_split_hz``: the fundamental's
    low-pass corner (None: no injection, the raw current is the fundamental)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    m = metrics or {}
    t = table["t"]
    T_s = float(t[1] - t[0]) if len(t) > 1 else 1.0
    scored = t >= scored_from_s
    if "mode" in table:
        scored &= table["mode"] != 0
    if np.count_nonzero(scored) < 2:  # a window before the scoring start: all of it
        scored = np.ones_like(t, dtype=bool)
    fig = plt.figure(figsize=(10, 12))
    gs = fig.add_gridspec(4, 1, height_ratios=(1.0, 1.3, 1.0, 1.0))
    ax_ang = fig.add_subplot(gs[0])
    ax_err = fig.add_subplot(gs[1])
    ax_spd = fig.add_subplot(gs[2])
    ax_cur = fig.add_subplot(gs[3], sharex=ax_spd)

    # angle: the last electrical periods of the scored window
    ts = t[scored]
    t_end = float(ts[-1])
    w_e = abs(float(np.mean(table["w_m_rpm"][scored][-max(1, int(0.1 / T_s)) :])))
    f_e = w_e / 60.0 * (n_p or _pole_pairs(table, scored))
    span = min(ANGLE_PERIODS / f_e, 0.5) if f_e > 0.5 else 0.5
    win = scored & (t >= t_end - span)
    ax_ang.plot(t[win], table["theta_e"][win], lw=1.0, label=r"$\theta_e$ (true)")
    ax_ang.plot(t[win], table["theta_hat"][win], lw=1.0, ls="--",
                label=r"$\hat\theta_e$ (estimated)")  # fmt: skip
    ax_ang.set_ylabel("electrical angle (rad)")
    ax_ang.set_title(f"angle, last {span:.3g} s of the run", fontsize=9, loc="left")
    ax_ang.legend(loc="upper right", fontsize=8)

    # position error: the scored window, with the whole run in an inset
    err = table["theta_err_deg"]
    ax_err.plot(ts, err[scored], lw=0.6, color="tab:red")
    ax_err.axhline(0.0, color="k", lw=0.5)
    known = err[scored][np.isfinite(err[scored])]  # none where no telemetry came
    lo, hi = (float(known.min()), float(known.max())) if len(known) else (-1.0, 1.0)
    pad = max(0.1 * (hi - lo), 0.05)
    ax_err.set_ylim(lo - pad, hi + pad + 0.6 * (hi - lo + 2 * pad))  # room for the inset
    ax_err.set_ylabel(r"$\Delta\theta$ (deg, electrical)")
    ax_err.set_title(f"position error over the scored window ({float(ts[0]):.2f} s on)",
                     fontsize=9, loc="left")  # fmt: skip
    _markers(ax_err, t, table, m, T_s, scored_from_s, legend=False)
    ax_err.set_xlim(float(ts[0]), t_end)  # the markers may lie outside the window
    inset = ax_err.inset_axes((0.62, 0.62, 0.36, 0.34))
    inset.plot(t, err, lw=0.4, color="tab:red")
    _markers(inset, t, table, m, T_s, scored_from_s, legend=False)
    inset.set_title("whole run", fontsize=7)
    inset.tick_params(labelsize=6)
    ax_err.text(0.01, 0.97, metrics_text(m), transform=ax_err.transAxes, va="top", ha="left",
                fontsize=8, family="monospace",
                bbox={"boxstyle": "round", "fc": "white", "alpha": 0.85})  # fmt: skip

    # speed and current: the whole run, phases shaded
    ax_spd.plot(t, table["w_m_rpm"], lw=0.8, label="true")
    ax_spd.plot(t, table["w_hat_rpm"], lw=0.8, ls="--", label="estimated")
    ax_spd.plot(t, table["w_ref_rpm"], lw=0.8, color="k", alpha=0.5, label="reference")
    ax_spd.set_ylabel("mechanical speed (rpm)")
    _markers(ax_spd, t, table, m, T_s, scored_from_s, legend=True)
    ax_spd.legend(loc="upper right", fontsize=7, ncol=2)
    ax_cur.plot(t, table["i_a"], lw=0.4, color="0.65", label="raw (with injection)")
    if f_split_hz is not None and len(t) > 30:
        ax_cur.plot(t, fundamental_a(table, T_s, f_split_hz), lw=0.9, color="tab:blue",
                    label=f"fundamental (d-q low-pass {f_split_hz:.0f} Hz)")  # fmt: skip
    _markers(ax_cur, t, table, m, T_s, scored_from_s, legend=False)
    if m.get("plant_fault") in (None, "none"):
        # scaled to the scored part: the start-up's polarity pulses would flatten it
        peak = float(np.nanmax(np.abs(table["i_a"][scored]))) if np.any(scored) else 0.0
        if math.isfinite(peak) and peak > 0.0:
            ax_cur.set_ylim(-1.3 * peak, 1.3 * peak)
    ax_cur.set_ylabel(r"$i_a$ (A)")
    ax_cur.set_xlabel("time (s)")
    ax_cur.legend(loc="upper right", fontsize=7)
    for a in (ax_ang, ax_err, ax_spd, ax_cur):
        a.grid(alpha=0.3)
    fig_ref = paper_figure(paper)
    fig.suptitle(title + (f"  (compare: {fig_ref})" if fig_ref else ""))
    fig.tight_layout()
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
