"""SIGINT and SIGTERM to ``bench suite`` and ``bench sweep``, and the death of ``bench run``.

Each test starts the command as a process, waits until part of its work
has finished (a run's files in ``--out``, a line of ``points.jsonl``) and
part is still running (a run's ``bench plant`` and ``bench controller``,
in process groups of their own), takes the whole process tree from
``/proc``, sends the signal, and checks:

- the command exits with status 130 within :data:`LIMIT_S` of the signal;
- no process of the tree is left (workers, the multiprocessing helper,
  the node processes of the runs under way);
- what finished is kept: its files, and the summary or results files
  written for the finished part.

The requirement is 3 s.  :data:`MARGIN_S` is added for a machine whose two
cores are taken by other work.  Where the time goes (profiled at a load of
11 to 15, docs/SCALING.md): noticing the signal, under 0.1 s; killing and
reaping the workers, 0.1 to 0.2 s; writing ``summary.json`` and
``report.md``, milliseconds; the interpreter's exit, 0.1 s for the suite's
process (numpy and python-can), more where matplotlib or scipy were loaded.
The suite's process used to downscale each finished run's plot and read
its signal table itself, and a signal that came meanwhile waited for it
(0.5 to 0.8 s at that load); the workers do that now.  The suite stops in
0.55 s at a load of 11 and took 4.7 s at a load of 28 to 34 (two busy loops
beside other test runs), where the command gets a fifteenth of a core.
"""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: What the issue asks: the command ends within 3 s of the signal.
LIMIT_S = 3.0
#: Allowance for a loaded machine (module docstring): a 6 s bound in all.
MARGIN_S = 3.0

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="reads /proc")


def _stat(pid: int) -> list[str] | None:
    """Fields of ``/proc/PID/stat`` after the command name (state first), None if gone."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return text[text.rindex(")") + 2 :].split()


def _alive(pid: int) -> bool:
    st = _stat(pid)
    return st is not None and st[0] not in ("Z", "X")


def _cmdline(pid: int) -> list[str]:
    try:
        raw = Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return []
    return [a.decode(errors="replace") for a in raw.split(b"\0") if a]


class Proc(NamedTuple):
    pgrp: int
    cmd: list[str]


def tree(root: int) -> dict[int, Proc]:
    """Every live descendant of ``root`` (any process group or session): its group, its
    command line."""
    stats: dict[int, list[str]] = {}
    for name in os.listdir("/proc"):
        if name.isdigit():
            st = _stat(int(name))
            if st is not None:
                stats[int(name)] = st
    found: dict[int, Proc] = {}
    todo = [root]
    while todo:
        p = todo.pop()
        for c, fields in stats.items():
            if int(fields[1]) == p and c not in found and _alive(c):
                found[c] = Proc(int(fields[2]), _cmdline(c))
                todo.append(c)
    return found


def _nodes(kids: dict[int, Proc]) -> dict[int, Proc]:
    return {
        pid: p
        for pid, p in kids.items()
        if "bench" in p.cmd and ("plant" in p.cmd or "controller" in p.cmd)
    }


def _wait_for(pred: Callable[[], bool], timeout: float, proc: subprocess.Popen[str]) -> None:
    t0 = time.monotonic()
    while not pred():
        if proc.poll() is not None:
            _, err = proc.communicate()
            raise AssertionError(f"the command ended first ({proc.returncode}): {err[-2000:]}")
        if time.monotonic() - t0 > timeout:
            raise AssertionError("timed out")
        time.sleep(0.05)


def _start(args: list[str], *, own_group: bool = False) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "bench", *args],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=own_group,
    )


def _signal_and_time(
    proc: subprocess.Popen[str], send: Callable[[], None], second: signal.Signals | None = None
) -> tuple[float, dict[int, Proc], str]:
    """Send the signal(s); seconds until the command exited, its tree at the signal, stderr."""
    kids = tree(proc.pid)
    t0 = time.monotonic()
    send()
    if second is not None:
        time.sleep(0.3)  # the second signal while the first is being handled
        proc.send_signal(second)
    try:
        _, err = proc.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        proc.kill()
        _, err = proc.communicate()
        raise AssertionError(f"still running 30 s after the signal: {err[-2000:]}") from None
    took = time.monotonic() - t0
    print(f"ended {took:.2f} s after the signal (status {proc.returncode})")  # pytest -s
    return took, kids, err


def _left(kids: dict[int, Proc]) -> dict[int, Proc]:
    """The processes of ``kids`` still alive 0.5 s after the command ended.

    The half second is for the kernel and init: a process killed when its
    parent died is reaped by init, not at once.
    """
    time.sleep(0.5)
    return {pid: cmd for pid, cmd in kids.items() if _alive(pid)}


# ------------------------------------------------------------------- bench suite


def _suite(tmp: Path, *, own_group: bool = False) -> tuple[subprocess.Popen[str], Path]:
    """A suite of a short run (xue-fig13, 3 s at 1 kHz) and a long one (wen-5.1 held for
    120 s at 10 kHz, minutes of wall time) over udp_multicast on two workers: the short
    one finishes while the long one runs."""
    long = tmp / "long.toml"
    long.write_text('extends = "wen-5.1"\nname = "long"\nduration = 120.0\n')
    out = tmp / "out"
    proc = _start(
        ["suite", "paper", "--scenarios", f"xue-fig13,{long}", "--estimators", "sensored",
         "--plants", "ideal", "--no-sweep", "--interface", "udp_multicast", "-j", "2", "--out",
         str(out), "--runs-dir", str(tmp / "runs")],
        own_group=own_group,
    )  # fmt: skip
    done = out / "runs" / "xue-fig13" / "sensored" / "metrics.json"
    _wait_for(done.is_file, 240, proc)
    # the long run's nodes are up (in sessions of their own)
    _wait_for(lambda: len(_nodes(tree(proc.pid))) >= 2, 60, proc)
    return proc, out


def _check_suite_kept(out: Path) -> None:
    summary = json.loads((out / "summary.json").read_text())
    assert summary["suite"]["interrupted"] is True
    assert summary["suite"]["finished"]["runs_planned"] == 2
    runs = {(r["scenario"], r["estimator"]): r for r in summary["runs"]}
    # the finished run, with its numbers; the one cut short is not in the summary
    assert ("xue-fig13", "sensored") in runs and ("long", "sensored") not in runs
    xue = runs[("xue-fig13", "sensored")]
    assert "error" not in xue and xue["metrics"]["steps"] > 0
    kept = json.loads((out / "runs" / "xue-fig13" / "sensored" / "metrics.json").read_text())
    assert kept["steps"] == xue["metrics"]["steps"]
    report = (out / "report.md").read_text()
    assert "**Interrupted: 1 of 2 runs" in report


@pytest.mark.parametrize(
    ("first", "second"),
    [
        (signal.SIGINT, None),
        (signal.SIGTERM, None),
        (signal.SIGINT, signal.SIGINT),
        (signal.SIGTERM, signal.SIGINT),
    ],
    ids=["sigint", "sigterm", "sigint-twice", "sigterm-then-sigint"],
)
def test_suite_ends_on_a_signal_within_the_limit_and_keeps_what_finished(
    tmp_path: Path, first: signal.Signals, second: signal.Signals | None
) -> None:
    proc, out = _suite(tmp_path)
    took, kids, err = _signal_and_time(proc, lambda: proc.send_signal(first), second)
    assert proc.returncode == 130, err
    assert "Traceback" not in err, err
    assert took < LIMIT_S + MARGIN_S, f"{took:.2f} s"
    assert len(_nodes(kids)) >= 2, kids  # the test saw the nodes of the run under way
    assert _left(kids) == {}
    assert "1 of 2 runs" in err, err
    _check_suite_kept(out)


def test_suite_ended_through_its_process_group_leaves_no_node(tmp_path: Path) -> None:
    """``kill -- -PGID``: the signal reaches the suite and its workers, not the nodes
    (groups of their own); the suite ends them."""
    proc, out = _suite(tmp_path, own_group=True)
    took, kids, err = _signal_and_time(proc, lambda: os.killpg(proc.pid, signal.SIGTERM))
    assert proc.returncode == 130, err
    assert took < LIMIT_S + MARGIN_S, f"{took:.2f} s"
    nodes = _nodes(kids)
    # the nodes led groups of their own, which the signal to the command's group missed
    assert nodes and all(p.pgrp == pid != proc.pid for pid, p in nodes.items())
    assert _left(kids) == {}
    _check_suite_kept(out)


def test_suite_killed_outright_takes_its_tree_with_it(tmp_path: Path) -> None:
    """SIGKILL cannot be handled: the workers die with the suite and the nodes with
    their worker (PR_SET_PDEATHSIG); what finished before stays in --out."""
    proc, out = _suite(tmp_path)
    _, kids, _ = _signal_and_time(proc, proc.kill)
    assert proc.returncode == -signal.SIGKILL
    assert len(_nodes(kids)) >= 2
    assert _left(kids) == {}
    assert (out / "runs" / "xue-fig13" / "sensored" / "metrics.json").is_file()


# ------------------------------------------------------------------- bench sweep


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["sigint", "sigterm"])
def test_sweep_ends_on_a_signal_and_writes_the_finished_points(
    tmp_path: Path, sig: signal.Signals
) -> None:
    out = tmp_path / "sweep"
    seeds = ",".join(str(k) for k in range(1, 41))
    proc = _start(
        ["sweep", "xue-fig13", "-e", "square-wave", "--grid", f"seed={seeds}", "--duration",
         "0.6", "--workers", "2", "--out", str(out)]
    )  # fmt: skip
    log = out / "points.jsonl"
    _wait_for(lambda: log.is_file() and log.read_text().count("\n") >= 2, 120, proc)
    took, kids, err = _signal_and_time(proc, lambda: proc.send_signal(sig))
    assert proc.returncode == 130, err
    assert "Traceback" not in err, err
    assert took < LIMIT_S + MARGIN_S, f"{took:.2f} s"
    assert len(kids) >= 2, kids  # the two workers (and the multiprocessing helper)
    assert _left(kids) == {}
    finished = [json.loads(line) for line in log.read_text().splitlines()]
    assert 2 <= len(finished) < 40
    with (out / "results.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert sorted(r["seed"] for r in rows) == sorted(str(p["values"]["seed"]) for p in finished)
    summary = json.loads((out / "sweep.json").read_text())
    assert summary["interrupted"] is True and summary["finished"] == len(finished)
    assert summary["missing"] == 40 - len(finished)
    assert not (out / "plots").exists()


# ------------------------------------------------------------------- bench run


def test_run_killed_outright_takes_its_nodes_with_it(tmp_path: Path) -> None:
    """``bench run`` ended by SIGKILL (no handler runs): its nodes, in sessions of
    their own, die with it (PR_SET_PDEATHSIG) instead of running on."""
    from tests.ports import free_port

    out = tmp_path / "run"
    proc = _start(
        ["run", "wen-5.1", "-e", "sensored", "--interface", "udp_multicast", "--port",
         str(free_port()), "--out", str(out), "-q"]
    )  # fmt: skip
    _wait_for(lambda: len(_nodes(tree(proc.pid))) >= 2, 90, proc)
    _wait_for(lambda: (out / "plant.log").is_file(), 30, proc)
    _, kids, _ = _signal_and_time(proc, proc.kill)
    assert len(_nodes(kids)) == 2
    assert _left(kids) == {}


def test_suite_sweep_ends_on_a_signal_and_keeps_the_finished_points(tmp_path: Path) -> None:
    """``bench suite sweep``: the points (in-process, in the workers) that finished are in
    ``summary.json``; the others are not invented."""
    out = tmp_path / "out"
    err_file = tmp_path / "stderr.txt"
    with err_file.open("w") as err_fh:
        proc = subprocess.Popen(
            [sys.executable, "-m", "bench", "suite", "sweep", "--quick", "--sweeps", "speed",
             "-j", "2", "--out", str(out)],
            cwd=ROOT, stdout=subprocess.PIPE, stderr=err_fh, text=True,
        )  # fmt: skip
        _wait_for(lambda: "[2/9]" in err_file.read_text(), 240, proc)
        took, kids, _ = _signal_and_time(proc, lambda: proc.send_signal(signal.SIGINT))
    err = err_file.read_text()
    assert proc.returncode == 130, err
    assert "Traceback" not in err, err
    assert took < LIMIT_S + MARGIN_S, f"{took:.2f} s"
    assert len(kids) >= 2
    assert _left(kids) == {}
    summary = json.loads((out / "summary.json").read_text())
    fin = summary["suite"]["finished"]
    assert summary["suite"]["interrupted"] is True and fin["sweep_points_planned"] == 9
    assert 2 <= fin["sweep_points"] < 9
    methods = summary["sweeps"]["speed"]["methods"]
    assert sum(len(m["x"]) for m in methods.values()) == fin["sweep_points"]
    assert not (out / "sweeps").exists()  # no plots of a part
