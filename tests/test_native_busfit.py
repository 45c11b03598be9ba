"""``bench run`` against the bus's bit rate (issue 29, item 5): refuse, warn, or run.

The load is ``bench busload``'s (bench/wire/_busload.py); the figures are
checked against its table, and the bit rates chosen so that the load falls
where each case needs it (on a classic bus the load is inversely
proportional to the bit rate, low-rate frames included).
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from bench._errors import BenchError
from bench.cli import main
from bench.runs._busfit import check_bus_rate, run_frames
from bench.scenarios._schema import load_scenario
from bench.scenarios._setup import sample_period
from bench.wire._bus import BusSpec
from bench.wire._busload import LAYOUTS, bus_of, busload_table, parse_link_bitrates, rate_fit
from bench.wire._codec import Codec
from tests.ports import free_port

SCN = "xue-fig13"  # 1 kHz: loads near 100 % at real bit rates


@pytest.fixture(scope="module")
def scn():
    return load_scenario(SCN)


def _spec(bitrate: int | None, data_bitrate: int | None = None) -> BusSpec:
    return BusSpec("udp_multicast", "239.74.163.2", 45000, bitrate, data_bitrate)


def _bitrate_for(scn, load: float) -> int:
    """The classic bit rate at which the run's frames take ``load`` of the bus."""
    at_1m = rate_fit(Codec(), run_frames(scn, external=False), bus_of(1e6), 1 / sample_period(scn))
    return round(1e6 * at_1m.load / load)


def test_the_run_frames_are_the_busload_layout(scn) -> None:
    frames = run_frames(scn, external=False)
    assert sorted(frames) == sorted(LAYOUTS["control+recorder"])
    (row,) = [
        r
        for r in busload_table(Codec(), rates=[1e3])
        if r["layout"] == "control+recorder" and r["bus"] == "FD 1M/5M"
    ]
    fit = rate_fit(Codec(), frames, bus_of(1_000_000, 5_000_000), 1e3)
    assert fit.load == pytest.approx(row["load"][1e3], rel=1e-12)
    assert fit.max_rate_hz == pytest.approx(row["max_rate_hz"], rel=1e-12)
    assert fit.max_rate_hz_practical == pytest.approx(row["max_rate_hz_practical"], rel=1e-12)


def test_a_run_with_faults_counts_the_true_currents_frame(scn, tmp_path: Path) -> None:
    """A scenario with a [[faults]] timeline makes the plant send PlantCurrents (DBC 2.4)
    with each PlantTruth: the bus-rate check counts it, and it costs load."""
    src = tmp_path / "f.toml"
    src.write_text(f'extends = "{SCN}"\n[[faults]]\nat_s = 1.0\nkind = "open_phase"\nphase = "b"\n')
    faulted = run_frames(load_scenario(str(src)), external=False)
    assert faulted == {**run_frames(scn, external=False), "PlantCurrents": 1.0}
    f_sw = 1 / sample_period(scn)
    bus = bus_of(1_000_000, 5_000_000)
    more = rate_fit(Codec(), faulted, bus, f_sw).load
    assert more > rate_fit(Codec(), run_frames(scn, external=False), bus, f_sw).load


def test_a_controller_under_test_gets_the_position_sensor_not_telemetry(scn) -> None:
    frames = run_frames(scn, external=True)
    assert frames["PositionSensor"] == 1.0 and "CtrlTelemetry" not in frames


def test_no_bit_rate_no_check(scn) -> None:
    assert check_bus_rate(scn, _spec(None), mode="realtime", external=False) is None


def test_below_80_percent_runs_silently(scn) -> None:
    spec = _spec(_bitrate_for(scn, 0.7))
    assert check_bus_rate(scn, spec, mode="realtime", external=False) is None


def test_above_80_percent_warns(scn) -> None:
    bitrate = _bitrate_for(scn, 0.9)
    fit = rate_fit(Codec(), run_frames(scn, external=False), bus_of(bitrate), 1e3)
    line = check_bus_rate(scn, _spec(bitrate), mode="realtime", external=False)
    assert line is not None and line.startswith("warning: bus: 1 kHz real time needs 90 % of ")
    assert "\n" not in line
    assert f"; {fit.max_rate_hz_practical / 1e3:.2f} kHz stays below it" in line
    assert 0.85e3 < fit.max_rate_hz_practical < 0.8e3 / 0.9  # 80 % of 1 kHz / 0.9, less background


def test_above_100_percent_refuses_naming_the_highest_rate(scn) -> None:
    bitrate = _bitrate_for(scn, 1.25)
    fit = rate_fit(Codec(), run_frames(scn, external=False), bus_of(bitrate), 1e3)
    with pytest.raises(BenchError) as e:
        check_bus_rate(scn, _spec(bitrate), mode="realtime", external=False)
    text = str(e.value)
    assert "\n" not in text and "needs 125 % of " in text
    assert f"the highest PWM rate that fits is {fit.max_rate_hz / 1e3:.2f} kHz" in text
    assert 0.75e3 < fit.max_rate_hz < 0.8e3  # 1 kHz / 1.25, less the low-rate frames' share


def test_lockstep_is_never_refused_but_says_it_is_slower(scn) -> None:
    spec = _spec(_bitrate_for(scn, 2.0))
    line = check_bus_rate(scn, spec, mode="lockstep", external=False)
    assert line is not None and line.startswith("bus: lockstep at 1 kHz needs 200 % of ")
    assert (
        check_bus_rate(scn, _spec(_bitrate_for(scn, 0.9)), mode="lockstep", external=False) is None
    )


def test_bench_run_refuses_in_one_line_and_writes_nothing(tmp_path: Path, capsys) -> None:
    out = tmp_path / "run"
    argv = ["run", SCN, "--mode", "realtime", "--interface", "udp_multicast"]
    argv += ["--port", str(free_port()), "--bitrate", "500000", "--duration", "0.1"]
    assert main([*argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len([line for line in err if "highest PWM rate that fits" in line]) == 1
    assert err[-1].startswith("bench: error: scenario xue-fig13: 1 kHz real time needs ")
    assert not out.exists()


IP_CAN0_FD = [
    {
        "ifname": "can0",
        "linkinfo": {
            "info_kind": "can",
            "info_data": {
                "state": "ERROR-ACTIVE",
                "bittiming": {"bitrate": 1000000, "sample_point": "0.800"},
                "data_bittiming": {"bitrate": 5000000, "sample_point": "0.750"},
            },
        },
    }
]
IP_CAN1_CLASSIC = [
    {"ifname": "can1", "linkinfo": {"info_data": {"bittiming": {"bitrate": 500000}}}}
]
IP_VCAN0 = [{"ifname": "vcan0", "linkinfo": {"info_kind": "vcan"}}]


def test_ip_link_bit_rates() -> None:
    assert parse_link_bitrates(json.dumps(IP_CAN0_FD)) == (1_000_000, 5_000_000)
    assert parse_link_bitrates(json.dumps(IP_CAN1_CLASSIC)) == (500_000, None)
    assert parse_link_bitrates(json.dumps(IP_VCAN0)) is None
    assert parse_link_bitrates("not json") is None
