"""Real-time settings of a node process: scheduling class, memory lock, CPU, GC.

What an RT-LAB or dSPACE target gives its model by construction, a Linux
process has to ask for:

- ``SCHED_FIFO`` at a priority (``--rt-priority N``, 1-99): the node runs
  before every normal process as soon as it is runnable, so a busy recorder
  or compiler cannot delay its deadline.  Needs root or ``CAP_SYS_NICE``
  (or an ``rtprio`` limit); the kernel's real-time throttling
  (``/proc/sys/kernel/sched_rt_runtime_us``, 95 % by default) still leaves
  the rest of the machine some time if the node spins.
- ``mlockall``: no page fault in the loop (needs ``CAP_IPC_LOCK`` or a large
  enough ``memlock`` limit).
- a CPU (``--cpu N``): keeps the node on one core and its caches warm.
- Python's cyclic garbage collector is switched off for the loop (always in
  real-time mode): a full collection takes milliseconds and would be a
  deadline miss.  The loops allocate only acyclic objects (frames, tuples),
  which reference counting frees at once; everything built before the loop
  is frozen out of the collector, and it is switched on again afterwards.

A setting the system refuses is not fatal: the node prints one line saying
what was refused and why, runs with what it got, and the node's report
(``plant.json`` / ``controller.json``, key ``rt``) records what was granted,
so a figure is never read as if it came from a real-time setting it did not
have.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import gc
import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

#: ``mlockall`` flags (Linux, <sys/mman.h>).
MCL_CURRENT = 1
MCL_FUTURE = 2


@dataclass
class RtSettings:
    """What a node asked for (``priority``, ``cpu``) and what it got."""

    priority: int | None = None
    cpu: int | None = None
    policy: str = "normal"
    memory_locked: bool = False
    cpus: list[int] = field(default_factory=list)
    refused: list[str] = field(default_factory=list)

    def as_dict(self) -> dict[str, object]:
        return {
            "policy": self.policy,
            "priority": self.priority if self.policy == "fifo" else None,
            "memory_locked": self.memory_locked,
            "cpus": self.cpus,
            "refused": self.refused,
        }


def _mlockall() -> str | None:
    """Lock the process's memory; None on success, else the reason."""
    name = ctypes.util.find_library("c")
    if name is None:
        return "no C library found"
    libc = ctypes.CDLL(name, use_errno=True)
    if libc.mlockall(MCL_CURRENT | MCL_FUTURE) != 0:
        return os.strerror(ctypes.get_errno())
    return None


def apply_rt(priority: int | None, cpu: int | None, *, role: str) -> RtSettings:
    """Ask the system for ``SCHED_FIFO`` at ``priority``, locked memory and ``cpu``.

    ``priority`` None leaves the scheduling class alone; ``cpu`` None leaves
    the affinity alone.  Refusals are printed (one line each, on stderr) and
    recorded, never raised.
    """
    rt = RtSettings(priority=priority, cpu=cpu)
    if cpu is not None:
        try:
            os.sched_setaffinity(0, {cpu})
        except (OSError, ValueError) as e:
            rt.refused.append(f"cpu {cpu}: {e.strerror if isinstance(e, OSError) else e}")
    if priority is not None:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
            rt.policy = "fifo"
        except (OSError, AttributeError) as e:
            reason = e.strerror if isinstance(e, OSError) else "not supported here"
            rt.refused.append(f"SCHED_FIFO priority {priority}: {reason}")
        why = _mlockall()
        if why is None:
            rt.memory_locked = True
        else:
            rt.refused.append(f"mlockall: {why}")
    try:
        rt.cpus = sorted(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        rt.cpus = []
    for r in rt.refused:
        print(f"{role}: real-time setting refused, running without it: {r}", file=sys.stderr)
    return rt


@contextmanager
def no_gc(active: bool = True) -> Iterator[None]:
    """Run the block with the cyclic garbage collector off (objects so far frozen).

    ``active`` False makes it a no-op (lockstep runs keep the collector).
    """
    if not active:
        yield
        return
    was = gc.isenabled()
    gc.collect()
    gc.freeze()
    gc.disable()
    try:
        yield
    finally:
        gc.unfreeze()
        if was:
            gc.enable()
