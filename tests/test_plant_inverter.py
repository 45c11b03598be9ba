"""Inverter: duty clamping, dead time, and the disabled bridge (freewheeling, rectification)."""

from __future__ import annotations

import math

import pytest

from plant_rt import InverterPars, Plant, preset


def locked(theta_e: float = 0.0, **kw: object) -> Plant:
    p = preset("wen2023")
    inv = kw.pop("inverter", p.inverter)
    plant = Plant(p.motor, inv, p.T_s, theta_m0=theta_e / p.motor.n_p, meter=True, **kw)  # type: ignore[arg-type]
    plant.impose_speed(0.0)
    return plant


def test_duties_are_clamped() -> None:
    a = locked(0.3)
    b = locked(0.3)
    for _ in range(50):
        a.step(1.7, -0.4, 0.5)
        b.step(1.0, 0.0, 0.5)
    assert a.currents_abc() == b.currents_abc()
    assert abs(a.currents_abc()[0]) > 1.0


def test_dead_time_voltage_error_opposes_current() -> None:
    """Locked rotor, u_alpha = 40 V: i_a > 0, i_b, i_c < 0. Each leg loses
    t_dead / T_s * u_dc = 10.8 V against its current; after removing the
    common mode, phase a loses 4/3 of that: i_a = (40 - 14.4) / R_s."""
    p = preset("wen2023")
    inv = InverterPars(u_dc=540.0, t_dead=2e-6)
    plant = locked(0.0, inverter=inv)
    d = (0.5 + 40.0 / 540.0, 0.5 - 20.0 / 540.0, 0.5 - 20.0 / 540.0)
    for _ in range(8000):
        plant.step(*d)
    du = inv.t_dead / p.T_s * inv.u_dc
    assert plant.currents_abc()[0] == pytest.approx((40.0 - 4.0 / 3.0 * du) / p.motor.R_s, rel=1e-6)


def test_disabled_bridge_freewheels_d_current_to_zero() -> None:
    """theta_e = 0, i_d = I: phase a conducts through the lower diode, b and c
    through the upper ones, so u_d = -(2/3) u_dc and
    i_d(t) = (I + c) e^{-t R/L_d} - c with c = (2/3) u_dc / R_s, zero at
    t_0 = (L_d / R_s) ln(1 + I / c) (0.62 ms here). The current must follow
    this, reach zero within one substep of t_0 and stay there."""
    p = preset("wen2023")
    m = p.motor
    plant = locked(0.0, substeps=2)
    d = (0.5 + 4.0 * m.R_s / 540.0, 0.5 - 0.5 * 4.0 * m.R_s / 540.0)
    for _ in range(8000):
        plant.step(d[0], d[1], d[1])
    I0 = plant.truth().i_d
    assert abs(I0 - 4.0) < 4e-6
    c = 2.0 / 3.0 * 540.0 / m.R_s
    t_zero = m.L_d / m.R_s * math.log(1.0 + I0 / c)
    for k in range(1, 40):
        plant.step(0.0, 0.0, 0.0, enable=False)
        t = k * p.T_s
        tr = plant.truth()
        if t < t_zero - 0.5 * p.T_s:
            assert tr.i_d == pytest.approx((I0 + c) * math.exp(-t * m.R_s / m.L_d) - c, rel=1e-6)
        elif t > t_zero + 0.5 * p.T_s:
            assert (tr.i_d, tr.i_q) == (0.0, 0.0)
    assert plant.currents_abc() == (0.0, 0.0, 0.0)


def test_disabled_bridge_two_phase_conduction_then_zero() -> None:
    """Unequal currents: the smallest phase current reaches zero first and
    stays blocked (its pole floats between the rails) while the other two
    carry equal and opposite currents down to zero. Energy flows back to the
    DC link."""
    plant = locked(0.9)
    d = (0.5 + 10.0 / 540.0, 0.5 - 2.0 / 540.0, 0.5 - 8.0 / 540.0)
    for _ in range(8000):
        plant.step(*d)
    i0 = plant.currents_abc()
    assert i0[0] > 0.0 > i0[2] and abs(i0[1]) < abs(i0[2])
    assert plant.meter is not None
    e_in0 = plant.meter.e_in
    seen_two_phase = False
    for _ in range(60):
        plant.step(0.3, 0.3, 0.3, enable=False)
        i_a, i_b, i_c = plant.currents_abc()
        assert i_a >= 0.0 >= i_c  # no diode conducts backwards
        if i_a > 0.0 and i_b == pytest.approx(0.0, abs=1e-9):
            seen_two_phase = True
            assert i_a == pytest.approx(-i_c, rel=1e-9)
    assert seen_two_phase
    assert plant.currents_abc() == (0.0, 0.0, 0.0)
    assert plant.meter.e_in - e_in0 < 0.0


@pytest.mark.parametrize(("ratio", "conducts"), [(0.97, False), (1.05, True)])
def test_disabled_bridge_rectifies_above_line_emf_threshold(ratio: float, conducts: bool) -> None:
    """Open stator at an imposed speed: the diode bridge conducts only when
    the line back-EMF amplitude sqrt(3) w_e psi_f exceeds u_dc; then the
    machine brakes (tau_e opposes w_m) and feeds the DC link."""
    p = preset("wen2023")
    m = p.motor
    w_e = ratio * p.inverter.u_dc / (math.sqrt(3.0) * m.psi_f)
    plant = Plant(m, p.inverter, p.T_s, theta_m0=0.2, meter=True)
    plant.impose_speed(w_e / m.n_p)
    i_peak = 0.0
    braking = 0.0
    for _ in range(1000):
        plant.step(0.0, 0.0, 0.0, enable=False)
        tr = plant.truth()
        i_peak = max(i_peak, max(abs(i) for i in plant.currents_abc()))
        braking = min(braking, tr.tau_e * tr.w_m)
    assert plant.meter is not None
    if conducts:
        assert i_peak > 1e-3
        assert braking < 0.0
        assert plant.meter.e_in < 0.0
    else:
        assert i_peak == 0.0
        assert plant.meter.e_in == 0.0
