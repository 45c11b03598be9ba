"""``bench soak``: pour random frames and injected faults at the nodes for a long time.

See :func:`bench.studies._soak.run_soak`; the figures of the last run go into
``docs/RELIABILITY.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from bench._errors import BenchError


def cmd_soak(args: argparse.Namespace) -> int:
    from bench.studies._soak import run_soak

    if args.frames < 1:
        raise BenchError(f"--frames must be >= 1, got {args.frames}")
    if args.loop_periods < 1 or args.fault_every < 1:
        raise BenchError("--loop-periods and --fault-every must be >= 1")
    if args.out:  # before the soak, not after it has run for hours
        parent = Path(args.out).resolve().parent
        if not parent.is_dir() or not os.access(parent, os.W_OK):
            raise BenchError(f"--out {args.out}: cannot write there (no such writable folder)")
    rep = run_soak(
        args.frames,
        seed=args.seed,
        scenario=args.scenario,
        loop_periods=args.loop_periods,
        fault_every=args.fault_every,
        progress=None if args.quiet else (lambda s: print(s, file=sys.stderr)),
        dbc=args.dbc,
    )
    d = rep.as_dict()
    text = json.dumps(d, indent=2, sort_keys=True)
    if args.out:
        try:
            Path(args.out).write_text(text + "\n")
        except OSError as e:
            raise BenchError(f"--out {args.out}: cannot write: {e.strerror}") from None
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
    print("soak: " + ("ok" if rep.ok else "FAILED"))
    return 0 if rep.ok else 1


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
    p.set_defaults(func=cmd_soak)
