"""Field-oriented control blocks against closed forms: transforms, PI, SVPWM, current loop."""

from __future__ import annotations

import math

import numpy as np
import pytest

from controller import (
    PIController,
    clarke,
    inv_clarke,
    inv_park,
    park,
    svpwm,
    wrap_2pi,
    wrap_pi,
)
from plant_rt import preset
from tests.loop_helpers import make_loop, run


def test_clarke_park_round_trip_and_amplitude_invariance() -> None:
    """A balanced set of amplitude 3 A at angle 0.8 rad is the vector 3 exp(j 0.8)."""
    amp, th = 3.0, 0.8
    i_abc = [amp * math.cos(th - n * 2 * math.pi / 3) for n in range(3)]
    i_al, i_be = clarke(*i_abc)
    assert i_al == pytest.approx(amp * math.cos(th), abs=1e-12)
    assert i_be == pytest.approx(amp * math.sin(th), abs=1e-12)
    i_d, i_q = park(i_al, i_be, math.cos(th), math.sin(th))
    assert (i_d, i_q) == pytest.approx((amp, 0.0), abs=1e-12)
    assert inv_park(i_d, i_q, math.cos(th), math.sin(th)) == pytest.approx((i_al, i_be))
    assert inv_clarke(i_al, i_be) == pytest.approx(i_abc)
    assert wrap_pi(3.5 * math.pi) == pytest.approx(-0.5 * math.pi)
    assert wrap_2pi(-0.5 * math.pi) == pytest.approx(1.5 * math.pi)


def test_pi_anti_windup_integrates_the_realised_output() -> None:
    """Saturated for 1 s: the integral settles where the unlimited output is
    ``u_lim + k_t e`` (back-calculation fixed point) instead of growing by
    ``k_i e t``; the output leaves saturation on the first sample after the
    error changes sign."""
    T_s, k_p, k_i, u_max = 1e-3, 1.0, 20.0, 0.5
    pi = PIController(k_p, k_i, T_s)
    for _ in range(1000):
        u = pi.output(1.0, 0.0)
        pi.update(min(u, u_max))
    assert pi.u_i == pytest.approx(u_max, rel=1e-6)  # u = 0.5 + k_p * 1 -> u_i = 0.5
    u = pi.output(0.0, 0.6)  # error -0.6
    assert u < u_max
    # Without the realised output the integrator winds up to k_i e t = 20.
    wound = PIController(k_p, k_i, T_s)
    for _ in range(1000):
        wound.update(wound.output(1.0, 0.0))
    assert wound.u_i == pytest.approx(k_i * 1.0 * 1000 * T_s, rel=1e-9)
    assert wound.output(0.0, 0.6) > u_max


def test_pi_two_degree_of_freedom_law() -> None:
    """``u = k_t r - k_p y + u_i``, ``u_i += T_s k_i (r - y)`` when not limited."""
    pi = PIController(k_p=3.0, k_i=50.0, T_s=1e-3, k_t=2.0)
    u = pi.output(1.5, 0.5)
    assert u == pytest.approx(2.0 * 1.5 - 3.0 * 0.5)
    pi.update(u)
    assert pi.u_i == pytest.approx(1e-3 * 50.0 * 1.0)


@pytest.mark.parametrize("seed", [0, 1])
def test_svpwm_duties_and_line_voltages(seed: int) -> None:
    """Inside the hexagon's inscribed circle the duties lie in [0, 1] and reproduce the
    reference exactly: line voltage ``(d_a - d_b) u_dc = u_a - u_b`` etc.; the min-max
    zero sequence centres the duties, ``max + min = 1``."""
    rng = np.random.default_rng(seed)
    u_dc = 540.0
    for _ in range(500):
        mag = rng.uniform(0.0, 1.0) * u_dc / math.sqrt(3.0)
        ang = rng.uniform(-math.pi, math.pi)
        u_al, u_be = mag * math.cos(ang), mag * math.sin(ang)
        d = svpwm(u_al, u_be, u_dc)
        assert all(0.0 <= x <= 1.0 for x in d)
        u_a, u_b, u_c = inv_clarke(u_al, u_be)
        assert (d[0] - d[1]) * u_dc == pytest.approx(u_a - u_b, abs=1e-9)
        assert (d[1] - d[2]) * u_dc == pytest.approx(u_b - u_c, abs=1e-9)
        assert max(d) + min(d) == pytest.approx(1.0, abs=1e-12)
        assert clarke(*(x * u_dc for x in d)) == pytest.approx((u_al, u_be), abs=1e-9)
    # Where the inscribed circle touches the hexagon (30 deg), two phases hit the rails.
    r = u_dc / math.sqrt(3.0)
    d = svpwm(r * math.cos(math.pi / 6), r * math.sin(math.pi / 6), u_dc)
    assert max(d) == pytest.approx(1.0) and min(d) == pytest.approx(0.0)
    # Overmodulation is clipped to [0, 1].
    assert all(0.0 <= x <= 1.0 for x in svpwm(600.0, 100.0, u_dc))


def _designed_step(L: float, R: float, a_c: float, T_s: float, n: int) -> np.ndarray:
    """Sampled step response of the designed loop, computed independently: exact ZOH
    model of ``L di/dt = -R i + u``, the 2DOF PI law with ``k_t = a_c L``,
    ``k_p = 2 a_c L - R``, ``k_i = a_c^2 L``, and the one-period computation delay
    (the voltage from sample k acts in period k + 1)."""
    a = math.exp(-R * T_s / L)
    b = (1.0 - a) / R
    k_t, k_p, k_i = a_c * L, 2 * a_c * L - R, a_c * a_c * L
    i = u_i = u_next = 0.0
    y = np.empty(n)
    for k in range(n):
        y[k] = i
        u = k_t * 1.0 - k_p * i + u_i
        u_i += T_s * k_i * (1.0 - i)
        i = a * i + b * u_next  # period k uses the voltage computed at k - 1
        u_next = u
    return y


@pytest.mark.parametrize("axis", ["d", "q"])
def test_current_loop_step_matches_bandwidth(axis: str) -> None:
    """Locked rotor, sensored, no saturation: a 2 A current step.

    The design gives ``alpha_c / (s + alpha_c)`` in continuous time. Checked:
    (1) the sampled response equals the independently computed response of
    the designed discrete loop with its one-period delay within 1 % of the
    step; (2) the fitted time constant of the tail is within 10 % of
    ``1/alpha_c``; (3) the 63 % rise time is within 10 % of ``1/alpha_c``
    (the delay and the 2DOF disturbance gain shift it by about -6 %);
    (4) no overshoot beyond 5 %, no coupling into the other axis beyond 5 %."""
    p = preset("wen2023")
    plant, ctrl = make_loop(p, "sensored", theta_e0=0.7, saturation=False)
    plant.impose_speed(0.0)
    i_ref = (2.0, 0.0) if axis == "d" else (0.0, 2.0)
    ctrl.set_current_ref(i_ref)
    n = 200
    tr = run(plant, ctrl, n, sensored=True)
    y = (tr.i_d if axis == "d" else tr.i_q) / 2.0
    a_c = float(ctrl.pars.alpha_c or 0.0)
    L = p.motor.L_d if axis == "d" else p.motor.L_q
    y_design = _designed_step(L, p.motor.R_s, a_c, p.T_s, n)
    assert np.abs(y - y_design).max() < 0.01
    t = tr.t
    sel = (y > 0.2) & (y < 0.9)
    slope, _ = np.polyfit(t[sel], np.log(1.0 - y[sel]), 1)
    assert -1.0 / slope == pytest.approx(1.0 / a_c, rel=0.10)
    t63 = float(np.interp(1.0 - math.exp(-1.0), y[:100], t[:100]))
    assert t63 == pytest.approx(1.0 / a_c, rel=0.10)
    assert y.max() < 1.05
    other = tr.i_q if axis == "d" else tr.i_d
    assert np.abs(other).max() < 0.05 * 2.0


@pytest.mark.parametrize("rpm", [500.0, 1500.0])
def test_inverse_park_uses_mid_point_of_the_next_period(rpm: float) -> None:
    """The voltage computed from sample k is applied (constant in alpha-beta) over
    period k + 1; its best rotor-frame match is at the mid-point, 1.5 T_s after the
    sample. Sensored drive at imposed speed: the plant's mean voltage of period
    k + 1, rotated by the true angle at (k + 1.5) T_s, equals the controller's
    d-q voltage of step k. Without the compensation the mismatch would be
    ``1.5 T_s w_e`` (5.4 degrees at 1500 rpm)."""
    p = preset("wen2023")
    w_m = rpm * 2 * math.pi / 60
    plant, ctrl = make_loop(p, "sensored", theta_e0=0.2, w_m0=w_m, saturation=False)
    plant.impose_speed(w_m)
    ctrl.set_current_ref((0.0, 1.0))
    from controller import Measurement

    d = (0.5, 0.5, 0.5)
    w_e = p.motor.n_p * w_m
    worst = 0.0
    prev = (0.0, 0.0)
    for n in range(400):
        s = plant.sample()
        tr = plant.truth()
        out = ctrl.step(Measurement(s.k, s.i_a, s.i_b, s.i_c, s.u_dc, tr.theta_e, tr.w_e))
        plant.step(*d, enable=n > 0)
        if n > 300:
            # plant.u_s_ab is the mean voltage of period n, computed from sample n - 1
            th_mid = tr.theta_e + 0.5 * p.T_s * w_e  # (n + 0.5) T_s = (n - 1) + 1.5
            u_d, u_q = park(*plant.u_s_ab, math.cos(th_mid), math.sin(th_mid))
            worst = max(worst, math.hypot(u_d - prev[0], u_q - prev[1]) / math.hypot(*prev))
        prev = (ctrl.u_d, ctrl.u_q)
        d = (out.d_a, out.d_b, out.d_c)
    assert worst < 1e-6
