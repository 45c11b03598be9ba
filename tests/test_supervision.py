"""The drive's supervision (controller/_supervision.py): thresholds from their targets,
each detection on deterministic signals, the reaction, and no false alarm on the papers'
scenarios."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import bench
from bench import load_scenario
from bench.scenarios._setup import build_controller, supervision_pars
from controller import ControlOutput, Measurement, MotorModel
from controller._api import MODE_ALIGN, MODE_DISABLED, MODE_RUN
from controller._supervision import (
    DETECTION_MODES,
    K_SIGMA,
    MODE_CURRENT_SENSOR,
    MODE_DC_OVERVOLTAGE,
    MODE_DC_UNDERVOLTAGE,
    MODE_OPEN_PHASE,
    SUPPLY_TOLERANCE,
    T_DC_DETECT,
    T_OPEN_MAX,
    T_STUCK_DETECT,
    SupervisionPars,
    Supervisor,
)
from tests.oracle.blocks import oracle

T_S = 1e-4
U_DC = 540.0
L_Q = 0.08


def _pars(**kw: float) -> SupervisionPars:
    d = {
        "T_s": T_S,
        "L_q": L_Q,
        "u_dc": U_DC,
        "u_dc_trip": 1.2 * U_DC,
        "i_max": 10.0,
        "i_fs": 20.0,
        "i_lsb": 40.0 / 4096,
        "i_noise": 0.0,
        "i_offset": 0.01,
        "u_lsb": 0.5,
        "u_noise": 0.0,
    }
    d.update(kw)
    return SupervisionPars.design(**d)


def _out(
    k: int,
    d: tuple[float, float, float] = (0.5, 0.5, 0.5),
    w_hat: float = 0.0,
    mode: int = MODE_RUN,
) -> ControlOutput:
    return ControlOutput(k, *d, True, 0.0, w_hat, 0.0, mode)


def test_thresholds_follow_their_targets() -> None:
    p = _pars()
    lsb = 40.0 / 4096
    assert p.u_uv == pytest.approx((1 - 2 * SUPPLY_TOLERANCE) * U_DC)  # 432 V
    assert p.u_ov == pytest.approx(0.5 * ((1 + SUPPLY_TOLERANCE) * U_DC + 1.2 * U_DC))  # 621 V
    assert (1 + SUPPLY_TOLERANCE) * U_DC < p.u_ov < 1.2 * U_DC
    assert p.u_hyst == pytest.approx(0.5 * SUPPLY_TOLERANCE * U_DC)
    assert p.n_dc == round(T_DC_DETECT / T_S) == 10
    assert p.i_rail == pytest.approx(20.0 - lsb)
    assert p.i_res == pytest.approx(lsb)  # no noise: one code
    assert p.du_stuck == pytest.approx(4 * lsb * L_Q / T_S)
    assert p.n_stuck == round(T_STUCK_DETECT / T_S)
    assert p.i_min == pytest.approx(K_SIGMA * lsb / math.sqrt(12) + 0.01)
    assert p.n_open_max == round(T_OPEN_MAX / T_S)
    noisy = _pars(i_noise=0.05)
    assert noisy.i_res == pytest.approx(lsb + 2 * K_SIGMA * 0.05)
    with pytest.raises(ValueError, match="no margin"):
        _pars(u_noise=50.0)


@pytest.mark.parametrize(
    ("u", "mode"), [(0.79 * U_DC, MODE_DC_UNDERVOLTAGE), (1.16 * U_DC, MODE_DC_OVERVOLTAGE)]
)
def test_dc_link_detected_on_the_first_mean(u: float, mode: int) -> None:
    sup = Supervisor(_pars())
    hits = [sup.check(0.0, 0.0, u, _out(k)) for k in range(25)]
    assert hits.index(mode) == 9  # the mean of the first n_dc = 10 samples
    # the supply's tolerance never alarms
    ok = Supervisor(_pars())
    for u_ok in (0.9 * U_DC, 1.1 * U_DC):
        assert not any(ok.check(0.0, 0.0, u_ok, _out(k)) for k in range(100))


def _loop(sup: Supervisor, u: list[float], enable_at: int | None = None) -> tuple[list[int], int]:
    """The wrapped step on a stand-in controller; returns the modes and the disable count."""
    state = {"enabled": True, "disables": 0}

    def step(m: Measurement) -> ControlOutput:
        return _out(m.k, mode=MODE_RUN if state["enabled"] else MODE_DISABLED)

    def disable() -> None:
        state["enabled"] = False
        state["disables"] += 1

    f = sup.wrap(step, disable)
    modes = []
    for k, uk in enumerate(u):
        if k == enable_at:
            state["enabled"] = True
        modes.append(f(Measurement(k, 0.0, 0.0, 0.0, uk)).mode)
    return modes, state["disables"]


def test_reaction_latches_and_releases_with_hysteresis() -> None:
    p = _pars()
    sag = [0.7 * U_DC] * 20
    # re-enabled inside the hysteresis band: stays stopped
    modes, n_dis = _loop(Supervisor(p), sag + [p.u_uv + 0.5 * p.u_hyst] * 30, enable_at=25)
    assert modes[9] == MODE_DC_UNDERVOLTAGE and all(m == MODE_DC_UNDERVOLTAGE for m in modes[9:])
    assert n_dis == 2  # on detection, and again on the enable inside the band
    # re-enabled above the band: released, runs again
    modes, n_dis = _loop(Supervisor(p), sag + [U_DC] * 30, enable_at=25)
    assert modes[24] == MODE_DC_UNDERVOLTAGE and modes[25:] == [MODE_RUN] * 25 and n_dis == 1


def test_no_detection_returns_the_same_output_and_stops_on_one() -> None:
    sup = Supervisor(_pars())
    out = _out(0)
    f = sup.wrap(lambda m: out, lambda: None)
    assert f(Measurement(0, 1.0, -0.5, -0.5, U_DC)) is out
    rail = _pars().i_rail
    f(Measurement(1, rail, 0.0, -rail, U_DC))
    stopped = f(Measurement(2, rail, 0.0, -rail, U_DC))
    assert stopped.mode == MODE_CURRENT_SENSOR and not stopped.enable
    assert (stopped.d_a, stopped.d_b, stopped.d_c) == (0.5, 0.5, 0.5)
    assert sup.detected_k == 2


def test_out_of_range_needs_two_samples_at_the_rail() -> None:
    p = _pars()
    sup = Supervisor(p)
    assert sup.check(p.i_rail, 0.0, U_DC, _out(0)) == 0
    assert sup.check(0.0, 0.0, U_DC, _out(1)) == 0  # one glitch is not a fault
    assert sup.check(0.0, -p.i_rail, U_DC, _out(2)) == 0
    assert sup.check(0.0, -p.i_rail, U_DC, _out(3)) == MODE_CURRENT_SENSOR
    # not while the controller is not running
    idle = Supervisor(p)
    assert not any(idle.check(p.i_rail, 0.0, U_DC, _out(k, mode=MODE_ALIGN)) for k in range(5))


def _hf(k: int, v_h: float = 50.0, f_h: float = 500.0) -> tuple[float, ...]:
    """Currents and duties of a rotating HF voltage v_h at f_h on an inductance L_Q."""
    ph = 2 * math.pi * f_h * k * T_S
    i_h = v_h / (2 * math.pi * f_h * L_Q)
    i = [i_h * math.sin(ph - 2 * math.pi * j / 3) for j in range(3)]
    d = [0.5 + v_h / U_DC * math.cos(ph - 2 * math.pi * j / 3) for j in range(3)]
    return (*i, *d)


def test_stuck_sensor_while_the_voltage_moves() -> None:
    p = _pars()
    healthy = Supervisor(p)
    for k in range(5 * p.n_stuck):
        i_a, i_b, _, d_a, d_b, d_c = _hf(k)
        assert healthy.check(i_a, i_b, U_DC, _out(k, (d_a, d_b, d_c))) == 0
    sup = Supervisor(p)
    k0 = 3 * p.n_stuck // 2  # stuck from the middle of the second window
    held = _hf(k0 - 1)[0]
    hits = []
    for k in range(4 * p.n_stuck):
        i_a, i_b, _, d_a, d_b, d_c = _hf(k)
        hits.append(sup.check(held if k >= k0 else i_a, i_b, U_DC, _out(k, (d_a, d_b, d_c))))
    # the first whole window after k0 is the third: it ends at 3 n_stuck - 1
    assert hits.index(MODE_CURRENT_SENSOR) == 3 * p.n_stuck - 1
    # a constant current with constant duties is not stuck (no voltage swing)
    still = Supervisor(p)
    assert not any(still.check(2.0, -1.0, U_DC, _out(k)) for k in range(3 * p.n_stuck))


def test_a_reading_held_at_zero_is_an_open_phase_at_any_speed() -> None:
    """The stuck check's pattern with the reading held within ``i_res`` of zero is a phase
    that carries nothing: reported as ``open_phase`` in the same window, at standstill of
    the estimate (``w_hat = 0``, where the block check does not score); held elsewhere it
    stays a stuck sensor."""
    p = _pars()
    k0 = 3 * p.n_stuck // 2
    for held, mode in ((0.0, MODE_OPEN_PHASE), (0.5 * p.i_res, MODE_OPEN_PHASE),
                       (3.0 * p.i_res, MODE_CURRENT_SENSOR)):  # fmt: skip
        sup = Supervisor(p)
        hits = []
        for k in range(4 * p.n_stuck):
            i_a, i_b, _, d_a, d_b, d_c = _hf(k)
            hits.append(sup.check(held if k >= k0 else i_a, i_b, U_DC, _out(k, (d_a, d_b, d_c))))
        first = next(h for h in hits if h)
        assert first == mode and hits.index(first) == 3 * p.n_stuck - 1, held


def _three_phase(k: int, f_e: float, amp: float) -> tuple[float, float, float]:
    th = 2 * math.pi * f_e * k * T_S
    return tuple(amp * math.cos(th - 2 * math.pi * j / 3) for j in range(3))  # type: ignore[return-value]


def test_open_phase_over_one_electrical_period() -> None:
    p = _pars()
    f_e = 20.0
    w = 2 * math.pi * f_e
    n_e = round(1 / (f_e * T_S))  # 500 periods a block
    healthy = Supervisor(p)
    for k in range(10 * n_e):
        i_a, i_b, _ = _three_phase(k, f_e, 5.0)
        assert healthy.check(i_a, i_b, U_DC, _out(k, w_hat=w)) == 0
    for open_j in range(3):
        sup = Supervisor(p)
        hits = []
        for k in range(4 * n_e):
            i = list(_three_phase(k, f_e, 5.0))
            if k >= n_e:  # the phase opens: the others carry its current between them
                i = [0.0, 0.0, 0.0]
                a, b = [j for j in range(3) if j != open_j]
                i[a] = 5.0 * math.cos(2 * math.pi * f_e * k * T_S)
                i[b] = -i[a]
            hits.append(sup.check(i[0], i[1], U_DC, _out(k, w_hat=w)))
        assert hits.index(MODE_OPEN_PHASE) == 2 * n_e - 1, open_j  # the first whole block
    # below 1 / T_OPEN_MAX electrical hertz no block is scored
    slow = Supervisor(p)
    for k in range(3 * p.n_open_max):
        assert slow.check(5.0, -5.0, U_DC, _out(k, w_hat=0.5 * 2 * math.pi / T_OPEN_MAX)) == 0


def test_modes_are_the_dbc_value_table() -> None:
    from bench.wire._codec import default_codec

    sig = default_codec().message("CtrlTelemetry").get_signal_by_name("mode")
    assert sig.choices is not None
    for m, name in DETECTION_MODES.items():
        assert str(sig.choices[m]) == name
    assert sig.maximum == max(DETECTION_MODES)


def test_supervision_follows_the_scenario(tmp_path: Path) -> None:
    plain = load_scenario("wen-5.1")
    assert supervision_pars(plain, _model()) is None
    assert not any(k.startswith("supervision.") for k in build_controller(plain, "tt-dq").gains())
    on = load_scenario("wen-5.1", {"controller.supervision": True})
    g = build_controller(on, "tt-dq").gains()
    assert g["supervision.u_uv"] == pytest.approx(0.8 * 540.0)
    f = tmp_path / "f.toml"
    f.write_text(
        'extends = "wen-5.1"\n[controller]\nsupervision = false\n'
        '[[faults]]\nat_s = 1.0\nkind = "resistance_drift"\nR_s_factor = 1.2\n'
    )
    assert supervision_pars(load_scenario(str(f)), _model()) is None


def _model() -> MotorModel:
    return MotorModel(
        n_p=4,
        R_s=1.0,
        L_d=0.05,
        L_q=L_Q,
        psi_f=0.5,
        J=0.003,
        b=0.0,
        i_max=10.0,
        tau_max=10.0,
    )


@pytest.mark.parametrize(
    ("scenario", "estimator", "duration"),
    [("wen-5.1", "tt-dq", 1.3), ("xue-fig13", "square-wave", 2.5)],
)
@pytest.mark.parametrize("profile", ["ideal", "drive"])
def test_no_false_alarm_on_the_papers_scenarios(
    scenario: str, estimator: str, duration: float, profile: str
) -> None:
    r = bench.run(
        scenario,
        estimator=estimator,
        plant_profile=profile,
        duration=duration,
        overrides={"controller.supervision": True},
    )
    modes = set(np.asarray(r.signals["mode"]).astype(int).tolist())
    assert MODE_RUN in modes and not modes & set(DETECTION_MODES), modes
    assert r.exit_status == 0


def test_a_stuck_sensor_is_detected_in_a_run(tmp_path: Path) -> None:
    f = tmp_path / "f.toml"
    f.write_text(
        'extends = "xue-fig13"\nduration = 1.2\n[[faults]]\nat_s = 0.6\n'
        'kind = "current_stuck"\nphase = "b"\nexpect = "detect"\n'
    )
    r = bench.run(str(f), estimator="square-wave")
    (fault,) = r.metrics["faults"]
    assert fault["detected_by"] == "controller_current_sensor" and fault["met"] is True
    assert 0.0 < fault["reaction_ms"] <= 2e3 * T_STUCK_DETECT
    mode = np.asarray(r.signals["mode"]).astype(int)
    t = np.asarray(r.signals["t"])
    assert np.all(mode[t >= 0.6 + 2 * T_STUCK_DETECT] == MODE_CURRENT_SENSOR)


# with an injection the other phase moves: the held-at-zero pattern within two stuck
# windows; the sensored drive at no load holds its currents still, and the block check
# over an electrical period reports it
@pytest.mark.parametrize(
    ("estimator", "bound_s"), [("tt-dq", 2 * T_STUCK_DETECT), ("sensored", 2 * T_OPEN_MAX)]
)
def test_an_open_phase_is_detected_as_one_in_a_run(estimator: str, bound_s: float) -> None:
    """The fault study's open phase (plant_rt/core/plant_leg.c) is reported as
    ``open_phase``, not as a sensor fault: the phase's reading sits at zero while the other
    carries current. (Before, the stuck check called it ``current_sensor``.)"""
    from bench.studies._faults import _u_dc, catalogue, run_case, scenario_for

    cat = dict(catalogue(_u_dc(scenario_for(estimator))))
    r = run_case(estimator, "open_phase: a", cat["open_phase: a"], 1.5)
    assert r["detected_by"] == "controller_open_phase", r
    assert 0.0 < r["reaction_ms"] <= 1e3 * bound_s + 1.0, r


def test_the_same_detection_under_each_engine_name(tmp_path: Path) -> None:
    """``engine="python"`` is kept as a name of the core (controller._engine): the same
    detection, in the same period, as ``"compiled"``."""
    f = tmp_path / "f.toml"
    f.write_text(
        'extends = "xue-fig13"\nduration = 1.2\n[[faults]]\nat_s = 0.6\n'
        'kind = "current_stuck"\nphase = "b"\n'
    )
    py = bench.run(str(f), estimator="square-wave", engine="python")
    cc = bench.run(str(f), estimator="square-wave", engine="compiled")
    assert py.metrics["faults"] == cc.metrics["faults"]
    assert py.metrics["faults"][0]["detected_by"] == "controller_current_sensor"
    assert np.array_equal(py.signals["mode"], cc.signals["mode"])


def test_a_back_emf_swing_with_still_currents_is_not_a_stuck_sensor() -> None:
    """The cause of the false detection of a demagnetisation as ``current_sensor`` (the
    sensored drive at no load): the commanded voltage follows the rotating back-EMF, which
    swings far more than ``du_stuck`` within a window, and every current holds still. The
    other sensor's reading does not move either, so nothing tells a stuck sensor from a
    healthy one; with an injection it moves, and the stuck one is seen."""
    p = _pars()
    f_e, u_e = 50.0, 100.0  # back-EMF: 50 Hz, 100 V, far above du_stuck
    assert 2 * u_e > 5 * p.du_stuck

    def duties(k: int) -> tuple[float, float, float]:
        th = 2 * math.pi * f_e * k * T_S
        return tuple(  # type: ignore[return-value]
            0.5 + u_e / U_DC * math.cos(th - 2 * math.pi * j / 3) for j in range(3)
        )

    still = Supervisor(p)
    assert not any(still.check(0.3, -0.2, U_DC, _out(k, duties(k))) for k in range(4 * p.n_stuck))
    # a reading held while the other phase moves (the injection's current) is stuck
    stuck = Supervisor(p)
    hits = [stuck.check(0.3, _hf(k)[1], U_DC, _out(k, duties(k))) for k in range(2 * p.n_stuck)]
    assert hits.index(MODE_CURRENT_SENSOR) == p.n_stuck - 1


def test_a_sensor_offset_is_not_an_open_phase() -> None:
    """The cause of an offset reported as an open phase: a small balanced current and an
    offset on phase a's reading (which i_c = -i_a - i_b carries too) give a and c a mean
    square far above b's. About each phase's block mean the offset is gone, and so is the
    detection; an open phase carrying the same offset is still one."""
    p = _pars()
    f_e, amp, off = 20.0, 0.3, 1.0
    w = 2 * math.pi * f_e
    n_e = round(1 / (f_e * T_S))
    assert amp > p.i_min
    sup = Supervisor(p)
    for k in range(4 * n_e):
        i_a, i_b, _ = _three_phase(k, f_e, amp)
        assert sup.check(i_a + off, i_b, U_DC, _out(k, w_hat=w)) == 0
    opened = Supervisor(p)
    hits = []
    for k in range(3 * n_e):
        i_a = amp * math.cos(2 * math.pi * f_e * k * T_S)  # b open: a and c carry it
        hits.append(opened.check(i_a + off, 0.0, U_DC, _out(k, w_hat=w)))
    assert hits.index(MODE_OPEN_PHASE) == n_e - 1


def _sequence(p: SupervisionPars, fault: str) -> list[Measurement]:
    """Healthy HF and fundamental currents, then ``fault`` from the middle on: a reading at
    the rail now and then, a stuck reading, or a DC-link sag that recovers."""
    out: list[Measurement] = []
    n = 6 * p.n_stuck
    for k in range(n):
        i_a, i_b, *_ = _hf(k)
        e = _three_phase(k, 20.0, 3.0)
        i_a, i_b = i_a + e[0], i_b + e[1]
        u = U_DC
        late = k >= n // 3
        if fault == "rail" and late and k % 50 > 45:
            i_a = p.i_rail
        elif fault == "stuck" and late:
            i_a = 0.25
        elif fault == "zero" and late:
            i_a = 0.0
        elif fault == "sag" and n // 3 <= k < n // 2:
            u = 0.7 * U_DC
        out.append(Measurement(k, i_a, i_b, -i_a - i_b, u + 0.37 * math.sin(k)))
    return out


@pytest.mark.parametrize(
    ("fault", "mode"),
    [
        ("rail", MODE_CURRENT_SENSOR),
        ("stuck", MODE_CURRENT_SENSOR),
        ("zero", MODE_OPEN_PHASE),
        ("sag", MODE_DC_UNDERVOLTAGE),
    ],
)
def test_the_compiled_check_is_the_python_check_bit_for_bit(fault: str, mode: int) -> None:
    """controller/core/cc_supervision.c against Supervisor.wrap with the check's oracle
    (tests/oracle/blocks.py), on the same compiled controller step: every output of every
    period equal, through the detection, its latch, the re-enables and (DC link) the
    release."""
    from dataclasses import replace

    from controller import Controller

    scn = load_scenario("wen-5.1", {"controller.supervision": True})
    pars = replace(build_controller(scn, "tt-dq").pars, startup=False)
    sup_pars = pars.supervision
    assert sup_pars is not None
    c_ctl = Controller(pars, "compiled")
    py_ctl = Controller(replace(pars, supervision=None), "compiled")
    assert c_ctl.engine == py_ctl.engine == "compiled"
    py_sup = oracle(Supervisor(sup_pars))
    assert type(py_sup).__module__ == "tests.oracle.blocks"
    py_step = py_sup.wrap(py_ctl.step, lambda: py_ctl.set_enable(False))
    modes = []
    for ctl in (c_ctl, py_ctl):
        ctl.set_speed_ref(50.0)
        ctl.set_enable(True)
    for m in _sequence(sup_pars, fault):
        if m.k % 250 == 0:  # the bench enables again now and then
            c_ctl.set_enable(True)
            py_ctl.set_enable(True)
        a, b = c_ctl.step(m), py_step(m)
        assert a == b, m.k
        modes.append(a.mode)
    assert modes[0] == MODE_RUN and mode in modes
    if fault == "sag":
        assert modes[-1] == MODE_RUN  # released on the enable after the sag
    else:
        assert modes[-1] == mode
    assert c_ctl._core.sup_detected_k == py_sup.detected_k >= 0


@pytest.mark.parametrize("label", ["demagnetisation: psi_f x0.7", "current_offset: a +1 A"])
def test_the_fault_studys_false_detections_on_sensored_are_gone(label: str) -> None:
    """The two cases of the fault study (docs/FAULTS.md, ``sensored`` column) that reported
    a healthy sensor: a demagnetisation as ``current_sensor`` (the back-EMF swing with still
    currents) and a sensor offset as ``open_phase`` (the offset taken for current). Both
    are ridden through, and a stuck sensor on the same drive is still detected."""
    from bench.studies._faults import _u_dc, catalogue, run_case, scenario_for

    cat = dict(catalogue(_u_dc(scenario_for("sensored"))))
    r = run_case("sensored", label, cat[label], 1.5)
    assert r["detected_by"] is None and r["outcome"] == "ridden through", r
    stuck = run_case("sensored", "current_stuck: a", cat["current_stuck: a"], 1.5)
    assert stuck["detected_by"] == "controller_current_sensor", stuck
