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

- :func:`show_view`: the view over an open bus, until quit; the ``bench monitor``
  command line (:mod:`bench.cli.monitor`, which ``python -m bench.cli.monitor``
  runs alone) resolves the bus and the settings and calls it;
- :func:`run_monitor`: the same view in a child process for ``bench run
  --monitor``, attached to the run's bus, closed when the run ends.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from bench.monitor._model import MonitorPars

# Only the entry points here, and no heavy import at the top: the model
# (numpy, cantools) and the view (Textual) load only when the monitor runs.
# The model is bench.monitor._model, the view bench.monitor._app.
__all__ = [
    "DEFAULT_BITRATE",
    "DEFAULT_DATA_BITRATE",
    "run_monitor",
    "show_view",
]

#: Reference bus of the load figures when the options give no bit rate (bit/s):
#: the ``FD 1M/5M`` bus of ``bench busload``.
DEFAULT_BITRATE = 1_000_000
DEFAULT_DATA_BITRATE = 5_000_000


def show_view(
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
    -m bench.cli.monitor``) that opens a listening socket of its own on the run's
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
    cmd = [sys.executable, "-m", "bench.cli.monitor", *spec.args(), "--exit-with-parent"]
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
