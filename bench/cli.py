"""The ``bench`` command line.

One function per subcommand, registered in :func:`build_parser`; a missing
optional dependency breaks only its own subcommand.  A user's mistake (bad
scenario, unknown estimator, unreadable capture, missing interface) is a
:class:`~bench._errors.BenchError`: one line on stderr, exit code 2, no
traceback.
"""

from __future__ import annotations

import argparse
import importlib
import json
import math
import os
import random
import signal
import sys
import threading
from pathlib import Path
from typing import Any, NoReturn

from bench._errors import BenchError, InterfaceError

MODES = ("lockstep", "realtime")
#: Exit status of ``bench run`` when the plant tripped a protection (files written).
EXIT_PLANT_TRIPPED = 3

#: Modules that add subcommands: each has ``register(subparsers)`` and keeps
#: its heavy imports inside its command functions.
SUBCOMMAND_MODULES = (
    "bench._cli_suite",
    "bench._cli_replay",
    "bench._cli_firmware",
    "bench._cli_perf",
    "bench._cli_reliability",
)


def _add_bus(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("bus")
    g.add_argument(
        "--interface",
        "-i",
        help="python-can interface (socketcan, udp_multicast, virtual, pcan, ...)",
    )
    g.add_argument(
        "--channel", "-c", help="channel (vcan0, can0, PCAN_USBBUS1, a multicast group, ...)"
    )
    g.add_argument("--port", type=int, help="UDP port (udp_multicast only)")
    g.add_argument("--bitrate", type=int, help="nominal bit rate (real adapters)")
    g.add_argument("--data-bitrate", type=int, help="CAN FD data bit rate (real adapters)")


def _rt_priority(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        v = 0
    if not 1 <= v <= 99:
        raise argparse.ArgumentTypeError(f"expected a SCHED_FIFO priority 1-99, got {text!r}")
    return v


def _number(kind: type, lo: float, strict: bool) -> Any:
    """An argparse type: a ``kind`` number above ``lo`` (``strict``) or at least ``lo``."""
    what = f"{'a whole' if kind is int else 'a'} number {'>' if strict else '>='} {lo:g}"

    def parse(text: str) -> Any:
        try:
            v = kind(text)
        except ValueError:
            v = None
        if v is None or not math.isfinite(v) or (v <= lo if strict else v < lo):
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}")
        return v

    return parse


_POS_INT = _number(int, 0, True)
_NONNEG_INT = _number(int, 0, False)
_POS_FLOAT = _number(float, 0.0, True)
_NONNEG_FLOAT = _number(float, 0.0, False)


def _rates_khz(text: str) -> list[float]:
    out = []
    for part in text.split(","):
        try:
            v = float(part)
        except ValueError:
            v = math.nan
        if not (math.isfinite(v) and v > 0.0):
            raise argparse.ArgumentTypeError(
                f"expected positive PWM rates in kHz separated by commas, got {text!r}"
            )
        out.append(v)
    return out


def _add_rt(p: argparse.ArgumentParser, *, cpu: bool = True) -> None:
    g = p.add_argument_group("real time (see bench/_rt.py)")
    g.add_argument(
        "--rt-priority",
        type=_rt_priority,
        metavar="N",
        help="real time: run under SCHED_FIFO at priority N (1-99) with memory locked "
        "(needs root or CAP_SYS_NICE; refused settings are reported, not fatal)",
    )
    if cpu:
        g.add_argument("--cpu", type=int, metavar="N", help="real time: pin the node to CPU N")


def _node_rt(args: argparse.Namespace, role: str) -> dict[str, object] | None:
    """Apply the node's real-time settings (real-time mode only); what was granted."""
    if args.mode != "realtime":
        return None
    from bench._rt import apply_rt

    return apply_rt(args.rt_priority, args.cpu, role=role).as_dict()


def _add_scenario_overrides(p: argparse.ArgumentParser) -> None:
    p.add_argument("--mode", choices=MODES, default="lockstep")
    p.add_argument("--duration", type=_POS_FLOAT, help="simulated seconds (overrides the scenario)")
    p.add_argument(
        "--delay-steps",
        type=_NONNEG_INT,
        help="injected latency on the duty direction, whole PWM periods (lockstep)",
    )
    p.add_argument(
        "--sample-delay-steps",
        type=_NONNEG_INT,
        help="injected latency on the sample direction (lockstep)",
    )
    p.add_argument(
        "--seed", type=_NONNEG_INT, help="seed of noise and jitter (overrides the scenario)"
    )


def _scenario(args: argparse.Namespace) -> Any:
    from dataclasses import replace

    from bench._scenario import load_scenario

    scn = load_scenario(args.scenario)
    lat = scn.latency
    if getattr(args, "delay_steps", None) is not None:
        lat = replace(lat, duty_delay_steps=max(0, args.delay_steps))
    if getattr(args, "sample_delay_steps", None) is not None:
        lat = replace(lat, sample_delay_steps=max(0, args.sample_delay_steps))
    if getattr(args, "duration", None) is not None and args.duration <= 0:
        raise BenchError(f"--duration must be > 0, got {args.duration}")
    return scn.with_overrides(
        duration=getattr(args, "duration", None), seed=getattr(args, "seed", None), latency=lat
    )


def _spec(args: argparse.Namespace, *, announce: bool, one_process: bool = False) -> Any:
    """The bus of the command's options (or python-can's configuration, or the default).

    ``one_process``: the command's bus may be python-can's in-process
    ``virtual`` bus (replay); the bench's nodes are separate processes and
    cannot meet on it.
    """
    from bench._bus import check_interface, default_transport, python_can_config
    from bench._run import BusSpec

    if args.interface is None and (cfg := python_can_config()) is not None:
        # python-can's own configuration (~/.canrc, CAN_INTERFACE, ...) names the bus
        args.interface = str(cfg.get("interface"))
        args.channel = args.channel or cfg.get("channel")
        for key in ("bitrate", "data_bitrate"):
            if getattr(args, key, None) is None and cfg.get(key) is not None:
                setattr(args, key, int(cfg[key]))
        if announce:
            print(
                f"transport: {args.interface} {args.channel} (python-can configuration)",
                file=sys.stderr,
            )
    if args.interface is not None:
        check_interface(args.interface)
        if args.interface == "virtual" and not one_process:
            raise InterfaceError(
                "--interface virtual: python-can's virtual bus lives inside one process "
                "and the bench's nodes are separate processes; use udp_multicast (the "
                "default without vcan) or socketcan"
            )
    if args.interface is None:
        if args.channel is not None:
            raise InterfaceError("--channel given without --interface")
        iface, chan, reason = default_transport()
        if announce:
            print(f"transport: {iface} {chan} ({reason})", file=sys.stderr)
        port = args.port
        if iface == "udp_multicast" and port is None:
            # a port of its own per run: parallel runs must not hear each other
            port = 44000 + 2 * random.Random(os.getpid()).randrange(5000)
        return BusSpec(
            iface, chan, port, getattr(args, "bitrate", None), getattr(args, "data_bitrate", None)
        )
    from bench._bus import default_channel

    channel: str | None = args.channel or default_channel(args.interface)
    if channel is None:
        raise InterfaceError(f"--interface {args.interface}: this adapter needs --channel")
    return BusSpec(
        args.interface,
        channel,
        args.port,
        getattr(args, "bitrate", None),
        getattr(args, "data_bitrate", None),
    )


_STOP = threading.Event()


def _ready() -> None:
    print("READY", flush=True)


def _stop_on_signals() -> None:
    """SIGTERM/SIGINT end a node's loop cleanly (report written, exit code 0)."""

    def handler(signum: int, frame: Any) -> None:
        _STOP.set()

    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, handler)


def _write_report(path: str | None, data: dict[str, Any]) -> None:
    if path:
        Path(path).write_text(json.dumps(data, indent=2, default=str) + "\n")


def _run_node_args(args: argparse.Namespace) -> dict[str, list[str]]:
    """Options ``bench run`` passes on to its plant and controller processes."""
    out: dict[str, list[str]] = {"plant": [], "controller": []}
    if args.watchdog_ms is not None:
        out["plant"] += ["--watchdog-ms", repr(args.watchdog_ms)]
    if args.rt_priority is not None:
        # the plant keeps the clock: it goes first; the controller one below
        out["plant"] += ["--rt-priority", str(args.rt_priority)]
        out["controller"] += ["--rt-priority", str(max(1, args.rt_priority - 1))]
    return out


def _check_estimator_fits(scn: Any, est: str) -> None:
    """Build the controller once here, so a misfit is one line before any process starts."""
    from bench._setup import build_controller

    try:
        build_controller(scn, est)
    except (ValueError, TypeError) as e:
        raise BenchError(
            f"--estimator {est}: cannot run scenario {scn.name} ({e}); "
            f"the scenario's estimators: {', '.join(scn.estimators)}"
        ) from None


def cmd_run(args: argparse.Namespace) -> int:
    from bench._run import fault_warning, format_metrics, realtime_warning, run_scenario
    from bench._setup import sample_period

    scn = _scenario(args)
    est = args.estimator or scn.estimator
    from controller._registry import ESTIMATOR_NAMES

    if est not in ESTIMATOR_NAMES:
        raise BenchError(
            f"--estimator: unknown estimator {est!r} (known: {', '.join(ESTIMATOR_NAMES)})"
        )
    _check_estimator_fits(scn, est)
    spec = _spec(args, announce=True)
    out = Path(args.out) if args.out else Path("runs") / f"{scn.name}-{est}"
    # the heading of the report on stdout: stderr carries progress and errors only
    print(f"run: {scn.name} with {est}, {args.mode}, {spec.describe()} -> {out}", flush=True)
    res = run_scenario(
        scn,
        est,
        spec=spec,
        out_dir=out,
        mode=args.mode,
        log_format=args.log_format,
        progress=not args.quiet,
        node_args=_run_node_args(args),
    )
    for role, rep in res.meta.get("node_reports", {}).items():
        for why in ((rep or {}).get("rt") or {}).get("refused", []):
            print(f"{role}: real-time setting refused: {why}", file=sys.stderr)
    print(format_metrics(res.metrics, scn.paper_result, scn.estimator))
    if args.mode == "realtime" and (warn := realtime_warning(res.metrics)):
        print(warn, file=sys.stderr)
    tripped = fault_warning(res.metrics, sample_period(scn))
    if tripped:
        print(tripped, file=sys.stderr)
    missing = int(res.metrics.get("steps_missing", 0))
    if missing and not res.meta.get("interrupted"):
        print(
            f"warning: {missing} periods of the run have no row in signals.csv (frames the "
            "recording lost); the metrics cover the rows present",
            file=sys.stderr,
        )
    names = [f"capture{Path(res.capture).suffix}", "signals.csv", "metrics.json", "meta.json"]
    written = [n for n in [*names, "run.png"] if (out / n).is_file()]
    print(f"files: {out}/ ({', '.join(written)})")
    if res.meta.get("interrupted"):
        print("bench: interrupted", file=sys.stderr)
        return 130
    # every file is written; the status says the run is not a scenario result
    return EXIT_PLANT_TRIPPED if tripped else 0


def cmd_plant(args: argparse.Namespace) -> int:
    from bench._codec import Codec
    from bench._loops import make_plant_node, plant_loop

    scn = _scenario(args)
    spec = _spec(args, announce=False)
    codec = Codec()
    node = make_plant_node(
        scn,
        codec,
        truth_every=args.truth_every,
        watchdog_s=None if args.watchdog_ms is None else args.watchdog_ms * 1e-3,
        watchdog_rounds=args.watchdog_rounds,
    )
    if args.mode == "lockstep":
        node.pace_every = args.pace_every
    bus = spec.open()
    _stop_on_signals()
    rt = _node_rt(args, "plant")
    try:
        plant_loop(bus, node, realtime=args.mode == "realtime", on_ready=_ready, stop=_STOP.is_set)
    finally:
        bus.shutdown()
        _write_report(args.report, {**node.report(), "rt": rt})
    return 0


def cmd_controller(args: argparse.Namespace) -> int:
    from bench._codec import Codec
    from bench._loops import controller_loop, make_controller_node

    scn = _scenario(args)
    est = args.estimator or scn.estimator
    spec = _spec(args, announce=False)
    codec = Codec()
    node = make_controller_node(scn, est, codec)
    bus = spec.open()
    _stop_on_signals()
    rt = _node_rt(args, "controller")
    try:
        controller_loop(
            bus,
            node,
            realtime=args.mode == "realtime",
            on_ready=_ready,
            stop=_STOP.is_set,
            sample_timeout_s=args.sample_timeout_ms * 1e-3,
        )
    finally:
        bus.shutdown()
        _write_report(args.report, {**node.report(), "rt": rt})
    return 0


def cmd_link(args: argparse.Namespace) -> int:
    from bench._codec import Codec
    from bench._link import LockstepLink, RealtimeLink, link_loop
    from bench._run import BusSpec

    codec = Codec()
    a = _spec(args, announce=False)
    iface, _, chan = args.to.partition(":")
    if not iface or not chan:
        raise BenchError(f"--to: expected INTERFACE:CHANNEL, got {args.to!r}")
    b = BusSpec(iface, chan, args.to_port)
    for opt in ("drop_prob", "duty_drop_prob", "sample_drop_prob"):
        v = getattr(args, opt)
        if v is not None and not 0.0 <= v <= 1.0:
            raise BenchError(f"--{opt.replace('_', '-')}: a probability in [0, 1], got {v}")
    if _same_bus(a, b):
        raise BenchError(
            f"--to {b.describe()}: the same bus as the link's input ({a.describe()}); "
            "a link forwards between two buses"
        )
    logic: LockstepLink | RealtimeLink
    if args.mode == "lockstep":
        logic = LockstepLink(
            codec,
            sample_delay=args.sample_delay_steps or 0,
            duty_delay=args.delay_steps or 0,
            drop_prob=args.drop_prob,
            seed=args.seed or 0,
            sample_drop_prob=args.sample_drop_prob,
            duty_drop_prob=args.duty_drop_prob,
        )
    else:
        logic = RealtimeLink(
            codec,
            sample_delay_us=args.sample_delay_us,
            duty_delay_us=args.duty_delay_us,
            jitter_us=args.jitter_us,
            jitter_dist=args.jitter_dist,
            drop_prob=args.drop_prob,
            seed=args.seed or 0,
            sample_jitter_us=args.sample_jitter_us,
            duty_jitter_us=args.duty_jitter_us,
            sample_drop_prob=args.sample_drop_prob,
            duty_drop_prob=args.duty_drop_prob,
        )
    bus_a = a.open()
    try:
        bus_b = b.open()
    except BaseException:
        bus_a.shutdown()
        raise
    _stop_on_signals()
    sent: dict[str, int] = {}
    why = "stopped"
    try:
        why = link_loop(
            bus_a, bus_b, logic, on_ready=_ready, idle_s=args.idle_s, stop=_STOP.is_set, sent=sent
        )
    finally:
        bus_a.shutdown()
        bus_b.shutdown()
        if why == "idle":
            print(f"link: no traffic for {args.idle_s:g} s: stopping", file=sys.stderr)
        print(
            f"link: forwarded {sent.get('a_to_b', 0)} frames {a.describe()} -> {b.describe()}, "
            f"{sent.get('b_to_a', 0)} back; dropped {logic.dropped_samples} samples/truth and "
            f"{logic.dropped_duties} duties on purpose"
            + (
                f"; {sent['send_errors']} sends refused by a bus, "
                f"{sent.get('frames_lost_on_send', 0)} frames lost after retries"
                if sent.get("send_errors")
                else ""
            ),
            file=sys.stderr,
        )
    return 0


def _same_bus(a: Any, b: Any) -> bool:
    """Whether two bus specs name one bus (udp_multicast: one port is one bus, any group)."""
    if a.interface != b.interface:
        return False
    if a.interface == "udp_multicast":
        return (a.port or 43113) == (b.port or 43113)
    return bool(a.channel == b.channel)


def cmd_analyze(args: argparse.Namespace) -> int:
    from bench._cli_replay import cmd_analyze as analyze

    return analyze(args)


def cmd_busload(args: argparse.Namespace) -> int:
    from bench._busload import busload_table, format_busload
    from bench._codec import Codec

    print(format_busload(busload_table(Codec(), rates=[r * 1e3 for r in args.rates])))
    return 0


class _Parser(argparse.ArgumentParser):
    """Command-line mistakes as one line (with where to look), exit code 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    ap = _Parser(
        prog="bench",
        description="CAN hardware-in-the-loop bench for sensorless IPMSM control",
    )
    sub = ap.add_subparsers(dest="command", required=True)

    p = sub.add_parser("run", help="run a scenario: plant and controller as two processes over CAN")
    p.add_argument(
        "scenario", help="shipped scenario name (wen-5.1, xue-fig13, ...) or a .toml path"
    )
    p.add_argument(
        "--estimator", "-e", help="sfhf, tt-ab, tt-dq, square-wave, square-wave-nocic, sensored"
    )
    _add_scenario_overrides(p)
    _add_bus(p)
    p.add_argument("--out", "-o", help="run folder (default runs/SCENARIO-ESTIMATOR)")
    p.add_argument(
        "--log-format", choices=("blf", "asc", "log"), default="blf", help="capture format"
    )
    p.add_argument("--quiet", "-q", action="store_true", help="no progress line")
    p.add_argument(
        "--watchdog-ms",
        type=_POS_FLOAT,
        help="real time: the plant's safe state after this long without a valid duty",
    )
    _add_rt(p, cpu=False)
    p.set_defaults(func=cmd_run)

    p = sub.add_parser("plant", help="serve the plant emulator on a bus (one node)")
    p.add_argument("scenario")
    _add_scenario_overrides(p)
    _add_bus(p)
    p.add_argument(
        "--truth-every", type=_POS_INT, default=1, help="send PlantTruth every N periods"
    )
    p.add_argument(
        "--watchdog-ms",
        type=_POS_FLOAT,
        help="real time: safe state after this long without a valid duty (default 10 periods, >= 20 ms)",
    )
    p.add_argument(
        "--watchdog-rounds",
        type=_POS_INT,
        default=100,
        help="lockstep: safe state after this many 50 ms retransmission rounds without a duty",
    )
    p.add_argument("--report", help="write the node's counters to this JSON file at exit")
    p.add_argument(
        "--pace-every",
        type=_NONNEG_INT,
        default=0,
        metavar="N",
        help="lockstep: run period k only once a bench command for step k or later has come "
        "(the sender keeps one at least every N periods); 0: off (bench run sets it)",
    )
    _add_rt(p)
    p.set_defaults(func=cmd_plant)

    p = sub.add_parser("controller", help="serve the drive controller on a bus (one node)")
    p.add_argument("scenario")
    p.add_argument("--estimator", "-e")
    _add_scenario_overrides(p)
    _add_bus(p)
    p.add_argument("--report", help="write the node's counters to this JSON file at exit")
    p.add_argument(
        "--sample-timeout-ms",
        type=_POS_FLOAT,
        default=50.0,
        help="real time: disable the PWM after this long without a valid sample",
    )
    _add_rt(p)
    p.set_defaults(func=cmd_controller)

    p = sub.add_parser("link", help="latency link between two buses (delay, jitter, drop)")
    _add_bus(p)
    p.add_argument(
        "--to", required=True, help="the other bus, INTERFACE:CHANNEL (e.g. socketcan:vcan1)"
    )
    p.add_argument("--to-port", type=int, help="UDP port of the other bus (udp_multicast)")
    p.add_argument("--mode", choices=MODES, default="lockstep")
    p.add_argument(
        "--delay-steps", type=_NONNEG_INT, default=0, help="lockstep: duty direction, periods"
    )
    p.add_argument(
        "--sample-delay-steps",
        type=_NONNEG_INT,
        default=0,
        help="lockstep: sample direction, periods",
    )
    p.add_argument(
        "--duty-delay-us", type=_NONNEG_FLOAT, default=0.0, help="real time: duty direction"
    )
    p.add_argument(
        "--sample-delay-us", type=_NONNEG_FLOAT, default=0.0, help="real time: sample direction"
    )
    p.add_argument(
        "--jitter-us",
        type=_NONNEG_FLOAT,
        default=0.0,
        help="real time, both directions: standard deviation (normal) or half-width (uniform)",
    )
    for way in ("duty", "sample"):
        p.add_argument(
            f"--{way}-jitter-us",
            type=_NONNEG_FLOAT,
            help=f"real time: jitter of the {way} direction (default: --jitter-us)",
        )
    p.add_argument("--jitter-dist", choices=("normal", "uniform"), default="normal")
    p.add_argument(
        "--drop-prob", type=float, default=0.0, help="per frame, both directions, in [0, 1]"
    )
    for way in ("duty", "sample"):
        p.add_argument(
            f"--{way}-drop-prob",
            type=float,
            help=f"drop probability of the {way} direction (default: --drop-prob)",
        )
    p.add_argument(
        "--seed",
        type=_NONNEG_INT,
        default=0,
        help="seed of the drops and jitter (a stream per direction)",
    )
    p.add_argument("--duration", type=float, help="ignored (accepted for symmetry with the nodes)")
    p.add_argument(
        "--idle-s",
        type=float,
        default=30.0,
        help="exit after this long without traffic, once traffic has begun (s)",
    )
    p.set_defaults(func=cmd_link)

    p = sub.add_parser("analyze", help="decode a capture into signals.csv, metrics.json and plots")
    p.add_argument("log", help="a capture python-can reads (.blf, .asc, .log, .trc, .csv, .mf4)")
    p.add_argument("--out", "-o", help="output folder (default: beside the capture)")
    p.add_argument("--scenario", help="scenario of the capture (default: from meta.json beside it)")
    p.add_argument("--no-plots", action="store_true", help="skip run.png")
    p.set_defaults(func=cmd_analyze)

    p = sub.add_parser(
        "busload", help="CAN bus load of the DBC's frames per layout, bit rate and PWM rate"
    )
    p.add_argument(
        "--rates",
        type=_rates_khz,
        default=[1.0, 4.0, 10.0],
        help="PWM rates in kHz, comma-separated (default 1,4,10)",
    )
    p.set_defaults(func=cmd_busload)

    for mod in SUBCOMMAND_MODULES:
        try:
            module = importlib.import_module(mod)
        except ModuleNotFoundError as e:
            if e.name != mod:
                raise
            continue
        module.register(sub)
    return ap


def main(argv: list[str] | None = None) -> int:
    ap = build_parser()
    try:
        args = ap.parse_args(argv)
    except SystemExit as e:  # --help, or a mistake already reported on one line
        return e.code if isinstance(e.code, int) else 2
    try:
        rc: int = args.func(args)
        return rc
    except BenchError as e:
        print(f"bench: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("bench: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # output piped into head and the like
        sys.stderr.close()
        return 0


if __name__ == "__main__":
    sys.exit(main())
