"""tt-dq's acceleration feed-forward (``accel_ff``): the speed reference's designed
acceleration fed into the PLL, beside its loop, which keeps its margin and noise gain."""

from __future__ import annotations

import math
from dataclasses import fields
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from bench.scenarios._schema import load_scenario
from bench.scenarios._setup import build_plant
from controller import EstimatorInput, Measurement
from controller._engine import core_kind
from controller._pll import PositionObserver, open_loop
from controller._rotating import in_loop_response
from plant_rt import preset
from tests import oracle
from tests.loop_helpers import motor_model
from tests.oracle.blocks import OracleReferenceModel
from tests.oracle.estimators import make_oracle_estimator

P = preset("wen2023")
T_S = P.T_s
MODEL = motor_model(P)
W_H = 2.0 * math.pi * 500.0


def _noise_gain(est: object) -> float:
    """Peak of ``|L / (1 + L)|``: how much of the error's noise reaches the angle."""
    w = np.linspace(1.0, 0.999 * math.pi / T_S, 20000)
    loop = open_loop(est.w_o, T_S, w) * in_loop_response(  # type: ignore[attr-defined]
        "bpf+lpf",
        T_S,
        W_H,
        est.filters_z,  # type: ignore[attr-defined]
        w,
    )
    return float(np.max(np.abs(loop / (1.0 + loop))))


def test_the_loop_keeps_its_margin_and_noise_gain() -> None:
    plain = make_oracle_estimator("tt-dq", MODEL, T_S)
    ff = make_oracle_estimator("tt-dq", MODEL, T_S, accel_ff=True)
    assert ff.w_o == plain.w_o  # type: ignore[attr-defined]
    assert ff.phase_margin() == plain.phase_margin()  # type: ignore[attr-defined]
    pm, _ = ff.phase_margin()  # type: ignore[attr-defined]
    assert pm == pytest.approx(45.0, abs=0.1)
    assert _noise_gain(ff) == _noise_gain(plain) == pytest.approx(1.35, abs=0.01)


def test_the_feed_forward_is_beside_the_loop() -> None:
    """Superposition: the angle with an error and an acceleration is the sum of each alone,
    so the error's path to the angle is the PLL's whatever is fed forward."""
    rng = np.random.default_rng(3)
    err = 1e-3 * rng.standard_normal(400)
    acc = 50.0 * np.sin(np.arange(400) * 0.01)

    def run(e: np.ndarray, a: np.ndarray) -> np.ndarray:
        o = PositionObserver(58.5, T_S)
        o.reset(1.0)  # away from the wrap at 0 and 2 pi
        out = []
        for x, y in zip(e, a, strict=True):
            o.update(float(x), float(y))
            out.append(o.theta_hat)
        return np.asarray(out)

    both = run(err, acc) - 1.0
    assert both == pytest.approx((run(err, 0 * acc) - 1.0) + (run(0 * err, acc) - 1.0), abs=1e-12)


def _ramp_error(accel_ff: bool, a: float, n: int) -> float:
    """tt-dq's |theta_e - theta_hat| at the end of a constant acceleration ``a`` (rad/s^2,
    electrical) from standstill, on the synthetic currents of Wen eq. (4)."""
    est = make_oracle_estimator("tt-dq", MODEL, T_S, accel_ff=accel_ff)
    I_p, I_n = est.I_p, est.I_n  # type: ignore[attr-defined]
    est.reset(0.0)
    for k in range(n):
        t = k * T_S
        th = 0.5 * a * t * t
        i = I_p * np.exp(1j * (W_H * t - math.pi / 2)) + I_n * np.exp(
            1j * (-W_H * t + 2 * th + math.pi / 2)
        )
        est.update(EstimatorInput(k, float(i.real), float(i.imag), 0.0, accel_ref=a))
    th = 0.5 * a * (n * T_S) ** 2
    d = (th - est.theta_hat + math.pi) % (2 * math.pi) - math.pi
    return abs(d)


def test_a_known_acceleration_leaves_no_lag() -> None:
    a, n = 100.0, 5000  # 0.5 s: w_e reaches 50 rad/s, within the BPF's passband
    plain = make_oracle_estimator("tt-dq", MODEL, T_S)
    lag = a / plain.w_o**2  # type: ignore[attr-defined]
    without = _ramp_error(False, a, n)
    with_ff = _ramp_error(True, a, n)
    # the feed-forward takes away exactly the PLL's lag; what stays is the demodulation's
    # own small error at 50 rad/s with the BPF fixed at w_h, the same with or without it
    assert without - with_ff == pytest.approx(lag, rel=0.05)
    assert with_ff < 0.2 * lag
    half = _ramp_error(False, a / 2, n) - _ramp_error(True, a / 2, n)
    assert half == pytest.approx(lag / 2, rel=0.05)


def test_reference_model_is_the_designed_response() -> None:
    alpha_s, n_p, J = 18.8, 4, 0.003
    m = OracleReferenceModel(alpha_s, n_p, J, 100.0, T_S)  # a limit that does not act
    acc = np.array([m.update(10.0) for _ in range(20000)])
    k = np.arange(20000)
    # the step response of alpha_s / (s + alpha_s), forward Euler, differentiated
    assert acc == pytest.approx(
        n_p * alpha_s * 10.0 * (1.0 - alpha_s * T_S) ** k, rel=1e-9, abs=1e-9
    )
    assert np.sum(acc) * T_S == pytest.approx(n_p * 10.0, rel=1e-3)
    lim = OracleReferenceModel(alpha_s, n_p, J, 0.1, T_S)  # 0.1 N m: at most n_p 0.1 / J
    assert max(lim.update(10.0) for _ in range(100)) == pytest.approx(n_p * 0.1 / J)


def test_options_where_it_applies() -> None:
    with pytest.raises(ValueError, match="accel_ff"):
        make_oracle_estimator("sfhf", MODEL, T_S, accel_ff=True)
    with pytest.raises(ValueError, match="accel_ff"):
        make_oracle_estimator("tt-dq", MODEL, T_S, accel_ff=True, observer="mechanical")

    from types import SimpleNamespace

    # tt-dq's and the hybrid's tt-dq's feed-forward is in the core, with their kinds
    for name, kind in (("tt-dq", 1), ("hybrid-tt-dq", 6)):
        pars = SimpleNamespace(estimator=name, estimator_options={"accel_ff": True})
        assert core_kind(pars) == kind


def _trace(scn: Any, estimator: str, engine: str, n: int) -> tuple[list[tuple[float, ...]], Any]:
    """A closed loop on the compiled plant: start-up, then speed steps up and down; every
    output of every period."""
    sim = build_plant(scn, "compiled")
    ctrl = oracle.build(scn, estimator, engine)
    ctrl.set_enable(True)
    d = (0.5, 0.5, 0.5, False)
    out = []
    for k in range(n):
        if k in (n // 3, (2 * n) // 3):
            ctrl.set_speed_ref(30.0 if k == n // 3 else -20.0)
        s = sim.sample()
        o = ctrl.step(Measurement(s.k, s.i_a, s.i_b, s.i_c, s.u_dc))
        sim.step(*d)
        out.append(tuple(float(getattr(o, f.name)) for f in fields(o)))
        d = (o.d_a, o.d_b, o.d_c, o.enable)
    return out, ctrl


@pytest.mark.parametrize("estimator", ["tt-dq", "hybrid-tt-dq"])
def test_accel_ff_is_the_oracles(tmp_path: Path, estimator: str) -> None:
    """wen-5.1's start-up and two speed steps with ``accel_ff``: the core gives the oracle's
    output (tests/oracle, tolerance 0: bit for bit) in every period, and the feed-forward
    acts (the trace without it differs once the speed loop runs)."""
    assert oracle.TOLERANCE == 0.0  # the outputs' values are compared exactly
    f = tmp_path / "ff.toml"
    f.write_text('extends = "wen-5.1"\n[estimator_options]\naccel_ff = true\n')
    scn = load_scenario(str(f))
    n = 6000
    py, c_py = _trace(scn, estimator, "oracle", n)
    cc, c_cc = _trace(scn, estimator, "compiled", n)
    assert (c_py.engine, c_cc.engine, c_cc.engine_note) == ("oracle", "compiled", None)
    first = next((k for k in range(n) if py[k] != cc[k]), None)
    assert first is None, f"the engines part at period {first}"
    plain, _ = _trace(load_scenario("wen-5.1"), estimator, "compiled", n)
    parted = next(k for k in range(n) if plain[k] != cc[k])
    assert n // 3 <= parted < n // 3 + 10  # the first period of the step's acceleration


def test_the_tables_maxima_with_accel_ff_are_claims_per_plant() -> None:
    from bench.studies._report import NOT_REPRODUCED, REPRODUCED, evaluate_claims, render_markdown
    from tests.test_report import _run, good_summary

    s = good_summary()
    s["runs"].append(
        _run(
            "wen-5.3",
            "tt-dq",
            {"theta_err_max_deg": 5.0, "theta_err_min_deg": -5.0, "theta_err_mean_deg": 2.5},
            theta_err_abs_max_deg=7.9,
        )
        | {"paper": "Wen et al. 2023, Sec. 5.3, Fig. 16, Table 7"}
    )
    where = {"t_s": 1.01, "theta_err_deg": 6.0, "context": "0.11 s after the load change"}
    s["accel_ff"] = {
        "ideal": {"wen-5.3": {"theta_err_abs_max_deg": 6.0, "lock_lost": False, "where_max": where}}
    }
    c = {x["id"]: x for x in evaluate_claims(s)}["wen-5.3-max-accel-ff"]
    assert c["verdict"] == NOT_REPRODUCED and "Table 7" in c["claim"]
    assert "6.00 deg (without accel_ff 7.90)" in c["detail"] and "load change" in c["detail"]
    s["claims"] = evaluate_claims(s)
    assert "cannot where the largest error follows a change of load" in render_markdown(s)
    s["accel_ff"]["ideal"]["wen-5.3"]["theta_err_abs_max_deg"] = 4.9
    v = {x["id"]: x["verdict"] for x in evaluate_claims(s)}
    assert v["wen-5.3-max-accel-ff"] == REPRODUCED
