"""In-process closed loop with speed and load profiles, recording the hybrid estimator's state.

Same timing as :mod:`tests.loop_helpers` (sample ``k`` to the controller,
its duties applied in period ``k + 1``); the load is a piecewise-linear
profile applied as a constant torque per period, as the bench's commands do.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from controller import Controller, HybridEstimator, Measurement
from plant_rt import ConstantLoad, Plant
from tests.loop_helpers import RPM, wrap


@dataclass
class HybridTrace:
    """Per-step signals (arrays over the sample instants)."""

    t: np.ndarray
    err: np.ndarray  # wrap(theta_e - theta_hat) (rad)
    theta_hat: np.ndarray  # reported estimate (rad)
    w_e: np.ndarray  # true electrical speed (rad/s)
    w_hat: np.ndarray  # the estimator's own speed estimate (rad/s, electrical)
    w_m: np.ndarray  # true mechanical speed (rad/s)
    w_m_ref: np.ndarray  # speed reference (rad/s)
    w_m_hat: np.ndarray  # the filtered speed estimate the speed loop uses (rad/s)
    weight: np.ndarray  # observer weight used for this sample
    gain: np.ndarray  # injection factor of the period after this sample
    y: np.ndarray  # schedule speed after the play, after this sample (rad/s)
    u_h: np.ndarray  # |injection voltage| commanded for the next period (V)
    th_hf: np.ndarray  # the injection estimator's angle (rad; the output's below the band)
    th_obs: np.ndarray  # the flux observer's angle (rad)
    w_hf: np.ndarray  # their speeds (rad/s, electrical)
    w_obs: np.ndarray
    i_d: np.ndarray  # true rotor-frame currents (A)
    i_q: np.ndarray
    u_s: np.ndarray  # |fundamental voltage| the controller realised (V)
    mode: np.ndarray


def profile(points: Sequence[tuple[float, float]]) -> tuple[np.ndarray, np.ndarray]:
    """Breakpoints ``(t, value)`` as arrays for ``np.interp``."""
    return np.array([p[0] for p in points]), np.array([p[1] for p in points])


def run_profiles(
    plant: Plant,
    ctrl: Controller,
    duration: float,
    speed_rpm: Sequence[tuple[float, float]],
    load_nm: Sequence[tuple[float, float]] = ((0.0, 0.0),),
) -> HybridTrace:
    """Run ``duration`` s with piecewise-linear speed (rpm) and load (N m) profiles."""
    sensored = ctrl.family == "none"
    hybrid = isinstance(ctrl.estimator, HybridEstimator)
    T = plant.T_s
    n = int(round(duration / T))
    ts, vs = profile(speed_rpm)
    tl, vl = profile(load_nm)
    rec = {k: np.empty(n) for k in HybridTrace.__dataclass_fields__ if k != "mode"}
    mode = np.empty(n, dtype=int)
    d_a = d_b = d_c = 0.5
    en = False
    load = math.nan
    # the states are read from the controller (Controller.states), whichever engine runs
    # the periods: the Python estimator object keeps its start values on the compiled one
    st = ctrl.states()
    for k in range(n):
        s = plant.sample()
        tr = plant.truth()
        t = tr.t
        ref = float(np.interp(t, ts, vs)) * RPM
        ctrl.set_speed_ref(ref)
        tau = float(np.interp(t, tl, vl))
        if tau != load:
            plant.set_load(ConstantLoad(tau))
            load = tau
        w_used = st["weight"] if hybrid else 0.0
        if sensored:
            out = ctrl.step(Measurement(s.k, s.i_a, s.i_b, s.i_c, s.u_dc, tr.theta_e, tr.w_e))
        else:
            out = ctrl.step(Measurement(s.k, s.i_a, s.i_b, s.i_c, s.u_dc))
        st = ctrl.states()
        plant.step(d_a, d_b, d_c, en)
        d_a, d_b, d_c, en = out.d_a, out.d_b, out.d_c, out.enable
        rec["t"][k] = t
        rec["err"][k] = tr.theta_e - out.theta_hat
        rec["theta_hat"][k] = out.theta_hat
        rec["w_e"][k] = tr.w_e
        rec["w_hat"][k] = st["w_hat"]
        rec["w_m"][k] = tr.w_m
        rec["w_m_ref"][k] = ref
        rec["w_m_hat"][k] = st["w_m_hat"]
        rec["weight"][k] = w_used
        rec["gain"][k] = st["gain"] if hybrid else 1.0
        rec["y"][k] = st["y"] if hybrid else 0.0
        rec["u_h"][k] = math.hypot(st["u_h_alpha"], st["u_h_beta"])
        if hybrid:
            rec["th_hf"][k] = st["hf_theta_hat"]
            rec["th_obs"][k] = st["obs_theta_hat"]
            rec["w_hf"][k] = st["hf_w_hat"]
            rec["w_obs"][k] = st["obs_w_hat"]
        else:
            rec["th_hf"][k] = rec["th_obs"][k] = out.theta_hat
            rec["w_hf"][k] = rec["w_obs"][k] = st["w_hat"]
        rec["i_d"][k] = tr.i_d
        rec["i_q"][k] = tr.i_q
        rec["u_s"][k] = math.hypot(st["u_d"], st["u_q"])
        mode[k] = out.mode
    rec["err"] = wrap(rec["err"])
    return HybridTrace(mode=mode, **rec)
