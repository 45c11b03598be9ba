"""``bench run --dut COMMAND``: the controller under test started by the run, from the shell.

The command line's twin of ``bench.run(dut=[...])`` (tests/test_api_dut.py): one
string split as a shell splits it, the same placeholders, its output in
``dut.log``, a process that ends before its first valid ``PwmDuty`` ending the run
at once with exit 2, and a mistake in the option one line and exit 2 before any
process starts.  The scored run is docs/PROTOCOL.md's one-command form, read from
the page (the block after its ``protocol-dut-test`` mark), on a bus of the test's
own and with this interpreter as its ``python``.
"""

from __future__ import annotations

import json
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from tests.ports import free_port

ROOT = Path(__file__).resolve().parents[1]
PROTOCOL = ROOT / "docs" / "PROTOCOL.md"
SCENARIO = ROOT / "docs" / "examples" / "ci-project" / "scenarios" / "quick-start.toml"
GROUP = "239.74.163.6"
#: The example controller's start (Python, python-can, cantools and a ``bench show``)
#: takes about 2 s of CPU; on a shared 2-core host several times that.
DUT_TIMEOUT_S = 120.0


def documented_command() -> list[str]:
    """docs/PROTOCOL.md's ``bench run ... --dut COMMAND``, its ``python`` this interpreter."""
    m = re.search(r"<!-- protocol-dut-test:[^>]*-->\n```\n(.*?)```", PROTOCOL.read_text(), re.S)
    assert m, "docs/PROTOCOL.md has no protocol-dut-test block"
    cmd = shlex.split(m.group(1))
    assert cmd[:2] == ["bench", "run"] and cmd.count("--dut") == 1, cmd
    i = cmd.index("--dut") + 1
    dut = shlex.split(cmd[i])
    assert dut[0] == "python", dut
    cmd[i] = shlex.join([sys.executable, *dut[1:]])
    return cmd[2:]


def bench_run(out: Path, *args: str, scenario: Path = SCENARIO) -> subprocess.CompletedProcess[str]:
    """``bench run`` with a controller under test on a udp_multicast bus of the test's own."""
    from bench.runs._run import build_native_libraries

    build_native_libraries()  # the tests' cache starts empty (tests/conftest.py)
    if not args or args[0].startswith("-"):
        args = (str(scenario), "--controller", "external", *args)
    cmd = [sys.executable, "-m", "bench", "run", *args,
           "--interface", "udp_multicast", "--channel", GROUP, "--port", str(free_port()),
           "--dut-timeout", repr(DUT_TIMEOUT_S), "--out", str(out), "--quiet"]  # fmt: skip
    return subprocess.run(
        cmd, cwd=ROOT, capture_output=True, text=True, timeout=DUT_TIMEOUT_S + 240
    )


@pytest.mark.timeout(DUT_TIMEOUT_S + 300)
def test_the_example_controller_started_with_dut_is_scored(tmp_path: Path) -> None:
    out = tmp_path / "run"
    p = bench_run(out, *documented_command())
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-3000:]
    meta = json.loads((out / "meta.json").read_text())
    assert meta["controller"] == "external" and meta["controller_name"] == "my-drive"
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["scored_steps"] > 1000 and metrics["lock_lost"] is False
    # the run's own port reached the controller through {port}: it answered on it
    assert meta["dut_first_duty_s"] is not None
    assert (out / "dut.log").is_file()
    assert "dut.log" in next(ln for ln in p.stdout.splitlines() if ln.startswith("files: "))


@pytest.mark.timeout(DUT_TIMEOUT_S + 300)
def test_a_dut_that_exits_ends_the_run_with_exit_2_and_its_log(tmp_path: Path) -> None:
    out = tmp_path / "run"
    quits = shlex.join(
        [sys.executable, "-c", "import sys; print('mode', sys.argv[1]); sys.exit(7)"]
    )
    p = bench_run(out, "--dut", quits + " {mode}", "--dut-name", "quits")
    assert p.returncode == 2, p.stdout[-2000:] + p.stderr[-3000:]
    lines = [ln for ln in p.stderr.splitlines() if "before its first valid PwmDuty" in ln]
    assert len(lines) == 1, p.stderr
    assert "quits ended (exit status 7)" in lines[0] and str(out / "dut.log") in lines[0]
    assert "Traceback" not in p.stderr
    assert (out / "dut.log").read_text().strip() == "mode lockstep"


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (("--controller", "bench", "--dut", "ctl"), "--dut: only with --controller external"),
        (("--dut", "python 'ctl.py"), '--dut: "python \'ctl.py": No closing quotation'),
        (("--dut", "  "), "--dut: an empty command"),
        (("--dut", "python {nope}"), "--dut: ['python', '{nope}']: unknown placeholder 'nope'"),
    ],
)
def test_a_mistake_in_dut_is_one_line_and_exit_2(
    tmp_path: Path, extra: tuple[str, ...], message: str
) -> None:
    p = bench_run(tmp_path / "run", *extra)
    assert p.returncode == 2, p.stdout + p.stderr
    errors = [ln for ln in p.stderr.splitlines() if ln.startswith("bench: ")]
    assert len(errors) == 1 and message in errors[0], p.stderr
    assert "Traceback" not in p.stderr
    assert not (tmp_path / "run" / "dut.log").exists()
