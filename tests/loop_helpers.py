"""In-process closed loops of plant_rt and controller for the controller tests.

Timing (DESIGN.md): at step ``k`` the plant's sample ``k`` goes to the
controller, whose duties apply in period ``k + 1``; the plant runs period
``k`` with the duties computed from sample ``k - 1``. The position error is
scored at each sample instant: ``wrap(theta_e(k T_s) - theta_hat_k)``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from bench.scenarios._setup import motor_model
from controller import Controller, ControllerPars, Measurement
from plant_rt import Plant, Preset


def wrap(x: np.ndarray) -> np.ndarray:
    """Wrap angles (rad) to [-pi, pi)."""
    return (x + np.pi) % (2.0 * np.pi) - np.pi


@dataclass
class Trace:
    """Per-step signals of a closed loop (arrays over the sample instants)."""

    t: np.ndarray
    err: np.ndarray  # wrap(theta_e - theta_hat) (rad)
    w_m: np.ndarray  # true mechanical speed (rad/s)
    w_m_hat: np.ndarray  # controller's filtered estimate (rad/s)
    mode: np.ndarray
    i_d: np.ndarray  # true rotor-frame currents (A)
    i_q: np.ndarray


def run(
    plant: Plant,
    ctrl: Controller,
    n_steps: int,
    w_m_ref: Callable[[float], float] | float = 0.0,
    sensored: bool = False,
) -> Trace:
    """Run ``n_steps`` PWM periods in lockstep and return the trace."""
    out_t = np.empty(n_steps)
    err = np.empty(n_steps)
    w_m = np.empty(n_steps)
    w_hat = np.empty(n_steps)
    mode = np.empty(n_steps, dtype=int)
    i_d = np.empty(n_steps)
    i_q = np.empty(n_steps)
    d_a = d_b = d_c = 0.5
    en = False
    ref = w_m_ref if callable(w_m_ref) else None
    if ref is None:
        ctrl.set_speed_ref(float(w_m_ref))  # type: ignore[arg-type]
    for n in range(n_steps):
        s = plant.sample()
        tr = plant.truth()
        if ref is not None:
            ctrl.set_speed_ref(ref(tr.t))
        if sensored:
            meas = Measurement(s.k, s.i_a, s.i_b, s.i_c, s.u_dc, tr.theta_e, tr.w_e)
        else:
            meas = Measurement(s.k, s.i_a, s.i_b, s.i_c, s.u_dc)
        out = ctrl.step(meas)
        plant.step(d_a, d_b, d_c, en)  # period k: duties from sample k - 1
        d_a, d_b, d_c, en = out.d_a, out.d_b, out.d_c, out.enable
        out_t[n] = tr.t
        err[n] = tr.theta_e - out.theta_hat
        w_m[n] = tr.w_m
        w_hat[n] = ctrl.w_m_hat
        mode[n] = out.mode
        i_d[n] = tr.i_d
        i_q[n] = tr.i_q
    return Trace(out_t, wrap(err), w_m, w_hat, mode, i_d, i_q)


def make_loop(
    preset: Preset,
    estimator: str,
    theta_e0: float = 0.0,
    w_m0: float = 0.0,
    saturation: bool = True,
    **pars: object,
) -> tuple[Plant, Controller]:
    """A plant at its preset's PWM rate and an enabled controller for it."""
    T_s = preset.T_s
    plant = Plant(
        preset.motor,
        preset.inverter,
        T_s,
        saturation=saturation,
        theta_m0=theta_e0 / preset.motor.n_p,
        w_m0=w_m0,
    )
    ctrl = Controller(
        ControllerPars(motor=motor_model(preset), T_s=T_s, estimator=estimator, **pars)  # type: ignore[arg-type]
    )
    ctrl.set_enable(True)
    return plant, ctrl


RPM = 2.0 * math.pi / 60.0
