"""``bench show`` and ``bench list``: what a controller author needs, without reading code."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from bench.cli import main
from bench.scenarios._schema import SHIPPED, load_scenario
from bench.scenarios._setup import command_schedule, get_preset, n_steps
from controller import ESTIMATOR_NAMES
from plant_rt import PROFILE_NAMES


def run_json(capsys: pytest.CaptureFixture[str], argv: list[str]) -> dict[str, Any]:
    assert main(argv) == 0
    out: dict[str, Any] = json.loads(capsys.readouterr().out)
    return out


def test_show_gives_the_motor_the_rate_and_the_commands_as_frames(
    capsys: pytest.CaptureFixture[str],
) -> None:
    d = run_json(capsys, ["show", "xue-fig15", "--json"])
    scn = load_scenario("xue-fig15")
    p = get_preset(scn)
    assert d["motor"]["preset"] == "xue2022" and d["motor"]["L_q"] == p.motor.L_q
    assert d["motor"]["psi_f"] == p.motor.psi_f and d["motor"]["replaced"] == []
    assert d["pwm"]["f_sw_hz"] == 1000.0 and d["pwm"]["periods"] == n_steps(scn)
    sched = command_schedule(scn)
    assert [(c["step"], c["cmd"], c["speed_ref_rpm"], c["load_nm"]) for c in d["commands"]] == [
        (c.apply_step, c.cmd, c.speed_ref_rpm, c.load_nm) for c in sched
    ]
    assert d["commands"][0]["cmd_name"] == "start" and d["commands"][-1]["cmd_name"] == "stop"
    assert d["commands"][-1]["step"] == n_steps(scn)
    assert d["transport"]["interface"] in ("udp_multicast", "socketcan")
    assert d["plant"]["profile"] == "ideal"


def test_show_names_the_replaced_motor_values_and_an_override(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    f = tmp_path / "mine.toml"
    f.write_text('extends = "wen-5.1"\n[motor]\nR_s = 1.4\n')
    d = run_json(capsys, ["show", str(f), "--json", "--plant-profile", "drive", "--port", "47000"])
    assert d["motor"]["R_s"] == 1.4 and d["motor"]["replaced"] == ["R_s"]
    assert d["plant"]["inverter"]["model"] == "switching"
    assert d["transport"]["port"] == 47000 or d["transport"]["interface"] == "socketcan"
    assert main(["show", str(f)]) == 0
    text = capsys.readouterr().out
    assert "[motor] sets R_s" in text and "R_s        1.4 Ohm" in text


def test_list_names_every_scenario_estimator_and_profile(
    capsys: pytest.CaptureFixture[str],
) -> None:
    d = run_json(capsys, ["list", "--json"])
    assert list(d["scenarios"]) == list(SHIPPED)
    assert list(d["estimators"]) == list(ESTIMATOR_NAMES)
    assert d["plant_profiles"] == list(PROFILE_NAMES)
    assert set(d["presets"]) == {"wen2023", "xue2022"}
    assert main(["list"]) == 0
    assert "wide-speed-wen" in capsys.readouterr().out


def test_show_of_a_missing_scenario_is_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["show", "wen-9.9"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "unknown scenario" in err[0]
