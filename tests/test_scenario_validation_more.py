"""Scenario fields checked on load: estimator options, command ranges, delays, saliency.

Each mistake is one line naming the file, the field and the reason (exit
status 2 from the command line, no traceback), raised before any process
starts and before an estimator divides by a zero amplitude.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import pytest

from bench._errors import ScenarioError
from bench.cli import main
from bench.scenarios._schema import (
    estimator_option_keys,
    load_scenario,
    parse_scenario,
    scenario_from_dict,
    write_effective,
)
from bench.scenarios._setup import build_controller
from controller._rotating import RotatingInjectionPars
from plant_rt import PRESETS

ROOT = Path(__file__).resolve().parents[1]
WEN = (ROOT / "bench" / "scenarios" / "wen-5.1.toml").read_text()
XUE = (ROOT / "bench" / "scenarios" / "xue-fig13.toml").read_text()


def _write(tmp_path: Path, extra: str, base: str = WEN) -> str:
    f = tmp_path / "s.toml"
    f.write_text(base + "\n" + extra)
    return str(f)


def _error(path: str) -> str:
    with pytest.raises(ScenarioError) as e:
        load_scenario(path)
    msg = str(e.value)
    assert msg.startswith(f"{path}: field '"), msg
    assert "\n" not in msg, msg
    return msg


def _cli_error(capsys: pytest.CaptureFixture[str], argv: list[str]) -> str:
    rc = main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2
    assert len(err) == 1, err
    assert re.match(r"bench( [a-z]+)?: error: ", err[0]), err
    assert "Traceback" not in err[0]
    return err[0]


# -- [estimator_options] -------------------------------------------------------


def test_zero_injection_amplitude_is_a_field_error_not_a_zero_division(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _write(tmp_path, "[estimator_options]\nV_h = 0.0\n")
    line = _cli_error(capsys, ["run", path, "--estimator", "tt-dq"])
    assert f"{path}: field 'estimator_options.V_h': must be > 0, got 0.0" in line


@pytest.mark.parametrize(
    ("extra", "needle"),
    [
        ("V_h = 0.0", "'estimator_options.V_h': must be > 0, got 0.0"),
        ("V_h = -50", "'estimator_options.V_h': must be > 0, got -50.0"),
        ("f_h = 0.0", "'estimator_options.f_h': must be > 0, got 0.0"),
        ('V_h = "x"', "'estimator_options.V_h': expected a number, got str 'x'"),
        ("V_h = nan", "'estimator_options.V_h': must be finite"),
        ("V_h = true", "'estimator_options.V_h': expected a number, got bool True"),
        (
            "V_h = 1e9",
            "'estimator_options.V_h': injection amplitude 1e+09 V is above the inverter's "
            "linear limit u_dc/sqrt(3) = 311.8 V (preset wen2023, u_dc = 540 V)",
        ),
        (
            "f_h = 5000.0",
            "'estimator_options.f_h': injection frequency 5000 Hz is not below the Nyquist "
            "frequency 5000 Hz of the 10000 Hz sample rate",
        ),
        ("w_o = -1.0", "'estimator_options.w_o': must be >= 0.0, got -1.0"),
        ('normalise = "peak"', "'estimator_options.normalise': expected 'model' or 'measured'"),
        ("bpf = [[1.0], [0.0, 1.0]]", "'estimator_options.bpf': expected [[b_0, b_1, ...]"),
        ("lpf = [1.0, 2.0]", "'estimator_options.lpf': expected [[b_0, b_1, ...]"),
        ("U_h = 400.0", "'estimator_options.U_h': injection amplitude 400 V is above"),
        ("M = 0", "'estimator_options.M': must be >= 1, got 0"),
        ("M = 2.5", "'estimator_options.M': expected an integer"),
        ("a = 0.0", "'estimator_options.a': must be > 0"),
        ("delay_comp = -1.5", "'estimator_options.delay_comp': must be >= 0.0"),
    ],
)
def test_bad_estimator_options_are_one_line(tmp_path: Path, extra: str, needle: str) -> None:
    msg = _error(_write(tmp_path, f"[estimator_options]\n{extra}\n"))
    assert needle in msg, msg


def test_unknown_estimator_option_names_the_key_and_lists_the_valid_ones(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _write(tmp_path, "[estimator_options]\nv_h = 50.0\n")
    line = _cli_error(capsys, ["run", path])
    assert f"{path}: field 'estimator_options.v_h': unknown key (known: " in line
    for k in ("V_h", "f_h", "w_o", "U_h", "M"):
        assert k in line
    assert "unexpected keyword" not in line


def test_option_keys_are_the_union_of_the_families_parameters() -> None:
    keys = set(estimator_option_keys())
    assert {f for f in RotatingInjectionPars.__dataclass_fields__} <= keys
    assert {"U_h", "a", "M", "delay_comp"} <= keys
    assert not keys & {"self", "motor", "T_s", "cic"}  # not options: set by name or controller


def test_nyquist_follows_the_scenarios_sample_rate(tmp_path: Path) -> None:
    # xue2022 samples at 1 kHz: 500 Hz is Nyquist; f_sw = 2 kHz makes 600 Hz legal
    msg = _error(_write(tmp_path, "[estimator_options]\nf_h = 500.0\n", XUE))
    assert "Nyquist frequency 500 Hz of the 1000 Hz sample rate" in msg
    s = load_scenario(
        _write(
            tmp_path,
            "[motor]\n[estimator_options]\nf_h = 600.0\n",
            XUE.replace("f_sw = 1000.0", "f_sw = 2000.0"),
        )
    )
    assert s.estimator_options == {"f_h": 600.0}


def test_good_options_load_and_build_and_survive_the_effective_scenario(tmp_path: Path) -> None:
    extra = (
        "[motor]\n[estimator_options]\nV_h = 40\nf_h = 400.0\nw_o = 0.0\n"
        'normalise = "measured"\nlpf = [[628.0], [1.0, 628.0]]\n'
    )
    s = load_scenario(_write(tmp_path, extra))
    assert s.estimator_options == {
        "V_h": 40.0,
        "f_h": 400.0,
        "w_o": 0.0,
        "normalise": "measured",
        "lpf": ((628.0,), (1.0, 628.0)),
    }
    ctrl = build_controller(s, "tt-dq")
    assert ctrl.pars.estimator_options["V_h"] == 40.0
    back = load_scenario(str(write_effective(s, tmp_path / "scenario.json")))
    assert back.estimator_options == s.estimator_options
    # the square-wave family's keys load too; the amplitude limit is exactly u_dc/sqrt(3)
    u_lin = PRESETS["xue2022"].inverter.u_dc / math.sqrt(3.0)
    d = json.loads(json.dumps(load_scenario("xue-fig13").to_dict()))
    d["estimator_options"] = {"U_h": u_lin, "M": 3, "a": 50.0, "delay_comp": 0.0}
    sq = scenario_from_dict(d, "x.json")
    assert build_controller(sq, "square-wave").estimator.M == 3  # type: ignore[attr-defined]


# -- speed_rpm and load_nm within the BenchCommand frame ------------------------


def test_speed_beyond_the_frame_is_an_error_not_a_silent_clip(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _write(tmp_path, "", WEN.replace("[0.8, 100.0]", "[0.8, 1000000]"))
    line = _cli_error(capsys, ["run", path])
    assert (
        f"{path}: field 'speed_rpm': entry 2: 1000000 rpm outside the range the BenchCommand "
        "frame carries (-6553.6 to 6553.5 rpm)"
    ) in line


@pytest.mark.parametrize(
    ("key", "value", "ok"),
    [
        ("speed_rpm", 6553.5, True),
        ("speed_rpm", -6553.6, True),
        ("speed_rpm", 6553.6, False),
        ("speed_rpm", -7000.0, False),
        ("load_nm", 65.534, True),
        ("load_nm", -65.536, True),
        ("load_nm", 65.6, False),
        ("load_nm", -100.0, False),
    ],
)
def test_profile_limits_come_from_the_dbc(key: str, value: float, ok: bool) -> None:
    data = {"preset": "wen2023", "duration": 1.0, key: [[0.0, 0.0], [0.5, value]]}
    if ok:
        parse_scenario(data, "p.toml")
        return
    with pytest.raises(ScenarioError) as e:
        parse_scenario(data, "p.toml")
    unit = "rpm" if key == "speed_rpm" else "N m"
    assert f"p.toml: field '{key}': entry 1: " in str(e.value)
    assert f"{unit} outside the range the BenchCommand frame carries" in str(e.value)


# -- injected lockstep delays within the step counters' range ------------------


@pytest.mark.parametrize(
    ("extra", "needle"),
    [
        (
            "duty_delay_steps = 100000",
            "'latency.duty_delay_steps': 100000 periods is more than 256",
        ),
        ("sample_delay_steps = 257", "'latency.sample_delay_steps': 257 periods is more than 256"),
        (
            "duty_delay_steps = 200\nsample_delay_steps = 100",
            "'latency': duty_delay_steps + sample_delay_steps = 300 periods is more than 256",
        ),
    ],
)
def test_delays_beyond_the_step_counters_are_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], extra: str, needle: str
) -> None:
    path = _write(tmp_path, f"[latency]\n{extra}\n")
    line = _cli_error(capsys, ["run", path])
    assert f"{path}: field {needle}" in line
    assert "10-bit step counters of PwmDuty/PhaseSamples/PositionSensor wrap" in line


def test_delay_bound_is_inclusive_and_applies_to_command_line_overrides(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    s = load_scenario(
        _write(tmp_path, "[latency]\nduty_delay_steps = 128\nsample_delay_steps = 128\n")
    )
    assert s.latency.duty_delay_steps + s.latency.sample_delay_steps == 256
    line = _cli_error(capsys, ["run", "wen-5.1", "--delay-steps", "100000"])
    assert "wen-5.1: field 'latency.duty_delay_steps': 100000 periods is more than 256" in line


# -- saliency: the motor's own, not the controller_model factors ---------------


def test_non_salient_motor_blames_the_motor_not_the_controller_model(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _write(tmp_path, "[motor]\nL_d = 0.1\nL_q = 0.05\n")
    line = _cli_error(capsys, ["run", path])
    assert f"{path}: field 'motor.L_q': the motor is not salient (L_q 0.05 H <= L_d 0.1 H)" in line
    assert "controller_model" not in line


def test_non_salient_motor_by_l_d_alone_names_motor_l_d(tmp_path: Path) -> None:
    msg = _error(_write(tmp_path, "[motor]\nL_d = 0.1\n"))  # above the preset's L_q 0.082 H
    assert "field 'motor.L_d': the motor is not salient (L_q 0.082 H <= L_d 0.1 H)" in msg
    assert "(sfhf, tt-ab, tt-dq, self-demod, epf)" in msg


def test_non_salient_motor_runs_with_the_sensored_estimator(tmp_path: Path) -> None:
    base = WEN.replace('estimator = "tt-dq"', 'estimator = "sensored"')
    base = re.sub(r"estimators = \[.*\]", 'estimators = ["sensored"]', base)
    s = load_scenario(_write(tmp_path, "[motor]\nL_d = 0.07\nL_q = 0.07\n", base))
    assert build_controller(s, "sensored").pars.motor.L_q == 0.07


def test_non_salient_motor_with_an_injection_estimator_on_the_command_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The file's only estimator is sensored: the misfit shows with ``--estimator``."""
    base = WEN.replace('estimator = "tt-dq"', 'estimator = "sensored"')
    base = re.sub(r"estimators = \[.*\]", 'estimators = ["sensored"]', base)
    path = _write(tmp_path, "[motor]\nL_d = 0.1\nL_q = 0.05\n", base)
    line = _cli_error(capsys, ["run", path, "--estimator", "tt-dq"])
    assert f"{path}: field 'motor.L_q': the motor is not salient (L_q 0.05 H <= L_d 0.1 H)" in line
    assert "controller_model" not in line


def test_realtime_delays_beyond_the_step_counters_are_one_line(tmp_path: Path) -> None:
    """256 periods at wen2023's 10 kHz: 25.6 ms; at a scenario's own f_sw, that rate's periods."""
    assert load_scenario(_write(tmp_path, "[latency]\nduty_delay_us = 25600.0\n")).latency
    msg = _error(_write(tmp_path, "[latency]\nsample_delay_us = 25700.0\n"))
    assert "field 'latency.sample_delay_us': 25700 us is more than 256 PWM periods" in msg
    assert "(25600 us)" in msg
    # the bound follows the scenario's PWM rate
    slow = WEN.replace('preset = "wen2023"', 'preset = "wen2023"\nf_sw = 1000.0')
    assert slow != WEN
    assert load_scenario(_write(tmp_path, "[latency]\nduty_delay_us = 200000.0\n", slow))
