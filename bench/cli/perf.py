"""``bench perf``: the benchmark harness (see :mod:`bench.studies._perf`)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any


def cmd_perf(args: argparse.Namespace) -> int:
    from bench.studies._perf import format_perf, run_perf

    out = Path(args.out)
    res = run_perf(out, quick=args.quick)
    print(format_perf(res))
    print(f"written: {out / 'perf.json'}")
    return 0


def register(sub: Any) -> None:
    p = sub.add_parser(
        "perf", help="benchmark: in-process, two-process lockstep, real time, codec, bus load"
    )
    p.add_argument("--out", "-o", default="runs/perf", help="folder for perf.json")
    p.add_argument(
        "--quick",
        action="store_true",
        help="short runs (about a minute); no timing targets are asserted",
    )
    p.set_defaults(func=cmd_perf)
