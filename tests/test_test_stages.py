"""tools/test-stages ends both stages whole on INT or TERM: every process under each
stage, also one in a process group of its own (as ``timeout`` puts linux.uml), is gone
when it exits, and its status says which signal ended it.

The stages are a fake ``make`` (``MAKE``): each starts a child that sleeps in a process
group of its own and one that sleeps in the stage's, writes their pids and waits, as
``make vcan`` waits on User-Mode Linux.  The script runs from a copy in a folder of the
test's own (it works in its parent folder: ``.vcan/stage.log``)."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

FAKE_MAKE = """#!/usr/bin/env bash
# $1 is --no-print-directory, $2 the stage
"{python}" -c 'import os, time; os.setpgid(0, 0); time.sleep(600)' &
echo $! >>"{dir}/$2.pids"
sleep 600 &
echo $! >>"{dir}/$2.pids"
wait
"""


def _alive(pid: int) -> bool:
    """A process that exists and is not a zombie (an ended child not yet reaped)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except FileNotFoundError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


def _pids(d: Path, stage: str) -> list[int]:
    f = d / f"{stage}.pids"
    return [int(x) for x in f.read_text().split()] if f.is_file() else []


def _default_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.mark.skipif(shutil.which("setsid") is None, reason="needs setsid (util-linux)")
@pytest.mark.parametrize(("sig", "status"), [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
@pytest.mark.timeout(120)
def test_a_signal_ends_every_process_of_both_stages(
    tmp_path: Path, sig: signal.Signals, status: int
) -> None:
    (tmp_path / "tools").mkdir()
    script = tmp_path / "tools" / "test-stages"
    shutil.copy(ROOT / "tools" / "test-stages", script)
    make = tmp_path / "fake-make"
    make.write_text(FAKE_MAKE.format(python=sys.executable, dir=tmp_path))
    make.chmod(0o755)
    env = dict(os.environ, MAKE=str(make), STOP_GRACE_S="10")
    # SIGINT as a terminal's Ctrl-C finds it: this test may itself run under
    # tools/test-stages (make test), whose stages bash starts with SIGINT ignored, and a
    # shell cannot trap a signal that was ignored when it started
    p = subprocess.Popen([str(script)], env=env, stdout=subprocess.PIPE,
                         stderr=subprocess.STDOUT, text=True,
                         preexec_fn=_default_sigint)  # fmt: skip
    pids: list[int] = []
    try:
        t_end = time.monotonic() + 60
        while time.monotonic() < t_end:
            pids = _pids(tmp_path, "unit") + _pids(tmp_path, "vcan")
            if len(pids) == 4:
                break
            time.sleep(0.05)
        assert len(pids) == 4, p.communicate()[0] if p.poll() is not None else pids
        # each stage in a session of its own, away from the script's
        sessions = {os.getsid(pid) for pid in pids}
        assert len(sessions) == 2 and os.getsid(p.pid) not in sessions
        p.send_signal(sig)
        out, _ = p.communicate(timeout=60)
        assert p.returncode == status, out
        assert "interrupted; ending both stages" in out
        t_end = time.monotonic() + 10  # the kernel's reparenting and reaping
        while any(_alive(pid) for pid in pids) and time.monotonic() < t_end:
            time.sleep(0.05)
        assert not [pid for pid in pids if _alive(pid)]
    finally:
        for pid in pids:
            if _alive(pid):
                os.kill(pid, signal.SIGKILL)
        if p.poll() is None:
            p.kill()
            p.wait()


@pytest.mark.timeout(60)
def test_both_stages_status_when_they_end_by_themselves(tmp_path: Path) -> None:
    (tmp_path / "tools").mkdir()
    script = tmp_path / "tools" / "test-stages"
    shutil.copy(ROOT / "tools" / "test-stages", script)
    make = tmp_path / "fake-make"
    make.write_text('#!/bin/sh\necho "stage $2"\n[ "$2" = unit ] && exit 0\nexit 5\n')
    make.chmod(0o755)
    p = subprocess.run([str(script)], env=dict(os.environ, MAKE=str(make)),
                       capture_output=True, text=True, timeout=50)  # fmt: skip
    assert p.returncode == 5, p.stdout + p.stderr
    assert "stage unit" in p.stdout
    assert "---- SocketCAN stage" in p.stdout and "stage vcan" in p.stdout
    assert "unit stage exit 0, SocketCAN stage exit 5" in p.stdout
