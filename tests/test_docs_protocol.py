"""docs/PROTOCOL.md's first run works as written: its two commands, the bench with
``--controller external`` and the example controller (a sensored FOC written from
that page, python-can and cantools only), give a scored run that the page's own
claims hold for.

The commands are read from the page (the block after its ``protocol-test`` mark);
only the bus's port is replaced by one of this test's own (on a shared host another
run may hold python-can's default port, and the bench refuses a shared bus), and the
run folder goes to the test's temporary folder.
"""

from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.ports import free_port

ROOT = Path(__file__).resolve().parents[1]
PROTOCOL = ROOT / "docs" / "PROTOCOL.md"
DEFAULT_PORT = "43113"

#: The example controller's start (Python, python-can, cantools and a ``bench show``)
#: takes about 2 s of CPU; on a shared 2-core host several times that.
DUT_TIMEOUT_S = 120.0


def documented_commands() -> tuple[list[str], list[str]]:
    """The bench's command and the controller's, as the page gives them."""
    text = PROTOCOL.read_text()
    m = re.search(r"<!-- protocol-test:[^>]*-->\n```\n(.*?)```", text, re.S)
    assert m, "docs/PROTOCOL.md has no protocol-test block"
    lines = [shlex.split(line) for line in m.group(1).strip().splitlines()]
    assert len(lines) == 2, lines
    bench_cmd, ctrl_cmd = lines
    assert bench_cmd[:2] == ["bench", "run"] and "--controller" in bench_cmd, bench_cmd
    assert ctrl_cmd[0] == "python", ctrl_cmd
    return bench_cmd, ctrl_cmd


def test_the_page_names_the_default_bus() -> None:
    """The controller's line uses the bus ``bench show`` prints for the scenario."""
    bench_cmd, ctrl = documented_commands()
    show = subprocess.run(
        [sys.executable, "-m", "bench", "show", bench_cmd[2], "--json"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
    )
    bus = json.loads(show.stdout)["transport"]
    opts = dict(zip(ctrl[3::2], ctrl[4::2], strict=True))
    assert opts == {"-i": bus["interface"], "-c": bus["channel"], "-p": str(bus["port"])}


@pytest.mark.timeout(DUT_TIMEOUT_S + 240)
def test_the_first_run_is_scored(tmp_path: Path) -> None:
    bench_cmd, ctrl_cmd = documented_commands()
    port = str(free_port())
    out = tmp_path / "run"
    bin_dir = Path(sys.executable).parent
    env = dict(os.environ, PATH=f"{bin_dir}{os.pathsep}{os.environ.get('PATH', '')}")
    bench_args = [
        str(bin_dir / "bench"),
        *bench_cmd[1:],
        "--port",
        port,
        "--out",
        str(out),
        "--dut-timeout",
        str(DUT_TIMEOUT_S),
    ]
    ctrl_args = [sys.executable, *[port if a == DEFAULT_PORT else a for a in ctrl_cmd[1:]]]
    assert port in ctrl_args
    bench_p = subprocess.Popen(
        bench_args, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    )
    time.sleep(0.5)  # the documented order: the bench first (either order works)
    ctrl_p = subprocess.Popen(
        ctrl_args, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    )
    try:
        bench_out, _ = bench_p.communicate(timeout=DUT_TIMEOUT_S + 180)
        ctrl_out, _ = ctrl_p.communicate(timeout=60)
    finally:
        for p in (bench_p, ctrl_p):
            if p.poll() is None:
                p.kill()
                p.wait()
    assert bench_p.returncode == 0, bench_out[-3000:] + ctrl_out[-2000:]
    # the controller ends by itself once it has answered the stop (the page: the end of a run)
    assert ctrl_p.returncode == 0, ctrl_out[-2000:]
    metrics = json.loads((out / "metrics.json").read_text())
    meta = json.loads((out / "meta.json").read_text())
    assert meta["controller"] == "external" and meta["controller_name"] == "my-drive"
    assert meta["dbc_version"] == "2.4"
    # scored: every period of the scored window in mode 3 (run), the angle within
    # half an encoder count of the 65536-count default sensor and 4 pole pairs
    # (0.011 deg, PROTOCOL.md) plus the quantisation of theta_hat (0.003 deg)
    assert metrics["scored_steps"] > 1000
    assert metrics["theta_err_abs_max_deg"] < 0.015
    assert metrics["lock_lost"] is False
    # every command held and acknowledged in time, the stop included
    c = meta["commands"]
    assert c["commands_verified"] is True
    assert (c["commands_late"], c["commands_unacknowledged"]) == (0, 0)
    assert c["stop_unacknowledged"] is False
    assert (out / "run.png").stat().st_size > 0
