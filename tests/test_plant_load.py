"""Load profiles, mechanics and the speed-imposed (dynamometer) mode."""

from __future__ import annotations

import math

import pytest

from plant_rt import (
    ConstantLoad,
    LoadSum,
    Plant,
    RampLoad,
    SpeedProportionalLoad,
    StepLoad,
    preset,
)


def test_profiles() -> None:
    assert ConstantLoad(2.5).tau(3.0, 10.0) == 2.5
    step = StepLoad(t_step=1.0, tau_after=3.0, tau_before=0.5)
    assert (step.tau(0.999, 0.0), step.tau(1.0, 0.0)) == (0.5, 3.0)
    ramp = RampLoad(t_start=1.0, t_end=3.0, tau_start=-1.0, tau_end=3.0)
    assert [ramp.tau(t, 0.0) for t in (0.0, 1.0, 2.0, 2.5, 4.0)] == [-1.0, -1.0, 1.0, 2.0, 3.0]
    assert SpeedProportionalLoad(0.01).tau(0.0, -50.0) == pytest.approx(-0.5)
    total = LoadSum(ConstantLoad(1.0), step, SpeedProportionalLoad(0.01))
    assert total.tau(2.0, 100.0) == pytest.approx(1.0 + 3.0 + 1.0)
    assert LoadSum([ConstantLoad(1.0), step]).tau(2.0, 0.0) == 4.0
    assert (ConstantLoad(1.0) + step).tau(0.0, 0.0) == 1.5
    with pytest.raises(ValueError):
        RampLoad(1.0, 1.0, 0.0, 1.0)
    with pytest.raises(TypeError):
        LoadSum(ConstantLoad(1.0), 3.0)  # type: ignore[arg-type]


def test_coast_down_with_friction_and_speed_load_is_exponential() -> None:
    """Open stator below the diode threshold, tau_L = k w_m: the speed decays as
    w_0 exp(-(b + k) t / J). The load is evaluated once per substep (held
    over it), a first-order error of about k (b + k) h t / (2 J^2) = 7e-6
    here; the bound allows for it."""
    p = preset("wen2023")
    m = p.motor
    k_w = 0.002
    plant = Plant(m, p.inverter, p.T_s, load=SpeedProportionalLoad(k_w), w_m0=100.0)
    for _ in range(5000):
        plant.step(0.0, 0.0, 0.0, enable=False)
    tr = plant.truth()
    assert tr.w_m == pytest.approx(100.0 * math.exp(-(m.b + k_w) * 0.5 / m.J), rel=3e-5)
    assert tr.tau_L == pytest.approx(k_w * tr.w_m)
    assert tr.tau_e == 0.0


def test_constant_load_ramp_down_matches_kinematics() -> None:
    """No friction term from the load, open stator: J dw/dt = -tau_L - b w."""
    p = preset("xue2022")
    m = p.motor
    plant = Plant(m, p.inverter, p.T_s, load=StepLoad(0.1, 2.0), w_m0=50.0)
    for _ in range(300):
        plant.step(0.0, 0.0, 0.0, enable=False)
    # Closed form: w = -tau/b + (w(0.1) + tau/b) exp(-b (t - 0.1)/J), w(0.1) by free decay.
    w01 = 50.0 * math.exp(-m.b * 0.1 / m.J)
    w = -2.0 / m.b + (w01 + 2.0 / m.b) * math.exp(-m.b * 0.2 / m.J)
    assert plant.truth().w_m == pytest.approx(w, rel=1e-6)


def test_set_load_at_run_time() -> None:
    p = preset("wen2023")
    plant = Plant(p.motor, p.inverter, p.T_s, w_m0=10.0)
    plant.set_load(ConstantLoad(1.5))
    assert plant.truth().tau_L == 1.5
    w = plant.truth().w_m
    plant.step(0.5, 0.5, 0.5, enable=False)
    assert plant.truth().w_m < w - 1.5 / p.motor.J * p.T_s * 0.99


def test_imposed_speed_holds_and_releases() -> None:
    """The dynamometer holds w_m whatever the motor torque; tau_L reports the
    torque it applies (tau_e - b w_m). Released, the rotor keeps its speed
    and the profile load acts again."""
    p = preset("wen2023")
    m = p.motor
    plant = Plant(m, p.inverter, p.T_s, load=ConstantLoad(5.0))
    plant.impose_speed(30.0)
    th0 = plant.truth().theta_m
    for _ in range(100):
        plant.step(0.7, 0.3, 0.5)  # strong current, torque
    tr = plant.truth()
    assert tr.w_m == 30.0
    assert abs(tr.tau_e) > 0.1
    assert tr.tau_L == pytest.approx(tr.tau_e - m.b * 30.0)
    assert tr.theta_m == pytest.approx((th0 + 30.0 * 100 * p.T_s) % (2 * math.pi), abs=1e-9)
    assert tr.theta_e == pytest.approx((m.n_p * tr.theta_m) % (2 * math.pi), abs=1e-9)
    plant.impose_speed(60.0)  # changed at run time
    plant.step(0.5, 0.5, 0.5, enable=False)
    assert plant.truth().w_m == 60.0
    plant.impose_speed(None)
    assert plant.truth().tau_L == 5.0
    plant.step(0.5, 0.5, 0.5, enable=False)
    assert plant.truth().w_m < 60.0
