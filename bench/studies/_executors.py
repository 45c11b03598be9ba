"""Where the points of a study run: local processes, or a Dask distributed cluster.

Both executors are existing engines, not a home-made scheduler:

- ``local``: :class:`concurrent.futures.ProcessPoolExecutor` with spawned
  processes on this machine (the default).  A worker process that dies
  breaks the pool; the points it had not finished are submitted again to a
  new pool (at most :data:`MAX_ATTEMPTS` times each), the finished ones are
  kept.
- ``dask``: :mod:`distributed` (``pip install 'can-hil-bench[dask]'``).  With a
  scheduler address (``tcp://HOST:8786``) the points go to the cluster
  started there with ``dask scheduler`` and ``dask worker`` (or
  dask-jobqueue, docs/SCALING.md); without one, to a local cluster of
  ``workers`` single-threaded worker processes.  The scheduler reruns the
  tasks of a worker that dies on another worker (``distributed.scheduler.
  allowed-failures`` times); a point that still fails is reported as not
  finished, so a resumed sweep runs it again.

Every result is handed to ``on_done`` the moment it arrives, in the parent
process, which writes it to disk: a point once finished is never lost,
whatever happens to the workers afterwards.

Signals.  A command that runs a study holds :func:`catch_signals` around
it: SIGINT or SIGTERM (a second one alike) sets a flag, and :func:`execute`
then stops at once, within :data:`STOP_POLL_S`: no further point starts, the
local worker processes are killed (:func:`end_workers`), the Dask
futures cancelled and a local Dask cluster's workers killed with no restart
(:func:`_end_dask`), the points under way are dropped (they run again on a
resume), and :func:`execute` returns with ``interrupted`` set, so the
command writes what finished and exits with status 130.  The local workers,
a local Dask cluster's included (:func:`dask_setup`), ignore SIGINT and
SIGTERM themselves (a Ctrl-C on the terminal reaches the whole process
group): the parent alone decides, so a worker never turns a signal into a
half-finished result.  Each worker dies with the parent
(``PR_SET_PDEATHSIG``, :func:`bench.runs._processes.die_with_parent`), and
the node processes of a run a worker started die with that worker, so no
process of the tree outlives the command, whatever ends it.
"""

from __future__ import annotations

import math
import multiprocessing as mp
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

from bench._errors import BenchError
from bench.runs._processes import die_with_parent

EXECUTORS = ("local", "dask")

#: How often a local point is submitted again after its worker died.
MAX_ATTEMPTS = 3

#: What a point whose worker died too often reports (not written: a resume reruns it).
LOST = "lost"

#: How often the parent looks at the signal flag while it waits for results (s).
#: The target: a study ends within 3 s of SIGINT/SIGTERM on a loaded 2-core machine.
#: Measured at a load of 11 to 15 (docs/SCALING.md): killing and reaping the workers
#: 0.1 to 0.2 s, the finished part's files milliseconds, Python's own exit (tearing
#: down numpy, matplotlib, scipy) 0.1 to 1.8 s; the wait for the flag is kept to a
#: tenth of a second.
STOP_POLL_S = 0.1
#: How long the parent waits for its killed workers to be reaped (s; SIGKILL cannot be held up).
REAP_S = 1.0

_STOP = threading.Event()


def interrupted() -> bool:
    """Whether SIGINT or SIGTERM came while :func:`catch_signals` was on."""
    return _STOP.is_set()


@contextmanager
def catch_signals() -> Iterator[None]:
    """SIGINT and SIGTERM set the stop flag (:func:`interrupted`) instead of raising.

    Held by the commands that run studies around their whole work, so that a
    signal, a second one included, can never cut short the ending of the
    workers or the writing of what finished; after a signal, the command's
    last steps ignore any further one.  Outside the main thread it does
    nothing (signals are delivered there only).
    """
    _STOP.clear()
    prev: dict[signal.Signals, Any] = {}

    def on_signal(signum: int, frame: Any) -> None:
        if not _STOP.is_set():
            print(
                f"bench: {signal.Signals(signum).name}: stopping, keeping what finished",
                file=sys.stderr,
                flush=True,
            )
        _STOP.set()

    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            prev[sig] = signal.signal(sig, on_signal)
    try:
        yield
    finally:
        if _STOP.is_set():
            # the command now ends with status 130: a further signal is ignored, also while
            # the interpreter shuts down (where Python's own handlers are gone and a
            # SIGINT would kill the process with no status of its own)
            for sig in prev:
                signal.signal(sig, signal.SIG_IGN)
        else:
            for sig, h in prev.items():
                signal.signal(sig, h)
        _STOP.clear()


def _worker_init(parent: int) -> None:
    """A local worker: the parent alone reacts to signals, and the worker dies with it."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    die_with_parent(parent)


def end_workers(procs: Sequence[Any]) -> None:
    """Kill the given worker processes (``multiprocessing`` processes) and reap them.

    SIGKILL, not SIGTERM: the points under way are dropped anyway, and their
    node processes die with them (``PR_SET_PDEATHSIG``).
    """
    for p in procs:
        if p.is_alive():
            p.kill()
    deadline = time.monotonic() + REAP_S
    for p in procs:
        p.join(max(0.0, deadline - time.monotonic()))


@dataclass(slots=True)
class RunInfo:
    """How a batch of points ran: executor, workers, wall time, points lost."""

    executor: str
    workers: int
    scheduler: str | None = None
    wall_s: float = 0.0
    done: int = 0
    lost: int = 0
    restarts: int = 0
    notes: list[str] = field(default_factory=list)
    #: SIGINT/SIGTERM stopped the batch: the points not handed to ``on_done`` did not run.
    interrupted: bool = False


class Bar:
    """Progress of a study on stderr: a rich progress bar with an ETA on a terminal,
    else one line per finished point with the elapsed and the estimated time left.

    The time left scales the elapsed time by the share of the work still to do
    (points weighted by ``cost``, e.g. simulated steps).
    """

    def __init__(self, total: float, n: int, title: str, *, enabled: bool = True) -> None:
        self.total = total
        self.n = n
        self.enabled = enabled
        self.done = 0
        self.done_cost = 0.0
        self.t0 = time.perf_counter()
        self.tty = sys.stderr.isatty()
        self._rich: Any = None
        if enabled and self.tty:
            from rich.console import Console
            from rich.progress import (
                BarColumn,
                MofNCompleteColumn,
                Progress,
                TextColumn,
                TimeElapsedColumn,
                TimeRemainingColumn,
            )

            self._rich = Progress(
                TextColumn("{task.description}"),
                BarColumn(),
                MofNCompleteColumn(),
                TextColumn("elapsed"),
                TimeElapsedColumn(),
                TextColumn("left"),
                TimeRemainingColumn(),
                console=Console(file=sys.stderr),
            )
            self._rich.start()
            self._task = self._rich.add_task(title, total=total)

    def advance(self, label: str, cost: float, ok: bool) -> None:
        self.done += 1
        self.done_cost += cost
        if not self.enabled:
            return
        if self._rich is not None:
            self._rich.update(self._task, advance=cost)
            return
        el = time.perf_counter() - self.t0
        left = el * (self.total - self.done_cost) / self.done_cost if self.done_cost else math.nan
        print(
            f"[{self.done}/{self.n}] {label} {'done' if ok else 'FAILED'}  "
            f"{_mmss(el)} elapsed, ~{_mmss(left)} left",
            file=sys.stderr,
            flush=True,
        )

    def close(self) -> None:
        if self._rich is not None:
            self._rich.stop()


def _mmss(s: float) -> str:
    if not math.isfinite(s):
        return "?"
    s = max(0.0, s)
    return f"{int(s // 60)}:{int(s % 60):02d}"


def noop(task: Any) -> dict[str, Any]:
    """A task that does nothing: what an executor costs per point, without the point."""
    return {"task": task}


def burn(n: int) -> dict[str, Any]:
    """A pure-Python busy loop of ``n`` additions: what one CPU gives a process."""
    t0 = time.perf_counter()
    x = 0
    for i in range(n):
        x += i
    return {"wall_s": time.perf_counter() - t0, "x": x}


def execute(
    tasks: Sequence[Any],
    fn: Callable[[Any], dict[str, Any]],
    on_done: Callable[[int, dict[str, Any]], None],
    *,
    executor: str = "local",
    workers: int = 2,
    scheduler: str | None = None,
) -> RunInfo:
    """Run ``fn(task)`` for every task; ``on_done(index, result)`` as each one finishes.

    ``fn`` must be a module-level function and the tasks picklable; ``fn``
    returns a dict (a failing point returns ``{"error": ...}`` itself).  A
    point whose workers died :data:`MAX_ATTEMPTS` times is passed to
    ``on_done`` as ``{"error": LOST, ...}``.
    """
    if executor not in EXECUTORS:
        raise BenchError(f"--executor: unknown executor {executor!r} (known: local, dask)")
    if workers < 1:
        raise BenchError(f"--workers must be >= 1, got {workers}")
    t0 = time.perf_counter()
    if executor == "dask":
        info = _dask(tasks, fn, on_done, workers, scheduler)
    else:
        if scheduler:
            raise BenchError("--scheduler needs --executor dask")
        info = _local(tasks, fn, on_done, workers)
    info.wall_s = time.perf_counter() - t0
    return info


def _local(
    tasks: Sequence[Any],
    fn: Callable[[Any], dict[str, Any]],
    on_done: Callable[[int, dict[str, Any]], None],
    workers: int,
) -> RunInfo:
    info = RunInfo("local", workers)
    todo = list(range(len(tasks)))
    attempts = [0] * len(tasks)
    while todo and not interrupted():
        ex = ProcessPoolExecutor(
            workers,
            mp_context=mp.get_context("spawn"),
            initializer=_worker_init,
            initargs=(os.getpid(),),
        )
        pending: dict[Future[dict[str, Any]], int] = {}
        queue = list(todo)
        todo = []
        broken = False
        try:
            while (queue or pending) and not interrupted():
                # keep at most two points per worker queued: a broken pool loses only those
                while queue and len(pending) < 2 * workers and not broken:
                    i = queue.pop(0)
                    attempts[i] += 1
                    pending[ex.submit(fn, tasks[i])] = i
                if not pending:
                    break
                done, _ = wait(pending, timeout=STOP_POLL_S, return_when=FIRST_COMPLETED)
                if interrupted():
                    break  # what came with the signal may be a run the signal cut short
                for f in done:
                    i = pending.pop(f)
                    try:
                        res = f.result()
                    except BrokenProcessPool:
                        broken = True
                        todo.append(i)
                        continue
                    info.done += 1
                    on_done(i, res)
        except BaseException:  # KeyboardInterrupt outside catch_signals, or a bug
            _end_pool(ex)
            raise
        if interrupted():
            info.interrupted = True
            _end_pool(ex)
        else:
            ex.shutdown(wait=True)
        if broken and not interrupted():
            info.restarts += 1
            todo += queue
            for i in [i for i in todo if attempts[i] >= MAX_ATTEMPTS]:
                todo.remove(i)
                info.lost += 1
                on_done(i, {"error": LOST, "why": "its worker process died", "wall_s": 0.0})
            if todo:
                info.notes.append(
                    f"a worker process died; {len(todo)} unfinished points resubmitted"
                )
    info.interrupted = info.interrupted or interrupted()
    return info


#: The longest an interrupted pool's manager thread is waited for (s): it ends within
#: milliseconds once its workers are killed; the bound is a sixth of the 3 s a suite's
#: stop is allowed (docs/SCALING.md).
MANAGER_JOIN_S = 0.5


def _end_pool(ex: ProcessPoolExecutor) -> None:
    """Kill a pool's worker processes (the points under way are dropped) and shut it down.

    ``shutdown(wait=True)`` would let the workers finish the points already
    handed to them first: minutes of runs after a Ctrl-C.
    """
    # the pool's own worker processes (``_processes``: pid -> Process, stable since Python 3.8)
    end_workers(list((getattr(ex, "_processes", None) or {}).values()))
    manager = getattr(ex, "_executor_manager_thread", None)
    ex.shutdown(wait=False, cancel_futures=True)
    # The pool's manager thread sees its workers gone, closes its wake-up pipe and ends.
    # Until it has ended, Python 3.11's exit hook (concurrent.futures.process._python_exit)
    # still holds that pipe and writes to it: "Exception ignored ... OSError: [Errno 9] Bad
    # file descriptor", a traceback on the way out of an interrupted run. With its workers
    # killed it ends within milliseconds; the bound only keeps a stuck one from holding
    # the stop.
    if manager is not None:
        manager.join(timeout=MANAGER_JOIN_S)
        del manager


def _dask(
    tasks: Sequence[Any],
    fn: Callable[[Any], dict[str, Any]],
    on_done: Callable[[int, dict[str, Any]], None],
    workers: int,
    scheduler: str | None,
) -> RunInfo:
    try:
        from distributed import Client, LocalCluster, as_completed
    except ImportError:
        raise BenchError(
            "--executor dask needs Dask distributed: pip install 'can-hil-bench[dask]'"
        ) from None
    import logging

    info = RunInfo("dask", workers, scheduler)
    logging.getLogger("distributed").setLevel(logging.ERROR)
    cluster: Any = None
    client: Any = None
    try:
        if scheduler:
            try:
                client = Client(scheduler, timeout="20s")
            except OSError as e:
                raise BenchError(f"--scheduler {scheduler}: cannot connect ({e})") from None
            except (TypeError, ValueError) as e:  # tls:// without Dask's TLS configuration
                raise BenchError(
                    f"--scheduler {scheduler}: cannot connect ({e}); a tls:// scheduler needs "
                    "Dask's TLS configuration: distributed.comm.tls.ca-file, client.cert and "
                    "client.key (docs/SCALING.md)"
                ) from None
            info.workers = len(client.scheduler_info().get("workers", {}))
        else:
            cluster = LocalCluster(
                n_workers=workers,
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
                silence_logs=logging.ERROR,
                preload=[__name__],  # dask_setup: the workers leave signals to this process
            )
            client = Client(cluster)
        futs = [
            client.submit(fn, t, pure=False, key=f"point-{i}-{os.getpid()}")
            for i, t in enumerate(tasks)
        ]
        index = {f.key: i for i, f in enumerate(futs)}
        ac = as_completed(futs)
        while not ac.is_empty() and not interrupted():
            batch = ac.next_batch(block=False)
            if not batch:
                time.sleep(STOP_POLL_S)  # the signal flag is looked at between batches
                continue
            for fut in batch:
                i = index[fut.key]
                if fut.status == "finished":
                    info.done += 1
                    on_done(i, fut.result())
                else:  # KilledWorker after the scheduler's retries, or a lost connection
                    exc = fut.exception()
                    info.lost += 1
                    why = f"{type(exc).__name__}: {exc}"
                    on_done(i, {"error": LOST, "why": why, "wall_s": 0.0})
                fut.release()
        if interrupted():
            info.interrupted = True
            client.cancel([f for f in futs if not f.done()])
    except BaseException:
        _end_dask(client, cluster)
        raise
    if interrupted():
        _end_dask(client, cluster)
    else:
        client.close()
        if cluster is not None:
            cluster.close()
    return info


#: How long an interrupted study waits for Dask to close its client and local cluster (s).
#: With the nannies told not to restart (:func:`_end_dask`) and their worker processes
#: killed, closing is a few messages over loopback: milliseconds on an idle machine,
#: a fraction of a second at a load of 10 on two cores.  Past this bound what is left
#: (the scheduler's comms) is abandoned: the cluster is marked closed, so that Dask's
#: exit hook does not wait for it again (10 s), and its processes are killed.
DASK_CLOSE_S = 1.0


def dask_setup(worker: Any) -> None:
    """A local cluster's worker process (Dask preload, :func:`_dask`): the parent alone
    reacts to SIGINT and SIGTERM, as a local worker does (:func:`_worker_init`).

    A Ctrl-C on the terminal reaches the whole process group; a Dask worker
    would otherwise die of it with a traceback, and its nanny (in the parent)
    would start a new one while the command is stopping.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)


def _end_dask(client: Any, cluster: Any) -> None:
    """End a Dask batch at once: a local cluster's nannies told not to restart their
    workers, the worker processes killed, the client and the cluster closed within
    :data:`DASK_CLOSE_S` each, whatever is left killed.

    A nanny restarts a worker process that dies, unless it is closing: killed
    without that, each worker was started again while the cluster closed, and
    the close waited for the new processes (seconds, then 10 s more in Dask's
    exit hook), with the restarts' cancellation tracebacks on stderr.  A
    remote cluster's workers are not this machine's: the futures are
    cancelled and the client closed.
    """
    if cluster is not None:
        for nanny in list(getattr(cluster, "workers", {}).values()):
            close_gracefully = getattr(nanny, "close_gracefully", None)
            if close_gracefully is not None:  # a Nanny (processes=True): no restart
                close_gracefully(reason="bench: interrupted")
        end_workers(mp.active_children())  # the local cluster's processes are this one's
    for part in (client, cluster):
        if part is None:
            continue
        try:
            part.close(timeout=DASK_CLOSE_S)
        except Exception:  # a timeout or a closed comm: what is left is killed below
            pass
    if cluster is not None:
        if getattr(cluster, "status", None) is not None and cluster.status.name != "closed":
            from distributed.core import Status

            cluster.status = Status.closed  # Dask's exit hook would wait 10 s for it again
        end_workers(mp.active_children())
