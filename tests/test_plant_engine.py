"""The plant's two engines give the same trace bit for bit.

The compiled step (``plant_rt/_cplant.c``) is a second implementation of the
Python one; these tests are what keeps the two equal: every shipped
scenario's first second in the in-process loop, the drive profile's
switching plant in a closed loop, and each feature of the step (DC link,
sensor delay, dead time and drops, cross-saturation, imposed speed, loads
that depend on time and speed, the disabled bridge between enabled
periods, the sensors with noise and ADC). Equal means equal bits: the
states and samples after every period and every frame on the wire.
"""

from __future__ import annotations

import math
import os
import struct
import subprocess
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

import bench.nodes._loops as loops
from bench.cli._common import ENGINES as CLI_ENGINES
from bench.cli.run import run_node_args
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

SCENARIOS = sorted(p.stem for p in (Path(loops.__file__).parents[1] / "scenarios").glob("*.toml"))


@pytest.fixture(autouse=True)
def _compiled_built() -> None:
    """The compiled engine must be built: a skip off CI, a failure in CI (never a silent pass)."""
    why = compiled_engine_missing()
    if why is None:
        return
    if os.environ.get("CI"):
        pytest.fail(why)
    pytest.skip(why)


def _bits(*xs: float) -> bytes:
    return struct.pack(f"{len(xs)}d", *xs)


def _state(p: Plant) -> bytes:
    """Every state and output of a period, as bits."""
    return _bits(p._i_d, p._i_q, p._w_m, p._th_m, p._u_dc, *p.u_s_ab, float(p.k))


def _record_steps(plant: Plant, out: list[bytes], monkeypatch: pytest.MonkeyPatch) -> None:
    """Append the plant's state after each of its periods to ``out``."""
    step = plant.step

    def recorded(d_a: float, d_b: float, d_c: float, enable: bool = True) -> None:
        step(d_a, d_b, d_c, enable)
        out.append(_state(plant))

    monkeypatch.setattr(plant, "step", recorded)


@pytest.mark.parametrize("name", SCENARIOS)
def test_every_scenario_first_second_same_on_both_engines(
    name: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Each shipped scenario's first second in the in-process loop: the same frames and
    the same plant state after every period, bit for bit, on both engines."""
    scn = load_scenario(name).with_overrides(duration=1.0)
    codec = Codec()
    runs: dict[str, tuple[list[tuple[int, bytes]], list[bytes]]] = {}
    build = loops.build_plant
    for engine in ("python", "compiled"):
        states: list[bytes] = []

        def build_recorded(s: Any, e: str = "auto", states: list[bytes] = states) -> Plant:
            p = build(s, e)
            _record_steps(p, states, monkeypatch)
            return p

        monkeypatch.setattr(loops, "build_plant", build_recorded)
        frames = loops.run_inprocess(scn, scn.estimator, codec, engine=engine)
        runs[engine] = ([(m.arbitration_id, bytes(m.data)) for m in frames], states)
    py, cc = runs["python"], runs["compiled"]
    n = round(1.0 * (scn.f_sw or preset(scn.preset).f_sw))
    assert len(py[1]) == n  # every period of the second was recorded
    assert py[1] == cc[1]
    assert py[0] == cc[0]
    # a real closed loop: the rotor moved, currents flowed
    assert struct.unpack("8d", py[1][-1])[2] != 0.0


def _drive_loop(
    preset_name: str, scenario: str, estimator: str, engine: str, n: int
) -> tuple[list[bytes], Plant]:
    """The drive profile's plant (switching inverter, dead time, drops, ADC,
    cross-saturation) under the scenario's controller, with a disabled stretch,
    a load step and a load ramp that calls back into Python."""
    p = preset(preset_name)
    prof = drive_profile(p)
    plant = Plant(
        p.motor,
        prof.inverter,
        p.T_s,
        sensors=prof.sensors,
        saturation=prof.saturation,
        cross_saturation=prof.cross_saturation,
        engine=engine,
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
def test_drive_profile_closed_loop_same_on_both_engines(
    preset_name: str, scenario: str, estimator: str, n: int
) -> None:
    """The switching plant of the drive profile under its controller: the same state and
    samples after every period, bit for bit, through a load step, a load ramp and a
    stretch of disabled periods (the diode bridge runs in Python, the compiled step
    takes the state back)."""
    py, p_py = _drive_loop(preset_name, scenario, estimator, "python", n)
    cc, p_cc = _drive_loop(preset_name, scenario, estimator, "compiled", n)
    assert (p_py.engine, p_cc.engine) == ("python", "compiled")
    assert p_py._switching and p_cc._switching
    first = next((k for k in range(n) if py[k] != cc[k]), None)
    assert first is None, f"the engines part at period {first}"
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
    }


def _open_loop(model: str, engine: str, kw: dict[str, Any], n: int = 400) -> list[bytes]:
    """A rotating voltage vector of 30 % modulation at 50 Hz, over- and under-modulated
    legs (duties past 0 and 1), and a disabled stretch."""
    p = preset("wen2023")
    kw = dict(kw)
    prof = drive_profile(p) if model == "switching" else ideal_profile(p)
    imposed = kw.pop("imposed", None)
    plant = Plant(
        p.motor,
        kw.pop("inverter", prof.inverter),
        p.T_s,
        sensors=kw.pop("sensors", prof.sensors),
        saturation=kw.pop("saturation", prof.saturation),
        cross_saturation=kw.pop("cross_saturation", prof.cross_saturation),
        load=kw.pop("load", ConstantLoad(0.5)),
        engine=engine,
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
def test_each_feature_same_on_both_engines(model: str, feature: str) -> None:
    """Each feature of the step, open loop, on the average and the switching model: the
    same state and samples after every period, bit for bit."""
    p = preset("wen2023")
    base = (drive_profile(p) if model == "switching" else ideal_profile(p)).inverter
    kw = _features(base)[feature]
    py = _open_loop(model, "python", kw)
    cc = _open_loop(model, "compiled", kw)
    first = next((k for k in range(len(py)) if py[k] != cc[k]), None)
    assert first is None, f"the engines part at period {first}"
    i_q = struct.unpack("d", py[-1][8:16])[0]
    assert i_q != 0.0


def test_engine_choice() -> None:
    """auto takes the compiled engine when built, and Python for the energy meter; an
    unknown name or a compiled meter is a ValueError; the CLI offers the same names and
    bench run passes the choice to its plant."""
    p = preset("wen2023")
    assert Plant(p.motor, p.inverter, p.T_s).engine == "compiled"
    assert Plant(p.motor, p.inverter, p.T_s, engine="python").engine == "python"
    assert Plant(p.motor, p.inverter, p.T_s, meter=True).engine == "python"
    assert resolve_engine("auto", meter=True) == "python"
    with pytest.raises(ValueError, match="meter"):
        Plant(p.motor, p.inverter, p.T_s, meter=True, engine="compiled")
    with pytest.raises(ValueError, match="unknown plant engine"):
        resolve_engine("fortran")
    assert CLI_ENGINES == ENGINES
    args = type("Args", (), {"engine": "python", "watchdog_ms": None, "rt_priority": None})()
    assert run_node_args(args)["plant"] == ["--engine", "python"]
    node = loops.make_plant_node(load_scenario("wen-5.1"), Codec(), engine="python")
    assert node.report()["engine"] == "python"


def test_without_the_compiled_engine_the_plant_runs_in_python() -> None:
    """A machine where the extension is missing: auto runs in Python, one line says why,
    and asking for the compiled engine is an error."""
    code = (
        "import sys; sys.modules['plant_rt._cplant'] = None\n"
        "from plant_rt import Plant, preset, compiled_engine_missing, resolve_engine\n"
        "p = preset('wen2023')\n"
        "assert Plant(p.motor, p.inverter, p.T_s).engine == 'python'\n"
        "why = compiled_engine_missing()\n"
        "assert why and '\\n' not in why and 'pure Python' in why, why\n"
        "try:\n"
        "    resolve_engine('compiled')\n"
        "except ValueError:\n"
        "    print('ok')\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "ok"
