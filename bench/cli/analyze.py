"""``bench analyze``: a capture decoded into signals.csv, metrics.json, meta.json and plots."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from bench.cli._common import files_line, writable_dir


def cmd_analyze(args: argparse.Namespace) -> int:
    """``bench analyze``: the metrics table with the paper's column, and the files written."""
    from bench.captures._read import (
        analyze_capture,
    )
    from bench.runs._results import format_metrics, outcome

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
    )
    scn = res.meta.get("scenario", {})
    print(format_metrics(res.metrics, scn.get("paper_result"), scn.get("estimator")))
    status, warnings = outcome(res.metrics, float(res.meta.get("T_s") or 0.0))
    for line in warnings:
        print(line, file=sys.stderr)
    names = ["signals.csv", "metrics.json", "meta.json"] + (["run.png"] if plots else [])
    print(files_line(res.out_dir, names))
    return status


def register(sub: Any) -> None:
    p = sub.add_parser("analyze", help="decode a capture into signals.csv, metrics.json and plots")
    p.add_argument("log", help="a capture python-can reads (.blf, .asc, .log, .trc, .csv, .mf4)")
    p.add_argument("--out", "-o", help="output folder (default: beside the capture)")
    p.add_argument("--scenario", help="scenario of the capture (default: from meta.json beside it)")
    p.add_argument("--no-plots", action="store_true", help="skip run.png")
    p.set_defaults(func=cmd_analyze)
