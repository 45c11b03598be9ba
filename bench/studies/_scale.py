"""Throughput of the sweep's executors: the same points on 1 and 2 local workers and on a
local Dask cluster of 2 workers (``bench sweep ... --scale``).

Each configuration runs the whole plan from scratch into a folder of its own
(``OUT/scale-local-1`` ...).  Figures per configuration: points per second
over the wall time (start of the workers included), the mean time a point
computes inside its worker, and the per-point overhead ``workers * wall / n
- compute`` (worker-seconds spent per point beyond the point itself: start
of the pool or cluster, pickling, scheduling, idle tails).  The speed-up is
the points per second over those of one local worker.  The machine's load
from other work is recorded beside (``os.getloadavg``), since the figures
depend on it.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from bench.studies._executors import burn, execute, noop
from bench.studies._grid import Plan, run_sweep

#: No-op tasks per executor for the dispatch overhead.
N_NOOP = 200

#: (name, executor, workers) of the configurations compared.
CONFIGS = (("local-1", "local", 1), ("local-2", "local", 2), ("dask-2", "dask", 2))
#: Speed-up of 2 workers over 1 the issue sets as the target on 2 cores.
TARGET_SPEEDUP = 1.7


#: Additions of the busy loop that calibrates the machine (about 1 s on one core).
N_BURN = 30_000_000


def machine_speedup(n: int = N_BURN) -> dict[str, float]:
    """What the machine gives two processes now: a busy loop in 1 and in 2 processes.

    ``speedup = 2 * wall(1 process) / wall(2 processes)``: 2.0 on two idle
    cores, 1.0 when the other load leaves one core's worth of time.  The
    executors cannot do better than this.
    """
    import time

    out: dict[str, float] = {}
    for k in (1, 2):
        t0 = time.perf_counter()
        execute([n] * k, burn, lambda i, r: None, workers=k)
        out[f"wall_{k}_s"] = time.perf_counter() - t0
    out["speedup"] = 2.0 * out["wall_1_s"] / out["wall_2_s"]
    return out


def measure_scale(plan: Plan, out: Path, *, progress: bool = False) -> dict[str, Any]:
    """Run ``plan`` once per configuration of :data:`CONFIGS`; the figures of each."""
    machine_before = machine_speedup()
    rows: dict[str, Any] = {}
    for name, executor, workers in CONFIGS:
        load0 = os.getloadavg()[0]
        res = run_sweep(
            plan,
            out / f"scale-{name}",
            executor=executor,
            workers=workers,
            progress=progress,
            resume=False,
            plots=False,
        )
        tp = dict(res.summary.get("throughput") or {})
        tp["load_before"] = load0
        tp["load_after"] = os.getloadavg()[0]
        tp.update(dispatch_overhead(executor, workers))
        rows[name] = tp
    base = rows["local-1"].get("points_per_s") or float("nan")
    for tp in rows.values():
        tp["speedup"] = (tp.get("points_per_s") or float("nan")) / base
    return {
        "machine_speedup": {"before": machine_before, "after": machine_speedup()},
        "plan": plan.to_dict(),
        "points": len(plan.points()) * len(plan.estimators),
        "cpus": os.cpu_count(),
        "target_speedup": TARGET_SPEEDUP,
        "configs": rows,
    }


def dispatch_overhead(executor: str, workers: int, n: int = N_NOOP) -> dict[str, float]:
    """What the executor costs without the points: ``n`` no-op tasks.

    ``startup_s``: from the call to the first result (start of the pool or
    cluster); ``dispatch_ms``: then per task, in the parent's wall time (send,
    run nothing, return, record).
    """
    import time

    t0 = time.perf_counter()
    first: list[float] = []

    def on_done(i: int, res: dict[str, object]) -> None:
        if not first:
            first.append(time.perf_counter())

    info = execute(list(range(n)), noop, on_done, executor=executor, workers=workers)
    end = t0 + info.wall_s
    return {
        "startup_s": first[0] - t0,
        "dispatch_ms": 1e3 * (end - first[0]) / max(1, n - 1),
    }


def scale_table(scale: dict[str, Any]) -> str:
    """The figures as a Markdown table."""
    lines = [
        "| executor | workers | points/s | speed-up over 1 worker | s per point (wall) "
        "| CPU s per point "
        "| overhead s per point | start-up (s) | dispatch per point (ms) "
        "| load avg before/after |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, tp in scale["configs"].items():
        lines.append(
            f"| {tp.get('executor', name)} | {tp.get('workers', '?')} "
            f"| {tp.get('points_per_s', float('nan')):.3f} | {tp.get('speedup', float('nan')):.2f}x "
            f"| {tp.get('point_compute_s', float('nan')):.3f} "
            f"| {tp.get('point_cpu_s', float('nan')):.3f} "
            f"| {tp.get('overhead_s_per_point', float('nan')):.3f} "
            f"| {tp.get('startup_s', float('nan')):.2f} "
            f"| {tp.get('dispatch_ms', float('nan')):.2f} "
            f"| {tp.get('load_before', float('nan')):.1f} / {tp.get('load_after', float('nan')):.1f} |"
        )
    return "\n".join(lines)


def write_scale(scale: dict[str, Any], out: Path) -> str:
    """Write ``scale.json`` and ``scale.md`` to ``out``; the table."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "scale.json").write_text(json.dumps(scale, indent=2, default=str) + "\n")
    table = scale_table(scale)
    p = scale["plan"]
    head = (
        f"{scale['points']} runs of {p['scenario']} ({', '.join(p['estimators'])}; "
        f"{p['duration'] or 'scenario'} s each) on {scale['cpus']} CPUs; "
        f"target: >= {scale['target_speedup']}x with 2 workers"
    )
    ms = scale.get("machine_speedup")
    if ms:
        head += (
            "; a pure-Python busy loop ran "
            f"{ms['before']['speedup']:.2f}x (before) and {ms['after']['speedup']:.2f}x (after) "
            "as fast in 2 processes as in 1: what the machine gave two processes then"
        )
    (out / "scale.md").write_text(f"{head}\n\n{table}\n")
    return f"{head}\n\n{table}"


BEGIN = "<!-- scale:begin (bench sweep ... --scale; do not edit) -->"
END = "<!-- scale:end -->"


def update_doc(text: str, block: str) -> str:
    """``text`` with the block between :data:`BEGIN` and :data:`END` replaced by ``block``."""
    i, j = text.find(BEGIN), text.find(END)
    if i < 0 or j < i:
        raise ValueError(f"no {BEGIN} ... {END} markers")
    return text[: i + len(BEGIN)] + "\n" + block.rstrip() + "\n" + text[j:]
