"""``bench suite faults``: every fault kind for every shipped estimator (:mod:`bench.studies._faults`).

``bench suite faults [--out DIR] [--doc FILE] [--readme FILE] [--estimators
A,B] [--kinds K,L] [--controllers C,D] [--process-catalogue bus|full] [--update]
[--duration S] [--jobs N]`` writes ``DIR/faults.json`` and
``DIR/report.md`` (default ``runs/faults``). ``--controllers`` says where the
controller runs (in-process, python, native, external; default all), and
``--process-catalogue`` what the process variants run (default ``bus``: the bus
kinds with one estimator). ``--update`` keeps the records of ``DIR/faults.json``
for the cases not run now (a study updated in part). ``--doc`` writes the same
report to FILE (``make faults``: docs/FAULTS.md), ``--readme`` the headline
block of that README between its markers. ``--from-json`` renders them from
an existing ``faults.json`` without running. Exits 0 whatever the drives did
(the table is the result); 2 on a user's mistake.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from bench._errors import BenchError


def cmd_faults(args: argparse.Namespace) -> int:
    from bench.studies._faults import (
        AT_S,
        CONTROLLERS,
        DURATION_S,
        PROCESS_CATALOGUES,
        catalogue,
        headline,
        render_doc,
        run_fault_study,
        shortest_duration,
    )
    from controller import ESTIMATOR_NAMES

    if args.from_json:
        src = Path(args.from_json)
        try:
            summary = json.loads(src.read_text(encoding="utf-8"))
            render_doc(summary)
        except (OSError, ValueError, KeyError, TypeError) as e:
            raise BenchError(f"--from-json {src}: not a fault study's faults.json ({e})") from None
    else:
        ests = tuple(x.strip() for x in (args.estimators or "").split(",") if x.strip())
        for name in ests:
            if name not in ESTIMATOR_NAMES:
                raise BenchError(
                    f"--estimators: unknown name {name!r} (known: {', '.join(ESTIMATOR_NAMES)})"
                )
        known_kinds = tuple(dict.fromkeys(f["kind"] for _, f in catalogue(1.0)))
        kinds = tuple(x.strip() for x in (args.kinds or "").split(",") if x.strip())
        for k in kinds:
            if k not in known_kinds:
                raise BenchError(f"--kinds: unknown kind {k!r} (known: {', '.join(known_kinds)})")
        ctls = tuple(x.strip() for x in (args.controllers or "").split(",") if x.strip())
        for c in ctls:
            if c not in CONTROLLERS:
                raise BenchError(f"--controllers: unknown {c!r} (known: {', '.join(CONTROLLERS)})")
        if args.process_catalogue not in PROCESS_CATALOGUES:
            raise BenchError(
                f"--process-catalogue: unknown {args.process_catalogue!r} "
                f"(known: {', '.join(PROCESS_CATALOGUES)})"
            )
        duration = args.duration if args.duration is not None else DURATION_S
        if not duration > (least := shortest_duration()):
            raise BenchError(
                f"--duration must be > {least:g} s (the faults start at {AT_S:g} s, the "
                f"scenarios score from {least:g} s), got {duration:g}"
            )
        if args.jobs < 1:
            raise BenchError(f"--jobs must be >= 1, got {args.jobs}")
        out = Path(args.out) if args.out else Path("runs") / "faults"
        keep = None
        if args.update:
            try:
                keep = json.loads((out / "faults.json").read_text(encoding="utf-8"))
                keep["records"]
            except (OSError, ValueError, KeyError, TypeError) as e:
                raise BenchError(
                    f"--update: {out / 'faults.json'}: not a fault study's faults.json ({e})"
                ) from None
        summary = run_fault_study(
            out,
            estimators=ests or ESTIMATOR_NAMES,
            kinds=kinds or None,
            controllers=ctls or CONTROLLERS,
            process_catalogue=args.process_catalogue,
            duration=duration,
            jobs=args.jobs,
            keep=keep,
            progress=None if args.quiet else lambda s: print(s, file=sys.stderr, flush=True),
        )
        print(f"report: {out / 'report.md'}, {out / 'faults.json'}")
    _write_docs(args, summary)
    for (est, ctl), c in headline(summary).items():
        print(f"{est} ({ctl}): " + ", ".join(f"{n} {o}" for o, n in c.items() if n))
    return 0


def _write_docs(args: argparse.Namespace, summary: dict[str, Any]) -> None:
    from bench.studies._faults import render_doc, update_readme

    if args.doc:
        Path(args.doc).write_text(render_doc(summary), encoding="utf-8")
        print(f"doc: {args.doc}")
    if args.readme:
        readme = Path(args.readme)
        readme.write_text(update_readme(readme.read_text(encoding="utf-8"), summary))
        print(f"fault-study block: {readme}")


def add_parser(ss: Any) -> None:
    """``bench suite faults`` under the ``bench suite`` subparsers ``ss``."""
    q = ss.add_parser(
        "faults",
        help="every fault kind for every shipped estimator, drive plant, in-process and with "
        "the controller as a process",
    )
    q.add_argument("--out", "-o", help="report folder (default runs/faults)")
    q.add_argument("--doc", help="also write the report to this file (docs/FAULTS.md)")
    q.add_argument("--readme", help="also rewrite the fault-study block of this README")
    q.add_argument("--from-json", help="render --doc/--readme from this faults.json, run nothing")
    q.add_argument("--estimators", help="comma-separated shipped estimators (default: all)")
    q.add_argument("--kinds", help="comma-separated fault kinds (default: the whole catalogue)")
    q.add_argument(
        "--controllers",
        help="comma-separated: in-process, python, native, external (default: all)",
    )
    q.add_argument(
        "--process-catalogue",
        default="bus",
        help="what the process variants run: bus (the bus kinds, one estimator; default) "
        "or full (every kind, every estimator)",
    )
    q.add_argument(
        "--update",
        action="store_true",
        help="keep the records of OUT/faults.json for the cases not run now",
    )
    q.add_argument("--duration", type=float, help="simulated seconds per case (default 1.5)")
    q.add_argument("--jobs", "-j", type=int, default=2, help="parallel workers (default 2)")
    q.add_argument("--quiet", "-q", action="store_true", help="no progress lines")
    q.set_defaults(func=cmd_faults)
