"""Decoding a whole capture at once: the DBC applied to arrays of payloads.

:meth:`bench.wire._codec.Codec.decode` handles one frame in a few microseconds,
which is right for a node but makes the analysis of a long capture slow.
Here the frames of each message are stacked into one ``(n, length)`` byte
array and every check the codec makes is done column-wise with numpy:

- length against the DBC (``bad_length``),
- the E2E CRC (CRC-8 SAE J1850 over the data ID and the payload, see
  :mod:`bench.wire._e2e`), one table lookup per byte column (``bad_crc``),
- little-endian bit fields unpacked from the byte columns and scaled with
  the DBC's ``raw * scale + offset`` in float64, the same arithmetic cantools
  does on Python floats, so every value is bit-identical to ``Codec.decode``,
- the ``[min|max]`` checks of the signals whose raw range exceeds them
  (``out_of_range``).

Messages with big-endian, float or multiplexed signals fall back to the
per-frame codec. Error and remote frames are counted as frames and skipped,
IDs not in the DBC are counted as unknown.
"""

from __future__ import annotations

import operator
from collections.abc import Collection, Sequence
from dataclasses import dataclass, field

import can
import numpy as np
import numpy.typing as npt

from bench.wire._codec import REJECT_BAD_CRC, REJECT_BAD_LENGTH, REJECT_OUT_OF_RANGE, Codec, _Spec
from bench.wire._e2e import CRC8_J1850_TABLE
from bench.wire._frames import FrameArray

__all__ = ["BatchDecoded", "MessageBatch", "decode_batch"]

IntArray = npt.NDArray[np.int64]
FloatArray = npt.NDArray[np.float64]

_EXTENDED = 1 << 31
_SKIP = -1  # key of error and remote frames
_TABLE = np.array(CRC8_J1850_TABLE, dtype=np.uint8)
_DATA = operator.attrgetter("data")


@dataclass(slots=True)
class MessageBatch:
    """The valid frames of one message, in capture order.

    Parameters
    ----------
    name : str
        Message name.
    index : int array
        Position of each valid frame in the capture.
    signals : dict of str to float array
        Physical values per signal (``crc`` included when the message has one;
        ``i_c`` derived for ``PhaseSamples`` as the codec does).
    """

    name: str
    index: IntArray
    signals: dict[str, FloatArray]


@dataclass(slots=True)
class BatchDecoded:
    """Every frame of a capture, decoded."""

    messages: dict[str, MessageBatch]
    frames: int = 0
    skipped: int = 0
    unknown_ids: int = 0
    rejected: dict[str, int] = field(default_factory=dict)


def _vector_ok(spec: _Spec) -> bool:
    return all(
        s.byte_order == "little_endian" and not s.is_float and s.length <= 56
        for s in spec.message.signals
    )


def _unpack(
    spec: _Spec, data: npt.NDArray[np.uint8], only: Collection[str] | None = None
) -> dict[str, FloatArray]:
    """Physical values of every signal of ``spec`` (of ``only`` and the range-checked
    ones, when given) from stacked payloads ``data``."""
    out: dict[str, FloatArray] = {}
    n = data.shape[0]
    keep = None if only is None else {*only, *(name for name, _, _ in spec.checked)}
    for s in spec.message.signals:
        if keep is not None and s.name not in keep:
            continue
        b0, b1 = s.start // 8, (s.start + s.length - 1) // 8
        acc = np.zeros(n, dtype=np.uint64)
        for b in range(b0, b1 + 1):
            acc |= data[:, b].astype(np.uint64) << np.uint64(8 * (b - b0))
        raw = (acc >> np.uint64(s.start % 8)) & np.uint64((1 << s.length) - 1)
        val = raw.astype(np.int64)
        if s.is_signed:
            val = np.where(val >= (1 << (s.length - 1)), val - (1 << s.length), val)
        scale, offset = s.conversion.scale, s.conversion.offset
        phys = val.astype(np.float64)
        if not (scale == 1 and offset == 0):
            phys = phys * float(scale) + float(offset)
        out[s.name] = phys
    return out


def _crc_ok(spec: _Spec, data: npt.NDArray[np.uint8]) -> npt.NDArray[np.bool_]:
    reg = np.full(data.shape[0], spec.e2e_start, dtype=np.uint8)
    for j in range(data.shape[1]):
        if j != spec.crc_index:
            reg = _TABLE[reg ^ data[:, j]]
    ok: npt.NDArray[np.bool_] = (reg ^ np.uint8(0xFF)) == data[:, spec.crc_index]
    return ok


def _decode_one_by_one(
    codec: Codec, spec: _Spec, frames: Sequence[can.Message], idx: list[int], res: BatchDecoded
) -> MessageBatch:
    keep: list[int] = []
    rows: list[dict[str, float]] = []
    for i in idx:
        d = codec._decode(spec, frames[i].data)
        if d.reason is not None:
            res.rejected[d.reason] = res.rejected.get(d.reason, 0) + 1
            continue
        keep.append(i)
        rows.append(d.signals)
    names = list(rows[0]) if rows else [s.name for s in spec.message.signals]
    sig = {k: np.array([float(r[k]) for r in rows], dtype=np.float64) for k in names}
    return MessageBatch(spec.name, np.array(keep, dtype=np.int64), sig)


def decode_batch(
    frames: Sequence[can.Message], codec: Codec, only: Collection[str] | None = None
) -> BatchDecoded:
    """Decode and check every frame of ``frames`` with ``codec``'s DBC.

    The result per message holds exactly the frames :meth:`Codec.decode`
    accepts, with the same values; rejected frames are counted by reason.
    ``only``: the signals wanted (the checks are made all the same; of a message
    decoded frame by frame, every signal comes).
    A :class:`~bench.wire._frames.FrameArray` is read from its columns, without a
    :class:`can.Message` made (but for a message decoded frame by frame).
    """
    n = len(frames)
    res = BatchDecoded(messages={}, frames=n)
    rows = frames.rows if isinstance(frames, FrameArray) and not frames.made else None
    if rows is not None:  # the block's columns: no can.Message made
        keys = rows["id"].astype(np.int64) | np.where(rows["extended"], _EXTENDED, 0)
        keys[rows["error"] | rows["remote"]] = _SKIP
    else:
        keys = np.fromiter(
            (
                _SKIP
                if m.is_error_frame or m.is_remote_frame
                else (m.arbitration_id | _EXTENDED if m.is_extended_id else m.arbitration_id)
                for m in frames
            ),
            dtype=np.int64,
            count=n,
        )
    specs: dict[int, _Spec] = codec._by_id
    res.skipped = int(np.count_nonzero(keys == _SKIP))
    order = np.argsort(keys, kind="stable")
    sorted_keys = keys[order]
    n_known = 0
    for key, spec in specs.items():
        lo, hi = np.searchsorted(sorted_keys, [key, key + 1])
        if hi == lo:
            continue
        n_known += int(hi - lo)
        idx_arr = order[lo:hi]  # stable sort: capture order within the message
        idx = idx_arr.tolist()
        if not _vector_ok(spec):
            res.messages[spec.name] = _decode_one_by_one(codec, spec, frames, idx, res)
            continue
        L = spec.length
        if rows is not None:
            lens = rows["len"][idx_arr].astype(np.int64)
        else:
            payloads = list(map(_DATA, map(frames.__getitem__, idx)))
            lens = np.fromiter(map(len, payloads), dtype=np.int64, count=len(payloads))
        good_len = lens == L
        n_bad_len = int(len(lens) - np.count_nonzero(good_len))
        if n_bad_len:
            res.rejected[REJECT_BAD_LENGTH] = res.rejected.get(REJECT_BAD_LENGTH, 0) + n_bad_len
            idx_arr = idx_arr[good_len]
            if rows is None:
                payloads = [p for p, g in zip(payloads, good_len.tolist(), strict=True) if g]
        if rows is not None:
            data = np.ascontiguousarray(rows["data"][idx_arr, :L])
        else:
            data = np.frombuffer(b"".join(payloads), dtype=np.uint8).reshape(len(payloads), L)
        ok = np.ones(len(data), dtype=bool)
        if spec.crc_index >= 0:
            ok = _crc_ok(spec, data)
            n_bad = int(len(ok) - np.count_nonzero(ok))
            if n_bad:
                res.rejected[REJECT_BAD_CRC] = res.rejected.get(REJECT_BAD_CRC, 0) + n_bad
        sig = _unpack(spec, data, only)
        if spec.checked:
            in_range = np.ones(len(ok), dtype=bool)
            for name, s_lo, s_hi in spec.checked:
                v = sig[name]
                in_range &= (v >= s_lo) & (v <= s_hi)
            bad = ok & ~in_range
            n_bad = int(np.count_nonzero(bad))
            if n_bad:
                res.rejected[REJECT_OUT_OF_RANGE] = res.rejected.get(REJECT_OUT_OF_RANGE, 0) + n_bad
            ok &= in_range
        if not np.all(ok):
            idx_arr = idx_arr[ok]
            sig = {k: v[ok] for k, v in sig.items()}
        if spec.derive_i_c and "i_a" in sig and "i_b" in sig:
            sig["i_c"] = -sig["i_a"] - sig["i_b"]
        res.messages[spec.name] = MessageBatch(spec.name, idx_arr.astype(np.int64), sig)
    res.unknown_ids = n - res.skipped - n_known
    return res
