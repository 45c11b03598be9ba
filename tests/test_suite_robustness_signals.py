"""SIGINT to ``bench suite robustness``: status 130 and a summary of what finished.

The paper suite and ``bench sweep`` keep a partial summary on a signal
(``tests/test_signals_studies.py``); the robustness suite does the same: the
study that finished is whole (with its figure), the one under way holds its
finished points (no figure), no point is invented, and the same command
again runs only the missing points.

The stop took 1.2 to 4.3 s at a load of 11 to 15 on the two cores and 9.7 s
at a load of 28 to 34: the command's own part is under 0.2 s (profiled),
the rest the exit of a Python process that drew the finished study's
figure with matplotlib, at a fifteenth of a core.  :data:`LIMIT_S`, three
times the slowest, catches a hang, not a slow machine.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from tests.test_signals_studies import _left, _signal_and_time, _wait_for

ROOT = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="reads /proc")

#: Xue's two estimators on R_s (3 values) then on the current noise (7 values).
FIRST, SECOND = "model-resistance", "current-noise"
PLANNED = 2 * (3 + 7)
#: The bound on the stop (module docstring): 3 x 9.7 s, the slowest at load 34.
LIMIT_S = 30.0


def _lines(path: Path) -> int:
    return path.read_text().count("\n") if path.is_file() else 0


def test_robustness_ends_on_a_signal_and_keeps_a_summary(tmp_path: Path) -> None:
    out = tmp_path / "rob"
    err_file = tmp_path / "stderr.txt"
    with err_file.open("w") as err_fh:
        proc = subprocess.Popen(
            [sys.executable, "-m", "bench", "suite", "robustness", "--papers", "xue",
             "--studies", f"{FIRST},{SECOND}", "--duration", "0.6", "-j", "2", "--out",
             str(out)],
            cwd=ROOT, stdout=subprocess.PIPE, stderr=err_fh, text=True,
        )  # fmt: skip
        second = out / "xue" / SECOND / "points.jsonl"
        _wait_for(lambda: _lines(second) >= 1, 300, proc)
        took, kids, _ = _signal_and_time(proc, lambda: proc.send_signal(signal.SIGINT))
    err = err_file.read_text()
    assert proc.returncode == 130, err
    assert "Traceback" not in err, err
    assert took < LIMIT_S, f"{took:.2f} s"
    assert len(kids) >= 2, kids
    assert _left(kids) == {}
    done_second = _lines(second)
    assert 1 <= done_second < 14
    assert f"bench: interrupted: {6 + done_second} of {PLANNED} points finished" in err, err

    summary = json.loads((out / "summary.json").read_text())
    assert summary["interrupted"] is True
    assert summary["finished"] == {"points": 6 + done_second, "points_planned": PLANNED}
    studies = summary["papers"]["xue"]["studies"]
    assert list(studies) == [FIRST, SECOND]
    assert studies[FIRST]["points"] == 6 and studies[FIRST]["missing"] == 0
    assert "interrupted" not in studies[FIRST] and studies[FIRST]["figures"]
    assert (out / studies[FIRST]["figures"][0]).is_file()
    cut = studies[SECOND]
    assert cut["interrupted"] is True and cut["figures"] == []
    assert cut["points"] == done_second and cut["missing"] == 14 - done_second
    regions = cut["regions"]
    assert sum(r["points"] for r in regions.values()) == done_second
    report = (out / "report.md").read_text()
    assert f"**Interrupted: {6 + done_second} of {PLANNED} points finished.**" in report
