"""``bench perf``: the benchmark harness (see :mod:`bench.studies._perf`)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any


def cmd_perf(args: argparse.Namespace) -> int:
    from bench._errors import BenchError
    from bench.studies._perf import format_perf, render_benchmarks, run_perf, update_readme

    if args.from_json:
        src = Path(args.from_json)
        try:
            res = json.loads(src.read_text(encoding="utf-8"))
        except (OSError, ValueError) as e:
            raise BenchError(f"--from-json {src}: unreadable ({e})") from None
    else:
        from bench.cli._common import writable_dir

        out = writable_dir(Path(args.out))  # checked before the minutes of measuring
        res = run_perf(out, quick=args.quick, echo=lambda s: print(s, file=sys.stderr))
    print(format_perf(res))
    if not args.from_json:
        print(f"written: {out / 'perf.json'} (the run took {res['wall_s']:.0f} s)")
    if args.doc:
        doc = Path(args.doc)
        doc.write_text(render_benchmarks(res), encoding="utf-8")
        print(f"written: {doc}")
    if args.realtime_doc:
        from bench.studies._perf import update_realtime_doc

        rdoc = Path(args.realtime_doc)
        try:
            text = update_realtime_doc(rdoc.read_text(encoding="utf-8"), res)
        except OSError as e:
            raise BenchError(f"--realtime-doc {rdoc}: {e}") from None
        rdoc.write_text(text, encoding="utf-8")
        print(f"written: {rdoc} (native nodes block)")
    if args.readme:
        readme = Path(args.readme)
        try:
            text = update_readme(readme.read_text(encoding="utf-8"), res)
        except (OSError, ValueError) as e:
            raise BenchError(f"--readme {readme}: {e}") from None
        readme.write_text(text, encoding="utf-8")
        print(f"written: {readme} (perf block)")
    return 0


def register(sub: Any) -> None:
    p = sub.add_parser(
        "perf",
        help="benchmark: in-process on both plant engines, two-process lockstep, real time, "
        "codec, analysis, bus load",
    )
    p.add_argument("--out", "-o", default="runs/perf", help="folder for perf.json")
    p.add_argument(
        "--quick",
        action="store_true",
        help="short runs (about a minute); no timing targets are asserted",
    )
    p.add_argument(
        "--doc", help="write the benchmarks page rendered from the figures (docs/BENCHMARKS.md)"
    )
    p.add_argument(
        "--realtime-doc",
        help="rewrite the native nodes' block of this page (docs/REALTIME.md, between its "
        "perf-native markers)",
    )
    p.add_argument(
        "--readme", help="rewrite the perf block of this README (between its perf markers)"
    )
    p.add_argument(
        "--from-json",
        metavar="PERF_JSON",
        help="measure nothing: print and render the figures of this perf.json",
    )
    p.set_defaults(func=cmd_perf)
