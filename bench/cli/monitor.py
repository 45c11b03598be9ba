"""``bench monitor``: a live terminal view of a bench's bus (the work is :mod:`bench.monitor`)."""

from __future__ import annotations

import argparse
from typing import Any


def cmd_monitor(args: argparse.Namespace) -> int:
    from bench.monitor import main

    return main(args)


def register(sub: Any) -> None:
    from bench.monitor import add_arguments  # light: the view's libraries load in main

    p = sub.add_parser(
        "monitor",
        help="live view of a running bench: angles, speeds, currents, duties, plant state, "
        "frame rates and bus load, rejections, late periods and stalls",
    )
    add_arguments(p)
    p.set_defaults(func=cmd_monitor)
