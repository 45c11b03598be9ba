"""The monitor's terminal view, built with Textual and textual-plotext.

Why Textual: it is a maintained text-UI framework (Textualize, frequent
releases) that owns everything this view must get right on a plain
terminal and that hand-written drawing gets wrong: the alternate screen
and raw mode entered and restored on every way out (quit, Ctrl-C, an
exception, SIGTERM), resize (SIGWINCH) with relayout by CSS fractions, key
bindings with a footer that lists them, and output that works over SSH
(plain escape sequences, no mouse needed: the mouse is left off so the
terminal's own selection keeps working). textual-plotext (Textualize) wraps
plotext's terminal plots as a widget, so the traces are real plots with
axes (each with a coloured legend line above it). urwid has no plotting; rich + plotext would leave keys,
resize and the terminal's state to us.

Cost: the view redraws ``refresh_hz`` times a second (4 by default; a
plotext build takes 2-10 ms per plot, and a plot without data is not built
again); the bus is read by :class:`~bench.monitor._reader.BusReader` in its
own thread and decoding takes at most a fifth of a core
(:class:`~bench.monitor._model.MonitorPars`). Measured here (2 cores): about
3 % of a core on an idle bus, about 30 % beside a lockstep ``wen-5.1`` run at
40,000 frames/s (mostly python-can's receive path), the monitor niced by 10.
"""

from __future__ import annotations

import asyncio
import math
import signal
import time
from collections.abc import Callable
from typing import ClassVar

from rich.text import Text
from textual.app import App, ComposeResult
from textual.binding import Binding, BindingType
from textual.containers import Grid, Horizontal, Vertical
from textual.css.query import NoMatches
from textual.widgets import Footer, Static
from textual_plotext import PlotextPlot

from bench.monitor._model import TRACES, MonitorModel, Numbers, envelope

__all__ = ["EXIT_INTERRUPTED", "WINDOWS_S", "MonitorApp", "format_numbers"]

#: Exit status when the view is left with Ctrl-C (as the bench's other commands).
EXIT_INTERRUPTED = 130
#: Time windows of the plots (s), zoomed through with + and -.
WINDOWS_S = (0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0)
DEFAULT_WINDOW_S = 2.0

#: The plots: (widget id, title, fixed y range, or the least span of an automatic one).
#: The least spans keep a steady signal from being drawn as noise in the last
#: digits of its LSB: about 1 deg, 10 rpm, 0.5 N m, 0.5 A.
PLOTS: tuple[tuple[str, str, tuple[float, float] | float], ...] = (
    ("angle", "rotor angle, deg el.", (0.0, 360.0)),
    ("error", "position error (true - estimate), deg el.", 1.0),
    ("speed", "speed, rpm mech.", 10.0),
    ("torque", "torque, N m", 0.5),
    ("currents", "phase currents, A", 0.5),
    ("duties", "duties", (0.0, 1.0)),
)
#: Colours of a plot's first, second and third trace (RGB, for plotext and the legend).
_COLORS = ((0, 175, 255), (255, 135, 0), (95, 215, 0))
#: plotext's marker: quadrant blocks (2 x 2 dots per cell, Unicode Block
#: Elements), which nearly every terminal font draws, where braille (2 x 4)
#: is missing from some (and from the fonts of SVG renderers).
MARKER = "hd"


def _f(x: float | None, fmt: str, unit: str = "") -> str:
    return "-" if x is None or not math.isfinite(x) else format(x, fmt) + unit


def format_numbers(n: Numbers, window_s: float, paused: bool) -> tuple[str, str, str]:
    """The three number panels (plant, frames, health) as plain text, 38 columns at most."""
    step = "-" if n.step is None else str(n.step)
    if n.sim_s is not None:
        step += f"  t {n.sim_s:.3f} s"
    if n.progress is not None:
        step += f"  {100 * n.progress:.0f} %"
    lines = [
        f"plant      {n.state or '-'}  fault {n.fault or '-'}",
        f"ctrl mode  {n.ctrl_mode or '-'}  n_p {n.n_p or '-'}"
        + (" (inferred)" if n.n_p_inferred else ""),
        f"step       {step}",
    ]
    if n.realtime_factor is not None:
        lines.append(f"sim speed  x{n.realtime_factor:.2f} real time")
    lines += [
        f"speed ref  {_f(n.speed_ref, '.1f', ' rpm')}",
        f"speed      {_f(n.speed, '.1f')}  est {_f(n.speed_hat, '.1f')} rpm",
        f"angle      {_f(n.theta_e, '.1f')}  est {_f(n.theta_hat, '.1f')} deg el.",
        f"pos. error {_f(n.theta_err, '+.1f')} deg el.",
        f"torque     {_f(n.tau_e, '.2f')}  load {_f(n.tau_L, '.2f')} N m",
        "i_abc      " + ("-" if n.i_abc is None else " ".join(f"{i:+.2f}" for i in n.i_abc) + " A"),
        "duties     "
        + (
            "-"
            if n.duties is None
            else " ".join(f"{d:.3f}" for d in n.duties) + (" on" if n.enable else " off")
        ),
        f"duty age   {'-' if n.duty_age is None else n.duty_age} periods",
    ]
    plant = "\n".join(lines)

    rows = [f"{'message':<14}{'fr/s':>7}{'load':>7}{'frames':>9}"]
    for m in n.messages:
        rows.append(f"{m.name:<14}{m.rate_hz:>7.0f}{100 * m.load:>6.1f}%{m.frames:>9}")
    rows.append(f"{'total':<14}{n.total_rate_hz:>7.0f}{100 * n.total_load:>6.1f}%")
    rows.append(f"load: {n.bus_name}, worst stuffing")
    frames = "\n".join(rows)

    period = "-" if n.period_s is None else f"{1e3 * n.period_s:.3f} ms"
    health = [
        "plant's late periods (PlantStatus)",
        f" overruns    {_f(n.overruns, 'd')}  {_f(n.overruns_rate, '+.1f', '/s')}",
        f" late duties {_f(n.late_frames, 'd')}  {_f(n.late_rate, '+.1f', '/s')}",
        f"stalls {n.stalls}  longest {1e3 * n.longest_stall_s:.0f} ms"
        + (f"  now {1e3 * n.stall_now_s:.0f} ms" if n.stall_now_s else ""),
        f" plant samples every {period}",
        "rejected by the monitor",
    ]
    rejected = [
        f" {msg} {reason} {count}"
        for msg, by in sorted(n.rejected.items())
        for reason, count in sorted(by.items())
    ]
    health += rejected or [" none"]
    health.append(f"view dropped {n.dropped} of {n.dropped + n.decoded}")
    health.append(f"periods not received {n.missed}")
    health.append(f"window {window_s:g} s" + ("  PAUSED" if paused else ""))
    return plant, frames, "\n".join(health)


class MonitorApp(App[None]):
    """Live view of a bench's bus (see :mod:`bench.monitor`).

    Parameters
    ----------
    model : MonitorModel
        Fed by a :class:`~bench.monitor._reader.BusReader` (or by hand).
    title : str
        First line of the screen (the bus, the run).
    refresh_hz : float
        Redraws per second.
    stop : callable, optional
        Polled at every redraw; True closes the view (exit status 0).
    reader_error : callable, optional
        The bus reader's last error, shown on the status line.
    clock : callable
        Time source (``time.time``; the screenshot tool freezes it).
    """

    CSS = """
    Screen { layout: vertical; }
    #title { height: 1; background: $primary-darken-2; color: $text; text-style: bold; }
    #status { height: 1; padding: 0 1; }
    #status.live { background: $success-darken-2; }
    #status.stalled { background: $warning-darken-2; }
    #status.waiting, #status.foreign, #status.stopped { background: $error-darken-1; }
    #plots { grid-size: 3 2; height: 1fr; min-height: 12; }
    #plots .legend { height: 1; text-wrap: nowrap; text-overflow: ellipsis; padding: 0 1; }
    #numbers { height: auto; max-height: 16; }
    #numbers Static {
        width: 1fr; max-width: 42; padding: 0 1; border-left: solid $primary-darken-2;
        text-wrap: nowrap; text-overflow: ellipsis;
    }
    #numbers #plant { border-left: none; }
    """

    TITLE = "bench monitor"
    ENABLE_COMMAND_PALETTE = False

    BINDINGS: ClassVar[list[BindingType]] = [
        Binding("q", "quit_view", "quit"),
        Binding("space,p", "pause", "pause"),
        Binding("plus,equals_sign,i", "zoom(-1)", "zoom in"),
        Binding("minus,o", "zoom(1)", "zoom out"),
        Binding("r", "reset", "reset statistics"),
        Binding("ctrl+c", "interrupt", "interrupt", show=False, priority=True),
    ]

    def __init__(
        self,
        model: MonitorModel,
        title: str,
        *,
        refresh_hz: float = 4.0,
        stop: Callable[[], bool] | None = None,
        reader_error: Callable[[], str | None] | None = None,
        clock: Callable[[], float] = time.time,
    ) -> None:
        super().__init__()
        self.model = model
        self.title_text = title
        self.refresh_hz = refresh_hz
        self.stop = stop
        self.reader_error = reader_error
        self.clock = clock
        self.paused = False
        self.t_view = clock()
        self._had_data: dict[str, bool] = {}
        windows = [w for w in WINDOWS_S if w <= model.pars.max_window_s] or [WINDOWS_S[0]]
        self.windows = tuple(windows)
        self.i_window = min(
            range(len(windows)), key=lambda i: abs(math.log(windows[i] / DEFAULT_WINDOW_S))
        )

    @property
    def window_s(self) -> float:
        return self.windows[self.i_window]

    def compose(self) -> ComposeResult:
        yield Static(self.title_text, id="title", markup=False)
        yield Static("", id="status", markup=False)
        with Grid(id="plots"):
            for pid, title, _ in PLOTS:
                with Vertical():
                    yield Static(self._legend(pid, title), classes="legend")
                    yield PlotextPlot(id=pid)
        with Horizontal(id="numbers"):
            yield Static("", id="plant", markup=False)
            yield Static("", id="frames", markup=False)
            yield Static("", id="health", markup=False)
        yield Footer()

    @staticmethod
    def _legend(pid: str, title: str) -> Text:
        """A plot's title with its traces in their colours (plotext's legend hides data)."""
        text = Text(title, style="bold")
        names = [n for n, (plot, _, _) in TRACES.items() if plot == pid]
        for (r, g, b), name in zip(_COLORS, names, strict=False):
            text.append("  ")
            text.append("━━ " + TRACES[name][1], style=f"rgb({r},{g},{b})")
        return text

    def on_mount(self) -> None:
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGTERM, signal.SIGHUP):
            try:
                loop.add_signal_handler(sig, self.exit)
            except (NotImplementedError, RuntimeError, ValueError):
                pass  # not the main thread (tests drive the app in-process)
        self.tick()
        self.set_interval(1.0 / self.refresh_hz, self.tick)

    # -- keys --------------------------------------------------------------

    def action_quit_view(self) -> None:
        self.exit(return_code=0)

    def action_interrupt(self) -> None:
        self.exit(return_code=EXIT_INTERRUPTED)

    def action_pause(self) -> None:
        self.paused = not self.paused
        self.draw()

    def action_zoom(self, step: int) -> None:
        self.i_window = max(0, min(len(self.windows) - 1, self.i_window + step))
        self.draw()

    def action_reset(self) -> None:
        self.model.reset(self.clock())
        self.draw()

    # -- drawing -----------------------------------------------------------

    def tick(self) -> None:
        if self.stop is not None and self.stop():
            self.exit(return_code=0)
            return
        now = self.clock()
        self.model.update(now)
        if not self.paused:
            self.t_view = now
            self.draw()

    def draw(self) -> None:
        try:
            self._draw()
        except NoMatches:  # a redraw racing the screen's teardown at exit
            pass

    def _draw(self) -> None:
        now = self.t_view
        n = self.model.numbers(now)
        status = self.query_one("#status", Static)
        line = n.status_line
        err = self.reader_error() if self.reader_error else None
        if err:
            line += f"; bus error: {err}"
        if self.paused:
            line = "PAUSED (space to resume) - " + line
        status.update(line)
        status.set_classes(n.status)
        plant, frames, health = format_numbers(n, self.window_s, self.paused)
        self.query_one("#plant", Static).update(plant)
        self.query_one("#frames", Static).update(frames)
        self.query_one("#health", Static).update(health)
        self._plots(now)

    def _plots(self, now: float) -> None:
        w = self.window_s
        t0 = now - w
        by_plot: dict[str, list[str]] = {}
        for name, (plot, _, _) in TRACES.items():
            by_plot.setdefault(plot, []).append(name)
        for pid, _, ylim in PLOTS:
            widget = self.query_one(f"#{pid}", PlotextPlot)
            plt = widget.plt
            plt.clear_data()
            buckets = max(8, widget.size.width)
            lo, hi = math.inf, -math.inf
            windows = [self.model.traces[name].window(t0, now) for name in by_plot.get(pid, [])]
            has_data = any(len(t) for t, _ in windows)
            if not has_data and not self._had_data.get(pid, True):
                continue  # empty before and now: no need to build it again
            self._had_data[pid] = has_data
            for color, (t, v) in zip(_COLORS, windows, strict=False):
                x, y = envelope(t, v, t0, now, buckets)
                if len(x):
                    plt.plot((x - now).tolist(), y.tolist(), marker=MARKER, color=color)
                    lo, hi = min(lo, float(y.min())), max(hi, float(y.max()))
            plt.xlim(-w, 0.0)
            if isinstance(ylim, tuple):
                plt.ylim(*ylim)
            elif hi >= lo:
                pad = max(0.0, ylim - (hi - lo)) / 2.0
                plt.ylim(lo - pad, hi + pad)
            widget.refresh()
