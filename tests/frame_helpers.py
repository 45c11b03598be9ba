"""Shared by the tests that compare frames: every field of a :class:`can.Message` a
consumer or a capture file keeps, as one tuple (two frames are the same when these are)."""

from __future__ import annotations

import can


def message_fields(m: can.Message) -> tuple[object, ...]:
    """The frame's time, identifier, flags, length, data, channel and direction."""
    return (
        m.timestamp,
        m.arbitration_id,
        m.is_extended_id,
        m.is_remote_frame,
        m.is_error_frame,
        m.is_fd,
        m.bitrate_switch,
        m.error_state_indicator,
        m.dlc,
        bytes(m.data),
        m.channel,
        m.is_rx,
    )
