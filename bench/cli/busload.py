"""``bench busload``: the CAN bus load of the DBC's frames per layout, bit rate and PWM rate."""

from __future__ import annotations

import argparse
from typing import Any

from bench.cli._common import rates_khz


def cmd_busload(args: argparse.Namespace) -> int:
    from bench.wire._busload import busload_table, format_busload
    from bench.wire._codec import Codec

    print(format_busload(busload_table(Codec(), rates=[r * 1e3 for r in args.rates])))
    return 0


def register(sub: Any) -> None:
    p = sub.add_parser(
        "busload", help="CAN bus load of the DBC's frames per layout, bit rate and PWM rate"
    )
    p.add_argument(
        "--rates",
        type=rates_khz,
        default=[1.0, 4.0, 10.0],
        help="PWM rates in kHz, comma-separated",
    )
    p.set_defaults(func=cmd_busload)
