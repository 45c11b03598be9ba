"""What the subcommands share: bus and real-time options, scenario overrides, signals.

Every subcommand module (:mod:`bench.cli.run`, :mod:`bench.cli.plant`, ...)
builds its options from these helpers, so the same option means the same
thing everywhere.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import sys
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

from bench._errors import BenchError

MODES = ("lockstep", "realtime")
#: ``--plant-profile`` choices: :data:`plant_rt.PROFILE_NAMES` (tested equal; not
#: imported here, so that building the parser stays light).
PLANT_PROFILES = ("ideal", "drive")
#: The engines of the plant and the controller, as ``plant_rt.ENGINES`` and ``controller.ENGINES``
#: (not imported here: the CLI starts without them).
ENGINES = ("auto", "compiled", "python")
#: ``--engine`` choices: :data:`ENGINES`, and ``native``: the plant node's whole loop in C
#: (:mod:`bench.nodes.native._plant_native`), which ``auto`` also picks where it can run.
ENGINE_CHOICES = (*ENGINES, "native")
#: Help of the LOG argument of the capture commands.
LOG_HELP = "a capture python-can reads (.blf, .asc, .log, .trc, .csv, .mf4) or a run folder"


def add_bus(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("bus")
    g.add_argument(
        "--interface",
        "-i",
        help="python-can interface: socketcan, udp_multicast, pcan, kvaser, slcan, ... "
        "(default: vcan0 when it exists, else udp_multicast; or python-can's configuration)",
    )
    g.add_argument(
        "--channel", "-c", help="channel (vcan0, can0, PCAN_USBBUS1, a multicast group, ...)"
    )
    g.add_argument("--port", type=int, help="UDP port (udp_multicast only)")
    g.add_argument(
        "--bitrate", type=int, help="nominal bit rate, bit/s (real adapters; socketcan: ip link)"
    )
    g.add_argument(
        "--data-bitrate",
        type=int,
        help="CAN FD data bit rate, bit/s (real adapters, slcan included; socketcan: ip link)",
    )


def rt_priority(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        v = 0
    if not 1 <= v <= 99:
        raise argparse.ArgumentTypeError(f"expected a SCHED_FIFO priority 1-99, got {text!r}")
    return v


def number(kind: type, lo: float, strict: bool) -> Any:
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


POS_INT = number(int, 0, True)
NONNEG_INT = number(int, 0, False)
POS_FLOAT = number(float, 0.0, True)


def run_id_arg(text: str) -> int:
    """An argparse type: a run nonce, 1..65535 (decimal or 0x hex)."""
    try:
        v = int(text, 0)
    except ValueError:
        v = 0
    if not 1 <= v <= 0xFFFF:
        raise argparse.ArgumentTypeError(f"expected a run id 1..65535, got {text!r}")
    return v


NONNEG_FLOAT = number(float, 0.0, False)


def rates_khz(text: str) -> list[float]:
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


def add_rt(p: argparse.ArgumentParser, *, cpu: bool = True) -> None:
    g = p.add_argument_group("real time (see bench/nodes/_rt.py)")
    g.add_argument(
        "--rt-priority",
        type=rt_priority,
        metavar="N",
        help="real time: run under SCHED_FIFO at priority N (1-99) with memory locked "
        "(needs root or CAP_SYS_NICE; refused settings are reported, not fatal)",
    )
    if cpu:
        g.add_argument("--cpu", type=int, metavar="N", help="real time: pin the node to CPU N")


def estimator_help(default: str) -> str:
    """``--estimator``'s help: the registry's estimators (one list, the registry's), a
    plug-in, and ``default`` (what applies when the option is not given)."""
    from controller import ESTIMATOR_NAMES

    return (
        f"{', '.join(ESTIMATOR_NAMES)}, or a plug-in: package.module:factory "
        f"(docs/ESTIMATORS.md) ({default}; bench list)"
    )


def add_engine(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--engine",
        choices=ENGINE_CHOICES,
        default="auto",
        help="the engine of the plant and the controller: compiled (C, built when the project "
        "is installed; the controller's where it covers the estimator), python, native (each "
        "node's whole loop in C, on udp_multicast and socketcan), or auto (compiled, and the "
        "native plant and controller nodes where the build, the transport, the scenario and "
        "the estimator allow, else the Python node with one line why; default); native that "
        "cannot be served is refused with that line",
    )


def add_controller_engine(p: argparse.ArgumentParser) -> None:
    """``bench controller --engine``: the controller's engine, or ``native`` (the node's
    whole loop in C, bench/nodes/native/controller_node.py). Default: the engine the
    process inherits (``bench run``'s), else auto; :func:`choose_node_engine` decides."""
    p.add_argument(
        "--engine",
        choices=(*ENGINES, "native"),
        default=None,
        help="the controller's engine: compiled, python, auto, or native (the node's whole "
        "per-period loop in C on the compiled controller, over udp_multicast or socketcan; "
        "refused with one line saying why where it cannot serve). Default: auto (native where "
        "it can serve, on the compiled engine, else the Python node with that line)",
    )


def plant_engine(args: argparse.Namespace) -> str:
    """``--engine``, checked: one line when auto falls back to Python, an error when compiled
    cannot run. It also becomes the controller's (``ENGINE_ENV``, which the controller
    processes of a run inherit; every name runs the controller's core)."""
    import os

    from bench.scenarios._setup import ENGINE_ENV
    from plant_rt import compiled_engine_missing, resolve_engine

    core = "auto" if args.engine == "native" else str(args.engine)
    try:
        resolve_engine(core)
    except ValueError as e:
        raise BenchError(f"--engine {args.engine}: {e}") from None
    why = compiled_engine_missing()
    if core == "auto" and why:
        print(why, file=sys.stderr)
    os.environ[ENGINE_ENV] = core
    return core


#: ``--engine`` values that ask for a node's native loop (bench/nodes/native): ``auto``
#: where it can serve, ``native`` always.
NATIVE_ASKS = ("auto", "native")


def choose_node_engine(role: str, asked: str, why_not: Callable[[], str | None]) -> str:
    """The one rule for which loop serves a node (``bench plant``, ``bench controller``).

    ``asked`` is the node's ``--engine``; ``why_not()`` says in one line why the
    native loop cannot serve this node (the transport, the scenario, the
    controller, the build), or None when it can.  The rule:

    - ``compiled`` or ``python``: the Python node (``why_not`` is not asked);
    - ``auto``: ``native`` where it can serve, else the Python node with one line
      on stderr, ``ROLE: the Python node serves this run: WHY``;
    - ``native``: ``native`` where it can serve, else refused with one line,
      ``--engine native: WHY`` (:class:`BenchError`: exit 2).

    Returns ``"native"`` or ``"python"``.
    """
    if asked not in NATIVE_ASKS:
        return "python"
    why = why_not()
    if why is None:
        return "native"
    if asked == "native":
        raise BenchError(f"--engine native: {why}")
    print(f"{role}: the Python node serves this run: {why}", file=sys.stderr, flush=True)
    return "python"


def node_rt(args: argparse.Namespace, role: str) -> dict[str, object] | None:
    """Apply the node's real-time settings (real-time mode only); what was granted."""
    if args.mode != "realtime":
        return None
    from bench.nodes._rt import apply_rt

    return apply_rt(args.rt_priority, args.cpu, role=role).as_dict()


def add_plan(p: argparse.ArgumentParser) -> None:
    """``--plan FILE``: a node serves a run's resolved plan (:mod:`bench.nodes._plan`)."""
    p.add_argument(
        "--plan",
        metavar="FILE",
        help="serve this run plan (a run folder's plan.json) instead of a SCENARIO and its "
        "options (bench run starts its nodes so)",
    )


def add_scenario_overrides(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--mode",
        choices=MODES,
        default="lockstep",
        help="lockstep: the plant waits for each duty (deterministic); realtime: the plant "
        "on its own clock at the PWM rate (run bench rtcheck first)",
    )
    p.add_argument("--duration", type=POS_FLOAT, help="simulated seconds (overrides the scenario)")
    p.add_argument(
        "--delay-steps",
        type=NONNEG_INT,
        help="injected latency on the duty direction, whole PWM periods (lockstep)",
    )
    p.add_argument(
        "--sample-delay-steps",
        type=NONNEG_INT,
        help="injected latency on the sample direction (lockstep)",
    )
    p.add_argument(
        "--seed", type=NONNEG_INT, help="seed of noise and jitter (overrides the scenario)"
    )


def scenario_from_args(args: argparse.Namespace) -> Any:
    from dataclasses import replace

    from bench.scenarios._schema import load_scenario

    est = getattr(args, "estimator", None)
    scn = load_scenario(args.scenario, (est,) if isinstance(est, str) else ())
    lat = scn.latency
    if getattr(args, "delay_steps", None) is not None:
        lat = replace(lat, duty_delay_steps=max(0, args.delay_steps))
    if getattr(args, "sample_delay_steps", None) is not None:
        lat = replace(lat, sample_delay_steps=max(0, args.sample_delay_steps))
    if getattr(args, "duration", None) is not None and args.duration <= 0:
        raise BenchError(f"--duration must be > 0, got {args.duration}")
    return scn.with_overrides(
        duration=getattr(args, "duration", None),
        seed=getattr(args, "seed", None),
        latency=lat,
        plant_profile=getattr(args, "plant_profile", None),
    )


def bus_spec(args: argparse.Namespace, *, announce: bool, one_process: bool = False) -> Any:
    """The bus of the command's options (:func:`bench.wire._bus.resolve_bus`: the options,
    python-can's configuration, or the default transport with a port of the run's own).

    ``one_process``: the command's bus may be python-can's in-process
    ``virtual`` bus (replay); the bench's nodes are separate processes and
    cannot meet on it.  ``announce``: say on stderr which bus and why, when
    the options did not name it.  The options python-can's configuration
    fills in are written back to ``args``.
    """
    from bench.wire._bus import FROM_CONFIG, UDP_DEFAULT_PORT, own_udp_port, resolve_bus

    spec, why = resolve_bus(
        args.interface,
        args.channel,
        getattr(args, "port", None),
        getattr(args, "bitrate", None),
        getattr(args, "data_bitrate", None),
        # a port of its own per run: parallel runs must not hear each other
        own_port=own_udp_port(os.getpid()),
        virtual=None
        if one_process
        else (
            "--interface virtual: python-can's virtual bus lives inside one process "
            "and the bench's nodes are separate processes; use udp_multicast (the "
            "default without vcan) or socketcan"
        ),
    )
    if why == FROM_CONFIG:
        args.interface, args.channel, args.port = spec.interface, spec.channel, spec.port
        args.bitrate, args.data_bitrate = spec.bitrate, spec.data_bitrate
    if announce and why is not None:
        where = spec.describe()
        if spec.interface == "udp_multicast" and spec.port is None:
            where += f" port {UDP_DEFAULT_PORT}"
            why += "; python-can's default port"
        print(f"transport: {where} ({why})", file=sys.stderr)
    return spec


STOP = threading.Event()


def ready() -> None:
    print("READY", flush=True)


def stop_on_signals() -> None:
    """SIGTERM/SIGINT end a node's loop cleanly (report written, exit code 0)."""

    def handler(signum: int, frame: Any) -> None:
        STOP.set()

    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, handler)


def write_report(path: str | None, data: dict[str, Any]) -> None:
    if path:
        Path(path).write_text(json.dumps(data, indent=2, default=str) + "\n")


def same_bus(a: Any, b: Any) -> bool:
    """Whether two bus specs name one bus (udp_multicast: one port is one bus, any group)."""
    if a.interface != b.interface:
        return False
    if a.interface == "udp_multicast":
        from bench.wire._bus import UDP_DEFAULT_PORT

        return (a.port or UDP_DEFAULT_PORT) == (b.port or UDP_DEFAULT_PORT)
    return bool(a.channel == b.channel)


def writable_dir(path: Path, option: str = "--out") -> Path:
    """``path`` checked writable (creatable); one line (exit 2) when it is not.

    Checked before any work starts, so a folder that cannot be written
    (``/proc/x``, a path under a file, no permission) is the user's mistake
    on one line, not a traceback after the run.  The folders the check
    creates are removed again: a command refused later leaves nothing behind.
    """
    missing = [p for p in (path, *path.parents) if not p.exists()]
    try:
        path.mkdir(parents=True, exist_ok=True)
        probe = path / f".bench-write-check-{os.getpid()}"
        probe.write_bytes(b"")
        probe.unlink()
        for p in missing:  # deepest first
            p.rmdir()
    except OSError as e:
        why = e.strerror or type(e).__name__
        if isinstance(e, FileExistsError) or (path.exists() and not path.is_dir()):
            why = "a file of that name is in the way"
        elif isinstance(e, NotADirectoryError):
            why = "a part of the path is a file, not a folder"
        raise BenchError(f"{option} {path}: cannot write there ({why})") from None
    return path


def files_line(out_dir: Path, names: list[str]) -> str:
    return f"files: {out_dir}/ ({', '.join(names)})"


def add_plant_profile(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--plant-profile",
        choices=PLANT_PROFILES,
        help="ideal: the papers' plant; drive: switching inverter, dead time, device drops, "
        "ADC, offsets, cross-saturation (default: the scenario's plant_profile)",
    )


def serve_node(args: argparse.Namespace, spec: Any, role: str, node: Any, loop: Any) -> int:
    """Run one node's ``loop(bus)`` on ``spec``'s bus until it ends or a signal stops it.

    The node's counters (and the real-time settings it was granted) go to
    ``--report`` whatever ends the loop.
    """
    bus = spec.open()
    stop_on_signals()
    rt = node_rt(args, role)
    try:
        loop(bus)
    finally:
        bus.shutdown()
        write_report(args.report, {**node.report(), "rt": rt})
    return 0
