"""Plant profiles: the drive's values, the ideal profile is the legacy plant, the
scenario keys map onto the dataclass fields, and a drive plant runs."""

from __future__ import annotations

import cmath
import dataclasses
import math

import pytest

from plant_rt import (
    PRESETS,
    PROFILE_NAMES,
    InverterPars,
    Plant,
    PlantProfile,
    SensorPars,
    UnknownProfileError,
    drive_profile,
    plant_profile,
    preset,
)

INVERTER_KEYS = ("model", "t_dead", "v_ce", "v_f", "u_dc", "r_dc", "c_dc")


def test_inverter_keys_are_field_names() -> None:
    """The ``[inverter]`` table's keys are InverterPars fields: a table builds it as is."""
    names = {f.name for f in dataclasses.fields(InverterPars)}
    assert set(INVERTER_KEYS) <= names
    table = {
        "model": "switching",
        "t_dead": 2e-6,
        "v_ce": 1.5,
        "v_f": 1.2,
        "u_dc": 560.0,
        "r_dc": 0.1,
        "c_dc": 1e-3,
    }
    inv = InverterPars(**table)  # type: ignore[arg-type]
    assert {k: getattr(inv, k) for k in INVERTER_KEYS} == table


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_drive_profile_values(name: str) -> None:
    """The drive of the brief: switching inverter, 2 us dead time, 1.5 V drops, 12-bit
    ADC with a full scale of 2 i_max, 0.5 % gain mismatch between the transmitted
    phases a and b, 10 mA offsets, saturation and cross-saturation; every value is
    reasoned in the doc."""
    p = preset(name)
    prof = drive_profile(p)
    assert isinstance(prof, PlantProfile) and prof.name == "drive"
    inv = prof.inverter
    assert (inv.model, inv.t_dead, inv.v_ce, inv.v_f, inv.u_dc) == (
        "switching",
        2e-6,
        1.5,
        1.5,
        p.inverter.u_dc,
    )
    assert (inv.r_dc, inv.c_dc, inv.sample_at) == (0.0, 0.0, "peak")
    s = prof.sensors
    assert s.bits == 12 and s.i_fs == 2.0 * p.motor.i_max
    assert s.gain_abc[1] / s.gain_abc[0] == pytest.approx(1.005)
    assert all(abs(o) == 0.010 for o in s.offset_abc)
    assert s.offset_abc[0] == -s.offset_abc[1]  # they do not cancel in alpha-beta
    assert s.noise_i == 0.0 and s.t_delay == 0.0
    assert prof.saturation and prof.cross_saturation
    assert p.motor.cross.c_dq > 0.0
    for word in ("t_dead", "v_ce", "12 bits", "2 i_max", "0.5 %", "10 mA", "cross-saturation"):
        assert word in prof.doc
    assert plant_profile("drive", p) == prof


def test_ideal_profile_is_the_legacy_plant() -> None:
    """The ideal profile builds the plant the bench builds today: same trace, bit for bit."""
    p = preset("wen2023")
    prof = plant_profile("ideal", p)
    assert prof.inverter == p.inverter and prof.sensors == SensorPars()
    assert prof.saturation and not prof.cross_saturation
    a = Plant(p.motor, p.inverter, p.T_s, saturation=True, w_m0=20.0)
    b = Plant(
        p.motor,
        prof.inverter,
        p.T_s,
        sensors=prof.sensors,
        saturation=prof.saturation,
        cross_saturation=prof.cross_saturation,
        w_m0=20.0,
    )
    for k in range(300):
        d = (0.5 + 0.1 * math.sin(0.02 * k), 0.5, 0.5 - 0.1 * math.sin(0.02 * k))
        a.step(*d)
        b.step(*d)
        assert a.sample() == b.sample() and a.truth() == b.truth()


def test_unknown_profile() -> None:
    assert PROFILE_NAMES == ("ideal", "drive")
    with pytest.raises(UnknownProfileError) as exc:
        plant_profile("real", preset("wen2023"))
    assert isinstance(exc.value, KeyError)
    assert "real" in str(exc.value) and "ideal, drive" in str(exc.value)


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_drive_plant_runs_and_samples_are_adc_codes(name: str) -> None:
    """A drive plant under the rotating voltage of the ideal plant's steady state
    i_q = i_rated / 2: every current sample is a whole number of 4 i_max / 4096 steps
    and every DC-link sample of 1000 / 4096 V. Open loop, the dead-time and drop
    errors (several volts against an R_s i of 0.95 V for xue2022, 5.6 V for wen2023)
    move the current far from the ideal plant's, which is what a current controller
    has to correct. At rest the samples are the quantised offsets."""
    p = preset(name)
    m = p.motor
    prof = drive_profile(p)
    lsb = prof.sensors.lsb_i
    assert lsb == pytest.approx(4.0 * m.i_max / 4096)
    w_m = 0.1 * m.w_m_rated
    drv = Plant(
        m,
        prof.inverter,
        p.T_s,
        sensors=prof.sensors,
        saturation=True,
        cross_saturation=True,
        w_m0=w_m,
        theta_m0=0.1,
    )
    ideal = Plant(m, p.inverter, p.T_s, saturation=True, w_m0=w_m, theta_m0=0.1)
    rest = drv.sample()
    assert (rest.i_a, rest.i_b) == (
        math.floor(0.010 / lsb + 0.5) * lsb,
        math.floor(-0.010 / lsb + 0.5) * lsb,
    )
    w_e = m.n_p * 0.1 * m.w_m_rated
    i_q = 0.5 * m.i_rated
    u_dq = complex(-w_e * m.L_q * i_q, m.R_s * i_q + w_e * m.psi_f)
    for plant in (drv, ideal):
        plant.impose_speed(0.1 * m.w_m_rated)
    for _ in range(round(0.3 / p.T_s)):
        for plant in (drv, ideal):
            th = plant.truth().theta_e + 0.5 * w_e * p.T_s
            u_ab = u_dq * cmath.exp(1j * th)
            d_a, d_b, d_c = (
                0.5 + (u_ab * cmath.exp(-1j * ph)).real / p.inverter.u_dc
                for ph in (0.0, 2 * math.pi / 3, -2 * math.pi / 3)
            )
            plant.step(d_a, d_b, d_c)
        s = drv.sample()
        for v in (s.i_a, s.i_b, s.i_c):
            assert v / lsb == round(v / lsb)
        assert s.u_dc / prof.sensors.lsb_u == round(s.u_dc / prof.sensors.lsb_u)
    t_d, t_i = drv.truth(), ideal.truth()
    assert abs(t_i.i_q - i_q) < 0.01 * i_q
    assert math.hypot(t_d.i_d - t_i.i_d, t_d.i_q - t_i.i_q) > 0.2 * i_q
