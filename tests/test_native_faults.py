"""The native plant node with what the Python node alone served before: sensor noise,
a load profile, the energy meter, and the scenario's fault timeline.

Each is held to the Python node: a lockstep run on udp_multicast with the native
plant gives the in-process reference's frames (the Python node's) bit for bit
(:func:`tests.test_native_plant._assert_native_equals_python`), and, with faults,
the ``faults`` entries of metrics.json equal.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from bench.scenarios._schema import Noise
from bench.wire._bus import BusSpec
from tests.ports import free_port
from tests.test_native_plant import GROUP, _assert_native_equals_python
from tests.trace_helpers import short


def test_sensor_noise_native_gives_the_python_nodes_frames(tmp_path: Path) -> None:
    """Current noise and ADC quantisation: the same draws, in the same order, in C."""
    scn = replace(short("wen-5.1", 0.12), noise=Noise(current_std_a=0.05, adc_bits=12))
    spec = BusSpec("udp_multicast", GROUP, free_port())
    _assert_native_equals_python(scn, "tt-dq", spec, tmp_path / "noise")


def test_a_plant_stepped_by_a_c_caller_reports_the_cores_energy_meter() -> None:
    """The meter integrates in the core whoever steps it; :meth:`Plant.adopt_core` reads it
    (the native node's path), equal to the Python-stepped plant's to the bit."""
    from plant_rt import Plant, preset

    pre = preset("wen2023")
    a = Plant(pre.motor, pre.inverter, 1.0 / pre.f_sw, meter=True)
    b = Plant(pre.motor, pre.inverter, 1.0 / pre.f_sw, meter=True)
    duties = [(0.5 + 0.3 * (k % 7) / 7, 0.5, 0.5 - 0.2 * (k % 5) / 5) for k in range(200)]
    for d in duties:
        a.step(*d)
    for k, d in enumerate(duties):  # as bn_plant.c does: the core alone
        b._core.step(*d, k * b.T_s)
    b.adopt_core(len(duties), -1)
    assert a.meter is not None and b.meter is not None
    assert a.meter.e_in != 0.0 and a.meter.e_cu > 0.0
    assert b.meter == a.meter


def test_noise_load_profile_and_meter_leave_the_native_plant_eligible() -> None:
    """The fallback line names none of them any more (a run with a step count)."""
    from bench.nodes._plant_node import PlantNode
    from bench.nodes.native import _plant_native
    from plant_rt import Plant, SensorPars, StepLoad, preset
    from tests.trace_helpers import CODEC

    pre = preset("wen2023")
    plant = Plant(
        pre.motor,
        pre.inverter,
        1.0 / pre.f_sw,
        sensors=SensorPars(noise_i=0.1, noise_u=0.5, seed=3),
        load=StepLoad(0.01, 1.0),
        meter=True,
    )
    node = PlantNode(CODEC, plant, n_steps=100)
    why = _plant_native.native_missing(node, "udp_multicast", realtime=False, external=False)
    assert why is None
    node.n_steps = 0  # until stopped: the noise is drawn before the loop, so not native
    why = _plant_native.native_missing(node, "udp_multicast", realtime=False, external=False)
    assert why is not None and "noise" in why


def test_noise_values_are_the_generators_calls_in_the_cores_order() -> None:
    """:func:`noise_values` against the core's own calls of the Python generator."""
    import itertools

    from bench.nodes.native._plant_native import noise_values
    from plant_rt import Plant, SensorPars, preset

    pre = preset("wen2023")
    sens = SensorPars(noise_i=0.1, noise_u=0.5, seed=11)
    a = Plant(pre.motor, pre.inverter, 1.0 / pre.f_sw, sensors=sens)
    b = Plant(pre.motor, pre.inverter, 1.0 / pre.f_sw, sensors=sens)
    ideal = Plant(pre.motor, pre.inverter, 1.0 / pre.f_sw)
    vals = list(itertools.islice(noise_values(b), 4 * 5))
    for j in range(5):
        s, t = a.sample(), ideal.sample()
        got = (s.i_a - t.i_a, s.i_b - t.i_b, s.i_c - t.i_c, s.u_dc - t.u_dc)
        want = vals[4 * j : 4 * j + 4]
        assert got[:3] == tuple(want[:3])  # ideal ADC: the currents' noise exactly
        assert abs(got[3] - want[3]) < 1e-12
        a.step(0.5, 0.5, 0.5)
        ideal.step(0.5, 0.5, 0.5)
