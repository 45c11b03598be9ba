"""The position sensor of a sensored controller: plant physics and its frame (DBC 2.2).

``plant_rt.encoder_angle`` is the sensor (resolution, delay); the plant node
sends it as ``PositionSensor`` at the scenario's rate.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from bench.nodes._loops import make_plant_node
from bench.scenarios._schema import ScenarioError, load_scenario
from bench.wire._codec import Codec
from plant_rt import SensorPars, encoder_angle
from tests.trace_helpers import short

TWO_PI = 2.0 * math.pi


def test_a_constant_speed_gives_the_delayed_angle_floored_to_a_count() -> None:
    """Closed form: theta(t) = theta0 + w t; the reading at t is the count
    floor(theta(t - d) N / 2 pi) mod N, as an angle; its error lies in [0, 2 pi / N)."""
    n, d, w, th0 = 1024, 250e-6, 31.4, 5.9
    p = SensorPars(encoder_counts=n, encoder_delay_s=d)
    for t in np.linspace(0.0, 0.5, 997):
        th = th0 + w * t
        got = encoder_angle(th % TWO_PI, w, p)
        count = math.floor((th0 + w * (t - d)) * n / TWO_PI) % n
        assert got == pytest.approx(count * TWO_PI / n, abs=1e-12)
        lag = (th - w * d - got) % TWO_PI
        assert 0.0 <= lag < TWO_PI / n + 1e-12
    # no sensor: the angle itself, delay and all
    assert encoder_angle(1.0, 10.0, SensorPars(encoder_delay_s=0.01)) == pytest.approx(0.9)


def test_the_rate_in_whole_periods() -> None:
    assert SensorPars(encoder_counts=4096).encoder_every(1e-4) == 1
    assert SensorPars(encoder_counts=4096, encoder_rate_hz=2500.0).encoder_every(1e-4) == 4
    assert SensorPars(encoder_counts=4096, encoder_rate_hz=1e6).encoder_every(1e-4) == 1
    with pytest.raises(ValueError):
        SensorPars(encoder_counts=70000)


def test_the_plant_sends_the_sensor_at_its_rate_and_never_without_one() -> None:
    codec = Codec()
    scn = short("wen-5.1", 0.01)
    assert not any(
        codec.decode(m).name == "PositionSensor"  # type: ignore[union-attr]
        for m in make_plant_node(scn, codec).frames_now()
    )
    scn.sensors.update(encoder_counts=2048, encoder_rate_hz=2500.0, encoder_delay_s=1e-4)
    pn = make_plant_node(scn, codec)
    seen = []
    frames = pn.frames_now()
    for _ in range(12):
        for m in frames:
            d = codec.decode(m)
            assert d is not None and d.ok
            if d.name == "PositionSensor":
                tr = pn.plant.truth()
                want = encoder_angle(tr.theta_m, tr.w_m, pn.plant.sensor_pars)
                assert d.signals["theta_m"] == pytest.approx(want, abs=TWO_PI / 65536)
                seen.append(int(d.signals["step"]))
        pn.plant.step(0.5, 0.5, 0.5, False)
        frames = pn.frames_now()
    assert seen == [0, 4, 8]  # 2500 Hz at 10 kHz: every fourth period


def test_the_scenario_keys_are_checked(tmp_path: Path) -> None:
    f = tmp_path / "s.toml"
    f.write_text('extends = "wen-5.1"\n[sensors]\nencoder_counts = 70000\n')
    with pytest.raises(ScenarioError, match="encoder_counts"):
        load_scenario(str(f))
    f.write_text('extends = "wen-5.1"\n[sensors]\nencoder_counts = 4096\nencoder_delay_s = 1e-4\n')
    assert load_scenario(str(f)).sensors["encoder_counts"] == 4096


def test_a_controller_under_test_always_gets_a_sensor() -> None:
    """No [sensors] encoder: 65536 counts every period, no delay (the frame's own
    resolution); a scenario's own sensor stays as it is; the plant's numbers do not move."""
    from bench.scenarios._setup import (
        EXTERNAL_ENCODER_COUNTS,
        position_sensor,
        with_position_sensor,
    )

    codec = Codec()
    scn = short("wen-5.1", 0.01)
    ext = with_position_sensor(scn)
    assert ext.sensors["encoder_counts"] == EXTERNAL_ENCODER_COUNTS == 65536
    assert "encoder_counts" not in scn.sensors  # the caller's scenario is not changed
    ps = position_sensor(scn)
    assert (ps["counts"], ps["every"], ps["delay_s"], ps["default"]) == (65536, 1, 0.0, True)
    assert ps["rate_hz"] == pytest.approx(10e3)
    names = [codec.decode(m).name for m in make_plant_node(ext, codec).frames_now()]  # type: ignore[union-attr]
    assert names.count("PositionSensor") == 1
    own = short("wen-5.1", 0.01)
    own.sensors.update(encoder_counts=2048, encoder_rate_hz=2500.0, encoder_delay_s=1e-4)
    assert with_position_sensor(own) is own
    ps = position_sensor(own)
    assert (ps["counts"], ps["every"], ps["delay_s"], ps["default"]) == (2048, 4, 1e-4, False)
    # the sensor adds a frame and changes nothing the plant computes
    a, b = make_plant_node(scn, codec).plant, make_plant_node(ext, codec).plant
    for _ in range(50):
        a.step(0.6, 0.4, 0.5, True)
        b.step(0.6, 0.4, 0.5, True)
    assert a.truth() == b.truth() and a.sample() == b.sample()


def test_an_external_run_records_the_sensor_it_sent(tmp_path: Path) -> None:
    """bench run --controller external writes the effective scenario (with the sensor)
    that its plant ran: scenario.json names the counts the controller got."""
    import json

    from tests.test_external_controller import _run

    res, run_dir = _run(tmp_path)
    assert res.returncode == 0, res.stderr[-2000:]
    sc = json.loads((run_dir / "scenario.json").read_text())
    assert sc["sensors"]["encoder_counts"] == 65536
