"""``bench.run(dut=...)``: the controller under test's process, started by the run.

A process that ends before its first valid ``PwmDuty`` ends the run at once (not at
``dut_timeout``), with one line naming its exit status and its ``dut.log``, and the
status of a controller that never answered (a ``BenchError``: ``bench run``'s 2).
``{mode}`` in its command line is the run's mode.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

import bench
from tests.ports import free_port

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "tests" / "data" / "firmware-100rpm.toml"
GROUP = "239.74.163.4"
#: Far longer than the run takes to start and to see the process gone (seconds, a
#: loaded host included): a run that waited for it would fail on the test's timeout.
DUT_TIMEOUT_S = 600.0


@pytest.mark.timeout(300)
def test_a_dut_that_exits_ends_the_run_with_its_status_and_log(tmp_path: Path) -> None:
    out = tmp_path / "run"
    dut = [sys.executable, "-c", "import sys; print('mode', sys.argv[1]); sys.exit(7)", "{mode}"]
    with pytest.raises(bench.BenchError) as e:
        bench.run(
            SCENARIO,
            transport=f"udp_multicast:{GROUP}:{free_port()}",
            controller="external",
            dut=dut,
            dut_timeout=DUT_TIMEOUT_S,
            dut_name="quits",
            out=out,
        )
    line = str(e.value)
    assert "\n" not in line
    assert "quits ended (exit status 7) before its first valid PwmDuty" in line, line
    assert str(out / "dut.log") in line, line
    assert (out / "dut.log").read_text().strip() == "mode lockstep"
    assert (out / "error.txt").read_text().startswith("quits ended (exit status 7)")


def test_an_unknown_placeholder_names_the_known_ones_mode_among_them(tmp_path: Path) -> None:
    with pytest.raises(bench.BenchError, match=r"unknown placeholder 'nope'.*\{mode\}"):
        bench.run(
            SCENARIO,
            transport=f"udp_multicast:{GROUP}:{free_port()}",
            controller="external",
            dut=[sys.executable, "{nope}"],
            out=tmp_path / "run",
        )
