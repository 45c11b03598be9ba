"""``bench schema``: the scenario reference (docs/SCENARIOS.md), generated from the schema."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any


def cmd_schema(args: argparse.Namespace) -> int:
    from bench.scenarios._reference import render

    text = render()
    if args.doc:
        Path(args.doc).write_text(text, encoding="utf-8")
        print(f"written: {args.doc}")
    else:
        print(text, end="")
    return 0


def register(sub: Any) -> None:
    p = sub.add_parser(
        "schema",
        help="every scenario key with its unit, default, range and meaning (Markdown)",
    )
    p.add_argument("--doc", help="write it to this file (docs/SCENARIOS.md) instead of stdout")
    p.set_defaults(func=cmd_schema)
