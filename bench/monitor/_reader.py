"""The bus-reading thread of the monitor: every frame into the model, nothing sent.

The reader does no decoding (:meth:`MonitorModel.on_frame` looks at the
identifier only), so it keeps up with the bus while the view draws; what the
view cannot decode in time is dropped from the view by the model, never
from the bus. The monitor is a passive listener: it opens its own socket
(socketcan and udp_multicast deliver every frame to every socket) and never
calls ``send``. A real adapter opened by python-can may still acknowledge
frames on the wire like any node; python-can has no portable listen-only
switch.
"""

from __future__ import annotations

import threading
import time

import can

from bench.monitor._model import MonitorModel

__all__ = ["BusReader", "receive_time"]

#: A frame's own timestamp is used when it is within this far before now (s):
#: the kernel's receive stamp (socketcan, udp_multicast), which stays right
#: when the monitor reads its socket late (a niced monitor on a busy host may
#: lag by seconds). Much older, or ahead of now: another clock (an adapter's
#: time since it opened), replaced by the time of reading.
_STAMP_AGE_MAX_S = 60.0
_STAMP_AHEAD_MAX_S = 1.0


def receive_time(stamp: float, now: float) -> float:
    """Receive time of a frame on the ``time.time()`` clock (see :data:`_STAMP_AGE_MAX_S`)."""
    if now - _STAMP_AGE_MAX_S <= stamp <= now + _STAMP_AHEAD_MAX_S:
        return stamp
    return now


class BusReader:
    """Read ``bus`` in a daemon thread into ``model`` until :meth:`stop`.

    Parameters
    ----------
    bus : can.BusABC
        An open bus; the reader does not shut it down.
    model : MonitorModel
    """

    def __init__(self, bus: can.BusABC, model: MonitorModel) -> None:
        self.bus = bus
        self.model = model
        self.error: str | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="monitor-reader", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self, timeout: float = 1.0) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout)

    def _run(self) -> None:
        recv = self.bus.recv
        on_frame = self.model.on_frame
        while not self._stop.is_set():
            try:
                msg = recv(0.1)
            except Exception as e:  # a driver's error: shown, and the reading goes on
                self.error = f"{type(e).__name__}: {e}".splitlines()[0]
                time.sleep(0.1)
                continue
            if msg is None:
                continue
            on_frame(receive_time(msg.timestamp, time.time()), msg)
