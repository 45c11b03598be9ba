"""Sensing: sample instant, ADC quantisation, gain and offset, seeded noise."""

from __future__ import annotations

import math
import statistics

import pytest

from plant_rt import Plant, SensorPars, preset


def make(sensors: SensorPars, theta_e: float = 0.4) -> Plant:
    p = preset("wen2023")
    plant = Plant(p.motor, p.inverter, p.T_s, sensors=sensors, theta_m0=theta_e / p.motor.n_p)
    plant.impose_speed(0.0)
    for _ in range(5):  # some current: a few amperes after 0.5 ms
        plant.step(0.9, 0.2, 0.3)
    return plant


def test_ideal_sample_is_truth_at_period_boundary() -> None:
    plant = make(SensorPars())
    s = plant.sample()
    assert s.k == plant.k == 5
    assert (s.i_a, s.i_b, s.i_c) == plant.currents_abc()
    assert s.u_dc == 540.0
    assert s.i_a + s.i_b + s.i_c == pytest.approx(0.0, abs=1e-12)
    assert abs(s.i_a) > 1.0
    assert plant.sample() is s  # one sample per period


def test_quantisation_step_and_rounding() -> None:
    sens = SensorPars(bits=10, i_fs=8.0, u_fs=1000.0)
    plant = make(sens)
    s = plant.sample()
    lsb_i = 16.0 / 1024
    lsb_u = 1000.0 / 1024
    assert sens.lsb_i == lsb_i
    for meas, true in zip((s.i_a, s.i_b, s.i_c), plant.currents_abc(), strict=True):
        assert meas / lsb_i == pytest.approx(round(meas / lsb_i), abs=1e-9)
        assert abs(meas - true) <= 0.5 * lsb_i + 1e-12
    assert s.u_dc / lsb_u == pytest.approx(round(s.u_dc / lsb_u), abs=1e-9)
    assert abs(s.u_dc - 540.0) <= 0.5 * lsb_u
    # Saturation at the end codes.
    small = make(SensorPars(bits=8, i_fs=0.5, u_fs=400.0)).sample()
    assert max(small.i_a, small.i_b, small.i_c) <= 0.5 - 1.0 / 256
    assert min(small.i_a, small.i_b, small.i_c) >= -0.5
    assert small.u_dc == pytest.approx(400.0 * 255 / 256)


def test_gain_and_offset() -> None:
    sens = SensorPars(
        gain_abc=(1.02, 0.97, 1.0), offset_abc=(0.05, -0.1, 0.0), gain_u_dc=0.99, offset_u_dc=3.0
    )
    plant = make(sens)
    s = plant.sample()
    i_a, i_b, i_c = plant.currents_abc()
    assert s.i_a == pytest.approx(1.02 * i_a + 0.05, rel=1e-12)
    assert s.i_b == pytest.approx(0.97 * i_b - 0.1, rel=1e-12)
    assert s.i_c == pytest.approx(i_c, rel=1e-12)
    assert s.u_dc == pytest.approx(0.99 * 540.0 + 3.0, rel=1e-12)


def run_noise(seed: int, n: int = 400) -> list[tuple[float, float, float, float]]:
    p = preset("xue2022")
    sens = SensorPars(noise_i=0.05, noise_u=2.0, seed=seed)
    plant = Plant(p.motor, p.inverter, p.T_s, sensors=sens)
    plant.impose_speed(0.0)
    out = []
    for _ in range(n):
        s = plant.sample()
        out.append((s.i_a, s.i_b, s.i_c, s.u_dc))
        plant.step(0.5, 0.5, 0.5)
    return out


def test_seeded_noise_is_reproducible_and_seed_dependent() -> None:
    a = run_noise(7)
    assert a == run_noise(7)
    b = run_noise(8)
    assert all(x != y for x, y in zip(a, b, strict=True))
    # Zero current: the samples are the noise itself.
    noise_i = [v for row in a for v in row[:3]]
    noise_u = [row[3] - 540.0 for row in a]
    assert statistics.pstdev(noise_i) == pytest.approx(0.05, rel=0.1)
    assert abs(statistics.fmean(noise_i)) < 4 * 0.05 / math.sqrt(len(noise_i))
    assert statistics.pstdev(noise_u) == pytest.approx(2.0, rel=0.1)


def test_bad_sensor_pars_rejected() -> None:
    with pytest.raises(ValueError, match="bits"):
        SensorPars(bits=0)
    with pytest.raises(ValueError, match="noise"):
        SensorPars(noise_i=-1.0)
