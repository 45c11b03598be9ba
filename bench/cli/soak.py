"""``bench soak``: pour random frames and injected faults at the nodes for a long time.

See :func:`bench.studies._soak.run_soak`; with ``--processes`` also
:func:`bench.studies._reliability.run_process_checks`.  ``--doc`` renders
``docs/RELIABILITY.md`` from the figures (:func:`bench.studies._reliability.render_reliability`),
``--from-json`` from the JSON of an earlier run.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from bench._errors import BenchError


def cmd_soak(args: argparse.Namespace) -> int:
    from bench.studies._reliability import (
        process_checks_ok,
        render_reliability,
        run_process_checks,
    )
    from bench.studies._soak import run_soak

    if args.from_json:
        try:
            d = json.loads(Path(args.from_json).read_text())
        except (OSError, ValueError) as e:
            raise BenchError(f"--from-json {args.from_json}: unreadable ({e})") from None
        if not args.doc:
            raise BenchError("--from-json: give --doc FILE to render the page")
        _write(args.doc, render_reliability(d), "--doc")
        print(f"written: {args.doc}")
        return 0
    if args.frames < 1:
        raise BenchError(f"--frames must be >= 1, got {args.frames}")
    if args.loop_periods < 1 or args.fault_every < 1:
        raise BenchError("--loop-periods and --fault-every must be >= 1")
    for opt, path in (("--out", args.out), ("--doc", args.doc)):
        if path:  # before the soak, not after it has run for minutes
            parent = Path(path).resolve().parent
            if not parent.is_dir() or not os.access(parent, os.W_OK):
                raise BenchError(f"{opt} {path}: cannot write there (no such writable folder)")
    say = None if args.quiet else (lambda s: print(s, file=sys.stderr))
    rep = run_soak(
        args.frames,
        seed=args.seed,
        scenario=args.scenario,
        loop_periods=args.loop_periods,
        fault_every=args.fault_every,
        progress=say,
        dbc=args.dbc,
    )
    d = rep.as_dict()
    d.update(frames_per_node=args.frames, scenario=args.scenario)
    ok = rep.ok
    if args.processes:
        d["processes"] = run_process_checks(loaded_runs=args.loaded_runs, progress=say)
        ok = ok and process_checks_ok(d["processes"])
        d["ok"] = ok
    if args.out:
        _write(args.out, json.dumps(d, indent=2, sort_keys=True) + "\n", "--out")
    if args.doc:
        _write(args.doc, render_reliability(d), "--doc")
    print(
        f"frames fuzzed {rep.frames_fuzzed} (plant {rep.frames_fuzzed_plant}, controller "
        f"{rep.frames_fuzzed_controller}, closed loop {rep.frames_fuzzed_loop}); "
        f"rejected {sum(v for k, v in rep.rejected.items() if k != 'repeated_counter')}; "
        f"faults injected {sum(rep.faults_injected.values())}, recoveries {rep.recoveries}; "
        f"exceptions {rep.exceptions}, violations {rep.violations}, "
        f"uncounted {rep.unchecked_rejections}; data lost {rep.data_lost_periods} periods; "
        f"{rep.wall_s:.1f} s"
    )
    for n in rep.notes:
        print(f"  {n}")
    if args.processes:
        p = d["processes"]
        det = p["determinism_under_load"]["cases"]
        print(
            "processes: determinism under load "
            + ", ".join(f"{c['identical']}/{c['runs']}" for c in det)
            + "; kills "
            + ", ".join(f"{k['killed']} ({k['mode']}) exit {k['exit_code']}" for k in p["kills"])
            + "; signals "
            + ", ".join(f"{s['signal']} exit {s['exit_code']}" for s in p["signals"])
            + f"; parallel {p['parallel']['own_bus_identical']}/{p['parallel']['runs']}"
        )
    print("soak: " + ("ok" if ok else "FAILED"))
    return 0 if ok else 1


def _write(path: str, text: str, opt: str) -> None:
    try:
        Path(path).write_text(text)
    except OSError as e:
        raise BenchError(f"{opt} {path}: cannot write: {e.strerror}") from None


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("soak", help="fuzz both nodes and inject faults for a long soak run")
    p.add_argument("--frames", type=int, default=100_000, help="fuzzed frames per node")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--scenario", default="wen-5.1", help="scenario the nodes are built from")
    p.add_argument("--loop-periods", type=int, default=20_000, help="closed-loop periods")
    p.add_argument("--fault-every", type=int, default=500, help="periods between injected faults")
    p.add_argument("--dbc", help="DBC file (default: the bench's own)")
    p.add_argument("--out", "-o", help="write the figures as JSON to this file")
    p.add_argument("--quiet", "-q", action="store_true")
    p.add_argument(
        "--processes",
        action="store_true",
        help="also kill, signal, load and double real bench run processes (Linux; minutes)",
    )
    p.add_argument(
        "--loaded-runs", type=int, default=3, help="--processes: runs per case under load"
    )
    p.add_argument("--doc", help="write docs/RELIABILITY.md rendered from the figures")
    p.add_argument(
        "--from-json", help="measure nothing: render --doc from this JSON of an earlier run"
    )
    p.set_defaults(func=cmd_soak)
