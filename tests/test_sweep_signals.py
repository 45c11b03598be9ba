"""SIGINT and SIGTERM to ``bench sweep --executor dask`` on the local cluster it starts.

The process tests of the local executor are in ``tests/test_signals_studies.py``;
this one holds the Dask executor to the same contract: exit status 130 with
the local executor's line, no traceback, no process of the cluster left, and
the finished points kept (``points.jsonl``, ``results.csv`` and ``sweep.json``
marked ``interrupted``).

Before the nannies were told not to restart their killed workers
(:func:`bench.studies._executors._end_dask`), the stop took about 11 s and
printed Dask's cancellation tracebacks; it now takes 0.7 to 0.8 s on a
machine at load 5, 1.3 s at load 14, and 8.9 to 9.7 s at a load of 28 to 34
on the two cores (two busy loops beside other test runs), where the command
gets a fifteenth of a core: its own part after the signal (noticing it,
ending the cluster, writing the files) is under 0.3 s at load 14, the rest
is the exit of a Python process that holds Dask, numpy and tornado.

:data:`LIMIT_S` is three times the slowest stop measured at load 34: it
catches a hang, not a slow machine.  The fault this test was written for,
nannies that restart the killed workers, is caught by the assertion on
stderr (their tracebacks and ``ERROR`` lines) at any load.
"""

from __future__ import annotations

import csv
import json
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from tests.test_signals_studies import _left, _signal_and_time, _wait_for

ROOT = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="reads /proc")

#: Points of the sweep: far more than finish before the signal.
POINTS = 40
#: The bound on the stop (module docstring): 3 x 9.7 s, the slowest at load 34.
LIMIT_S = 30.0


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["sigint", "sigterm"])
def test_dask_sweep_ends_on_a_signal_and_keeps_the_finished_points(
    tmp_path: Path, sig: signal.Signals
) -> None:
    pytest.importorskip("distributed")
    out = tmp_path / "sweep"
    seeds = ",".join(str(k) for k in range(1, POINTS + 1))
    err_file = tmp_path / "stderr.txt"
    with err_file.open("w") as err_fh:
        proc = subprocess.Popen(
            [sys.executable, "-m", "bench", "sweep", "xue-fig13", "-e", "square-wave", "--grid",
             f"seed={seeds}", "--duration", "0.6", "--executor", "dask", "--workers", "2",
             "--out", str(out)],
            cwd=ROOT, stdout=subprocess.PIPE, stderr=err_fh, text=True,
        )  # fmt: skip
        log = out / "points.jsonl"
        _wait_for(lambda: log.is_file() and log.read_text().count("\n") >= 2, 240, proc)
        took, kids, _ = _signal_and_time(proc, lambda: proc.send_signal(sig))
    err = err_file.read_text()
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "ERROR" not in err, err
    # the local executor's lines, once each
    assert err.count(f"bench: {sig.name}: stopping, keeping what finished") == 1, err
    assert err.rstrip().endswith("bench: interrupted"), err
    assert took < LIMIT_S, f"{took:.2f} s"
    # the cluster's worker processes (and the multiprocessing helper) were there, and are gone
    assert len(kids) >= 2, kids
    assert _left(kids) == {}
    finished = [json.loads(line) for line in log.read_text().splitlines()]
    assert 2 <= len(finished) < POINTS
    with (out / "results.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert sorted(r["seed"] for r in rows) == sorted(str(p["values"]["seed"]) for p in finished)
    summary = json.loads((out / "sweep.json").read_text())
    assert summary["interrupted"] is True and summary["finished"] == len(finished)
    assert summary["missing"] == POINTS - len(finished)
    assert summary["throughput"]["executor"] == "dask"
    assert not (out / "plots").exists()
