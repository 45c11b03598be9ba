"""``bench suite paper``, ``sweep`` and ``robustness``: the papers' scenarios, sweeps and reports.

``bench suite paper [--out DIR]`` runs every shipped scenario with every
estimator it lists (two processes over CAN, lockstep), the sweeps of the
claims (in-process), and writes ``report.md``, ``summary.json`` and plots to
``DIR`` (default ``runs/suite-paper``); the full run folders (captures,
signal tables) go to ``--runs-dir``.  ``bench suite sweep`` runs only the
sweeps.  ``bench suite report DIR`` rewrites ``DIR/report.md`` from
``DIR/summary.json`` (claims re-evaluated, nothing re-run).  ``bench suite
robustness`` runs each paper's estimators under model errors, current noise,
dead time and ADC resolution (:mod:`bench.studies._robustness`); ``bench suite
faults`` every fault kind for every estimator (:mod:`bench.cli._suite_faults`).  ``make suite`` is ``bench suite paper --out docs/results``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from bench._errors import EXIT_INTERRUPTED, BenchError


def _csv(s: str | None) -> tuple[str, ...] | None:
    if s is None:
        return None
    return tuple(x.strip() for x in s.split(",") if x.strip())


def _check_names(names: tuple[str, ...] | None, known: tuple[str, ...], opt: str) -> None:
    for n in names or ():
        if n not in known:
            raise BenchError(f"{opt}: unknown name {n!r} (known: {', '.join(known)})")


def _check_new(out: Path, overwrite: bool) -> None:
    """A suite writes into a folder without a suite's results, unless told to overwrite."""
    if (out / "summary.json").exists() and not overwrite:
        raise BenchError(
            f"--out {out}: holds a suite's results (summary.json); choose another folder "
            "or give --overwrite to replace them"
        )


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the results of an earlier suite in --out (refused otherwise)",
    )
    p.add_argument(
        "--jobs",
        "-j",
        type=int,
        default=2,
        help="parallel workers (default 2: measured faster than 1 on a 2-core machine)",
    )
    p.add_argument("--quiet", "-q", action="store_true", help="no progress display")


def cmd_paper(args: argparse.Namespace) -> int:
    from bench.scenarios._schema import SHIPPED
    from bench.scenarios._setup import check_estimator_name
    from bench.studies._executors import catch_signals
    from bench.studies._suite import PLANTS, SMOKE, SuiteOptions, check_update, run_suite
    from bench.studies._sweep import SWEEPS

    smoke = args.quick and args.scenarios is None and args.estimators is None
    scenarios = _csv(args.scenarios) or (SMOKE.scenarios if smoke else SHIPPED)
    if args.update and args.scenarios is None and args.estimators is None and args.plants is None:
        scenarios = ()  # --update --sweeps ...: the sweeps only
    for s in scenarios:
        if s not in SHIPPED and not Path(s).is_file():
            raise BenchError(
                f"--scenarios: unknown scenario {s!r} (shipped: {', '.join(SHIPPED)}; or a .toml path)"
            )
    estimators = _csv(args.estimators) or (SMOKE.estimators if smoke else None)
    for e in estimators or ():
        check_estimator_name(e, "--estimators")
    plants = _csv(args.plants) or (SMOKE.plants if args.quick else PLANTS)
    _check_names(plants, PLANTS, "--plants")
    sweeps = (
        ()
        if args.no_sweep or (args.update and args.sweeps is None)
        else (_csv(args.sweeps) or (SMOKE.sweeps if args.quick else tuple(SWEEPS)))
    )
    _check_names(sweeps, tuple(SWEEPS), "--sweeps")
    if args.jobs < 1:
        raise BenchError(f"--jobs must be >= 1, got {args.jobs}")
    out = Path(args.out) if args.out else Path("runs") / "suite-paper"
    keep = None
    if args.update:
        if args.overwrite:
            raise BenchError(
                "--update keeps the records not chosen, --overwrite replaces them all; give one"
            )
        if (
            args.scenarios is None
            and args.estimators is None
            and args.plants is None
            and args.sweeps is None
        ):
            raise BenchError(
                "--update: choose what to run again (--scenarios, --estimators, --plants, --sweeps); "
                "the whole suite is --overwrite"
            )
        keep = _load_suite(out)
    else:
        _check_new(out, args.overwrite)
    runs_dir = Path(args.runs_dir) if args.runs_dir else Path("runs") / "suite-runs"
    opts = SuiteOptions(
        out_dir=out,
        runs_dir=runs_dir,
        scenarios=tuple(scenarios),
        estimators=estimators,
        plants=tuple(plants),
        quick=args.quick,
        sweeps=tuple(sweeps),
        sweep_quick=args.quick,
        inprocess=args.inprocess,
        workers=args.jobs,
        interface=args.interface,
        channel=args.channel,
        progress=not args.quiet,
        keep=keep,
    )
    if keep is not None:
        check_update(keep, opts, out / "summary.json")
    with catch_signals():
        summary = run_suite(opts)
    return _finish(summary, out)


def _load_suite(out: Path) -> dict[str, Any]:
    """The summary ``--update`` merges into: ``out/summary.json`` of a paper suite."""
    import json

    path = out / "summary.json"
    try:
        keep: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"))
        runs = keep["runs"]
        if not isinstance(runs, list) or not isinstance(keep["suite"], dict):
            raise TypeError("runs is not a list or suite is not a table")
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise BenchError(f"--update: {path}: not a paper suite's summary.json ({e})") from None
    return keep


def cmd_sweep(args: argparse.Namespace) -> int:
    from bench.studies._executors import catch_signals
    from bench.studies._suite import SuiteOptions, run_suite
    from bench.studies._sweep import SWEEPS

    sweeps = _csv(args.sweeps) or tuple(SWEEPS)
    _check_names(sweeps, tuple(SWEEPS), "--sweeps")
    if args.jobs < 1:
        raise BenchError(f"--jobs must be >= 1, got {args.jobs}")
    out = Path(args.out) if args.out else Path("runs") / "suite-sweep"
    _check_new(out, args.overwrite)
    with catch_signals():
        summary = run_suite(
            SuiteOptions(
                out_dir=out,
                runs_dir=out / "runs",
                scenarios=(),
                sweeps=tuple(sweeps),
                sweep_quick=args.quick,
                inprocess=True,
                workers=args.jobs,
                progress=not args.quiet,
            )
        )
    return _finish(summary, out)


def _finish(summary: dict[str, Any], out: Path) -> int:
    """The claims and the files of a suite; status 130 (files of the finished part) when
    SIGINT/SIGTERM stopped it."""
    fin = summary["suite"].get("finished")
    if summary["suite"].get("interrupted") and fin:
        print(
            f"bench: interrupted: {fin['runs']} of {fin['runs_planned']} runs and "
            f"{fin['sweep_points']} of {fin['sweep_points_planned']} sweep points finished, "
            f"kept in {out} (report.md, summary.json); --overwrite to run the suite there again",
            file=sys.stderr,
        )
        return EXIT_INTERRUPTED
    _print_claims(summary)
    print(f"report: {out / 'report.md'}, {out / 'summary.json'}")
    return 0


def cmd_robustness(args: argparse.Namespace) -> int:
    from bench.studies._executors import catch_signals
    from bench.studies._robustness import DURATION_S, PAPERS, STUDIES, run_robustness

    papers = _csv(args.papers) or tuple(PAPERS)
    _check_names(papers, tuple(PAPERS), "--papers")
    studies = _csv(args.studies) or tuple(STUDIES)
    _check_names(studies, tuple(STUDIES), "--studies")
    if args.scheduler and args.executor != "dask":
        raise BenchError("--scheduler needs --executor dask")
    if args.jobs < 1:
        raise BenchError(f"--jobs must be >= 1, got {args.jobs}")
    out = Path(args.out) if args.out else Path("runs") / "robustness"
    with catch_signals():
        summary = run_robustness(
            out,
            papers=tuple(papers),
            studies=tuple(studies),
            duration=args.duration or DURATION_S,
            executor=args.executor,
            workers=args.jobs,
            scheduler=args.scheduler,
            progress=not args.quiet,
        )
    fin = summary.get("finished")
    if summary.get("interrupted") and fin:
        print(
            f"bench: interrupted: {fin['points']} of {fin['points_planned']} points finished, "
            f"kept in {out} (report.md, summary.json); run the same command again to finish "
            "the others",
            file=sys.stderr,
        )
        return EXIT_INTERRUPTED
    for pname, p in summary["papers"].items():
        for sname, st in p["studies"].items():
            cells = ", ".join(f"{e} {r['ok']}/{r['points']}" for e, r in st["regions"].items())
            print(f"{pname} {sname}: within the bound: {cells}")
    print(f"report: {out / 'report.md'}, {out / 'summary.json'}")
    return 0


def cmd_report(args: argparse.Namespace) -> int:
    from bench.studies._report import rerender, update_readme

    out = Path(args.dir)
    summary = rerender(out)
    _print_claims(summary)
    print(f"report: {out / 'report.md'}")
    if args.readme:
        readme = Path(args.readme)
        readme.write_text(update_readme(readme.read_text(encoding="utf-8"), summary))
        print(f"claims table: {readme}")
    return 0


def _print_claims(summary: dict[str, Any]) -> None:
    for c in summary["claims"]:
        if c["verdict"] != "not run":
            print(f"{c['verdict']:>15}  {c['id']}: {c['detail']}"[:240])
    sys.stdout.flush()


def _sweep_names() -> str:
    from bench.studies._sweep import SWEEPS

    return ", ".join(SWEEPS)


def register(sub: Any) -> None:
    """Add ``bench suite paper`` and ``bench suite sweep``."""
    p = sub.add_parser("suite", help="paper reproduction suite, sweeps of the claims, report")
    ss = p.add_subparsers(dest="suite_command", required=True)

    q = ss.add_parser(
        "paper",
        help="every shipped scenario with every estimator it lists, the sweeps, and the report",
    )
    q.add_argument("--out", "-o", help="report folder (default runs/suite-paper)")
    q.add_argument("--runs-dir", help="full run folders with captures (default runs/suite-runs)")
    q.add_argument("--scenarios", help="comma-separated scenario names (default: all shipped)")
    q.add_argument(
        "--estimators",
        help="comma-separated estimators to keep (default: all listed); a plug-in "
        "(package.module:factory or an installed name) runs on every scenario chosen",
    )
    q.add_argument(
        "--plants",
        help="comma-separated plants: ideal (the papers'), drive (drive profile, countermeasures "
        "on), drive-nocomp (countermeasures off) (default: all three; with --quick: ideal)",
    )
    q.add_argument(
        "--sweeps",
        help=f"comma-separated sweeps ({_sweep_names()}; default: all; with --quick: speed)",
    )
    q.add_argument("--no-sweep", action="store_true", help="skip the sweeps")
    q.add_argument(
        "--quick",
        action="store_true",
        help="smoke test, about a minute on 2 cores: wen-5.1 tt-dq, xue-fig13 square-wave "
        "and wide-speed-xue hybrid-square-wave over CAN, cut to 1.6 s, on the ideal plant, and "
        "the speed sweep's 9 quick points (not comparable with the papers); "
        "--scenarios/--estimators/--plants/--sweeps choose another part, cut alike",
    )
    q.add_argument(
        "--inprocess", action="store_true", help="run the scenarios in-process instead of over CAN"
    )
    q.add_argument(
        "--interface", "-i", help="python-can interface (default: vcan0 or udp_multicast)"
    )
    q.add_argument("--channel", "-c", help="channel of --interface")
    q.add_argument(
        "--update",
        action="store_true",
        help="run again only the runs (and --sweeps) chosen by --scenarios/--estimators/--plants "
        "into the suite already in --out: their records and run folders are replaced, every "
        "other record is kept byte for byte; no sweep unless --sweeps names it; the runs are "
        "made as the suite's were (same --inprocess, --quick)",
    )
    _common(q)
    q.set_defaults(func=cmd_paper)

    q = ss.add_parser(
        "sweep",
        help="position error vs speed, delay, V_h, noise, dead time and ADC bits (in-process)",
    )
    q.add_argument("--out", "-o", help="report folder (default runs/suite-sweep)")
    q.add_argument("--sweeps", help=f"comma-separated sweeps ({_sweep_names()}; default: all)")
    q.add_argument("--quick", action="store_true", help="fewer points, shorter runs")
    _common(q)
    q.set_defaults(func=cmd_sweep)

    q = ss.add_parser(
        "robustness",
        help="each paper estimator under model errors, noise, dead time and ADC bits (in-process)",
    )
    q.add_argument("--out", "-o", help="report folder, resumable (default runs/robustness)")
    q.add_argument("--papers", help="comma-separated: wen, xue (default both)")
    q.add_argument(
        "--studies",
        help="comma-separated: model-inductances, model-inertia-flux, model-resistance, "
        "current-noise, dead-time, adc-bits (default all)",
    )
    q.add_argument("--duration", type=float, help="simulated seconds per point (default 1.6)")
    q.add_argument("--executor", choices=("local", "dask"), default="local")
    q.add_argument("--scheduler", help="Dask scheduler address (default: a local cluster)")
    _common(q)
    q.set_defaults(func=cmd_robustness)

    from bench.cli._suite_faults import add_parser as add_faults_parser

    add_faults_parser(ss)

    q = ss.add_parser(
        "report", help="re-evaluate the claims of a suite folder's summary.json, rewrite report.md"
    )
    q.add_argument("dir", help="folder with summary.json (e.g. docs/results)")
    q.add_argument(
        "--readme", help="also rewrite the claims table of this README (between its markers)"
    )
    q.set_defaults(func=cmd_report)
