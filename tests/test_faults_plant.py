"""Plant and sensor faults (plant_rt/_faults.py, Plant.set_parameters) against closed forms."""

from __future__ import annotations

import math

import pytest

from plant_rt import Plant, Sample, compiled_engine_missing, preset
from plant_rt._faults import FaultWindow, PlantFaults

ENGINES = ["python"] + ([] if compiled_engine_missing() else ["compiled"])


def _locked(engine: str) -> Plant:
    p = preset("wen2023")
    plant = Plant(p.motor, p.inverter, p.T_s, engine=engine)
    plant.impose_speed(0.0)
    return plant


def _run(plant: Plant, faults: PlantFaults, d: tuple[float, float, float], n: int) -> None:
    for _ in range(n):
        faults.before_period(plant)
        plant.step(*d)


@pytest.mark.parametrize("engine", ENGINES)
def test_resistance_drift_follows_the_first_order_closed_form(engine: str) -> None:
    """Locked rotor at theta_e = 0, a d-axis voltage u: i_d(t) = u/R' + (i_0 - u/R') e^{-R' t / L_d}
    from the fault's first period on, with R' = 1.5 R_s."""
    plant = _locked(engine)
    m = plant.motor
    u = 10.0
    d = (0.5 + u / plant.inverter.u_dc, 0.5 - 0.5 * u / plant.inverter.u_dc,
         0.5 - 0.5 * u / plant.inverter.u_dc)  # fmt: skip
    k0 = 500
    f = PlantFaults(plant, [FaultWindow("resistance_drift", k0, None, {"R_s_factor": 1.5})])
    _run(plant, f, d, k0)
    i0 = plant.truth().i_d
    assert i0 == pytest.approx(
        u / m.R_s * (1 - math.exp(-m.R_s * k0 * plant.T_s / m.L_d)), rel=1e-6
    )
    n = 300
    _run(plant, f, d, n)
    R = 1.5 * m.R_s
    assert plant.motor.R_s == R
    want = u / R + (i0 - u / R) * math.exp(-R * n * plant.T_s / m.L_d)
    assert plant.truth().i_d == pytest.approx(want, rel=1e-6)


@pytest.mark.parametrize("engine", ENGINES)
def test_demagnetisation_scales_the_short_circuit_current_and_the_back_emf(engine: str) -> None:
    """Imposed speed, all legs at 0.5 (u = 0): the steady short-circuit currents
    i_d = -w^2 L_q psi / (R^2 + w^2 L_d L_q), i_q = -w R psi / (...) follow psi_f' = 0.8 psi_f."""
    p = preset("wen2023")
    plant = Plant(p.motor, p.inverter, p.T_s, engine=engine)
    w_m = 20.0
    plant.impose_speed(w_m)
    m = p.motor
    k0 = 5000  # 0.5 s: more than 20 electrical time constants
    f = PlantFaults(plant, [FaultWindow("demagnetisation", k0, None, {"psi_f_factor": 0.8})])

    def steady(psi: float) -> tuple[float, float]:
        w = m.n_p * w_m
        den = m.R_s**2 + w * w * m.L_d * m.L_q
        return -w * w * m.L_q * psi / den, -w * m.R_s * psi / den

    _run(plant, f, (0.5, 0.5, 0.5), k0)
    tr = plant.truth()
    assert (tr.i_d, tr.i_q) == pytest.approx(steady(m.psi_f), rel=1e-5)
    emf0 = max(abs(e) for e in plant.back_emf_abc())
    _run(plant, f, (0.5, 0.5, 0.5), 1)
    emf1_amp = m.n_p * w_m * 0.8 * m.psi_f
    assert plant.motor.psi_f == pytest.approx(0.8 * m.psi_f, rel=1e-15)
    assert max(abs(e) for e in plant.back_emf_abc()) <= emf1_amp * (1 + 1e-12)
    assert emf0 > emf1_amp
    _run(plant, f, (0.5, 0.5, 0.5), 5000)
    tr = plant.truth()
    assert (tr.i_d, tr.i_q) == pytest.approx(steady(0.8 * m.psi_f), rel=1e-5)


@pytest.mark.parametrize("engine", ENGINES)
def test_dc_link_step_scales_the_voltage_and_is_measured_from_its_first_instant(
    engine: str,
) -> None:
    plant = _locked(engine)
    m = plant.motor
    u_dc = plant.inverter.u_dc
    d = (0.55, 0.475, 0.475)  # u_a - mean = 0.05 u_dc
    k0, k1 = 100, 20100
    f = PlantFaults(plant, [FaultWindow("dc_link_step", k0, k1, {"u_dc_v": 0.5 * u_dc})])
    _run(plant, f, d, k0)
    assert plant.sample().u_dc == u_dc
    f.before_period(plant)
    assert plant.sample().u_dc == 0.5 * u_dc
    assert plant.truth().u_dc == 0.5 * u_dc
    assert plant.protection_inputs()[3] == 0.5 * u_dc
    _run(plant, f, d, 20000)  # 2 s: 100 time constants L_d / R_s
    assert plant.truth().i_d == pytest.approx(0.05 * 0.5 * u_dc / m.R_s, rel=1e-9)
    _run(plant, f, d, 20000)  # past k1: the nominal link again
    assert plant.k > k1
    assert plant.sample().u_dc == u_dc
    assert plant.truth().i_d == pytest.approx(0.05 * u_dc / m.R_s, rel=1e-6)


def test_compiled_and_python_engines_agree_bit_for_bit_through_a_parameter_change() -> None:
    if compiled_engine_missing():
        pytest.skip("the compiled plant engine is not built")
    traces = []
    for engine in ("python", "compiled"):
        p = preset("xue2022")
        plant = Plant(p.motor, p.inverter, p.T_s, engine=engine, w_m0=10.0)
        f = PlantFaults(
            plant,
            [
                FaultWindow("resistance_drift", 40, 90, {"R_s_factor": 1.3}),
                FaultWindow("demagnetisation", 60, None, {"psi_f_factor": 0.7}),
                FaultWindow("dc_link_step", 70, 120, {"u_dc_v": 250.0}),
            ],
        )
        out = []
        for k in range(160):
            f.before_period(plant)
            plant.step(0.6, 0.45, 0.45 + 0.001 * k)
            tr = plant.truth()
            out.append((tr.i_d, tr.i_q, tr.w_m, tr.theta_m, tr.u_dc))
        traces.append(out)
    assert traces[0] == traces[1]


def test_parameters_in_force_at_the_window_edges() -> None:
    p = preset("wen2023")
    plant = Plant(p.motor, p.inverter, p.T_s)
    f = PlantFaults(
        plant,
        [
            FaultWindow("resistance_drift", 10, 20, {"R_s_factor": 2.0}),
            FaultWindow("resistance_drift", 15, 25, {"R_s_factor": 3.0}),
        ],
    )
    R = p.motor.R_s
    assert [f.parameters(k)[0] / R for k in (9, 10, 14, 15, 19, 20, 24, 25)] == pytest.approx([
        1.0, 2.0, 2.0, 6.0, 6.0, 3.0, 3.0, 1.0,
    ], rel=1e-15)  # fmt: skip


def test_sensor_faults_change_the_measured_sample_exactly() -> None:
    p = preset("wen2023")
    plant = Plant(p.motor, p.inverter, p.T_s)
    f = PlantFaults(
        plant,
        [
            FaultWindow("current_offset", 2, 4, {"phase": "a", "a": 0.25}),
            FaultWindow("current_gain", 3, None, {"phase": "b", "factor": 0.5}),
            FaultWindow("current_stuck", 5, 7, {"phase": "c"}),
            FaultWindow("current_lost", 6, 8, {"phase": "a"}),
            FaultWindow("dc_voltage_offset", 1, 2, {"v": -12.0}),
            FaultWindow("position_sensor_lost", 4, 5, {}),
        ],
    )
    got = [f.sample(Sample(k, 1.0 + k, 2.0 + k, -3.0 - 2 * k, 300.0)) for k in range(9)]
    assert [(s.i_a, s.i_b, s.i_c, s.u_dc) for s in got] == [
        (1.0, 2.0, -3.0, 300.0),
        (2.0, 3.0, -5.0, 288.0),
        (3.25, 4.0, -7.0, 300.0),
        (4.25, 2.5, -9.0, 300.0),
        (5.0, 3.0, -11.0, 300.0),
        (6.0, 3.5, -11.0, 300.0),  # stuck at sample 4's -11
        (0.0, 4.0, -11.0, 300.0),
        (0.0, 4.5, -17.0, 300.0),
        (9.0, 5.0, -19.0, 300.0),
    ]
    assert [f.position_lost(k) for k in range(3, 7)] == [False, True, False, False]
    assert [f.active(k) for k in (0, 1, 8)] == [False, True, True]
