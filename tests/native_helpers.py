"""The native controller unit fed frame by frame in a test, without a transport."""

from __future__ import annotations

import ctypes
from collections.abc import Callable
from typing import Any

import can

from bench.nodes._controller_node import ControllerNode


def native_answers(
    node: ControllerNode,
    frames: list[can.Message],
    on_event: Callable[[int], None] | None = None,
) -> list[tuple[int, bytes]]:
    """Every frame the native controller unit built on ``node`` answers to ``frames``, as
    ``(id, data)`` in order; each event the unit returns for handled as its node handles
    it (``on_event`` sees it first), its counters merged back into ``node`` at the end
    (``node.report()`` then reads them)."""
    from bench.nodes.native import controller_node as native

    nat = native.NativeController(node, realtime=False)
    got: list[tuple[int, bytes]] = []

    @native.SINK
    def sink(ctx: Any, f: Any) -> int:
        got.append((f.contents.id, bytes(f.contents.data[: f.contents.len])))
        return 0

    for msg in frames:
        f = native.Frame(id=msg.arbitration_id, len=len(msg.data), flags=0)
        f.data[: len(msg.data)] = list(msg.data)
        ev = nat.dll.bn_ctl_on_frame(nat.addr, ctypes.byref(f), sink, None)
        while ev != native.EV_NONE:
            if on_event is not None:
                on_event(ev)
            nat.handle(ev)
            ev = nat.dll.bn_ctl_resume(nat.addr, sink, None)
    nat.merge()
    return got
