"""Frames as one numpy array, made :class:`can.Message` only where one is asked for.

A run in this process (:func:`bench.nodes._loops.run_inprocess` on the native pair)
records hundreds of thousands of frames; a :class:`can.Message` per frame costs
more than the run's arithmetic.  :class:`FrameArray` keeps them as rows of
:data:`FRAME_DTYPE` (time stamp, identifier, flags, length, data bytes) and is a
:class:`~collections.abc.Sequence` of :class:`can.Message`: the first item or
iteration asked for makes the messages (the fields the codec gives them), once,
so every consumer that takes a list of frames takes it unchanged.  Those that look at the whole block at once
(:func:`bench.wire._batch_decode.decode_batch`) read :attr:`FrameArray.rows`
without any message being made, as long as none has been (:attr:`FrameArray.made`).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from typing import overload

import can
import numpy as np
import numpy.typing as npt

__all__ = ["FRAME_DTYPE", "FrameArray", "with_ids"]

#: One frame: receive time (s, 0.0 unknown), identifier without flag bits, the
#: message's kind as booleans, the payload length and the payload (0..64 bytes).
FRAME_DTYPE = np.dtype(
    [
        ("timestamp", np.float64),
        ("id", np.uint32),
        ("extended", np.bool_),
        ("fd", np.bool_),
        ("brs", np.bool_),
        ("remote", np.bool_),
        ("error", np.bool_),
        ("len", np.uint8),
        ("data", np.uint8, (64,)),
    ]
)


class FrameArray(Sequence[can.Message]):
    """Frames in wire order as rows of :data:`FRAME_DTYPE` (module docstring).

    ``rows`` is kept as given (not copied).  The first item or iteration asked for
    makes every frame a :class:`can.Message` (``is_rx`` True, no channel) and keeps
    them: from then on the array reads as that list (a time stamp a consumer sets
    stays), while ``rows`` stay the frames as recorded.  A slice of an array whose
    messages are not made is a :class:`FrameArray` of the same rows (nothing made).
    """

    __slots__ = ("_made", "rows")

    def __init__(self, rows: npt.NDArray[np.void]) -> None:
        if rows.dtype != FRAME_DTYPE or rows.ndim != 1:
            raise TypeError("FrameArray: rows of FRAME_DTYPE, one dimension")
        self.rows = rows
        self._made: list[can.Message] | None = None

    @classmethod
    def from_messages(cls, messages: Iterable[can.Message]) -> FrameArray:
        """The rows of ``messages`` (payloads of more than 64 bytes: ``ValueError``)."""
        ms = list(messages)
        rows = np.zeros(len(ms), dtype=FRAME_DTYPE)
        for j, m in enumerate(ms):
            d = bytes(m.data or b"")
            if len(d) > 64:
                raise ValueError(f"FrameArray: frame {j} has {len(d)} data bytes (at most 64)")
            r = rows[j]
            r["timestamp"] = m.timestamp
            r["id"] = m.arbitration_id
            r["extended"] = m.is_extended_id
            r["fd"] = m.is_fd
            r["brs"] = m.bitrate_switch
            r["remote"] = m.is_remote_frame
            r["error"] = m.is_error_frame
            r["len"] = len(d)
            r["data"][: len(d)] = np.frombuffer(d, dtype=np.uint8)
        return cls(rows)

    def messages(self) -> list[can.Message]:
        """Every frame as a :class:`can.Message`, made once (class docstring)."""
        if self._made is None:
            self._made = self._messages(self.rows)
        return self._made

    @property
    def made(self) -> bool:
        """True once the messages are made: a consumer may have changed them, so a reader
        of the whole block takes the messages, not ``rows``."""
        return self._made is not None

    def __len__(self) -> int:
        return len(self.rows)

    @overload
    def __getitem__(self, i: int) -> can.Message: ...

    @overload
    def __getitem__(self, i: slice) -> Sequence[can.Message]: ...

    def __getitem__(self, i: int | slice) -> can.Message | Sequence[can.Message]:
        if isinstance(i, slice):
            return FrameArray(self.rows[i]) if self._made is None else self._made[i]
        return self.messages()[i]

    def __iter__(self) -> Iterator[can.Message]:
        return iter(self.messages())

    def __repr__(self) -> str:
        return f"FrameArray({len(self.rows)} frames)"

    @staticmethod
    def _messages(rows: npt.NDArray[np.void]) -> list[can.Message]:
        ts = rows["timestamp"].tolist()
        ids = rows["id"].tolist()
        ext = rows["extended"].tolist()
        fd = rows["fd"].tolist()
        brs = rows["brs"].tolist()
        rtr = rows["remote"].tolist()
        err = rows["error"].tolist()
        lens = rows["len"].tolist()
        raw = rows["data"].tobytes()
        Message = can.Message
        out = []
        for j in range(len(ids)):
            o = 64 * j
            # can.Message's parameters in order: timestamp, arbitration_id, is_extended_id,
            # is_remote_frame, is_error_frame, channel, dlc, data, is_fd, is_rx,
            # bitrate_switch
            m = Message(ts[j], ids[j], ext[j], rtr[j], err[j], None, None, raw[o : o + lens[j]])
            m.is_fd, m.bitrate_switch = fd[j], brs[j]
            out.append(m)
        return out


def with_ids(frames: Sequence[can.Message], ids: Iterable[int]) -> Sequence[can.Message]:
    """The frames of ``frames`` whose identifier is one of ``ids``, in order, for a scan
    over a few messages: a :class:`FrameArray`'s rows selected by column (no
    :class:`can.Message` made for the others); any other sequence as it is."""
    if not isinstance(frames, FrameArray) or frames.made:
        return frames
    return FrameArray(frames.rows[np.isin(frames.rows["id"], np.fromiter(ids, dtype=np.uint32))])
