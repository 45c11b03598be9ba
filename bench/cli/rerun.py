"""``bench rerun``: a capture's samples through an estimator offline, scored."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from bench.cli._common import LOG_HELP, estimator_help, files_line


def cmd_rerun(args: argparse.Namespace) -> int:
    """Rerun and print the scores; the exit status is ``bench run``'s for the same metrics
    (:func:`bench.runs._results.outcome`: 3 a plant trip in the capture, 4 a lost rotor angle)."""
    import sys

    from bench.captures._rerun import rerun_capture

    res = rerun_capture(
        Path(args.log),
        args.estimator,
        scenario=args.scenario,
        out_dir=Path(args.out) if args.out else None,
        plots=not args.no_plots,
    )
    from bench.runs._results import format_metrics, outcome

    r: dict[str, Any] = res.report
    est = r["estimate"]
    print(format_metrics(res.metrics, res.paper_result, res.paper_method, args.estimator))
    if r["recorded_metrics"] is not None:
        rm = r["recorded_metrics"]
        print(
            f"recorded ({r['recorded_estimator'] or '?'}): theta_err max {rm['theta_err_max_deg']:.3f}"
            f" min {rm['theta_err_min_deg']:.3f} rms {rm['theta_err_rms_deg']:.3f} deg"
        )
    print(
        f"estimate vs recorded: {est['steps_identical']}/{est['steps_compared']} steps identical"
        + (" (bit for bit)" if est["reproduces_recorded_bit_for_bit"] else "")
    )
    print(f"note: {r['comparison']}")
    print(files_line(res.out_dir, res.files))
    status, warnings = outcome(res.metrics, res.T_s)
    for line in warnings:
        print(line, file=sys.stderr)
    return status


def register(sub: Any) -> None:
    p = sub.add_parser(
        "rerun", help="feed a capture's samples into an estimator offline and score it"
    )
    p.add_argument("log", help=LOG_HELP)
    p.add_argument(
        "--estimator",
        "-e",
        required=True,
        help=estimator_help("required"),
    )
    p.add_argument("--scenario", help="scenario of the capture (default: from meta.json beside it)")
    p.add_argument(
        "--out", "-o", help="output folder (default: rerun-ESTIMATOR beside the capture)"
    )
    p.add_argument("--no-plots", action="store_true", help="skip run.png")
    p.set_defaults(func=cmd_rerun)
