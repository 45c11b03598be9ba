"""``bench monitor``: a live terminal view of a running bench.

It attaches to any bus the bench can open (a ``bench run``, a standalone
``bench plant`` serving a real drive, a ``bench replay``), decodes every
frame with the DBC and shows rolling plots of the true and estimated rotor
angle and the position error (electrical, wrapped), the reference, true and
estimated speed (rpm, mechanical), the torques, the phase currents and the
duties, and the numbers beside them: the plant's state and fault (names from
the DBC's value tables), frame rate and bus load per message, frames rejected
by reason, the plant's late periods and the stalls the monitor measures.
Keys: space/p pause, + and - zoom the time window, r resets the statistics,
q quits (Ctrl-C too, with exit status 130).

A line at the top says when the bus carries no bench frames (nothing, or
only identifiers that are not in the DBC) and when a bench that was running
has stopped.

The monitor is a passive listener on a socket of its own and never sends; it
reads the bus in its own thread and drops from the view, and counts, what it
cannot draw in time (:mod:`bench.monitor._model`). The terminal side and the
choice of library are in :mod:`bench.monitor._app`.

Entry points:

- :func:`add_arguments` and :func:`main`: the ``bench monitor`` subcommand
  (``python -m bench.monitor`` runs it alone);
- :func:`run_monitor`: the same view in a child process for ``bench run
  --monitor``, attached to the run's bus, closed when the run ends.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import threading
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from bench.monitor._model import MonitorPars

# Only the entry points here, and no heavy import at the top: the bench's
# command line builds its parser with add_arguments for every command, and
# the model (numpy, cantools) and the view (Textual) load only when the
# monitor runs. The model is bench.monitor._model, the view bench.monitor._app.
__all__ = [
    "add_arguments",
    "main",
    "monitor_pars",
    "run_monitor",
]

#: Reference bus of the load figures when the options give no bit rate (bit/s):
#: the ``FD 1M/5M`` bus of ``bench busload``.
DEFAULT_BITRATE = 1_000_000
DEFAULT_DATA_BITRATE = 5_000_000
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


def _bus_spec(args: argparse.Namespace) -> Any:
    """The bus of the options, as ``bench run`` resolves it (:func:`bench.cli._common.bus_spec`).

    Without ``--port`` a udp_multicast bus is python-can's default port, not a
    port of its own as ``bench run`` picks: the monitor joins a bus, it does
    not make one.
    """
    from bench._errors import InterfaceError
    from bench.wire._bus import (
        BusSpec,
        check_interface,
        default_channel,
        default_transport,
        python_can_config,
    )

    interface, channel = args.interface, args.channel
    if interface is None and (cfg := python_can_config()) is not None:
        interface = str(cfg.get("interface"))
        channel = channel or cfg.get("channel")
        for key in ("bitrate", "data_bitrate"):
            if getattr(args, key, None) is None and cfg.get(key) is not None:
                setattr(args, key, int(cfg[key]))
    if interface is None:
        if channel is not None:
            raise InterfaceError("--channel given without --interface")
        interface, channel, _ = default_transport()
    check_interface(interface)
    if interface == "virtual":
        raise InterfaceError(
            "--interface virtual: python-can's virtual bus lives inside one process; "
            "the monitor is a process of its own (use the bench's udp_multicast or socketcan bus)"
        )
    channel = channel or default_channel(interface)
    if channel is None:
        raise InterfaceError(f"--interface {interface}: this adapter needs --channel")
    return BusSpec(interface, str(channel), args.port, args.bitrate, args.data_bitrate)


def monitor_pars(args: argparse.Namespace) -> MonitorPars:
    """Settings of the options: the scenario's motor and period, the load's bit rates."""
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


def main(args: argparse.Namespace) -> int:
    """Run the view until quit: 0, or 130 when left with Ctrl-C.

    Raises
    ------
    BenchError
        No terminal, a bad option, an unreadable DBC or scenario, a bus that
        cannot be opened (one line).
    """
    from bench._errors import BenchError
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
    spec = _bus_spec(args)
    title = f"bench monitor  {spec.describe()}" + (f"  {args.title}" if args.title else "")
    stop = None
    if args.exit_with_parent:
        parent = os.getppid()

        def stop() -> bool:
            return os.getppid() != parent

    return _run_view(spec.open(), codec, pars, title, refresh_hz=args.refresh, stop=stop)


def _run_view(
    bus: Any,
    codec: Any,
    pars: MonitorPars,
    title: str,
    *,
    refresh_hz: float = 4.0,
    stop: Any = None,
) -> int:
    """The view over an open bus (shut down on return)."""
    from bench.monitor._app import MonitorApp
    from bench.monitor._model import MonitorModel
    from bench.monitor._reader import BusReader

    # the size comes from the terminal: an exported COLUMNS or LINES would
    # freeze it (shutil.get_terminal_size, which Textual asks, prefers them)
    os.environ.pop("COLUMNS", None)
    os.environ.pop("LINES", None)
    model = MonitorModel(codec, pars)
    reader = BusReader(bus, model)
    reader.start()
    try:
        app = MonitorApp(
            model, title, refresh_hz=refresh_hz, stop=stop, reader_error=lambda: reader.error
        )
        app.run(mouse=False)
        rc = app.return_code
    finally:
        reader.stop()
        bus.shutdown()
    return 1 if rc is None else rc


def run_monitor(
    spec: Any,
    dbc: str | Path | None = None,
    stop: threading.Event | None = None,
    title: str | None = None,
    *,
    scenario: str | Path | None = None,
    interrupt: bool = True,
) -> int:
    """Show the view of the bus ``spec`` in this terminal until ``stop`` is set or it is quit.

    For ``bench run --monitor``: the view runs as a child process (``python
    -m bench.monitor``) that opens a listening socket of its own on the run's
    bus, so drawing never takes the run's interpreter (its recorder) and the
    run needs no change but to skip its progress line. Call it from a thread
    of its own while the run goes on in the main thread; set ``stop`` when
    the run has ended (the view closes, the terminal is restored) and join
    the thread before printing the run's report.

    Parameters
    ----------
    spec : BusSpec
        The run's bus (:class:`bench.wire._bus.BusSpec`).
    dbc : str or Path, optional
        DBC of the run (default: the bench's own).
    stop : threading.Event, optional
        Set to close the view.
    title : str, optional
        Shown after the bus on the first line (e.g. ``"wen-5.1 tt-dq lockstep"``).
    scenario : str or Path, optional
        The run's effective scenario (its ``scenario.json``): pole pairs, PWM
        period and the run's length for its progress.
    interrupt : bool
        When the view is left with Ctrl-C (the terminal is in raw mode while
        the view runs, so Ctrl-C reaches the view, not the run), send SIGINT
        to this process: the run stops as on Ctrl-C without the view.

    Returns
    -------
    int
        The view's exit status: 0 (quit with q, or ``stop``), 130 (Ctrl-C),
        another value when it failed (its error is on the terminal).
    """
    cmd = [sys.executable, "-m", "bench.monitor", *spec.args(), "--exit-with-parent"]
    if dbc is not None:
        cmd += ["--dbc", str(dbc)]
    if title:
        cmd += ["--title", title]
    if scenario is not None:
        cmd += ["--scenario", str(scenario)]
    proc = subprocess.Popen(cmd)
    try:
        while True:
            try:
                rc = proc.wait(timeout=0.1)
                break
            except subprocess.TimeoutExpired:
                pass
            if stop is not None and stop.is_set():
                rc = _end(proc)
                break
    finally:
        if proc.poll() is None:  # interrupted here: the view restores the terminal on SIGTERM
            _end(proc)
    if rc == 130 and interrupt:
        os.kill(os.getpid(), signal.SIGINT)
    return rc


def _end(proc: subprocess.Popen[bytes]) -> int:
    proc.send_signal(signal.SIGTERM)
    try:
        return proc.wait(timeout=5.0)
    except subprocess.TimeoutExpired:
        proc.kill()
        return proc.wait()
