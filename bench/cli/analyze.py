"""``bench analyze``: a capture decoded into signals.csv, metrics.json, meta.json and plots."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from bench.cli._common import POS_FLOAT, files_line, writable_dir


def cmd_analyze(args: argparse.Namespace) -> int:
    """``bench analyze``: the metrics table with the paper's column, and the files written."""
    from bench.captures._read import (
        analyze_capture,
    )
    from bench.runs._local import exit_status
    from bench.runs._plots import controller_label
    from bench.runs._results import format_metrics

    plots = not getattr(args, "no_plots", False)
    log = Path(args.log)
    # the default folder is the capture's (a run folder itself); a missing capture is reported first
    if args.out or log.exists():
        writable_dir(Path(args.out) if args.out else log if log.is_dir() else log.parent)
    res = analyze_capture(
        Path(args.log),
        out_dir=Path(args.out) if args.out else None,
        scenario=args.scenario,
        plots=plots,
        duration=getattr(args, "duration", None),
        dut_name=getattr(args, "dut_name", None),
    )
    scn = res.meta.get("scenario", {})
    print(f"analyze: {args.log} ({controller_label(res.meta)})")
    print(
        format_metrics(
            res.metrics, scn.get("paper_result"), scn.get("estimator"), res.meta.get("estimator")
        )
    )
    status, warnings = exit_status(res, analysis=True)
    for line in warnings:
        print(line, file=sys.stderr)
    missing = int(res.metrics.get("steps_missing", 0))
    if missing:
        print(
            f"warning: {missing} periods of the scenario have no row in the capture (a run "
            "shorter than its scenario: give --duration S; else frames the recording lost); "
            "the metrics cover the rows present",
            file=sys.stderr,
        )
    names = ["signals.csv", "signals.md", "metrics.json", "meta.json"] + (
        ["run.png"] if plots else []
    )
    print(files_line(res.out_dir, names))
    return status


def register(sub: Any) -> None:
    p = sub.add_parser("analyze", help="decode a capture into signals.csv, metrics.json and plots")
    p.add_argument("log", help="a capture python-can reads (.blf, .asc, .log, .trc, .csv, .mf4)")
    p.add_argument("--out", "-o", help="output folder (default: beside the capture)")
    p.add_argument("--scenario", help="scenario of the capture (default: from meta.json beside it)")
    p.add_argument(
        "--duration",
        type=POS_FLOAT,
        metavar="S",
        help="the run's length when shorter than the scenario's (its later periods are not missing)",
    )
    p.add_argument(
        "--dut-name",
        metavar="NAME",
        help="a capture of a controller under test: its name in meta.json and the plot titles",
    )
    p.add_argument("--no-plots", action="store_true", help="skip run.png")
    p.set_defaults(func=cmd_analyze)
