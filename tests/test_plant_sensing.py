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


# ------------------------------------------------------------------ scenario keys, delay
SENSOR_KEYS = (
    "current_offset_a",
    "current_gain_error",
    "adc_bits",
    "current_full_scale_a",
    "current_noise_a",
)


def test_sensor_keys_map_onto_fields() -> None:
    """The ``[sensors]`` keys build SensorPars directly (one value for all phases or one
    per phase; the gain error is relative) and read back under the same names; bits 0
    means no ADC."""
    s = SensorPars.from_keys(
        current_offset_a=(0.01, -0.02, 0.0),
        current_gain_error=0.005,
        adc_bits=12,
        current_full_scale_a=16.0,
        current_noise_a=0.003,
        sample_delay_s=5e-6,
        seed=9,
    )
    assert (s.bits, s.i_fs, s.noise_i, s.seed, s.t_delay) == (12, 16.0, 0.003, 9, 5e-6)
    assert s.offset_abc == (0.01, -0.02, 0.0)
    assert s.gain_abc == (1.005, 1.005, 1.005)
    for key in SENSOR_KEYS:
        assert hasattr(s, key)
    assert s.current_gain_error == pytest.approx((0.005, 0.005, 0.005), abs=1e-15)
    assert s.current_offset_a == s.offset_abc and s.adc_bits == 12
    assert s.current_full_scale_a == 16.0 and s.current_noise_a == 0.003
    assert s.sample_delay_s == 5e-6
    assert SensorPars.from_keys(adc_bits=0).bits is None
    assert SensorPars.from_keys(current_offset_a=0.02).offset_abc == (0.02, 0.02, 0.02)
    assert SensorPars.from_keys() == SensorPars()
    with pytest.raises(ValueError, match="current_gain_error"):
        SensorPars.from_keys(current_gain_error=(0.01, 0.02))


def test_keys_quantisation_step_offset_and_gain_are_exact() -> None:
    """12 bits over +-16 A: the step is 2 * 16 / 2^12 = 7.8125 mA and every sample is a
    whole number of steps, the one nearest gain * i + offset (round half up)."""
    s = SensorPars.from_keys(
        adc_bits=12,
        current_full_scale_a=16.0,
        current_offset_a=(0.01, -0.01, 0.01),
        current_gain_error=(0.0, 0.005, -0.005),
    )
    lsb = 2.0 * 16.0 / 2**12
    assert s.lsb_i == lsb == 0.0078125
    plant = make(s)
    smp = plant.sample()
    true = plant.currents_abc()
    for meas, i, g, o in zip(
        (smp.i_a, smp.i_b, smp.i_c), true, (1.0, 1.005, 0.995), (0.01, -0.01, 0.01), strict=True
    ):
        assert meas == math.floor((g * i + o) / lsb + 0.5) * lsb
    # at zero current the sample is the offset, quantised
    p = preset("wen2023")
    rest = Plant(p.motor, p.inverter, p.T_s, sensors=s).sample()
    assert (rest.i_a, rest.i_b) == (lsb, -lsb)


def test_sample_delay_reads_the_current_t_delay_before_the_sample_instant() -> None:
    """Locked rotor at theta_e = 0, a constant d-axis voltage V from rest: i_a = i_d =
    (V / R_s) (1 - exp(-t R_s / L_d)). With t_delay the sample of step k carries
    i_a(k T_s - t_delay) (the first sample, with no history, the present value)."""
    p = preset("wen2023")
    m = p.motor
    t_delay = 37e-6
    plant = Plant(m, p.inverter, p.T_s, sensors=SensorPars(t_delay=t_delay))
    plant.impose_speed(0.0)
    v = 60.0
    d = (0.5 + v / 540.0, 0.5 - 0.5 * v / 540.0, 0.5 - 0.5 * v / 540.0)  # u_alpha = v
    assert plant.sample().i_a == 0.0
    for k in range(1, 30):
        plant.step(*d)
        t = k * p.T_s - t_delay
        want = v / m.R_s * (1.0 - math.exp(-t * m.R_s / m.L_d))
        assert plant.sample().i_a == pytest.approx(want, rel=1e-9)
        assert plant.currents_abc()[0] > plant.sample().i_a  # the present value is later


def test_sample_delay_during_a_disabled_period() -> None:
    """A plant with T_s, two substeps and t_delay = T_s / 2 integrates the same
    half-period steps as one with T_s / 2 and one substep; its delayed sample is that
    plant's state at the half period, enabled or with the bridge open."""
    p = preset("wen2023")
    T = p.T_s
    a = Plant(p.motor, p.inverter, T, sensors=SensorPars(t_delay=0.5 * T), w_m0=50.0)
    b = Plant(p.motor, p.inverter, 0.5 * T, substeps=1, w_m0=50.0)
    peak = 0.0
    for k in range(40):
        d = (0.7, 0.3, 0.4)
        en = k < 20
        a.step(*d, enable=en)
        b.step(*d, enable=en)
        mid = b.currents_abc()
        b.step(*d, enable=en)
        s = a.sample()
        assert (s.i_a, s.i_b, s.i_c) == pytest.approx(mid, rel=1e-12, abs=1e-12)
        assert a.currents_abc() == pytest.approx(b.currents_abc(), rel=1e-12, abs=1e-12)
        peak = max(peak, abs(mid[0]))
    assert peak > 0.1
    assert a.currents_abc() == (0.0, 0.0, 0.0)  # the open bridge took the current to zero


def test_bad_delay_rejected() -> None:
    p = preset("wen2023")
    with pytest.raises(ValueError, match="t_delay"):
        SensorPars(t_delay=-1e-6)
    with pytest.raises(ValueError, match="t_delay"):
        Plant(p.motor, p.inverter, p.T_s, sensors=SensorPars(t_delay=p.T_s))
