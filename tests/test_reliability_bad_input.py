"""A user's mistake gives one line naming the file, field and reason, and exit status 2."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from bench.cli import main

ROOT = Path(__file__).resolve().parents[1]
WEN = (ROOT / "bench" / "scenarios" / "wen-5.1.toml").read_text()


def one_line_error(capsys: pytest.CaptureFixture[str], argv: list[str], *words: str) -> str:
    rc = main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2
    assert len(err) == 1, err
    last = err[-1]
    # ours: "bench: error: ..."; the command line's: "bench SUBCOMMAND: error: ..."
    assert re.match(r"bench( [a-z]+)?: error: ", last), err
    assert "Traceback" not in "\n".join(err)
    for w in words:
        assert w in last, (w, last)
    return last


def test_malformed_scenario(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    f = tmp_path / "bad.toml"
    f.write_text(WEN.replace("duration = 4.0", "duration = -1.0"))
    one_line_error(capsys, ["run", str(f), "--interface", "virtual", "--channel", "x"],
                   "bad.toml", "duration")  # fmt: skip
    f.write_text("duration = [")
    one_line_error(capsys, ["run", str(f)], "bad.toml", "TOML")


def test_unknown_preset(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    f = tmp_path / "preset.toml"
    f.write_text(WEN.replace('preset = "wen2023"', 'preset = "nope"'))
    one_line_error(capsys, ["run", str(f)], "preset.toml", "preset", "nope")


def test_unknown_estimator(capsys: pytest.CaptureFixture[str]) -> None:
    one_line_error(capsys, ["run", "wen-5.1", "-e", "nope"], "estimator", "nope")


def test_unreadable_dbc(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    missing = tmp_path / "missing.dbc"
    one_line_error(capsys, ["soak", "--dbc", str(missing), "--frames", "10"],
                   "missing.dbc", "not found")  # fmt: skip
    junk = tmp_path / "junk.dbc"
    junk.write_text("BO_ this is not a DBC\n")
    one_line_error(capsys, ["soak", "--dbc", str(junk), "--frames", "10"], "junk.dbc")


def test_unreadable_capture(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    one_line_error(capsys, ["analyze", str(tmp_path / "none.blf")], "none.blf")
    junk = tmp_path / "junk.blf"
    junk.write_bytes(b"\x00garbage" * 10)
    one_line_error(capsys, ["analyze", str(junk), "--scenario", "wen-5.1"], "junk.blf")


def test_missing_interface_or_channel(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = str(tmp_path / "r")
    one_line_error(capsys, ["run", "wen-5.1", "--interface", "nosuch", "--channel", "x", "-o", out],
                   "nosuch")  # fmt: skip
    one_line_error(capsys, ["run", "wen-5.1", "--channel", "vcan0", "-o", out], "--interface")


def test_bad_input_through_a_real_process() -> None:
    p = subprocess.run(
        [sys.executable, "-m", "bench", "run", "no-such-scenario"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert p.returncode == 2
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and "no-such-scenario" in lines[0], p.stderr
    assert "Traceback" not in p.stderr


def test_virtual_bus_is_refused_for_processes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # python-can's virtual bus does not leave its process: a run on it would wait forever
    line = one_line_error(
        capsys, ["run", "wen-5.1", "-i", "virtual", "-o", str(tmp_path / "r")], "virtual"
    )
    assert "separate processes" in line
    assert not (tmp_path / "r").exists()


def test_an_estimator_that_cannot_run_the_scenario_is_refused_before_any_process(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "r"
    line = one_line_error(capsys, ["run", "xue-fig13", "-e", "tt-dq", "-o", str(out)], "tt-dq")
    assert "xue-fig13" in line and "Nyquist" in line and "square-wave" in line
    assert not out.exists()


def test_python_can_configuration_names_the_bus(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    # CAN_INTERFACE is read (here a name python-can does not know, so nothing starts)
    monkeypatch.setenv("CAN_INTERFACE", "nosuchbus")
    monkeypatch.setenv("CAN_CHANNEL", "x")
    one_line_error(capsys, ["run", "wen-5.1", "-o", str(tmp_path / "r")], "nosuchbus")


@pytest.mark.parametrize("rates", ["abc", ",", "-1,0", "1,nan"])
def test_busload_rates_are_checked(rates: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["busload", f"--rates={rates}"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--rates" in err[0] and "positive" in err[0], err


@pytest.mark.parametrize(
    ("extra", "word"),
    [
        (["--to-port", "47100"], "the same bus"),
        (["--to-port", "47101", "--drop-prob", "2"], "--drop-prob"),
        (["--to-port", "47101", "--jitter-us", "-5"], "--jitter-us"),
        (["--to-port", "47101", "--delay-steps", "-1"], "--delay-steps"),
    ],
)
def test_link_settings_are_checked(
    extra: list[str], word: str, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["link", "-i", "udp_multicast", "--port", "47100", "--to", "udp_multicast:239.74.163.2"]
    one_line_error(capsys, [*argv, *extra], word)


@pytest.mark.parametrize(
    "argv",
    [
        ["plant", "wen-5.1", "--truth-every", "0"],
        ["run", "wen-5.1", "--delay-steps", "-3"],
        ["run", "wen-5.1", "--duration", "0"],
        ["run", "wen-5.1", "--watchdog-ms", "-1"],
        ["controller", "wen-5.1", "--sample-timeout-ms", "nan"],
    ],
)
def test_out_of_range_options_are_refused_not_clamped(
    argv: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    one_line_error(capsys, argv, argv[-2], repr(argv[-1]))


def test_soak_output_folder_is_checked_before_the_soak(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = str(tmp_path / "no-such-folder" / "soak.json")
    one_line_error(capsys, ["soak", "--frames", "10", "--quiet", "--out", bad], "--out", bad)
