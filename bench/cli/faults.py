"""``bench faults``: the fault kinds of a scenario's ``[[faults]]`` timeline, with their parameters."""

from __future__ import annotations

import argparse
from typing import Any


def cmd_faults(args: argparse.Namespace) -> int:
    from bench.scenarios._faults import describe_kinds

    print("\n".join(describe_kinds()))
    return 0


def register(sub: Any) -> None:
    p = sub.add_parser(
        "faults",
        help="the fault kinds of a scenario's [[faults]] timeline, with their parameters",
    )
    p.set_defaults(func=cmd_faults)
