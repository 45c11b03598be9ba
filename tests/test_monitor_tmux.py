"""The monitor in a real terminal: tmux runs it, the test types keys and reads the screen.

Each test starts ``python -m bench.cli.monitor`` (the code of ``bench monitor``)
in a detached tmux session of fixed size, on a udp_multicast port of its own,
sends frames of a known run (:mod:`tests.monitor_helpers`) from a thread,
and polls ``tmux capture-pane`` until the screen shows what it must, with a
deadline (a loaded machine is slow, never wrong). Without tmux the tests
skip, except in CI (``CI`` set), where they fail: ``make test`` installs it.
"""

from __future__ import annotations

import itertools
import os
import re
import shlex
import shutil
import subprocess
import sys
import textwrap
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import can
import pytest

from bench.wire._bus import BusSpec, udp_multicast_group
from bench.wire._codec import Codec
from tests import monitor_helpers as known
from tests.ports import free_port

ROOT = Path(__file__).resolve().parents[1]
DEADLINE_S = 30.0
_N = itertools.count()


class Tmux:
    """One private tmux server (``-L``) with one session ``t`` of fixed size."""

    def __init__(self, exe: str) -> None:
        self.exe = exe
        self.socket = f"bench-monitor-test-{os.getpid()}-{next(_N)}"

    def __call__(self, *args: str) -> str:
        env = {k: v for k, v in os.environ.items() if k not in ("COLUMNS", "LINES", "TMUX")}
        out = subprocess.run(
            [self.exe, "-L", self.socket, "-f", "/dev/null", *args],
            capture_output=True,
            text=True,
            timeout=30,
            env=env,
        )
        if out.returncode != 0:
            raise AssertionError(f"tmux {' '.join(args)}: {out.stderr.strip()}")
        return out.stdout

    def start(self, command: str, width: int = 150, height: int = 45) -> None:
        shell = (
            f"cd {shlex.quote(str(ROOT))} && {command}; echo monitor exit status $?; exec sleep 600"
        )
        self("new-session", "-d", "-s", "t", "-x", str(width), "-y", str(height), shell)

    def screen(self) -> str:
        return self("capture-pane", "-p", "-t", "t")

    def alternate_on(self) -> bool:
        return self("display-message", "-p", "-t", "t", "#{alternate_on}").strip() == "1"

    def keys(self, *keys: str) -> None:
        self("send-keys", "-t", "t", *keys)

    def wait_for(self, *patterns: str, timeout: float = DEADLINE_S) -> str:
        """The screen once every regular expression matches it (else fail with the screen)."""
        deadline = time.monotonic() + timeout
        screen = ""
        while time.monotonic() < deadline:
            screen = self.screen()
            if all(re.search(p, screen) for p in patterns):
                return screen
            time.sleep(0.2)
        missing = [p for p in patterns if not re.search(p, screen)]
        raise AssertionError(f"screen never showed {missing}; last screen:\n{screen}")

    def wait_until(self, what: str, ok: Callable[[], bool], timeout: float = DEADLINE_S) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if ok():
                return
            time.sleep(0.2)
        raise AssertionError(f"{what}: not within {timeout:.0f} s; screen:\n{self.screen()}")

    def kill(self) -> None:
        """End the server; the next :meth:`start` makes a new one (a new socket)."""
        subprocess.run(
            [self.exe, "-L", self.socket, "kill-server"], capture_output=True, timeout=30
        )
        tmp = Path(os.environ.get("TMUX_TMPDIR") or "/tmp") / f"tmux-{os.getuid()}"
        (tmp / self.socket).unlink(missing_ok=True)
        self.socket = f"bench-monitor-test-{os.getpid()}-{next(_N)}"


@pytest.fixture
def tmux() -> Iterator[Tmux]:
    exe = shutil.which("tmux")
    if exe is None:
        if os.environ.get("CI"):
            pytest.fail("tmux is not installed: make test installs it (apt-get, as root)")
        pytest.skip("tmux is not installed (apt-get install tmux)")
    t = Tmux(exe)
    try:
        yield t
    finally:
        t.kill()


class Sender:
    """Sends frames on a udp_multicast port from a thread, at a steady rate, until stopped."""

    def __init__(self, port: int, frames: Callable[[int], list[can.Message]], rate_hz: float):
        self.bus = BusSpec("udp_multicast", udp_multicast_group(), port).open()
        self.frames = frames
        self.rate_hz = rate_hz
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        t0 = time.perf_counter()
        k = 0
        while not self._stop.is_set():
            for m in self.frames(k):
                self.bus.send(m)
            k += 1
            wait = t0 + k / self.rate_hz - time.perf_counter()
            if wait > 0:
                self._stop.wait(wait)

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(10.0)
        self.bus.shutdown()


def _monitor(port: int, *extra: str) -> str:
    args = [
        sys.executable, "-m", "bench.cli.monitor", "-i", "udp_multicast",
        "-c", udp_multicast_group(), "--port", str(port), *extra,
    ]  # fmt: skip
    return " ".join(shlex.quote(a) for a in args)


def test_screen_of_a_known_run_then_stopped_then_quit(tmux: Tmux) -> None:
    codec = Codec()
    port = free_port()
    tmux.start(_monitor(port, "--pole-pairs", str(known.N_P)))
    tmux.wait_for(r"no bench frames on the bus: nothing received")
    assert tmux.alternate_on()

    foreign = Sender(port, lambda k: [known.foreign_frame(0x123)], 50.0)
    try:
        tmux.wait_for(r"no bench frames on the bus: only foreign IDs \(0x123")
    finally:
        foreign.stop()

    bench = Sender(port, lambda k: known.period_frames(codec, k), 500.0)
    try:
        screen = tmux.wait_for(
            r"live: ",
            r"plant\s+running\s+fault none",
            r"ctrl mode\s+run",
            r"speed ref\s+150\.0 rpm",
            r"speed\s+150\.0\s+est 150\.0 rpm",
            r"pos\. error \+3\.0 deg el\.",
            r"i_abc\s+\+1\.25 -0\.50 -0\.75 A",
            r"duties\s+0\.500 0\.250 0\.750 on",
            r"torque\s+1\.60\s+load 1\.50 N m",
            r"overruns\s+7 ",
            r"late duties\s+3 ",
            r"PhaseSamples\s+\d+\s+\d+\.\d%",
            r"(?m)rejected by the monitor *\n.*│ +none *$",
        )
        assert "Traceback" not in screen
        # keys: zoom in and out, pause and resume, reset the statistics
        tmux.keys("+")
        tmux.wait_for(r"window 1 s")
        tmux.keys("o", "o")
        tmux.wait_for(r"window 5 s")
        tmux.keys("Space")
        tmux.wait_for(r"PAUSED \(space to resume\)", r"window 5 s +PAUSED")
        tmux.keys("p")
        tmux.wait_until("view resumed", lambda: "PAUSED" not in tmux.screen())
        tmux.keys("r")
        tmux.wait_for(r"overruns\s+0 ", r"late duties\s+0 ")  # the plant's, since the reset
        # resize: the layout follows the new width
        tmux("resize-window", "-t", "t", "-x", "100", "-y", "36")

        def fits() -> bool:
            lines = tmux.screen().splitlines()
            tops = [ln for ln in lines if "┌" in ln]
            return bool(tops) and max(len(ln.rstrip()) for ln in tops) in range(90, 101)

        tmux.wait_until("plots laid out again for 100 columns", fits)
        tmux.wait_for(r"live: ", r"pos\. error \+3\.0 deg el\.")
    finally:
        bench.stop()
    tmux.wait_for(r"stopped: no bench frames for")

    tmux.keys("q")
    screen = tmux.wait_for(r"monitor exit status 0")
    assert not tmux.alternate_on()
    assert "late periods" not in screen  # the view went with the alternate screen


def test_ctrl_c_leaves_the_terminal_clean_with_status_130(tmux: Tmux) -> None:
    tmux.start(_monitor(free_port()), width=120, height=40)
    tmux.wait_for(r"no bench frames on the bus")
    tmux.keys("C-c")
    screen = tmux.wait_for(r"monitor exit status 130")
    assert not tmux.alternate_on()
    assert "no bench frames" not in screen


def test_run_monitor_closes_on_stop_and_passes_ctrl_c_on(tmux: Tmux, tmp_path: Path) -> None:
    """The function ``bench run --monitor`` calls: the view in a child process."""
    flag = tmp_path / "stop"
    script = tmp_path / "run.py"
    script.write_text(
        textwrap.dedent(
            f"""
            import sys, threading, time
            from pathlib import Path
            from bench.wire._bus import udp_multicast_group
            from bench.wire._bus import BusSpec
            from bench.monitor import run_monitor

            spec = BusSpec("udp_multicast", udp_multicast_group(), {free_port()})
            stop = threading.Event()
            def watch():
                while not Path({str(flag)!r}).exists():
                    time.sleep(0.05)
                stop.set()
            threading.Thread(target=watch, daemon=True).start()
            try:
                rc = run_monitor(spec, None, stop, "a test run")
                print("run_monitor returned", rc)
                time.sleep(5)  # Ctrl-C arrives as SIGINT just after the view returned
            except KeyboardInterrupt:
                print("run interrupted")
            """
        )
    )
    command = f"{shlex.quote(sys.executable)} {shlex.quote(str(script))}"
    tmux.start(command, width=120, height=40)
    tmux.wait_for(r"bench monitor .* a test run", r"no bench frames on the bus")
    flag.touch()
    tmux.wait_for(r"run_monitor returned 0", r"monitor exit status 0")
    assert not tmux.alternate_on()
    # Ctrl-C in the view interrupts the run, as Ctrl-C does without the view
    tmux.kill()
    flag.unlink()
    tmux.start(command, width=120, height=40)
    tmux.wait_for(r"no bench frames on the bus")
    tmux.keys("C-c")
    tmux.wait_for(r"run interrupted")
    assert not tmux.alternate_on()
