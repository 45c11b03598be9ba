"""Hybrid estimators: HF injection handed over to the flux observer (controller/_hybrid.py).

The closed-loop tests run the shipped ``wide-speed-*`` scenarios' speed and
load profiles in-process on ``plant_rt`` (floats, no DBC quantisation), the
hybrid and, for the speed comparison, the sensored baseline.
"""

from __future__ import annotations

import cmath
import functools
import itertools
import math
from dataclasses import replace

import numpy as np
import pytest

from bench.runs._metrics import (
    GOAL_DIP_PCT,
    GOAL_STEADY_DEG,
    GOAL_TRANSIENT_DEG,
    STEADY_SETTLE,
    steady_rows,
)
from bench.scenarios._schema import load_scenario, split_options
from bench.scenarios._setup import motor_model
from controller import Controller, HybridEstimator, TransitionBand, design, make_estimator
from controller._hybrid import ABOVE, BELOW, INSIDE
from controller._registry import injection_family
from plant_rt import Plant, preset
from tests.hybrid_helpers import HybridTrace, profile, run_profiles
from tests.loop_helpers import RPM, make_loop
from tests.test_closed_form_flux_observer import WEN, XUE, ZETA, run_ideal

CASES = {
    "wen": ("wide-speed-wen", "wen2023", "hybrid-tt-dq"),
    "xue": ("wide-speed-xue", "xue2022", "hybrid-square-wave"),
}


def test_registry_gives_the_injection_family_and_checks_options() -> None:
    """The hybrids belong to their injection method's family (the bench's scenario
    checks and reruns go by it); injection options pass through, unknown keys fail."""
    assert injection_family("hybrid-tt-dq") == "rotating"
    assert injection_family("hybrid-square-wave") == "square"
    m = motor_model(preset("wen2023"))
    est = make_estimator("hybrid-tt-dq", m, 1e-4, V_h=30.0, theta_max=math.radians(4.0))
    assert isinstance(est, HybridEstimator)
    assert est.hf.V_h == 30.0
    assert est.band.w_lo == pytest.approx(design(m, theta_max=math.radians(4.0)).band.w_lo)
    with pytest.raises(TypeError):
        make_estimator("hybrid-tt-dq", m, 1e-4, U_h=20.0)
    with pytest.raises(TypeError):
        make_estimator("hybrid-square-wave", motor_model(preset("xue2022")), 1e-3, V_h=20.0)


def test_design_meets_its_targets() -> None:
    """``w_lo``: the back-EMF is ``sqrt(1 + 4 zeta_f^2)/theta_max`` times the voltage
    uncertainty ``0.2 R_s i_max``; ``alpha_o``: the PLL's steady error at the largest
    acceleration the controller can command is ``theta_acc`` (5 degrees)."""
    for name in ("wen2023", "xue2022"):
        m = motor_model(preset(name))
        d = design(m)
        b = d.band
        assert d.du == pytest.approx(0.2 * m.R_s * m.i_max)
        err_at_w_lo = d.du * math.sqrt(1.0 + 4.0 * d.zeta_f**2) / (b.w_lo * m.psi_f)
        assert err_at_w_lo == pytest.approx(math.radians(5.0))
        assert (b.w_mid, b.w_hi, b.h) == pytest.approx((1.5 * b.w_lo, 2.0 * b.w_lo, 0.1 * b.w_lo))
        a_max = m.n_p * m.tau_max / m.J
        assert a_max / d.alpha_o**2 == pytest.approx(math.radians(5.0))
        # an inverter voltage error raises the band in proportion
        d2 = design(m, u_err=d.du)
        assert d2.band.w_lo == pytest.approx(2.0 * b.w_lo)


def test_schedule_hysteresis_and_exact_ends() -> None:
    """The play operator and the ramps: rising, the observer takes weight only above
    ``w_lo + h`` and the injection is exactly zero from ``w_hi + h``; falling, the
    injection returns below ``w_hi`` and the HF estimator takes weight below ``w_mid``;
    a ripple smaller than the play inside the band does not move the schedule."""
    band = TransitionBand(100.0, 150.0, 200.0, 10.0)
    y = 0.0
    up = np.linspace(0.0, 300.0, 3001)
    lam_up, g_up = [], []
    for s in up:
        y = band.play(y, float(s))
        lam, g = band.weights(y)
        lam_up.append(lam)
        g_up.append(g)
    lam_a, g_a = np.array(lam_up), np.array(g_up)
    assert (lam_a[up <= 110.0] == 0.0).all() and (lam_a[up > 110.05] > 0.0).all()
    assert (g_a[up >= 210.0] == 0.0).all() and (g_a[up < 209.95] > 0.0).all()
    assert (lam_a[up >= 160.0] == 1.0).all() and (g_a[up <= 160.0] == 1.0).all()
    down = up[::-1]
    lam_dn, g_dn = [], []
    for s in down:
        y = band.play(y, float(s))
        lam, g = band.weights(y)
        lam_dn.append(lam)
        g_dn.append(g)
    lam_d, g_d = np.array(lam_dn), np.array(g_dn)
    assert (g_d[down >= 200.0] == 0.0).all() and (g_d[down < 199.95] > 0.0).all()
    assert (lam_d[down >= 150.0] == 1.0).all() and (lam_d[down < 149.95] < 1.0).all()
    assert (lam_d[down <= 100.0] == 0.0).all() and (g_d[down <= 150.0] == 1.0).all()
    # negative speeds schedule like positive ones
    assert band.play(0.0, -300.0) == band.play(0.0, 300.0) == 290.0
    # ripple of +/- 4 (less than h/2) around 170: after its first peak has taken up
    # the play, y, so lam and g, stay put
    ripple = 170.0 + 4.0 * np.sin(np.linspace(0.0, 20.0 * math.pi, 400))
    y = 0.0
    for s in ripple[:20]:
        y = band.play(y, float(s))
    held = band.weights(y)
    assert 0.0 < held[1] < 1.0
    for s in ripple[20:]:
        y = band.play(y, float(s))
        assert band.weights(y) == held
    # the pure per-band split the bench uses (true speed: one more play either side)
    assert band.edges == (90.0, 220.0)
    got = [band.band_of(w) for w in (-89.9, 90.0, 220.0, -220.1)]
    assert got == [BELOW, INSIDE, INSIDE, ABOVE]


def test_band_edge_meets_the_angle_budget_for_the_stated_uncertainty() -> None:
    """At the lower band edge ``w_lo`` of :func:`controller.design`, a resistance error of
    ``r_tol = 20 %`` at the current limit, in any current direction with ``i_d <= 0``,
    leaves at most ``theta_max = 5`` degrees; at ``2 w_lo`` at most half."""
    for m, T in ((WEN, 1e-4), (XUE, 1e-3)):
        d = design(m)
        w_lo = d.band.w_lo
        model = replace(m, R_s=0.8 * m.R_s)
        worst = {1.0: 0.0, 2.0: 0.0}
        for phi in np.linspace(math.pi / 2, math.pi, 7):
            i_r = m.i_max * cmath.exp(1j * phi)
            for f in worst:
                w = f * w_lo
                errs, _, _ = run_ideal(
                    m, model, T, w, i_r, round(8.0 / (ZETA * w * T)), alpha_o=d.alpha_o, w_min=w_lo
                )
                worst[f] = max(worst[f], abs(errs[-1]))
        assert worst[1.0] <= math.radians(5.0)
        assert worst[1.0] > math.radians(2.5)  # the bound is not vacuous
        assert worst[2.0] <= math.radians(2.5)


@pytest.mark.parametrize(
    ("name", "hf", "rpm", "seconds"),
    [("wen2023", "tt-dq", 100.0, 1.0), ("xue2022", "square-wave", 30.0, 2.0)],
)
def test_below_the_band_the_hybrid_is_its_injection_estimator(
    name: str, hf: str, rpm: float, seconds: float
) -> None:
    """From an unknown angle (start-up with polarity test) to a speed below the band,
    ``hybrid-*`` and its injection estimator give bit-identical duties and estimates:
    the observer runs beside it (slaved) and changes nothing (tt-dq with the tracking
    BPF the hybrid turns on)."""
    P = preset(name)
    traces = []
    for est in (hf, f"hybrid-{hf}"):
        opts = {"bpf_tracking": True} if est == "tt-dq" else {}
        plant, ctrl = make_loop(P, est, theta_e0=2.2, estimator_options=opts)
        tr = run_profiles(plant, ctrl, seconds, [(0.0, 0.0), (0.3, 0.0), (0.5, rpm)])
        traces.append((tr, plant.truth()))
    (a, ta), (b, tb) = traces
    assert np.array_equal(a.theta_hat, b.theta_hat)
    assert np.array_equal(a.w_hat, b.w_hat)
    assert np.array_equal(a.u_h, b.u_h)
    assert ta == tb
    assert np.abs(b.w_m[-100:] / RPM - rpm).max() < 2.0
    assert (b.weight == 0.0).all()


def _options(case: str, estimator: str) -> dict[str, object]:
    """The scenario's estimator options that ``estimator`` takes (``u_err`` on xue)."""
    scn = load_scenario(CASES[case][0])
    return split_options(dict(scn.estimator_options), estimator)[0]


def _loop(case: str, estimator: str | None = None) -> tuple[Plant, Controller]:
    scn_name, name, est = CASES[case]
    scn = load_scenario(scn_name)
    est = estimator or est
    return make_loop(
        preset(name),
        est,
        theta_e0=math.radians(scn.theta_e0_deg),
        estimator_options=_options(case, est),
    )


@functools.cache
def _wide(case: str, estimator: str | None = None) -> HybridTrace:
    scn = load_scenario(CASES[case][0])
    plant, ctrl = _loop(case, estimator)
    return run_profiles(plant, ctrl, scn.duration, scn.speed_rpm.points, scn.load_nm.points)


def _band(case: str) -> TransitionBand:
    u_err = float(_options(case, CASES[case][2]).get("u_err", 0.0))  # type: ignore[arg-type]
    return design(motor_model(preset(CASES[case][1])), u_err=u_err).band


def _steady(case: str) -> np.ndarray:
    """The steady-speed rows of the ``wide-speed`` trace (bench.runs._metrics.steady_rows:
    reference and load unchanged for 6 / alpha_s), from the staircase the bench sends."""
    tr = _wide(case)
    scn = load_scenario(CASES[case][0])
    alpha_s = _loop(case)[1].alpha_s
    step = 1.0 / scn.reference_rate_hz
    held = np.floor(tr.t / step) * step  # the reference as the nodes' staircase holds it
    ts, vs = profile(scn.speed_rpm.points)
    tl, vl = profile(scn.load_nm.points)
    return steady_rows(
        tr.t, np.interp(held, ts, vs), np.interp(held, tl, vl), STEADY_SETTLE / alpha_s
    )


@pytest.mark.parametrize("case", ["xue", "wen"])
def test_wide_speed_keeps_the_angle_through_start_reversal_and_stop(case: str) -> None:
    """The whole ``wide-speed`` profile: start from an unknown angle, rated load at low
    and rated speed, reversal through zero under rated load, standstill. No lock lost:
    |dtheta| <= 10 degrees (the transient goal) everywhere after the start-up and <= 5
    degrees (the steady goal) at steady speeds, and the drive really went to +/- rated
    speed and back to standstill."""
    tr = _wide(case)
    scn = load_scenario(CASES[case][0])
    sel = tr.t >= scn.score_from_s
    e = np.degrees(np.abs(tr.err[sel]))
    assert e.max() <= GOAL_TRANSIENT_DEG
    steady = _steady(case)[sel]
    # steady rows below the band and at rated speed (each flat of the profile)
    w_ref = np.abs(tr.w_m_ref[sel]) / RPM
    rated_rpm = max(v for _, v in scn.speed_rpm.points)
    lo_rpm = _band(case).edges[0] / (preset(CASES[case][1]).motor.n_p * RPM)
    n_03 = 0.3 / float(tr.t[1] - tr.t[0])  # rows in 0.3 s
    assert (steady & (w_ref > 0.0) & (w_ref < lo_rpm)).sum() > n_03
    assert (steady & (w_ref >= rated_rpm)).sum() > n_03
    assert e[steady].max() <= GOAL_STEADY_DEG
    rated = max(v for _, v in scn.speed_rpm.points)
    w = tr.w_m / RPM
    assert w.max() > 0.98 * rated and w.min() < -0.98 * rated
    assert abs(w[-1]) < 2.0
    # the rated load was carried at rated speed by the observer alone (no injection)
    rated_loaded = (np.abs(tr.w_m_ref / RPM) >= rated) & (np.abs(tr.i_q) > 0.9 * tr.i_q.max())
    assert rated_loaded.sum() > 100
    assert (tr.u_h[rated_loaded] == 0.0).all()


@pytest.mark.parametrize("case", ["wen", "xue"])
def test_injection_is_exactly_zero_above_the_band_and_full_below(case: str) -> None:
    """Whenever the true speed is above the band (:meth:`TransitionBand.band_of`) the
    commanded HF voltage is exactly 0.0; below it, the injection estimator's full
    amplitude."""
    tr = _wide(case)
    band = _band(case)
    where = np.array([band.band_of(float(w)) for w in tr.w_e])
    above = where == ABOVE
    below = (where == BELOW) & (tr.mode == 3)
    assert above.sum() > 1000 and below.sum() > 1000
    assert (tr.u_h[above] == 0.0).all()
    assert (tr.gain[below] == 1.0).all()
    assert tr.u_h[below].min() > 0.0


#: Bound of the ripple of the trackers' integral speed states (rad/s, electrical), the
#: figure the play ``h`` is justified with (controller/_hybrid.py).
R_S = 1.0


def _windows(mask: np.ndarray) -> list[tuple[int, int]]:
    """``[start, end)`` index ranges where ``mask`` is true."""
    edges = np.flatnonzero(np.diff(np.concatenate(([0], mask.astype(int), [0]))))
    return list(zip(edges[::2], edges[1::2], strict=True))


@pytest.mark.parametrize("case", ["xue", "wen"])
def test_hand_over_is_continuous(case: str) -> None:
    """Across every hand-over (``0 < lam < 1``, both directions) the output moves, beyond
    the estimators' own step-to-step motion, by ``|dlam| |d|`` at most (``d =
    wrap(theta_obs - theta_HF)``). Derived bounds: the play and the ramp make ``lam``
    Lipschitz in the schedule speed, ``|dlam| <= |dy| / (w_mid - w_lo)``; the schedule
    speed moves per period by at most ``2 T a`` (``a`` the scenario's largest reference
    acceleration, doubled for the speed loop) plus twice the speed states' ripple bound
    ``R_S``; and ``|d| <= 10`` degrees (each estimator locked within its 5-degree budget).
    The same for the speed estimate, with the two speeds' largest disagreement in the
    blend (the tt-dq's raw speed carries its ``k_p err`` ripple, the square-wave's its
    lag under acceleration)."""
    tr = _wide(case)
    band = _band(case)
    scn = load_scenario(CASES[case][0])
    n_p = preset(CASES[case][1]).motor.n_p
    T = float(tr.t[1] - tr.t[0])
    pts = scn.speed_rpm.points
    a_ref = max(
        abs(v1 - v0) / (t1 - t0) for (t0, v0), (t1, v1) in itertools.pairwise(pts) if t1 > t0
    )
    dy_bound = 2.0 * T * a_ref * RPM * n_p + 2.0 * R_S
    dlam_bound = dy_bound / (band.w_mid - band.w_lo)
    lam = tr.weight
    blend = (lam > 0.0) & (lam < 1.0)
    assert len(_windows(blend)) >= 4  # up, down through zero, and the stop
    # the weight used at sample k + 1 is the schedule's after sample k
    assert np.array_equal(lam[1:], [band.weights(float(v))[0] for v in tr.y[:-1]])
    dlam = np.abs(np.diff(lam))
    dy = np.abs(np.diff(tr.y))
    assert (dlam[1:] <= dy[:-1] / (band.w_mid - band.w_lo) + 1e-12).all()
    settled = tr.t[1:] > 0.5
    assert dy[settled].max() <= dy_bound
    d = np.abs((tr.th_obs - tr.th_hf + math.pi) % (2.0 * math.pi) - math.pi)
    assert np.degrees(d[blend].max()) <= 10.0
    # per-step change of the angle error (the truth moves smoothly)
    jump = np.abs(np.diff(tr.err))
    step_blend = blend[1:] | blend[:-1]
    own = jump[settled & ~step_blend].max()
    bound = own + dlam_bound * math.radians(10.0)
    assert jump[step_blend].max() <= bound, (np.degrees(jump[step_blend].max()), np.degrees(bound))
    # speed estimate
    dw = np.abs(np.diff(tr.w_hat))
    own_w = dw[settled & ~step_blend].max()
    disagree = np.abs(tr.w_obs - tr.w_hf)[blend].max()
    assert dw[step_blend].max() <= own_w + dlam_bound * disagree


#: Peak of the 2DOF speed loop's response to a step in its speed measurement: the closed
#: loop from measurement to speed is ``(2 a s + a^2) / (s + a)^2``, step peak ``1 + e^-2``.
SPEED_LOOP_PEAK = 1.0 + math.exp(-2.0)


@pytest.mark.parametrize("case", ["wen", "xue"])
def test_no_speed_dip_at_the_hand_over(case: str) -> None:
    """While the schedule moves (blend or fade), the drive's speed departs from the
    sensored drive's on the same profile, counted from the difference the two had when
    the hand-over began, by at most 5 % of the speed plus what the hand-over must pass
    on: the injection estimator's speed error at that instant (the speed loop's
    measurement steps from it to the observer's), times the loop's step peak 1.135."""
    tr = _wide(case)
    ref = _wide(case, "sensored")
    moving = ((tr.weight > 0.0) & (tr.weight < 1.0)) | ((tr.gain > 0.0) & (tr.gain < 1.0))
    wins = _windows(moving)
    assert len(wins) >= 4
    for i0, i1 in wins:
        diff = tr.w_m[i0:i1] - ref.w_m[i0:i1]
        handed = SPEED_LOOP_PEAK * abs(tr.w_m_hat[i0] - tr.w_m[i0])
        excess = np.abs(diff - diff[0]) - 0.05 * np.abs(ref.w_m[i0:i1]) - handed
        assert excess.max() <= 0.0, (tr.t[i0], excess.max() / RPM)


@functools.cache
def _drive_metrics(case: str) -> dict[str, object]:
    """The hybrid's ``wide-speed`` run on the drive plant with its countermeasures
    (bench.studies._plants: switching inverter with 2 us dead time and 1.5 V drops, ADC,
    offsets, cross-saturation), in-process, as the suite runs it."""
    import tempfile
    from pathlib import Path

    from bench.studies._plants import plant_variant
    from bench.studies._suite import RunJob

    scn_name, _, est = CASES[case]
    scn = plant_variant(load_scenario(scn_name), "drive")
    with tempfile.TemporaryDirectory() as d:
        res = RunJob(scn, est, Path(d) / "run", None, "drive")()
    assert not res.get("error"), res.get("error")
    return dict(res["metrics"])


@pytest.mark.parametrize("case", ["wen", "xue"])
def test_the_full_speed_range_goals_on_the_drive_plant(case: str) -> None:
    """The goals on the drive plant: no lost lock, |dtheta| <= 5 degrees at steady speeds
    and <= 10 through the transients, every hand-over's dip within 5 %. Above the band
    the injection is off (the commanded HF voltage is exactly zero, tested on the ideal
    plant above); what the loss metric still finds there on a switching inverter is the
    PWM ripple above the separation's corner (0.14 % of the injection's loss below the
    band at 1 kHz), so it is bounded at 1 % of it."""
    m = _drive_metrics(case)
    assert m["lock_lost"] is False and not m.get("tripped")
    assert m["theta_err_steady_max_deg"] <= GOAL_STEADY_DEG  # type: ignore[operator]
    assert m["theta_err_transient_max_deg"] <= GOAL_TRANSIENT_DEG  # type: ignore[operator]
    assert len(m["handover_dips_pct"]) >= 4  # type: ignore[arg-type]
    assert m["handover_dip_max_pct"] <= GOAL_DIP_PCT  # type: ignore[operator]
    assert m["band_above_injection_loss_w"] < 1e-2 * m["band_below_injection_loss_w"]  # type: ignore[operator]
