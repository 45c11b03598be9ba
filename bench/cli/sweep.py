"""``bench sweep``: a scenario's own keys on a grid or at random, every point in-process.

::

    bench sweep SCENARIO [-e EST ...] [--grid KEY=V1,V2,... ...]
        [--random KEY=SPEC --samples N --seed S] [--duration S]
        [--executor local|dask] [--scheduler ADDRESS] [--workers N] --out DIR

Resumable: run it again with the same ``--out`` and only the missing
points run.  ``--scale`` measures the throughput of the executors on the
same points instead (docs/SCALING.md).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from bench._errors import EXIT_INTERRUPTED, BenchError
from bench.cli._common import POS_FLOAT


def cmd_sweep(args: argparse.Namespace) -> int:
    from bench.scenarios._dotted import parse_value
    from bench.scenarios._schema import load_scenario
    from bench.scenarios._setup import check_estimator_name
    from bench.studies._executors import catch_signals
    from bench.studies._grid import Plan, parse_grid, parse_random, run_sweep

    if args.scheduler and args.executor != "dask":
        raise BenchError("--scheduler needs --executor dask")
    if args.workers < 1:
        raise BenchError(f"--workers must be >= 1, got {args.workers}")
    scn = load_scenario(args.scenario, tuple(args.estimator or ()))
    ests = tuple(args.estimator or (scn.estimator,))
    for e in ests:
        check_estimator_name(e)
    rnd = {}
    for it in args.random or ():
        key, _, spec = it.partition("=")
        if not spec:
            raise BenchError(f"--random: {it!r}: expected KEY=SPEC (e.g. inverter.t_dead=0:4e-6)")
        rnd[key.strip()] = parse_random(spec.strip())
    fixed = {}
    for it in args.set or ():
        key, _, val = it.partition("=")
        if not val:
            raise BenchError(f"--set: {it!r}: expected KEY=VALUE")
        fixed[key.strip()] = parse_value(val.strip())
    plan = Plan(
        scenario=args.scenario,
        estimators=ests,
        grid=parse_grid(args.grid or ()),
        random=rnd,
        samples=args.samples or 0,
        seed=args.seed,
        duration=args.duration,
        fixed=fixed,
    )
    if not plan.keys:
        raise BenchError("give at least one --grid KEY=V1,V2,... or --random KEY=SPEC")
    out = Path(args.out)
    if args.scale:
        from bench.studies._scale import measure_scale, update_doc, write_scale

        scale = measure_scale(plan, out, progress=not args.quiet)
        text = write_scale(scale, out)
        print(text)
        if args.doc:
            doc = Path(args.doc)
            doc.write_text(update_doc(doc.read_text(encoding="utf-8"), text), encoding="utf-8")
            print(f"written: {doc}")
        return 0
    with catch_signals():
        res = run_sweep(
            plan,
            out,
            executor=args.executor,
            workers=args.workers,
            scheduler=args.scheduler,
            progress=not args.quiet,
            resume=not args.restart,
        )
    _report(res.summary, res.files, out)
    if res.summary.get("interrupted"):
        print("bench: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    return 0 if res.summary["missing"] == 0 else 1


def _report(summary: dict[str, Any], files: list[str], out: Path) -> None:
    tp = summary.get("throughput")
    print(f"sweep: {summary['finished']} of {summary['runs']} runs finished")
    if summary["missing"]:
        print(
            f"sweep: {summary['missing']} runs missing: run the same command again to finish them"
        )
    if tp:
        where = tp["scheduler"] or f"{tp['workers']} {tp['executor']} worker(s)"
        print(
            f"throughput: {tp['points_per_s']:.3g} points/s on {where}, "
            f"{tp['point_compute_s']:.3g} s per point, overhead {tp['overhead_s_per_point']:.3g} s "
            "per point"
        )
    print(f"files: {out}/ ({', '.join(files)})")
    sys.stdout.flush()


def register(sub: Any) -> None:
    p = sub.add_parser(
        "sweep",
        help="a scenario's keys on a grid or at random, in-process, resumable, local or on Dask",
        description="Run a scenario with some of its dotted keys changed (grid: every "
        "combination; random: N draws, each combined with every grid point), every point "
        "with every estimator, in-process. Writes results.csv (+ results.parquet with pyarrow), "
        "plots and sweep.json to --out; resumable.",
    )
    p.add_argument("scenario", help="shipped scenario name or a .toml path")
    p.add_argument(
        "--estimator",
        "-e",
        action="append",
        help="estimator (repeat for several; a plug-in: package.module:factory); "
        "default: the scenario's",
    )
    p.add_argument(
        "--grid",
        action="append",
        metavar="KEY=V1,V2,...",
        help="swept dotted key and values, e.g. controller_model.L_q=0.8,1,1.2 (repeatable)",
    )
    p.add_argument(
        "--random",
        action="append",
        metavar="KEY=SPEC",
        help="drawn key: LO:HI (uniform), log:LO:HI, int:LO:HI, choice:V1,V2 (repeatable)",
    )
    p.add_argument("--samples", type=int, help="number of random draws")
    p.add_argument("--seed", type=int, default=0, help="seed of the random draws (default 0)")
    p.add_argument(
        "--set", action="append", metavar="KEY=VALUE", help="a dotted key set at every point"
    )
    p.add_argument("--duration", type=POS_FLOAT, help="simulated seconds of every point")
    p.add_argument("--executor", choices=("local", "dask"), default="local")
    p.add_argument(
        "--scheduler", help="Dask scheduler address (tcp://HOST:8786); default: a local cluster"
    )
    p.add_argument("--workers", "-j", type=int, default=2, help="local workers (default 2)")
    p.add_argument("--out", "-o", required=True, help="output folder (resumable)")
    p.add_argument(
        "--restart", action="store_true", help="forget the finished points in --out, run all"
    )
    p.add_argument(
        "--scale",
        action="store_true",
        help="measure points/s with 1 and 2 local workers and a 2-worker local Dask cluster",
    )
    p.add_argument(
        "--doc", help="with --scale: also write the figures into this Markdown file's scale block"
    )
    p.add_argument("--quiet", "-q", action="store_true", help="no progress display")
    p.set_defaults(func=cmd_sweep)
