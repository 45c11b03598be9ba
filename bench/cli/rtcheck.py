"""``bench rtcheck``: this host's wake-up latency and the plant's computation per period.

The measurements and the verdict are :mod:`bench.studies._rtcheck`; what each
setting does is docs/REALTIME.md.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from bench.cli._common import POS_FLOAT, rates_khz


def cmd_rtcheck(args: argparse.Namespace) -> int:
    from bench._errors import BenchError
    from bench.studies._rtcheck import format_rtcheck, host_file, run_rtcheck, update_doc

    out = Path(args.out) if args.out else None
    if out is not None:
        try:
            out.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise BenchError(f"--out {out}: cannot create the folder ({e.strerror})") from None
    rates = [r * 1e3 for r in args.rate]
    print(f"rtcheck: {args.seconds:g} s per rate and setting, rates {args.rate} kHz")
    res = run_rtcheck(rates, args.seconds)
    print(format_rtcheck(res))
    # this host's result, for the warning of bench run --mode realtime
    try:
        host = host_file()
        host.parent.mkdir(parents=True, exist_ok=True)
        host.write_text(json.dumps(res, indent=2, sort_keys=True) + "\n")
        print(f"written: {host} (read by bench run --mode realtime)")
    except OSError as e:
        print(f"not written: {host_file()} ({e.strerror})")
    if out is not None:
        (out / "rtcheck.json").write_text(json.dumps(res, indent=2, sort_keys=True) + "\n")
        print(f"written: {out / 'rtcheck.json'}")
    for name in args.doc or []:
        doc = Path(name)
        text = doc.read_text(encoding="utf-8") if doc.exists() else ""
        doc.write_text(update_doc(text, res), encoding="utf-8")
        print(f"written: {doc} (measured block)")
    return 0


def register(sub: Any) -> None:
    p = sub.add_parser(
        "rtcheck",
        help="measure this host's wake-up latency and the plant's computation per period; "
        "which PWM rates it sustains, with which settings",
    )
    p.add_argument("--seconds", type=POS_FLOAT, default=5.0, help="seconds per rate and setting")
    p.add_argument(
        "--rate",
        type=rates_khz,
        default=[1.0, 4.0, 10.0],
        help="PWM rates in kHz, comma-separated",
    )
    p.add_argument("--out", "-o", help="also write rtcheck.json into this folder")
    p.add_argument(
        "--doc",
        action="append",
        help="rewrite the measured block of this Markdown file (docs/REALTIME.md, "
        "README.md; repeatable)",
    )
    p.set_defaults(func=cmd_rtcheck)
