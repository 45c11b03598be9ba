"""``bench monitor``: a live terminal view of a bench's bus (the view is :mod:`bench.monitor`).

This module is the command line: the options, the bus they name (resolved as
every command resolves one, :func:`bench.wire._bus.resolve_bus`, but without
a port of its own: the monitor joins a bus, it does not make one), the
monitor's settings (:func:`monitor_pars`) and its priority.  ``python -m
bench.cli.monitor`` runs it alone, without the rest of the bench's command
line: ``bench run --monitor`` starts it so (:func:`bench.monitor.run_monitor`).
"""

from __future__ import annotations

import argparse
import os
import sys
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from bench.monitor._model import MonitorPars

#: The monitor runs at this much lower priority (``nice``): on a host where the
#: bench's nodes keep the cores busy, the kernel gives them the CPU first (a
#: nice-10 process weighs about a tenth of a nice-0 one), and a monitor that
#: falls behind loses frames from its own socket, which it counts from the gaps
#: of the plant's step counter, instead of slowing the bench.
DEFAULT_NICE = 10


def _positive(kind: type) -> Any:
    def parse(text: str) -> Any:
        try:
            v = kind(text)
        except ValueError:
            v = None
        if v is None or not v > 0:
            raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
        return v

    return parse


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``bench monitor`` (bus options as ``bench run`` has them)."""
    from bench.monitor import DEFAULT_BITRATE, DEFAULT_DATA_BITRATE

    g = parser.add_argument_group("bus")
    g.add_argument(
        "--interface",
        "-i",
        help="python-can interface (socketcan, udp_multicast, pcan, ...)",
    )
    g.add_argument(
        "--channel", "-c", help="channel (vcan0, can0, PCAN_USBBUS1, a multicast group, ...)"
    )
    g.add_argument(
        "--port",
        type=int,
        help="UDP port (udp_multicast only; bench run prints the port of its bus)",
    )
    g.add_argument(
        "--bitrate",
        type=int,
        help="nominal bit rate: of a real adapter, and of the load figures "
        f"(default {DEFAULT_BITRATE})",
    )
    g.add_argument(
        "--data-bitrate",
        type=int,
        help="CAN FD data bit rate, as --bitrate "
        f"(default {DEFAULT_DATA_BITRATE} when neither is given)",
    )
    parser.add_argument("--dbc", metavar="FILE", help="DBC file (default: the bench's own)")
    parser.add_argument(
        "--scenario",
        help="scenario of the bench (name, .toml or a run's scenario.json): pole pairs, "
        "PWM period and length of the run",
    )
    parser.add_argument(
        "--pole-pairs",
        type=_positive(int),
        metavar="N",
        help="pole pairs of the motor (default: the scenario's, else inferred from "
        "estimated over true speed)",
    )
    parser.add_argument(
        "--refresh", type=_positive(float), default=4.0, metavar="HZ", help="redraws per second"
    )
    parser.add_argument(
        "--nice",
        type=int,
        default=DEFAULT_NICE,
        metavar="N",
        help=f"lower the monitor's scheduling priority by N (default {DEFAULT_NICE}; 0: as is)",
    )
    parser.add_argument("--title", help="text on the first line (default: the bus)")
    parser.add_argument("--exit-with-parent", action="store_true", help=argparse.SUPPRESS)


def monitor_bus(args: argparse.Namespace) -> Any:
    """The bus of the options (:func:`bench.wire._bus.resolve_bus`).

    Without ``--port`` a udp_multicast bus is python-can's default port, not a
    port of its own as ``bench run`` picks: the monitor joins a bus, it does
    not make one.
    """
    from bench.wire._bus import resolve_bus

    spec, _ = resolve_bus(
        args.interface,
        args.channel,
        args.port,
        args.bitrate,
        args.data_bitrate,
        virtual="--interface virtual: python-can's virtual bus lives inside one process; "
        "the monitor is a process of its own (use the bench's udp_multicast or socketcan bus)",
    )
    return spec


def monitor_pars(args: argparse.Namespace) -> MonitorPars:
    """Settings of the options: the scenario's motor and period, the load's bit rates."""
    from bench.monitor import DEFAULT_BITRATE, DEFAULT_DATA_BITRATE
    from bench.monitor._model import MonitorPars

    n_p: int | None = None
    T_s: float | None = None
    n_steps: int | None = None
    if args.scenario:
        from bench.scenarios._schema import load_scenario
        from bench.scenarios._setup import get_preset, sample_period
        from bench.scenarios._setup import n_steps as scenario_steps

        scn = load_scenario(args.scenario)
        n_p = int(get_preset(scn).motor.n_p)
        T_s = sample_period(scn)
        n_steps = scenario_steps(scn)
    if args.pole_pairs is not None:
        n_p = int(args.pole_pairs)
    if args.bitrate is None and args.data_bitrate is None:
        bitrate = float(DEFAULT_BITRATE)
        data_bitrate: float | None = float(DEFAULT_DATA_BITRATE)
    else:
        bitrate = float(args.bitrate or DEFAULT_BITRATE)
        data_bitrate = None if args.data_bitrate is None else float(args.data_bitrate)
    return MonitorPars(
        bitrate=bitrate, data_bitrate=data_bitrate, n_p=n_p, T_s=T_s, n_steps=n_steps
    )


def cmd_monitor(args: argparse.Namespace) -> int:
    """Run the view until quit: 0, or 130 when left with Ctrl-C.

    Raises
    ------
    BenchError
        No terminal, a bad option, an unreadable DBC or scenario, a bus that
        cannot be opened (one line).
    """
    from bench._errors import BenchError
    from bench.monitor import show_view
    from bench.wire._codec import Codec

    # Textual draws on standard error and reads keys from standard input
    if not (sys.stdin.isatty() and sys.stdout.isatty() and sys.stderr.isatty()):
        raise BenchError("monitor: needs a terminal (standard input, output and error)")
    if args.nice < 0:
        raise BenchError(f"--nice: the monitor only lowers its priority (N >= 0), got {args.nice}")
    if args.nice:
        os.nice(args.nice)
    codec = Codec(args.dbc)
    pars = monitor_pars(args)
    spec = monitor_bus(args)
    title = f"bench monitor  {spec.describe()}" + (f"  {args.title}" if args.title else "")
    stop = None
    if args.exit_with_parent:
        parent = os.getppid()

        def stop() -> bool:
            return os.getppid() != parent

    return show_view(spec.open(), codec, pars, title, refresh_hz=args.refresh, stop=stop)


def register(sub: Any) -> None:
    p = sub.add_parser(
        "monitor",
        help="live view of a running bench: angles, speeds, currents, duties, plant state, "
        "frame rates and bus load, rejections, late periods and stalls",
    )
    add_arguments(p)
    p.set_defaults(func=cmd_monitor)


def _main(argv: list[str] | None = None) -> int:
    """``python -m bench.cli.monitor``: the monitor alone (``bench run --monitor`` starts it)."""
    from bench._errors import BenchError, error_line

    ap = argparse.ArgumentParser(
        prog="bench monitor", description="live terminal view of a running bench"
    )
    add_arguments(ap)
    args = ap.parse_args(argv)
    try:
        return cmd_monitor(args)
    except BenchError as e:
        print(error_line(e), file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(_main())
