"""A node that bench run asks to stop and that ends on that SIGTERM did not fail."""

from __future__ import annotations

import subprocess
import sys

from bench.runs._processes import node_failures, stop_nodes


def sleeper() -> subprocess.Popen[str]:
    # no handler of its own: SIGTERM ends it with -15, as one in its final
    # shutdown (its handler gone) does
    return subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"], text=True)


def test_a_node_ended_by_the_benchs_sigterm_is_not_a_failure() -> None:
    procs = [("link", sleeper()), ("controller", sleeper())]
    asked = stop_nodes(procs, bus=None, cmds=[], link=True, interrupted=True, ended=None)
    assert asked == {"link", "controller"}
    assert all(p.returncode == -15 for _, p in procs)
    assert node_failures(procs, asked) == {}


def test_a_node_that_died_by_itself_is_a_failure() -> None:
    bad = subprocess.Popen([sys.executable, "-c", "raise SystemExit(3)"], text=True)
    bad.wait()
    killed = sleeper()
    killed.kill()
    killed.wait()
    procs = [("plant", bad), ("controller", killed)]
    asked = stop_nodes(procs, bus=None, cmds=[], link=False, interrupted=True, ended=None)
    assert asked == set()
    assert node_failures(procs, asked) == {"plant": 3, "controller": -9}
    # -15 that bench run did not send is a failure too
    term = sleeper()
    term.terminate()
    term.wait()
    assert node_failures([("controller", term)], set()) == {"controller": -15}
