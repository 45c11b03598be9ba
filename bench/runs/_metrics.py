"""Metrics of a run, from the per-step signal table (numpy arrays).

Position errors are electrical angles, ``wrap(theta_e - theta_hat)`` to
(-180, 180] degrees, scored from ``score_from_s`` on (the start-up transient
is reported separately by the plots, not hidden: the scored window is in the
metadata).  Two speed errors are reported because the papers use the word for
two things: ``speed_err_max_rpm`` is the estimation error |w_hat - w_true|,
``speed_track_err_max_rpm`` the tracking error |w_ref - w_true|.
"""

from __future__ import annotations

from typing import Any

import itertools
import math
from collections.abc import Mapping

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]


def wrap_pi(x: Array) -> Array:
    """Wrap angles (rad) to [-pi, pi)."""
    return (x + np.pi) % (2.0 * np.pi) - np.pi


def thd_pct(x: Array, T_s: float, f1: float, n_harmonics: int = 40) -> float:
    """Total harmonic distortion of ``x`` (percent of the fundamental).

    Computed over the largest whole number of fundamental periods that fits
    in ``x`` (taken from its end), by projecting on each harmonic's exact
    frequency (a DFT whose bins sit on the harmonics, so the fundamental does
    not leak); harmonics 2 to ``n_harmonics`` (the 40th by default).  The
    mean (DC) is removed first.

    Parameters
    ----------
    x : array
        Samples, one per ``T_s``.
    T_s : float
        Sample period (s).
    f1 : float
        Fundamental frequency (Hz), > 0.
    """
    if f1 <= 0.0:
        return math.nan
    n_per = 1.0 / (f1 * T_s)
    periods = int(len(x) / n_per)
    if periods < 1:
        return math.nan
    n = int(round(periods * n_per))
    seg = np.asarray(x[len(x) - n :], dtype=float)
    seg = seg - seg.mean()
    t = np.arange(n) * T_s
    amp = np.empty(n_harmonics)
    for h in range(1, n_harmonics + 1):
        ph = np.exp(-2j * np.pi * h * f1 * t)
        amp[h - 1] = 2.0 * abs(np.dot(seg, ph)) / n
    if amp[0] == 0.0:
        return math.nan
    return float(100.0 * math.sqrt(float(np.sum(amp[1:] ** 2))) / amp[0])


def overshoot_rpm(t: Array, w_ref: Array, w: Array, *, min_step_rpm: float = 1.0) -> float:
    """Largest overshoot of ``w`` beyond a stepped reference, in the step's direction.

    For every discontinuity of the reference (a change of at least
    ``min_step_rpm`` between two samples), the overshoot is the largest
    excursion of ``w`` past the new reference, in the direction of the step,
    until the next discontinuity.  Returns 0 when nothing overshoots and NaN
    when the reference has no step.
    """
    jumps = np.flatnonzero(np.abs(np.diff(w_ref)) >= min_step_rpm) + 1
    if len(jumps) == 0:
        return math.nan
    bounds = [*jumps.tolist(), len(t)]
    worst = 0.0
    for a, b in itertools.pairwise(bounds):
        direction = math.copysign(1.0, float(w_ref[a] - w_ref[a - 1]))
        over = direction * (w[a:b] - w_ref[a:b])
        worst = max(worst, float(np.max(over)))
    return worst


#: Lost rotor angle (DESIGN.md, exit status 4): |dtheta| above this (deg electrical) ...
LOCK_LOST_DEG = 90.0
#: ... for longer than this (s), after the scoring start ...
LOCK_LOST_S = 0.05
#: ... in total within any window of this length (s).  Beyond 90 degrees the
#: estimate's d axis is nearer the magnet's south than its north: the torque
#: the controller asks for has the wrong sign.  50 ms rules out a single
#: wrapped sample or a glitch.  Counting the time in a window, not only one
#: unbroken stretch, also catches an estimate that spins against the rotor:
#: it spends half of each slip period beyond 90 degrees, in stretches that can
#: be shorter than 50 ms; with a 200 ms window any slip period shorter than
#: 100 ms gives more than 50 ms (a longer one gives a stretch longer than 50 ms).
LOCK_WINDOW_S = 0.2


def lock_lost(t: Array, err_deg: Array, T_s: float) -> tuple[bool, float | None]:
    """Whether |dtheta| was above :data:`LOCK_LOST_DEG` for more than :data:`LOCK_LOST_S`
    within some :data:`LOCK_WINDOW_S` (one period ``T_s`` per row).

    ``t`` and ``err_deg`` are the scored rows, in time order.  Returns
    ``(True, t_0)`` with ``t_0`` the first row above the threshold in the
    first such window, else ``(False, None)``.
    """
    above = np.abs(err_deg) > LOCK_LOST_DEG
    if not np.any(above):
        return False, None
    w = max(1, int(round(LOCK_WINDOW_S / T_s)))
    need = LOCK_LOST_S / T_s
    c = np.concatenate(([0], np.cumsum(above)))
    n = len(above)
    ends = np.arange(1, n + 1)
    counts = c[ends] - c[np.maximum(ends - w, 0)]
    hit = np.flatnonzero(counts > need)
    if len(hit) == 0:
        return False, None
    end = int(hit[0])
    first = int(np.flatnonzero(above[max(0, end - w + 1) : end + 1])[0]) + max(0, end - w + 1)
    return True, float(t[first])


def compute_metrics(
    table: Mapping[str, Array],
    *,
    T_s: float,
    n_p: int,
    score_from_s: float = 0.0,
    thd_window_s: tuple[float, float] | None = None,
    overshoot: bool = False,
) -> dict[str, Any]:
    """The metrics of DESIGN.md from a per-step table.

    ``table`` needs the columns ``t``, ``theta_e``, ``theta_hat``,
    ``w_m_rpm``, ``w_hat_rpm``, ``w_ref_rpm`` and ``i_a``; rows whose
    optional ``mode`` column is 0 (controller disabled) are not scored.
    """
    t = table["t"]
    sel = t >= score_from_s
    if "mode" in table:
        # a disabled controller (mode 0, e.g. the stop step at the end) makes no estimate
        sel &= table["mode"] != 0
    if not np.any(sel):
        raise ValueError(f"no samples after score_from_s = {score_from_s} s")
    err = wrap_pi(table["theta_e"][sel] - table["theta_hat"][sel])
    err_deg = np.degrees(err)
    w = table["w_m_rpm"][sel]
    m: dict[str, Any] = {
        "theta_err_max_deg": float(np.max(err_deg)),
        "theta_err_min_deg": float(np.min(err_deg)),
        "theta_err_mean_deg": float(np.mean(err_deg)),
        "theta_err_abs_mean_deg": float(np.mean(np.abs(err_deg))),
        "theta_err_rms_deg": float(np.sqrt(np.mean(err_deg**2))),
        "theta_err_abs_max_deg": float(np.max(np.abs(err_deg))),
        "theta_err_abs_max_rad": float(np.max(np.abs(err))),
        "speed_err_max_rpm": float(np.max(np.abs(table["w_hat_rpm"][sel] - w))),
        "speed_track_err_max_rpm": float(np.max(np.abs(table["w_ref_rpm"][sel] - w))),
        "steps": len(t),
        "scored_steps": int(np.count_nonzero(sel)),
        "sim_s": float(len(t) * T_s),
    }
    lost, lost_at = lock_lost(t[sel], err_deg, T_s)
    m["lock_lost"] = lost
    m["lock_lost_at_s"] = lost_at
    if overshoot:
        m["speed_overshoot_rpm"] = overshoot_rpm(t[sel], table["w_ref_rpm"][sel], w)
    if thd_window_s is not None:
        win = (t >= thd_window_s[0]) & (t < thd_window_s[1])
        if np.count_nonzero(win) > 10:
            f1 = abs(float(np.mean(table["w_m_rpm"][win]))) / 60.0 * n_p
            m["thd_phase_a_pct"] = thd_pct(table["i_a"][win], T_s, f1)
    return m
