"""``bench sweep``: a user's study over a scenario's own keys, resumable, at any scale.

A sweep changes dotted keys of one scenario (:mod:`bench.scenarios._dotted`:
``controller_model.L_q``, ``inverter.t_dead``, ``sensors.current_noise_a``,
``seed``, ...) on a grid (``--grid KEY=V1,V2,...``, every combination) and/or
at random (``--random KEY=SPEC --samples N --seed S``, each sample combined
with every grid point), and runs every point with every estimator
in-process (:func:`bench.studies._sweep.run_point`, through
:func:`bench.runs._local.run_local`, the function of ``bench.run``: the same
frames between the same node objects as a run over CAN).

Files in ``--out``:

- ``points.jsonl``: one line per finished (point, estimator), written and
  flushed the moment it arrives.  A sweep started again with the same
  ``--out`` reads it and runs only what is missing (resumable; a point lost
  with its worker is not written, so it runs again).
- ``results.csv`` (and ``results.parquet`` where pyarrow is installed): one
  row per point and estimator, the swept keys as columns and the metrics of
  ``metrics.json`` beside them.
- ``plots/``: per estimator, a line over one swept key, a heatmap over two
  (lost-lock points marked); ``sweep.json``: the plan, the executor and the
  throughput (points per second, per-point overhead).
"""

from __future__ import annotations

import csv
import itertools
import json
import math
import os
import socket
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from bench._errors import BenchError
from bench.scenarios._dotted import parse_value, scenario_table, scenario_with, split_values
from bench.scenarios._schema import Scenario
from bench.studies._executors import LOST, Bar, execute
from bench.studies._extras import path_name

#: The metric the plots show, and its label.
PLOT_METRIC = "theta_err_abs_max_deg"
PLOT_LABEL = r"max $|\Delta\theta|$ (deg)"
#: Point-description columns of ``results.csv`` before the swept keys and the metrics.
LEAD_COLUMNS = ("point", "estimator", "scenario")


@dataclass(frozen=True, slots=True)
class RandomSpec:
    """How one key is drawn: ``LO:HI`` uniform, ``log:LO:HI`` log-uniform,
    ``int:LO:HI`` integers in [LO, HI], ``choice:V1,V2,...`` one of the values."""

    kind: str
    lo: float = 0.0
    hi: float = 0.0
    choices: tuple[Any, ...] = ()

    def draw(self, rng: np.random.Generator) -> Any:
        if self.kind == "choice":
            return self.choices[int(rng.integers(len(self.choices)))]
        if self.kind == "int":
            return int(rng.integers(int(self.lo), int(self.hi) + 1))
        if self.kind == "log":
            return float(math.exp(rng.uniform(math.log(self.lo), math.log(self.hi))))
        return float(rng.uniform(self.lo, self.hi))


def parse_random(spec: str) -> RandomSpec:
    """A ``--random`` value (:class:`RandomSpec`); a mistake is one line."""
    kind, _, rest = spec.partition(":")
    try:
        if kind == "choice":
            vals = tuple(parse_value(v) for v in split_values(rest))
            if not vals:
                raise ValueError
            return RandomSpec("choice", choices=vals)
        if kind in ("log", "int"):
            lo_s, hi_s = rest.split(":")
        else:
            kind, (lo_s, hi_s) = "uniform", spec.split(":")
        lo, hi = float(lo_s), float(hi_s)
    except ValueError:
        raise BenchError(
            f"--random: {spec!r}: expected LO:HI, log:LO:HI, int:LO:HI or choice:V1,V2,..."
        ) from None
    if not lo < hi or (kind == "log" and lo <= 0.0):
        raise BenchError(f"--random: {spec!r}: needs LO < HI (and LO > 0 for log)")
    return RandomSpec(kind, lo, hi)


def _key_value(opt: str, text: str) -> tuple[str, str]:
    key, eq, val = text.partition("=")
    if not eq or not key.strip() or not val.strip():
        raise BenchError(
            f"{opt}: {text!r}: expected KEY=VALUES (e.g. controller_model.L_q=0.8,1.2)"
        )
    return key.strip(), val.strip()


def parse_grid(items: Sequence[str]) -> dict[str, list[Any]]:
    """``--grid KEY=V1,V2,...`` options as ``{key: values}`` (values read as TOML)."""
    out: dict[str, list[Any]] = {}
    for it in items:
        key, vals = _key_value("--grid", it)
        if key in out:
            raise BenchError(f"--grid: {key} given twice")
        out[key] = [parse_value(v) for v in split_values(vals)]
    return out


@dataclass(frozen=True, slots=True)
class Plan:
    """What a sweep runs.

    Parameters
    ----------
    scenario : str
        Shipped scenario name or file.
    estimators : tuple of str
        Estimators run at every point (built-in names or plug-ins).
    grid : dict
        Dotted key -> values; every combination is a point.
    random : dict
        Dotted key -> :class:`RandomSpec`; ``samples`` draws, each combined
        with every grid point.
    samples, seed : int
        Number of random draws and the seed of the draws.
    duration : float or None
        Simulated seconds of every point (None: the scenario's).
    fixed : dict
        Dotted keys set at every point (not swept).
    """

    scenario: str
    estimators: tuple[str, ...]
    grid: dict[str, list[Any]] = field(default_factory=dict)
    random: dict[str, RandomSpec] = field(default_factory=dict)
    samples: int = 0
    seed: int = 0
    duration: float | None = None
    fixed: dict[str, Any] = field(default_factory=dict)

    @property
    def keys(self) -> tuple[str, ...]:
        return (*self.grid, *self.random)

    def points(self) -> list[dict[str, Any]]:
        """Every point as ``{key: value}``, grid first, in a fixed order."""
        grid = [
            dict(zip(self.grid, combo, strict=True))
            for combo in itertools.product(*self.grid.values())
        ]
        if not self.random:
            return grid
        if self.samples < 1:
            raise BenchError("--random needs --samples N (N >= 1)")
        rng = np.random.default_rng(self.seed)
        draws = [{k: s.draw(rng) for k, s in self.random.items()} for _ in range(self.samples)]
        return [{**g, **d} for g in grid for d in draws]

    def to_dict(self) -> dict[str, Any]:
        return {
            "scenario": self.scenario,
            "estimators": list(self.estimators),
            "grid": self.grid,
            "random": {
                k: {"kind": s.kind, "lo": s.lo, "hi": s.hi, "choices": list(s.choices)}
                for k, s in self.random.items()
            },
            "samples": self.samples,
            "seed": self.seed,
            "duration": self.duration,
            "fixed": self.fixed,
        }


@dataclass(frozen=True, slots=True)
class Point:
    """One (point, estimator) task: picklable, run by :func:`run_task` on any worker."""

    id: str
    values: tuple[tuple[str, Any], ...]
    estimator: str
    scenario: Scenario

    @property
    def cost(self) -> float:
        from bench.scenarios._setup import n_steps

        return float(n_steps(self.scenario))

    @property
    def label(self) -> str:
        vals = " ".join(f"{k}={v}" for k, v in self.values)
        return f"{vals or self.scenario.name} {self.estimator}"


def point_id(values: dict[str, Any], estimator: str, duration: float | None) -> str:
    """The identity of a task, stable across runs (for resuming)."""
    return json.dumps([sorted(values.items()), estimator, duration], default=str)


def run_task(p: Point) -> dict[str, Any]:
    """Run one task (module level: the executors pickle it by name)."""
    from bench.studies._sweep import run_point

    cpu0 = time.process_time()
    res = run_point(p.scenario, p.estimator)
    res["cpu_s"] = time.process_time() - cpu0
    res["worker"] = f"{socket.gethostname()}:{os.getpid()}"
    return res


def build_tasks(plan: Plan) -> list[Point]:
    """Every (point, estimator) task, each scenario built and validated here (one line on error)."""
    base = scenario_table(plan.scenario)
    tasks: list[Point] = []
    for n, vals in enumerate(plan.points()):
        scn = scenario_with(
            base, {**plan.fixed, **vals}, f"{base[0]['name']}-p{n}", plan.estimators
        )
        if plan.duration is not None:
            scn = scn.with_overrides(duration=plan.duration)
        for est in plan.estimators:
            pid = point_id(vals, est, plan.duration)
            tasks.append(Point(pid, tuple(vals.items()), est, scn))
    return tasks


def read_done(path: Path) -> dict[str, dict[str, Any]]:
    """The finished tasks of ``points.jsonl`` by id (a torn last line is ignored)."""
    done: dict[str, dict[str, Any]] = {}
    if not path.exists():
        return done
    for line in path.read_text(encoding="utf-8").splitlines():
        try:
            rec = json.loads(line)
        except ValueError:
            continue
        if isinstance(rec, dict) and "id" in rec:
            done[rec["id"]] = rec
    return done


def _jsonable(v: Any) -> Any:
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


@dataclass(slots=True)
class SweepResult:
    """What :func:`run_sweep` did: the records, the files, the throughput."""

    records: list[dict[str, Any]]
    summary: dict[str, Any]
    files: list[str]


def run_sweep(
    plan: Plan,
    out: Path,
    *,
    executor: str = "local",
    workers: int = 2,
    scheduler: str | None = None,
    progress: bool = True,
    resume: bool = True,
    plots: bool = True,
) -> SweepResult:
    """Run the plan's missing tasks, then write ``results.csv``, plots and ``sweep.json``.

    Stopped by SIGINT/SIGTERM (:func:`bench.studies._executors.catch_signals`):
    ``results.csv`` and ``sweep.json`` of the finished points (``interrupted``
    set), no plots; the points under way are not in ``points.jsonl`` and run
    on the next resume.
    """
    tasks = build_tasks(plan)
    out.mkdir(parents=True, exist_ok=True)
    log = out / "points.jsonl"
    if not resume and log.exists():
        log.unlink()
    done = read_done(log)
    wanted = {t.id for t in tasks}
    todo = [t for t in tasks if t.id not in done]
    if progress:
        where = f"dask at {scheduler}" if executor == "dask" and scheduler else executor
        print(
            f"sweep: {len(tasks)} runs ({len(tasks) - len(todo)} already done in {log}), "
            f"{len(todo)} to run on {where}, {workers} worker(s)",
            file=sys.stderr,
        )
    bar = Bar(sum(t.cost for t in todo), len(todo), "sweep", enabled=progress)
    walls: list[float] = []
    cpus: list[float] = []
    t_first: list[float] = []
    t0 = time.perf_counter()

    with log.open("a", encoding="utf-8") as fh:

        def on_done(i: int, res: dict[str, Any]) -> None:
            t = todo[i]
            ok = "error" not in res
            bar.advance(t.label, t.cost, ok)
            if res.get("error") == LOST:
                print(
                    f"sweep: {t.label}: lost ({res.get('why', '')}); rerun it by resuming",
                    file=sys.stderr,
                )
                return
            if not t_first:
                t_first.append(time.perf_counter() - t0)
            walls.append(float(res.get("wall_s", math.nan)))
            cpus.append(float(res.get("cpu_s", math.nan)))
            rec = {
                "id": t.id,
                "estimator": t.estimator,
                "scenario": t.scenario.name,
                "values": dict(t.values),
                "metrics": {k: _jsonable(v) for k, v in res.items()},
            }
            fh.write(json.dumps(rec, default=str) + "\n")
            fh.flush()
            os.fsync(fh.fileno())
            done[t.id] = rec

        try:
            info = (
                execute(
                    todo, run_task, on_done, executor=executor, workers=workers, scheduler=scheduler
                )
                if todo
                else None
            )
        finally:
            bar.close()
    records = [done[t.id] for t in tasks if t.id in done]
    summary: dict[str, Any] = {"plan": plan.to_dict(), "runs": len(tasks), "finished": len(records)}
    summary["missing"] = len(wanted - set(done))
    stopped = info is not None and info.interrupted
    if stopped:
        summary["interrupted"] = True
    if info is not None and walls:
        n = len(walls)
        compute = float(np.nanmean(walls))
        summary["throughput"] = {
            "executor": info.executor,
            "workers": info.workers,
            "scheduler": info.scheduler,
            "points": n,
            "wall_s": info.wall_s,
            "points_per_s": n / info.wall_s,
            "point_compute_s": compute,
            # CPU seconds of a point in its worker: what it costs on an idle core
            "point_cpu_s": float(np.nanmean(cpus)),
            # what a point costs beyond its own computation, the start of the
            # workers included: worker-seconds available per point minus the
            # point's own time
            "overhead_s_per_point": info.workers * info.wall_s / n - compute,
            "first_result_s": t_first[0] if t_first else math.nan,
            "lost": info.lost,
            "pool_restarts": info.restarts,
            "notes": info.notes,
            "cpus": os.cpu_count(),
        }
    files = write_results(records, plan, out)
    if plots and not stopped:  # seconds of matplotlib: not within the time a signal allows
        files += plot_sweep(records, plan, out / "plots")
    (out / "sweep.json").write_text(json.dumps(summary, indent=2, default=str) + "\n")
    files.append("sweep.json")
    return SweepResult(records, summary, files)


def flat_rows(
    records: Sequence[dict[str, Any]], plan: Plan
) -> tuple[list[str], list[dict[str, Any]]]:
    """``results.csv``'s columns and rows: point, estimator, scenario, swept keys, metrics."""
    metric_keys: list[str] = []
    for r in records:
        for k in r["metrics"]:
            if k not in metric_keys:
                metric_keys.append(k)
    cols = [*LEAD_COLUMNS, *plan.keys, *metric_keys]
    rows = []
    for r in records:
        row: dict[str, Any] = {
            "point": r["scenario"],
            "estimator": r["estimator"],
            "scenario": plan.scenario,
        }
        row.update(r["values"])
        row.update(r["metrics"])
        rows.append(row)
    return cols, rows


def write_results(records: Sequence[dict[str, Any]], plan: Plan, out: Path) -> list[str]:
    """``results.csv``, and ``results.parquet`` where pyarrow is installed."""
    cols, rows = flat_rows(records, plan)
    with (out / "results.csv").open("w", newline="", encoding="utf-8") as f:
        w = csv.DictWriter(f, fieldnames=cols, extrasaction="ignore")
        w.writeheader()
        for row in rows:
            w.writerow({k: ("" if row.get(k) is None else row.get(k)) for k in cols})
    files = ["results.csv"]
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        return files
    table = pa.Table.from_pylist([{k: _cell(row.get(k)) for k in cols} for row in rows])
    pq.write_table(table, out / "results.parquet")
    return [*files, "results.parquet"]


def _cell(v: Any) -> Any:
    return v if isinstance(v, int | float | str | bool) or v is None else str(v)


# --------------------------------------------------------------------- plots


def _num(v: Any) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


def _axis(values: Sequence[Any]) -> tuple[list[Any], bool]:
    """The distinct values of an axis in order, and whether they are numbers."""
    uniq = list(dict.fromkeys(values))
    numeric = all(isinstance(v, int | float) and not isinstance(v, bool) for v in uniq)
    if numeric:
        uniq.sort()
    return uniq, numeric


def cell_stats(
    records: Sequence[dict[str, Any]], keys: Sequence[str], metric: str = PLOT_METRIC
) -> dict[tuple[Any, ...], dict[str, float | bool]]:
    """Per value combination of ``keys``: the mean metric, whether any run lost lock or failed.

    Several records share a cell when other keys (a seed, a random draw) vary.
    """
    acc: dict[tuple[Any, ...], list[dict[str, Any]]] = {}
    for r in records:
        cell = tuple(_hashable(r["values"].get(k)) for k in keys)
        acc.setdefault(cell, []).append(r["metrics"])
    out: dict[tuple[Any, ...], dict[str, float | bool]] = {}
    for cell, ms in acc.items():
        vals = [_num(m.get(metric)) for m in ms]
        fin = [v for v in vals if math.isfinite(v)]
        out[cell] = {
            "value": float(np.mean(fin)) if fin else math.nan,
            "lost": any(bool(m.get("lock_lost")) for m in ms),
            "failed": any("error" in m for m in ms),
        }
    return out


def _hashable(v: Any) -> Any:
    return json.dumps(v) if isinstance(v, list | dict) else v


def plot_sweep(records: Sequence[dict[str, Any]], plan: Plan, out: Path) -> list[str]:
    """Per estimator: a line over one swept key, a heatmap over two (names under ``plots/``)."""
    keys = list(plan.grid) if len(plan.grid) in (1, 2) else list(plan.keys)
    if len(keys) not in (1, 2) or not records:
        return []
    import matplotlib

    matplotlib.use("Agg")

    out.mkdir(parents=True, exist_ok=True)
    names: list[str] = []
    title = scenario_name(plan.scenario)
    if len(keys) == 1:
        name = f"line-{_slug(keys[0])}.png"
        line_plot(records, keys[0], plan.estimators, out / name, f"{title}: vs {keys[0]}")
        return [f"plots/{name}"]
    scattered = any(k in plan.random for k in keys)
    for est in plan.estimators:
        recs = [r for r in records if r["estimator"] == est]
        if not recs:
            continue
        kind = "scatter" if scattered else "heatmap"
        name = f"{kind}-{path_name(est)}-{_slug(keys[0])}-{_slug(keys[1])}.png"
        if scattered:  # random draws are no grid: one dot per point
            scatter(recs, keys[0], keys[1], out / name, f"{title} {est}")
        else:
            heatmap(recs, keys[0], keys[1], out / name, f"{title} {est}")
        names.append(f"plots/{name}")
    return names


def scenario_name(scenario: str) -> str:
    """The name a plot shows for a sweep's scenario: its ``name``, not the path of its file."""
    return str(scenario_table(scenario)[0]["name"])


#: A line plot's value axis is logarithmic only where its values span more than this
#: ratio (largest over smallest positive value).  A log axis is for values that span
#: orders of magnitude (a point that lost the rotor at 180 deg beside points at 1 deg);
#: over a narrower range it squeezes the differences a sweep is about into a few
#: pixels, with no labelled tick between them (0.68-0.88 deg: none).
LOG_AXIS_RATIO = 10.0


def use_log_axis(values: Sequence[float]) -> bool:
    """Whether a value axis showing ``values`` is logarithmic (:data:`LOG_AXIS_RATIO`)."""
    pos = [v for v in values if math.isfinite(v) and v > 0]
    return bool(pos) and max(pos) / min(pos) > LOG_AXIS_RATIO


def scatter(recs: Sequence[dict[str, Any]], xkey: str, ykey: str, path: Path, title: str) -> None:
    """Randomly drawn points over two keys, coloured by :data:`PLOT_METRIC`; lost lock as x."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    x = np.array([_num(r["values"].get(xkey)) for r in recs])
    y = np.array([_num(r["values"].get(ykey)) for r in recs])
    v = np.array([_num(r["metrics"].get(PLOT_METRIC)) for r in recs])
    bad = np.array([bool(r["metrics"].get("lock_lost")) or "error" in r["metrics"] for r in recs])
    fig, ax = plt.subplots(figsize=(6.0, 4.2))
    with np.errstate(divide="ignore", invalid="ignore"):
        sc = ax.scatter(x[~bad], y[~bad], c=np.log10(v[~bad]), cmap="viridis", s=30)
    if np.any(~bad):
        fig.colorbar(sc, ax=ax).set_label(r"log$_{10}$ " + PLOT_LABEL, fontsize=8)
    if np.any(bad):
        ax.plot(x[bad], y[bad], "x", ms=9, mew=2, color="red", ls="", label="lost lock")
        ax.legend(fontsize=7)
    ax.set_xlabel(xkey, fontsize=8)
    ax.set_ylabel(ykey, fontsize=8)
    ax.grid(alpha=0.3)
    ax.set_title(title, fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


def line_plot(
    records: Sequence[dict[str, Any]],
    key: str,
    estimators: Sequence[str],
    path: Path,
    title: str,
    bound: float | None = None,
) -> None:
    """:data:`PLOT_METRIC` over one key, a line per estimator; lost lock or a failed run
    as a red x (a failed one at the bottom of the axis); ``bound`` (deg) as a dashed line."""
    import matplotlib.pyplot as plt

    fig = line_figure(records, key, estimators, title, bound)
    fig.savefig(path, dpi=80)
    plt.close(fig)


def line_figure(
    records: Sequence[dict[str, Any]],
    key: str,
    estimators: Sequence[str],
    title: str,
    bound: float | None = None,
) -> Any:
    """The figure of :func:`line_plot`; its value axis is logarithmic only where the
    values span more than :data:`LOG_AXIS_RATIO` (:func:`use_log_axis`)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 3.6))
    shown: list[float] = [] if bound is None else [bound]
    lost_drawn = False
    fin = [_num(r["metrics"].get(PLOT_METRIC)) for r in records]
    floor = min((v for v in fin if math.isfinite(v) and v > 0), default=1.0)
    for est in estimators:
        st = cell_stats([r for r in records if r["estimator"] == est], (key,))
        if not st:
            continue
        xs, numeric = _axis([c[0] for c in st])
        pos = [(_num(x) if numeric else float(i)) for i, x in enumerate(xs)]
        ys = [float(st[(x,)]["value"]) for x in xs]
        shown += ys
        ax.plot(pos, ys, "o-", ms=4, lw=1, label=est)
        bad = [
            (p, y if math.isfinite(y) else floor)
            for p, y, x in zip(pos, ys, xs, strict=True)
            if st[(x,)]["lost"] or st[(x,)]["failed"]
        ]
        if bad:
            ax.plot(
                [b[0] for b in bad],
                [b[1] for b in bad],
                "x",
                ms=9,
                mew=2,
                color="red",
                label=None if lost_drawn else "lost lock / failed",
            )
            lost_drawn = True
        if not numeric:
            ax.set_xticks(pos, [str(x) for x in xs])
    if bound is not None:
        ax.axhline(bound, ls="--", color="k", lw=1, label=f"paper bound {bound:.3g} deg")
    ax.set_xlabel(key)
    ax.set_ylabel(PLOT_LABEL)
    if use_log_axis(shown):
        ax.set_yscale("log")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    return fig


def heatmap(
    recs: Sequence[dict[str, Any]],
    xkey: str,
    ykey: str,
    path: Path,
    title: str,
    bound: float | None = None,
) -> None:
    """A heatmap of :data:`PLOT_METRIC` over two keys; cells that lost lock carry an ``x``,
    cells above ``bound`` (deg) a dot."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    st = cell_stats(recs, (xkey, ykey))
    xs, _ = _axis([c[0] for c in st])
    ys, _ = _axis([c[1] for c in st])
    z = np.full((len(ys), len(xs)), np.nan)
    for (x, y), s in st.items():
        z[ys.index(y), xs.index(x)] = float(s["value"])
    fig, ax = plt.subplots(figsize=(max(6.0, 2.8 + 0.9 * len(xs)), 1.9 + 0.6 * len(ys)))
    with np.errstate(divide="ignore", invalid="ignore"):
        im = ax.imshow(np.log10(z), origin="lower", cmap="viridis", aspect="auto")
    fin = np.log10(z[np.isfinite(z) & (z > 0)])
    lo_hi = (float(fin.min()), float(fin.max())) if fin.size else (0.0, 0.0)
    cb = fig.colorbar(im, ax=ax)
    cb.set_label(r"log$_{10}$ " + PLOT_LABEL, fontsize=8)
    for (x, y), s in st.items():
        i, j = ys.index(y), xs.index(x)
        v = float(s["value"])
        txt = f"{v:.3g}" if math.isfinite(v) else "not run"
        hi = math.isfinite(v) and v > 0 and math.log10(v) > 0.5 * (lo_hi[0] + lo_hi[1])
        ink = "k" if hi or not math.isfinite(v) else "w"
        ax.text(j, i, txt, ha="center", va="bottom", fontsize=7, color=ink)
        if s["failed"]:
            ax.plot(j, i - 0.2, "s", ms=7, mfc="none", mew=1.5, color="k")
        elif s["lost"]:
            ax.plot(j, i - 0.2, "x", ms=10, mew=2, color="red")
        elif bound is not None and not v <= bound:
            ax.plot(j, i - 0.2, "o", ms=6, mfc="none", mew=1.5, color="orange")
    ax.set_xticks(range(len(xs)), [str(x) for x in xs])
    ax.set_yticks(range(len(ys)), [str(y) for y in ys])
    ax.set_xlabel(xkey, fontsize=8)
    ax.set_ylabel(ykey.replace(".", ".\n", 1), fontsize=8)
    handles = [Line2D([], [], ls="", marker="x", color="red", mew=2, label="lost lock")]
    if any(s["failed"] for s in st.values()):
        handles.append(
            Line2D([], [], ls="", marker="s", mfc="none", color="k", label="failed or not run")
        )
    if bound is not None:
        handles.append(
            Line2D(
                [],
                [],
                ls="",
                marker="o",
                mfc="none",
                color="orange",
                label=f"above {bound:.3g} deg",
            )
        )
    ax.legend(handles=handles, fontsize=7, loc="upper left", bbox_to_anchor=(0.0, -0.18), ncol=3)
    ax.set_title(title, fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


def _slug(key: str) -> str:
    return key.replace(".", "_")
