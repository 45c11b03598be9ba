"""The plant's C core gives the reference model's trace bit for bit.

:class:`plant_rt.Plant` runs every period in the portable C core
(``plant_rt/core``); ``tests/plant_reference.py`` is the same model written
in Python, readable, with the same operation order. The tolerance is zero:
the states, the samples and the energy integrals after every period are
equal bits, for the drive profile's switching plant in a closed loop and
for each feature of the step (DC link, sensor delay, dead time and drops,
cross-saturation, imposed speed, loads that depend on time and speed, the
disabled bridge between enabled periods, the sensors with noise and ADC,
the energy meter).
"""

from __future__ import annotations

import math
import struct
import subprocess
import sys
from dataclasses import replace
from typing import Any

import pytest

import bench.nodes._loops as loops
from bench.cli._common import ENGINES as CLI_ENGINES
from bench.scenarios._schema import load_scenario
from bench.scenarios._setup import build_controller
from bench.wire._codec import Codec
from controller import Measurement
from plant_rt import (
    ENGINES,
    ConstantLoad,
    InverterPars,
    Plant,
    RampLoad,
    SensorPars,
    SpeedProportionalLoad,
    compiled_engine_missing,
    drive_profile,
    ideal_profile,
    preset,
    resolve_engine,
)
from tests.plant_reference import ReferencePlant

AnyPlant = Plant | ReferencePlant


def _bits(*xs: float) -> bytes:
    return struct.pack(f"{len(xs)}d", *xs)


def _state(p: AnyPlant) -> bytes:
    """Every state and output of a period (and the energy meter's integrals), as bits."""
    m = p.meter
    meter = () if m is None else (m.e_in, m.e_cu, m.e_em, m.e_fric, m.e_load, m.q_a, m.q_b, m.q_c)
    return _bits(p._i_d, p._i_q, p._w_m, p._th_m, p._u_dc, *p.u_s_ab, float(p.k), *meter)


def _plant(engine: str, *args: Any, **kw: Any) -> AnyPlant:
    """The core's plant (``"core"``) or the reference model (``"reference"``)."""
    return ReferencePlant(*args, **kw) if engine == "reference" else Plant(*args, **kw)


def _drive_loop(
    preset_name: str, scenario: str, estimator: str, engine: str, n: int
) -> tuple[list[bytes], AnyPlant]:
    """The drive profile's plant (switching inverter, dead time, drops, ADC,
    cross-saturation) under the scenario's controller, with a disabled stretch,
    a load step and a load ramp that calls back into Python."""
    p = preset(preset_name)
    prof = drive_profile(p)
    plant = _plant(
        engine,
        p.motor,
        prof.inverter,
        p.T_s,
        sensors=prof.sensors,
        saturation=prof.saturation,
        cross_saturation=prof.cross_saturation,
    )
    ctrl = build_controller(load_scenario(scenario), estimator)
    ctrl.set_enable(True)
    ctrl.set_speed_ref(300.0 * 2.0 * math.pi / 60.0)
    d = (0.5, 0.5, 0.5, False)
    out: list[bytes] = []
    off = (2 * n // 3, 2 * n // 3 + max(2, round(1.5e-3 / p.T_s)))  # 1.5 ms of diode bridge
    for k in range(n):
        if k == n // 3:
            plant.set_load(ConstantLoad(0.3 * p.motor.tau_rated))
        if k == n // 2:
            t = plant.t
            plant.set_load(RampLoad(t, t + 0.2 * n * p.T_s, 0.3 * p.motor.tau_rated, 0.0))
        s = plant.sample()
        o = ctrl.step(Measurement(s.k, s.i_a, s.i_b, s.i_c, s.u_dc, None, None))
        enable = d[3] and not (off[0] <= k < off[1])
        plant.step(d[0], d[1], d[2], enable)
        out.append(_state(plant) + _bits(s.i_a, s.i_b, s.i_c, s.u_dc))
        d = (o.d_a, o.d_b, o.d_c, o.enable)
    return out, plant


@pytest.mark.parametrize(
    ("preset_name", "scenario", "estimator", "n"),
    [("wen2023", "wen-5.1", "tt-dq", 3000), ("xue2022", "xue-fig13", "square-wave", 600)],
)
def test_drive_profile_closed_loop_core_is_the_reference(
    preset_name: str, scenario: str, estimator: str, n: int
) -> None:
    """The switching plant of the drive profile under its controller: the same state and
    samples after every period, bit for bit, through a load step, a load ramp and a
    stretch of disabled periods (the diode bridge)."""
    py, p_py = _drive_loop(preset_name, scenario, estimator, "reference", n)
    cc, p_cc = _drive_loop(preset_name, scenario, estimator, "core", n)
    assert p_py._switching and p_cc._switching
    first = next((k for k in range(n) if py[k] != cc[k]), None)
    assert first is None, f"the core and the reference part at period {first}"
    # the drive turned, with current, and stayed finite
    assert math.isfinite(p_py._i_d) and abs(p_py._w_m) > 1.0 and abs(p_py._i_q) > 0.01


def _features(base: InverterPars) -> dict[str, dict[str, Any]]:
    return {
        "plain": {},
        "dc_link_capacitor": {"inverter": replace(base, r_dc=0.5, c_dc=200e-6)},
        "dc_link_resistive": {"inverter": replace(base, r_dc=0.5)},
        "sensor_delay": {"sensors": SensorPars(t_delay=30e-6)},
        "sensor_noise_adc": {
            "sensors": SensorPars(
                bits=10, i_fs=16.0, u_fs=800.0, noise_i=0.05, noise_u=0.5, seed=7, t_delay=10e-6
            )
        },
        "dead_time_drops": {"inverter": replace(base, t_dead=3e-6, v_ce=1.2, v_f=0.9)},
        "valley": {"inverter": replace(base, sample_at="valley", t_dead=2e-6)},
        "cross_saturation": {"cross_saturation": True},
        "linear_magnetics": {"saturation": False},
        "three_substeps": {"substeps": 3},
        "speed_load": {"load": SpeedProportionalLoad(0.02)},
        "imposed_speed": {"imposed": 80.0},
        "meter": {"meter": True},
        "meter_imposed_speed": {"meter": True, "imposed": 80.0},
        "meter_dc_link_capacitor": {"meter": True, "inverter": replace(base, r_dc=0.5, c_dc=2e-4)},
    }


def _open_loop(model: str, engine: str, kw: dict[str, Any], n: int = 400) -> list[bytes]:
    """A rotating voltage vector of 30 % modulation at 50 Hz, over- and under-modulated
    legs (duties past 0 and 1), and a disabled stretch."""
    p = preset("wen2023")
    kw = dict(kw)
    prof = drive_profile(p) if model == "switching" else ideal_profile(p)
    imposed = kw.pop("imposed", None)
    plant = _plant(
        engine,
        p.motor,
        kw.pop("inverter", prof.inverter),
        p.T_s,
        sensors=kw.pop("sensors", prof.sensors),
        saturation=kw.pop("saturation", prof.saturation),
        cross_saturation=kw.pop("cross_saturation", prof.cross_saturation),
        load=kw.pop("load", ConstantLoad(0.5)),
        **kw,
    )
    if imposed is not None:
        plant.impose_speed(imposed)
    out = []
    for k in range(n):
        a = 2.0 * math.pi * 50.0 * k * p.T_s
        m = 0.3 if k < n // 2 else 0.7  # the second half clamps at the rails
        d = [0.5 + m * math.cos(a - j * 2.0 * math.pi / 3.0) for j in range(3)]
        s = plant.sample()
        plant.step(d[0], d[1], d[2], not (n // 4 <= k < n // 4 + 10))
        if k == n // 3 and imposed is not None:
            plant.impose_speed(None)
        out.append(_state(plant) + _bits(s.i_a, s.i_b, s.i_c, s.u_dc))
    return out


@pytest.mark.parametrize("model", ["average", "switching"])
@pytest.mark.parametrize("feature", sorted(_features(InverterPars(u_dc=540.0))))
def test_each_feature_core_is_the_reference(model: str, feature: str) -> None:
    """Each feature of the step, open loop, on the average and the switching model: the
    same state, samples and energy integrals after every period, bit for bit."""
    p = preset("wen2023")
    base = (drive_profile(p) if model == "switching" else ideal_profile(p)).inverter
    kw = _features(base)[feature]
    py = _open_loop(model, "reference", kw)
    cc = _open_loop(model, "core", kw)
    first = next((k for k in range(len(py)) if py[k] != cc[k]), None)
    assert first is None, f"the core and the reference part at period {first}"
    i_q = struct.unpack("d", py[-1][8:16])[0]
    assert i_q != 0.0


def test_engine_choice() -> None:
    """Every engine choice runs the plant on its core; an unknown name is an error; the
    command line offers the same names."""
    p = preset("wen2023")
    for engine in ENGINES:
        assert resolve_engine(engine) == "compiled"
        assert Plant(p.motor, p.inverter, p.T_s, engine=engine).engine == "compiled"
    assert Plant(p.motor, p.inverter, p.T_s, meter=True).engine == "compiled"
    assert compiled_engine_missing() is None
    with pytest.raises(ValueError, match="unknown plant engine"):
        resolve_engine("fortran")
    assert tuple(CLI_ENGINES) == tuple(ENGINES)
    node = loops.make_plant_node(load_scenario("wen-5.1"), Codec(), engine="python")
    assert node.report()["engine"] == "compiled"


def test_without_the_built_core_the_import_fails_in_one_line() -> None:
    """Without the built core ``import plant_rt`` fails with one line naming the remedy."""
    code = "import sys; sys.modules['plant_rt._cplant'] = None\nimport plant_rt\n"
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode != 0
    last = r.stderr.strip().splitlines()[-1]
    assert last.startswith("ImportError: plant_rt: the plant core (plant_rt/core, C) is not built")
    assert "tools/need-cc" in last
