"""The recorder's batch hand-off: the native reader's messages built from C-parsed fields
equal python-can's ``unpack_message``, and :meth:`Recorder.on_messages` follows a run
exactly as :meth:`Recorder.on_message_received` does frame by frame."""

from __future__ import annotations

import random
import struct

import can
import msgpack
import pytest
from can.interfaces.udp_multicast.utils import pack_message, unpack_message

from bench.nodes._loops import STATE_DONE
from bench.nodes.native import _recorder_native
from bench.runs._recorder import BATCH_DECODE_MIN, Recorder
from bench.wire._codec import Codec
from bench.wire._frames import FrameArray
from tests.frame_helpers import message_fields

CODEC = Codec()
RUN = 4242


class _Kept(can.Listener):
    def __init__(self) -> None:
        self.got: list[can.Message] = []

    def on_message_received(self, msg: can.Message) -> None:
        self.got.append(msg)


def _canonical() -> list[can.Message]:
    """Every kind of frame python-can's udp_multicast bus carries in its usual map."""
    return [
        can.Message(arbitration_id=0x123, is_extended_id=False, data=b"\x01\x02\x03"),
        can.Message(arbitration_id=0x7FF, is_extended_id=False, data=b""),
        can.Message(arbitration_id=0x1ABCDE0, is_extended_id=True, data=bytes(8)),
        can.Message(arbitration_id=0x55, is_fd=True, data=bytes(range(64))),
        can.Message(arbitration_id=0x56, is_fd=True, bitrate_switch=True, data=bytes(12)),
        can.Message(
            arbitration_id=0x57, is_fd=True, error_state_indicator=True, data=bytes(range(20))
        ),
        can.Message(arbitration_id=0x4, is_error_frame=True, data=bytes(8)),
        can.Message(arbitration_id=0x10, is_extended_id=False, channel=3, data=b"\x09"),
        can.Message(arbitration_id=0x11, is_extended_id=False, channel=70000, data=b"\x09"),
        CODEC.encode("PhaseSamples", {"i_a": 1, "i_b": 2, "u_dc": 300, "status": 0, "step": 5}),
    ]


def _packed(m: can.Message, **extra: object) -> bytes:
    d = msgpack.unpackb(pack_message(m), raw=False)
    d.update(extra)
    return bytes(msgpack.packb(d, use_bin_type=True))


def _odd() -> list[bytes]:
    """Datagrams bn_rec_parse leaves to python-can: another shape, a remote frame, and
    messages python-can's check refuses (counted as malformed)."""
    base = can.Message(arbitration_id=0x20, is_extended_id=False, data=b"\x01\x02")
    remote = can.Message(arbitration_id=0x21, is_extended_id=False, is_remote_frame=True, dlc=4)
    return [
        pack_message(remote),
        _packed(base, channel="vcan0"),  # a str channel
        _packed(base, extra_key=1),  # a twelfth key
        _packed(base, is_fd=1),  # an int for a bool
        _packed(base, timestamp=5),  # an int time stamp
        _packed(base, dlc=3),  # dlc and data disagree: refused
        _packed(base, arbitration_id=0x800),  # beyond 11 bits: refused
        _packed(base, bitrate_switch=True),  # BRS on a classic frame: refused
        _packed(base, data=bytes(9), dlc=9),  # 9 bytes classic: refused
        _packed(remote, is_error_frame=True),  # remote and error: refused
        _packed(base, data=None),
        pack_message(base)[:-3],  # truncated map
        b"\xc1 not msgpack",
        b"",
        bytes([0x8B]) + pack_message(base)[1:] + b"\x00",  # trailing byte
    ]


def _reference(dgrams: list[tuple[bytes, int, int]]) -> tuple[list[can.Message], int]:
    out, bad = [], 0
    for d, sec, nsec in dgrams:
        try:
            out.append(unpack_message(d, replace={"timestamp": sec + nsec * 1.0e-9}, check=True))
        except Exception:
            bad += 1
    return out, bad


def _same(a: list[can.Message], b: list[can.Message]) -> None:
    assert [message_fields(m) for m in a] == [message_fields(m) for m in b]
    assert all(type(x.data) is bytearray for x in a)
    assert [type(x.channel) for x in a] == [type(x.channel) for x in b]
    assert [type(x.arbitration_id) for x in a] == [type(x.arbitration_id) for x in b]


pytestmark = pytest.mark.skipif(
    _recorder_native.unavailable("udp_multicast") is not None,
    reason="the native library does not build here",
)


def test_a_parsed_datagram_is_the_message_unpack_message_makes() -> None:
    frames = _canonical()
    dgrams = [
        (pack_message(m), 1_700_000_000 + i, 123_456_789 * i % 10**9) for i, m in enumerate(frames)
    ]
    batch = _recorder_native.SlotBatch("udp_multicast", "239.0.0.1")
    msgs, bad, rows = batch.messages(batch.put(dgrams))
    assert batch.parsed == len(frames) and bad == 0  # every one parsed in C
    ref, _ = _reference(dgrams)
    _same(msgs, ref)
    # and as rows, the columns the recorder reads in place of the messages' fields
    assert rows is not None
    assert rows.tobytes() == FrameArray.from_messages(ref).rows.tobytes()
    # a float32 time stamp is replaced by the receive stamp all the same
    m = msgpack.unpackb(dgrams[0][0], raw=False)
    f32 = b"\x8b\xa9timestamp\xca" + struct.pack(">f", 1.5) + pack_message(frames[0])[20:]
    assert msgpack.unpackb(f32, raw=False).keys() == m.keys()
    msgs, bad, _ = batch.messages(batch.put([(f32, 7, 0)]))
    assert batch.parsed == 1 and msgs[0].timestamp == 7.0
    _same(msgs, _reference([(f32, 7, 0)])[0])


def test_other_datagrams_are_python_cans_and_its_refusals_counted_as_malformed() -> None:
    odd = _odd()
    frames = [pack_message(m) for m in _canonical()]
    dgrams = [(d, 10 + i, 0) for i, d in enumerate(odd + frames)]
    # a datagram longer than a slot: truncated by the socket
    dgrams.append((pack_message(_canonical()[3]) + bytes(400), 99, 0))
    batch = _recorder_native.SlotBatch("udp_multicast", "239.0.0.1")
    msgs, bad, rows = batch.messages(batch.put(dgrams))
    assert batch.parsed == len(frames) and rows is None
    ref, ref_bad = _reference(dgrams[:-1])
    assert bad == ref_bad + 1 and ref_bad >= 9
    _same(msgs, ref)


def _mixed(run_id: int) -> list[can.Message]:
    """A capture of every frame the recorder follows: samples through counter wraps,
    retransmitted and lost; this run's truth and telemetry with acknowledgements, other
    runs' and a controller's without a nonce (0); bad CRCs, bad lengths, extended and
    remote frames with the bench's identifiers; duties good and bad; status up to done."""
    rng = random.Random(7)
    m = 1 << CODEC.step_bits("PhaseSamples")
    out: list[can.Message] = []
    for k in range(3 * m):
        s = CODEC.encode(
            "PhaseSamples", {"i_a": 1.0, "i_b": -1.0, "u_dc": 300, "status": 0, "step": k % m}
        )
        if k % 97 == 3:
            continue  # lost
        out.append(s)
        if k % 50 == 7:
            out.append(out[-20])  # an old one again
        rid = run_id if k % 13 else rng.choice([run_id + 1, run_id + 2, 0])
        t = CODEC.encode(
            "PlantTruth",
            {
                "theta_e": 0.1,
                "w_m": 5.0,
                "tau_e": 0,
                "tau_L": 0,
                "step": k,
                "duty_age": 0,
                "run_id": rid,
            },
        )
        out.append(t)
        c = CODEC.encode(
            "CtrlTelemetry",
            {
                "theta_hat": 0.1,
                "w_hat": 1.0,
                "err": 0,
                "mode": 1,
                "step": k,
                "run_id": rid,
                "cmd_ack_valid": k % 2,
                "cmd_ack": k // 3,
            },
        )
        out.append(c)
        d = CODEC.encode(
            "PwmDuty",
            {"duty_a": 0.5, "duty_b": 0.5, "duty_c": 0.5, "enable": 1, "step": k % m},
        )
        out.append(d)
        if k % 31 == 0:  # a bad CRC on each kind
            for f in (s, t, c, d):
                data = bytearray(f.data)
                data[-1] ^= 0x5A
                out.append(
                    can.Message(
                        arbitration_id=f.arbitration_id,
                        is_extended_id=False,
                        is_fd=f.is_fd,
                        bitrate_switch=f.bitrate_switch,
                        data=data,
                    )
                )
        if k % 41 == 0:  # a short one, an extended and a remote one with its identifier
            out.append(
                can.Message(arbitration_id=s.arbitration_id, is_extended_id=False, data=s.data[:4])
            )
            out.append(
                can.Message(
                    arbitration_id=t.arbitration_id, is_extended_id=True, is_fd=True, data=t.data
                )
            )
            out.append(
                can.Message(
                    arbitration_id=s.arbitration_id,
                    is_extended_id=False,
                    is_remote_frame=True,
                    dlc=8,
                )
            )
        if k % 200 == 0 or k == 3 * m - 1:
            out.append(
                CODEC.encode(
                    "PlantStatus",
                    {
                        "state": STATE_DONE if k == 3 * m - 1 else 1,
                        "fault_code": k // 600,
                        "overruns": 0,
                        "late_frames": 0,
                        "step": k % 65536,
                    },
                )
            )
        if k % 300 == 5:
            out.append(can.Message(arbitration_id=0x6AA, is_extended_id=False, data=b"\x01"))
    return out


_FOLLOWED = (
    "step",
    "last_raw_step",
    "truth_step",
    "acks",
    "foreign",
    "known",
    "status",
    "fault_steps",
    "duties_ok",
    "duty_rejected",
)


@pytest.mark.parametrize("run_id", [None, RUN])
def test_a_batch_is_followed_as_its_frames_one_by_one(run_id: int | None) -> None:
    frames = _mixed(RUN)
    assert len(frames) >= 4 * BATCH_DECODE_MIN
    writers = [_Kept() for _ in range(4)]
    recs = [Recorder(CODEC, w, 2, watch_duties=True) for w in writers]
    for r in recs:
        r.run_id = run_id
    for f in frames:  # python-can's Notifier
        recs[0].on_message_received(f)
    recs[1].on_messages(list(frames))  # one batch: decoded column-wise
    recs[3].on_messages(list(frames), FrameArray.from_messages(frames).rows)  # the reader's
    rng = random.Random(1)
    i = 0
    while i < len(frames):  # batches short and long: both ways of decoding, mixed
        n = rng.choice([1, 5, BATCH_DECODE_MIN - 1, BATCH_DECODE_MIN, 700])
        recs[2].on_messages(list(frames[i : i + n]))
        i += n
    one = recs[0]
    assert one.step > 2 * (1 << CODEC.step_bits("PhaseSamples"))  # wrapped twice
    assert one.duties_ok > 0 and one.duty_rejected and one.done.is_set()
    if run_id is None:
        assert one.known > 0 and not one.acks
    else:
        assert one.truth_step > 0 and one.acks and set(one.foreign) == {RUN + 1, RUN + 2}
    for r, w in zip(recs[1:], writers[1:], strict=True):
        for k in _FOLLOWED:
            assert getattr(r, k) == getattr(one, k), k
        assert r.done.is_set() == one.done.is_set()
        assert r.frames == one.frames and all(m.channel == 2 for m in r.frames)
        assert w.got == writers[0].got


def test_decoding_only_some_signals_keeps_every_verdict_and_value() -> None:
    from bench.wire._batch_decode import decode_batch

    frames = _mixed(RUN)
    # an out-of-range value in a signal not asked for still rejects its frame
    status = CODEC.encode(
        "PlantStatus",
        {"state": 1, "fault_code": 0, "overruns": 0, "late_frames": 0, "step": 1},
    )
    data = bytearray(status.data)
    data[1] = 0xFF  # the state's byte: an undefined state
    frames.append(
        can.Message(
            arbitration_id=status.arbitration_id,
            is_extended_id=False,
            data=CODEC.with_crc("PlantStatus", data),
        )
    )
    whole = decode_batch(frames, CODEC)
    only = ("run_id", "step")
    part = decode_batch(frames, CODEC, only)
    assert part.rejected == whole.rejected and whole.rejected.get("out_of_range", 0) >= 1
    assert part.messages.keys() == whole.messages.keys()
    for name, w in whole.messages.items():
        p = part.messages[name]
        assert p.index.tolist() == w.index.tolist()
        for k in only:
            if k in w.signals:
                assert p.signals[k].tolist() == w.signals[k].tolist()
        assert set(p.signals) < set(w.signals) or name == "PlantStatus"
