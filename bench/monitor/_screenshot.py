"""A picture of the monitor's view of known frames (docs/USAGE.md's screenshot).

The frames of a run (a capture, or a scenario run in this process) are fed
to the model as the bus would deliver them, up to an instant, and the view is
drawn once, headless, at a fixed terminal size, and saved as SVG by Textual.
"""

from __future__ import annotations

import asyncio
from collections.abc import Iterable
from pathlib import Path

import can

from bench.monitor._model import MonitorModel, MonitorPars
from bench.wire._codec import Codec

__all__ = ["paced", "screenshot"]


def paced(
    frames: Iterable[can.Message], codec: Codec, T_s: float
) -> list[tuple[float, can.Message]]:
    """Frames with the receive times of a real-time bench: period k at ``k T_s``.

    For frames without timestamps (:func:`bench.nodes._loops.run_inprocess`):
    each ``PhaseSamples`` frame starts a period.
    """
    samples = codec.frame_id("PhaseSamples")
    out = []
    k = 0
    for m in frames:
        if m.arbitration_id == samples and not m.is_extended_id:
            k += 1
        out.append((k * T_s, m))
    return out


def screenshot(
    frames: Iterable[tuple[float, can.Message]],
    path: str | Path,
    *,
    at: float,
    codec: Codec,
    pars: MonitorPars,
    title: str,
    size: tuple[int, int] = (150, 45),
    window_s: float | None = None,
) -> Path:
    """Save the view at time ``at`` of ``frames`` (receive time, frame) as SVG.

    Every frame up to ``at`` is taken (no frame is dropped from the view:
    ``pars.max_view_frames`` is ignored), with the view's updates every
    quarter second as when it runs.
    """
    from dataclasses import replace

    from bench.monitor._app import MonitorApp

    model = MonitorModel(codec, replace(pars, max_view_frames=1 << 62, queue_frames=1 << 62))
    t_update = None
    for t, m in frames:
        if t > at:
            break
        if t_update is None:
            t_update = t
            model.update(t)
        while t >= t_update + 0.25:
            t_update += 0.25
            model.update(t_update)
        model.on_frame(t, m)
    model.update(at)
    app = MonitorApp(model, title, clock=lambda: at)
    if window_s is not None and window_s in app.windows:
        app.i_window = app.windows.index(window_s)
    out = Path(path)

    async def shoot() -> None:
        async with app.run_test(size=size) as pilot:
            await pilot.pause()
            app.draw()
            await pilot.pause()
            app.save_screenshot(filename=out.name, path=str(out.parent))

    asyncio.run(shoot())
    return out
