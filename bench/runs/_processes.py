"""The node processes of a run: command lines, start-up handshake, and how they end.

``bench run`` starts ``bench plant``, ``bench controller`` and, when latency
is injected, ``bench link`` as OS processes, each on the run's plan
(``plan.json``, :mod:`bench.nodes._plan`), with its stderr in ``ROLE.log``
and its counters in ``ROLE.json`` of the run folder.  The nodes start
together (their imports and set-up overlap) and the run goes on once each
has printed ``READY``: none sends a frame before the run's start command.

Each node runs in a session (process group) of its own, so that a Ctrl-C
on the terminal reaches ``bench run`` alone, which stops the nodes in order
and scores what was recorded.  The price is that a signal to the run's
process group, or the death of the process that started the nodes, no
longer reaches them.  The process that starts a node is therefore the one
responsible for ending it: while alive it stops its nodes itself
(:func:`stop_nodes`; ``bench run`` on SIGINT/SIGTERM), and on Linux each node
is started with ``PR_SET_PDEATHSIG`` = SIGKILL (:func:`die_with_parent`), so
the kernel ends it when that process dies by any means (SIGKILL, a crash, a
suite that ends its worker processes on Ctrl-C) instead of leaving it
orphaned on the bus.
"""

from __future__ import annotations

import ctypes
import functools
import os
import select
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from bench._errors import BenchError
from bench.nodes._plan import RunPlan

#: ``prctl`` option that sets the signal a process gets when its parent dies (linux/prctl.h).
PR_SET_PDEATHSIG = 1


@functools.cache
def _prctl() -> Any:
    """libc's ``prctl``, resolved once in the parent (None off Linux or without libc)."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        return ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return None


def die_with_parent(parent: int, sig: int = signal.SIGKILL) -> None:
    """End this process with ``sig`` when the thread that started it ends (Linux only).

    ``PR_SET_PDEATHSIG``: the kernel sends ``sig`` when the parent *thread*
    that forked this process exits, so it must be called in a child whose
    parent started it from a thread that lives as long as the child should
    (the main thread of ``bench run`` and of a suite's worker processes).
    The signal is SIGKILL: once the parent is gone, nobody reads what the
    child would still write, and SIGKILL cannot be held up by a busy loop
    or a blocked handler.  A parent that died before the call (``parent`` is
    no longer the parent) ends this process at once.  Safe between fork and
    exec (``preexec_fn``): it calls only the ``prctl`` resolved beforehand.
    """
    prctl = _prctl()
    if prctl is None:
        return
    prctl(PR_SET_PDEATHSIG, int(sig), 0, 0, 0)
    if os.getppid() != parent:
        os._exit(1)


def _wait_ready(
    proc: subprocess.Popen[str],
    role: str,
    log: Path,
    timeout: float = 60.0,
    stop: Any = lambda: False,
) -> None:
    """Wait for the node's READY line; return early when ``stop()`` (a signal came)."""
    assert proc.stdout is not None
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        if stop():
            return
        if not select.select([proc.stdout], [], [], 0.1)[0] and proc.poll() is None:
            continue
        line = proc.stdout.readline()
        if line.strip() == "READY":
            return
        if line == "" and proc.poll() is not None:
            how = how_ended(log.parent, role, proc.returncode)
            raise BenchError(f"{role} process exited before it was ready ({how})")
    raise BenchError(f"{role} process not ready after {timeout:.0f} s")


def ended_early(
    procs: list[tuple[str, subprocess.Popen[str]]], *, lockstep: bool = False
) -> str | None:
    """The role whose process ended while the plant still runs, else ``None``.

    The link is the bench's own infrastructure and never ends by itself during
    a run; without it the plant would only wait for its watchdog.  In real
    time a node that dies (the controller) is left to the plant, as a drive
    would be: the plant's watchdog and safe state are what such a run tests.
    In lockstep the plant cannot take another period without the controller,
    so its end ends the run at once (rather than after the plant's stall
    timeout), named with how it ended (:func:`how_ended`).
    """
    for role, p in procs:
        if role == "plant" or p.poll() is None:
            continue
        if role == "link" or (lockstep and p.returncode != 0):
            return role  # (a controller ends by itself, status 0, at the stop command)
    return None


def how_ended(out_dir: Path, role: str, returncode: int | None) -> str:
    """How a node process ended: the signal that killed it, or its status and last log line."""
    if returncode is not None and returncode < 0:
        try:
            name = signal.Signals(-returncode).name
        except ValueError:
            name = f"signal {-returncode}"
        return f"killed by {name}"
    line = last_line(out_dir, role)
    if returncode is None:
        return line
    return f"exit status {returncode}: {line}" if returncode else line


def last_line(out_dir: Path, role: str) -> str:
    """The last line a node process wrote to its log (empty if none)."""
    f = out_dir / f"{role}.log"
    lines = f.read_text(errors="replace").strip().splitlines() if f.exists() else []
    return lines[-1] if lines else "no output"


def node_roles(
    plan: RunPlan, node_args: dict[str, list[str]] | None
) -> list[tuple[str, list[str]]]:
    """The processes of a run in start order: (role, its options besides the plan).

    The link (when latency is injected) starts first, then the controller
    (none when the plan has none: a controller under test), then the plant,
    which keeps the clock.  ``node_args`` adds options per role: how a node
    serves the plan (``--engine``, ``--rt-priority``, ...), never the run's
    settings, which are the plan's alone.
    """
    extra = node_args or {}
    roles: list[tuple[str, list[str]]] = []
    if plan.link is not None:
        roles.append(("link", list(extra.get("link", []))))
    if plan.controller is not None:
        roles.append(("controller", list(extra.get("controller", []))))
    roles.append(("plant", list(extra.get("plant", []))))
    return roles


def start_nodes(
    roles: list[tuple[str, list[str]]],
    plan_file: Path,
    out_dir: Path,
    env: dict[str, str],
    procs: list[tuple[str, subprocess.Popen[str]]],
    *,
    stop: Any,
) -> None:
    """Start each role's process on the run's plan, all at once, and wait for every
    ``READY``; appended to ``procs`` as started.

    Every node reads ``plan_file`` (``bench ROLE --plan FILE``) and nothing else of
    the run; the plant and the controller write their report to ``ROLE.json``.
    The nodes are started together: each spends its start-up (imports, the
    controller's design, opening the bus) before its ``READY``, and none sends
    before the run's start command, so their order matters only in which
    failure is named first (the link, the controller, the plant).
    ``procs`` is filled in place so that the caller can kill what was started
    when a node fails to start.  ``stop()`` (a signal came) ends the start-up early.
    """
    started: list[tuple[str, subprocess.Popen[str]]] = []
    for role, extra in roles:
        if stop():
            return
        log = out_dir / f"{role}.log"
        cmd = [sys.executable, "-m", "bench", role, "--plan", str(plan_file), *extra]
        if role != "link":
            cmd += ["--report", str(out_dir / f"{role}.json")]
        _prctl()  # resolved here, not between fork and exec
        p = subprocess.Popen(
            cmd,
            stdout=subprocess.PIPE,
            stderr=log.open("w"),
            text=True,
            env=env,
            start_new_session=True,
            # its own session, and ended by the kernel if this process dies (module docstring)
            preexec_fn=functools.partial(die_with_parent, os.getpid()),
        )
        procs.append((role, p))
        started.append((role, p))
    for role, p in started:
        _wait_ready(p, role, out_dir / f"{role}.log", stop=stop)


def stop_nodes(
    procs: list[tuple[str, subprocess.Popen[str]]],
    bus: Any,
    cmds: list[tuple[int, Any]],
    *,
    link: bool,
    interrupted: bool,
    ended: str | None,
) -> set[str]:
    """End the node processes: a normal end waits for them, an interrupted one does not.

    Returns the roles this sent SIGTERM to: a node that ends on that signal
    (status -SIGTERM, when it came as the process was already shutting down
    and its own handler could no longer run) was asked to stop, it did not fail.

    The stop command is in the schedule; it is sent once more to be sure.
    With latency the controller never sees the last sample, so the nodes
    that do not end by themselves get SIGTERM (they stop cleanly on it).
    Interrupted (SIGINT/SIGTERM) or a node ended early: no waiting, every
    node gets SIGTERM at once, and is killed if it does not end in time.
    """
    roles = dict(procs)
    asked: set[str] = set()
    plant = roles.get("plant")
    if plant is not None and not interrupted and not ended and cmds:
        bus.send(cmds[-1][1])
        try:
            plant.wait(timeout=30.0)
        except subprocess.TimeoutExpired:
            plant.send_signal(signal.SIGTERM)
            asked.add("plant")
        ctrl = roles.get("controller")
        if ctrl is not None and not link:
            # it stops by itself at the stop command's step
            try:
                ctrl.wait(timeout=10.0)
            except subprocess.TimeoutExpired:
                pass
        if any(p.poll() is None for _, p in procs):
            # a node still running (the link, a controller behind it) answers the last frames
            time.sleep(0.2)
    for role, p in procs:
        if p.poll() is None:
            p.send_signal(signal.SIGTERM)
            asked.add(role)
    deadline = time.monotonic() + (2.0 if interrupted else 10.0)
    for _, p in procs:
        try:
            p.wait(timeout=max(0.1, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()
    return asked


def node_failures(
    procs: list[tuple[str, subprocess.Popen[str]]], asked: set[str]
) -> dict[str, int]:
    """The roles whose process failed, with their exit status.

    A process that ended with -SIGTERM after :func:`stop_nodes` asked it to
    stop (``asked``) did not fail; any other non-zero status is a failure.
    """
    return {
        role: p.returncode
        for role, p in procs
        if p.returncode not in (0, None) and not (role in asked and p.returncode == -signal.SIGTERM)
    }
