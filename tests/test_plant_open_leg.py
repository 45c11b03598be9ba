"""Open-leg faults of the plant (plant_rt/core/plant_leg.h, Plant.set_leg_faults) against
closed forms: an open phase and an open switch, in the average and the switching model.

Every case holds the rotor at theta_e = 0 (no back-EMF), so the alpha axis is the d axis
(inductance L_d) and the beta axis the q axis (L_q), and each circuit is a first-order RL
one with a closed form.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Literal

import pytest

from plant_rt import Plant, preset
from plant_rt._faults import FaultWindow, PlantFaults
from plant_rt._plant import LEG_FAULTS

Model = Literal["average", "switching"]
MODELS: tuple[Model, ...] = ("average", "switching")


def _locked(model: Model, substeps: int = 8, t_dead: float = 0.0) -> Plant:
    p = preset("wen2023")
    inv = replace(p.inverter, model=model, t_dead=t_dead)
    plant = Plant(p.motor, inv, p.T_s, substeps=substeps)
    plant.impose_speed(0.0)
    return plant


def _run(plant: Plant, d: tuple[float, float, float], n: int) -> None:
    for _ in range(n):
        plant.step(*d)


@pytest.mark.parametrize("model", MODELS)
def test_open_phase_two_phases_carry_i_and_minus_i(model: Model) -> None:
    """Phase a open, legs b and c at 0.5 +- 0.1: i_a = 0, i_b = -i_c, and the b-c loop is
    an RL circuit of 2 R_s and 2 L_q (q axis at theta_e = 0):
    i_b(t) = (v_b - v_c) / (2 R_s) (1 - exp(-R_s t / L_q)); the open terminal sits at the
    star point, (v_b + v_c) / 2, so u_alpha = 0 and u_beta = (v_b - v_c) / sqrt(3)."""
    plant = _locked(model)
    m, u = plant.motor, plant.inverter.u_dc
    plant.set_leg_faults("open_phase")
    assert plant.leg_faults == ("open_phase", "none", "none")
    n = 400
    _run(plant, (0.5, 0.6, 0.4), n)
    i_a, i_b, i_c = plant.currents_abc()
    want = 0.2 * u / (2 * m.R_s) * (1 - math.exp(-m.R_s * n * plant.T_s / m.L_q))
    assert i_a == 0.0
    assert i_b == -i_c
    # the switching model's sample at the zero vector sits on the ripple's trough
    assert i_b == pytest.approx(want, rel=1e-9 if model == "average" else 2e-4)
    u_al, u_be = plant.u_s_ab
    assert abs(u_al) < 1e-9 * u
    assert u_be == pytest.approx(0.2 * u / math.sqrt(3), rel=1e-9)


@pytest.mark.parametrize("model", MODELS)
def test_open_phase_current_decays_through_the_diode_to_zero_and_stays(model: Model) -> None:
    """A d-axis current i_0 in phase a, then phase a opens: the lower diode clamps leg a to
    the negative rail (v_f = 0 here), so i_a(t) = I + (i_0 - I) exp(-t R_s / L_d) with
    I = u_alpha / R_s, u_alpha = -(v_b + v_c) / 3, until its zero at
    t* = (L_d / R_s) ln((i_0 - I) / -I); from there it is held at zero (and b, c at equal
    duties carry nothing)."""
    plant = _locked(model)
    m, u, T = plant.motor, plant.inverter.u_dc, plant.T_s
    d = (0.5 + 10 / u, 0.5 - 5 / u, 0.5 - 5 / u)
    _run(plant, d, 4000)
    i0 = plant.currents_abc()[0]
    assert i0 == pytest.approx(10 / m.R_s, rel=1e-4)  # u_alpha = (2 * 10 + 5 + 5) / 3 V
    plant.set_leg_faults("open_phase")
    I = -(d[1] + d[2]) * u / 3 / m.R_s
    tau = m.L_d / m.R_s
    t_zero = tau * math.log((i0 - I) / -I)
    k_zero = math.ceil(t_zero / T)
    assert 5 < k_zero < 20  # a fraction of a millisecond, as L i / u_dc says
    for k in range(1, k_zero + 10):
        plant.step(*d)
        i_a, i_b, i_c = plant.currents_abc()
        if k < k_zero:
            want = I + (i0 - I) * math.exp(-k * T / tau)
            if model == "average":
                assert i_a == pytest.approx(want, rel=1e-9)
            else:  # b and c switch: their ripple moves the period-boundary value
                assert i_a == pytest.approx(want, abs=1e-5 * i0)
            assert i_b == pytest.approx(-0.5 * i_a, rel=1e-9)
        else:
            assert (i_a, i_b, i_c) == (0.0, 0.0, 0.0) or max(map(abs, (i_a, i_b, i_c))) < 1e-12


@pytest.mark.parametrize("model", MODELS)
def test_open_upper_switch_blocks_positive_current_only(model: Model) -> None:
    """Leg a with its upper switch open, b and c at 0.5. Healthy steady state
    i_a = (2/3) (d_a - 0.5) u_dc / R_s. d_a = 0.3 needs a negative i_a, which the upper
    diode carries: the same as healthy (bit for bit in the switching model, where only
    the open device's on-intervals change). d_a = 0.7 needs a positive one: the leg can
    only reach the negative rail through the lower diode, which drives i_a back to zero;
    the phase floats at the star point, so i = 0 and the mean u_alpha is 0 (healthy: the
    analytic PWM average (2/3)(d_a - 0.5) u_dc). The open lower switch mirrors it."""
    for d_a, blocked in ((0.3, "open_lower"), (0.7, "open_upper")):
        passed = "open_upper" if blocked == "open_lower" else "open_lower"
        healthy = _locked(model)
        u, R = healthy.inverter.u_dc, healthy.motor.R_s
        _run(healthy, (d_a, 0.5, 0.5), 4000)
        assert healthy.currents_abc()[0] == pytest.approx((2 / 3) * (d_a - 0.5) * u / R, rel=1e-5)
        assert healthy.u_s_ab[0] == pytest.approx((2 / 3) * (d_a - 0.5) * u, rel=1e-12)
        ok = _locked(model)
        ok.set_leg_faults(passed)
        _run(ok, (d_a, 0.5, 0.5), 4000)
        assert ok.currents_abc() == pytest.approx(healthy.currents_abc(), rel=1e-14)
        bad = _locked(model)
        bad.set_leg_faults(blocked)
        for _ in range(4000):
            bad.step(d_a, 0.5, 0.5)
            assert abs(bad.currents_abc()[0]) < 1e-9
        assert abs(bad.u_s_ab[0]) < 1e-9 * u


def test_open_upper_switch_turns_a_conducting_leg_into_a_diode_clamp() -> None:
    """Average model: leg a carries +i_0 (d_a = 0.6) when its upper switch opens: the lower
    diode pins it to the negative rail for the whole period, so the current decays as with an
    open phase (the same closed form) to zero, where the leg floats."""
    plant = _locked("average")
    m, u, T = plant.motor, plant.inverter.u_dc, plant.T_s
    d = (0.6, 0.5, 0.5)
    _run(plant, d, 4000)
    i0 = plant.currents_abc()[0]
    plant.set_leg_faults("open_upper")
    I = -(d[1] + d[2]) * u / 3 / m.R_s
    plant.step(*d)
    assert plant.currents_abc()[0] == pytest.approx(
        I + (i0 - I) * math.exp(-T * m.R_s / m.L_d), rel=1e-9
    )
    _run(plant, d, 100)
    assert abs(plant.currents_abc()[0]) < 1e-9


@pytest.mark.parametrize("model", MODELS)
def test_no_fault_is_bit_identical_and_clearing_restores_the_healthy_plant(model: Model) -> None:
    """set_leg_faults() with every leg healthy changes nothing, bit for bit; a fault that
    clears leaves the healthy equations (from an equal state, equal traces)."""
    a, b = _locked(model, t_dead=2e-6), _locked(model, t_dead=2e-6)
    b.set_leg_faults("none", "none", "none")
    for k in range(300):
        d = (0.5 + 0.2 * math.sin(k / 20), 0.5, 0.5 - 0.2 * math.sin(k / 20))
        a.step(*d)
        b.step(*d)
        assert a.currents_abc() == b.currents_abc()
        assert a.u_s_ab == b.u_s_ab
    b.set_leg_faults("none", "open_phase")
    _run(b, (0.5, 0.5, 0.5), 50)
    b.set_leg_faults()
    assert b.leg_faults == ("none",) * 3


def test_an_unknown_leg_fault_is_refused() -> None:
    plant = _locked("average")
    with pytest.raises(ValueError, match="leg b"):
        plant.set_leg_faults("none", "open")
    assert LEG_FAULTS[0] == "none"


@pytest.mark.parametrize("model", MODELS)
def test_disabled_bridge_with_an_open_phase_never_rectifies_through_it(model: Model) -> None:
    """All switches off at a speed whose line back-EMF exceeds u_dc: the healthy bridge
    rectifies through all three phases; with phase a open, i_a stays 0 and b, c carry
    i and -i."""
    p = preset("wen2023")
    inv = replace(p.inverter, model=model)
    w_m = 1.3 * inv.u_dc / (math.sqrt(3) * p.motor.n_p * p.motor.psi_f)
    plant = Plant(p.motor, inv, p.T_s, substeps=8, w_m0=w_m)
    plant.impose_speed(w_m)
    healthy = Plant(p.motor, inv, p.T_s, substeps=8, w_m0=w_m)
    healthy.impose_speed(w_m)
    plant.set_leg_faults("open_phase")
    peak = peak_a = 0.0
    for _ in range(400):
        plant.step(0.5, 0.5, 0.5, enable=False)
        healthy.step(0.5, 0.5, 0.5, enable=False)
        i_a, i_b, i_c = plant.currents_abc()
        assert i_a == 0.0 or abs(i_a) < 1e-12
        assert i_b == pytest.approx(-i_c, abs=1e-9)
        peak = max(peak, abs(i_b))
        peak_a = max(peak_a, abs(healthy.currents_abc()[0]))
    assert peak > 0.1  # the b-c line rectifies (its peak back-EMF is 1.3 u_dc)
    assert peak_a > 0.1  # and the healthy bridge through phase a too


@pytest.mark.parametrize("model", MODELS)
def test_plant_faults_apply_open_phase_and_open_switch_on_the_exact_period(model: Model) -> None:
    """PlantFaults opens the leg in period k0 and closes it in k1, and a stepped trace equals
    one with set_leg_faults called by hand at the same periods."""
    d = (0.5, 0.6, 0.4)
    k0, k1 = 30, 90
    for kind, params, leg in (
        ("open_phase", {"phase": "b"}, "open_phase"),
        ("open_switch", {"phase": "b", "device": "upper"}, "open_upper"),
    ):
        a, b = _locked(model), _locked(model)
        f = PlantFaults(a, [FaultWindow(kind, k0, k1, params)])
        for k in range(150):
            f.before_period(a)
            if k == k0:
                b.set_leg_faults("none", leg)
            if k == k1:
                b.set_leg_faults()
            assert a.leg_faults == b.leg_faults
            a.step(*d)
            b.step(*d)
            assert a.currents_abc() == b.currents_abc()
        assert f.leg_faults(k0) == ("none", leg, "none")
        assert f.leg_faults(k1) == ("none", "none", "none")
        assert f.active(k0) and not f.active(k1)


def test_two_open_switches_of_one_leg_are_an_open_phase() -> None:
    w = [
        FaultWindow("open_switch", 0, None, {"phase": "c", "device": "upper"}),
        FaultWindow("open_switch", 5, None, {"phase": "c", "device": "lower"}),
    ]
    f = PlantFaults(_locked("average"), w)
    assert f.leg_faults(0) == ("none", "none", "open_upper")
    assert f.leg_faults(5) == ("none", "none", "open_phase")
