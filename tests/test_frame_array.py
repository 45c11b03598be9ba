"""Frames as one array (bench.wire._frames.FrameArray): the in-process pair's result.

A :class:`FrameArray` must read as the list of :class:`can.Message` it stands for
(every field a consumer looks at), decode through ``decode_batch`` to the same
values and rejections without making a message, and the in-process native run
must score exactly as the list of its messages does.
"""

from __future__ import annotations

import shutil

import can
import numpy as np
import pytest

from bench.wire._batch_decode import decode_batch
from bench.wire._codec import Codec
from bench.wire._frames import FrameArray, with_ids
from tests.frame_helpers import message_fields


def _sample_frames() -> list[can.Message]:
    codec = Codec()
    good = codec.encode(
        "PwmDuty", {"duty_a": 0.5, "duty_b": 0.25, "duty_c": 0.75, "enable": 1, "step": 7}
    )
    bad_crc = can.Message(
        arbitration_id=good.arbitration_id,
        data=bytes(good.data[:-1]) + b"\x00",
        is_extended_id=False,
    )
    short = can.Message(
        arbitration_id=good.arbitration_id, data=bytes(good.data[:4]), is_extended_id=False
    )
    return [
        good,
        bad_crc,
        short,
        can.Message(timestamp=1.5, arbitration_id=0x1ABCDEF, data=b"\x01\x02", is_extended_id=True),
        can.Message(arbitration_id=0x123, data=bytes(range(48)), is_fd=True, bitrate_switch=True, is_extended_id=False),
        can.Message(arbitration_id=0x7, is_error_frame=True, is_extended_id=False),
        codec.encode("PwmDuty", {"duty_a": 0.1, "duty_b": 0.2, "duty_c": 0.3, "enable": 0, "step": 8}),
    ]  # fmt: skip


def test_a_frame_array_reads_as_its_messages() -> None:
    msgs = _sample_frames()
    fa = FrameArray.from_messages(msgs)
    assert len(fa) == len(msgs)
    assert [message_fields(m) for m in fa] == [message_fields(m) for m in msgs]
    assert message_fields(fa[3]) == message_fields(msgs[3])
    assert message_fields(fa[-1]) == message_fields(msgs[-1])
    assert [message_fields(m) for m in fa[2:5]] == [message_fields(m) for m in msgs[2:5]]
    with pytest.raises(IndexError):
        fa[len(msgs)]
    with pytest.raises(IndexError):
        fa[-len(msgs) - 1]
    with pytest.raises(ValueError, match="65 data bytes"):
        FrameArray.from_messages([can.Message(data=bytes(65), is_fd=True)])
    duty = Codec().frame_id("PwmDuty")
    picked = with_ids(FrameArray.from_messages(msgs), (duty,))
    assert isinstance(picked, FrameArray)
    assert [message_fields(m) for m in picked] == [
        message_fields(m) for m in msgs if m.arbitration_id == duty
    ]
    assert with_ids(msgs, (duty,)) is msgs
    # once made, the messages are kept: a time stamp set stays (a capture's writer),
    # and readers of the whole block take them, not the rows
    fa = FrameArray.from_messages(msgs)
    assert not fa.made
    for j, m in enumerate(fa):
        m.timestamp = 10.0 + j
    assert fa.made
    assert [m.timestamp for m in fa] == [10.0 + j for j in range(len(msgs))]
    assert fa[1:3][0].timestamp == 11.0
    assert with_ids(fa, (duty,)) is fa


def test_decode_batch_reads_the_columns_with_the_same_result(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    codec = Codec()
    msgs = _sample_frames()
    want = decode_batch(msgs, codec)
    fa = FrameArray.from_messages(msgs)

    def no_message(*a: object, **k: object) -> list[can.Message]:
        raise AssertionError("a can.Message was made")

    monkeypatch.setattr(FrameArray, "_messages", staticmethod(no_message))
    got = decode_batch(fa, codec)
    assert (got.frames, got.skipped, got.unknown_ids) == (
        want.frames,
        want.skipped,
        want.unknown_ids,
    )
    assert got.rejected == want.rejected and sum(want.rejected.values()) == 2
    assert set(got.messages) == set(want.messages) == {"PwmDuty"}
    a, b = got.messages["PwmDuty"], want.messages["PwmDuty"]
    assert a.index.tolist() == b.index.tolist() == [0, 6]
    for k, v in b.signals.items():
        assert np.array_equal(a.signals[k], v), k
    # a message changed after they were made is what a whole-block reader sees
    monkeypatch.undo()
    fa2 = FrameArray.from_messages(msgs)
    fa2[0].data = bytearray(8)  # its CRC no longer holds
    assert decode_batch(fa2, codec).rejected == {
        **want.rejected,
        "bad_crc": want.rejected["bad_crc"] + 1,
    }


@pytest.mark.skipif(not any(shutil.which(c) for c in ("cc", "gcc")), reason="needs a C compiler")
def test_an_inprocess_native_run_scores_as_its_messages(tmp_path: object) -> None:
    import bench.nodes._loops as loops
    from bench.runs._analysis import analyze_frames
    from bench.runs._results import plant_fault, plant_status_counters
    from bench.scenarios._schema import load_scenario
    from bench.scenarios._setup import sample_period

    scn = load_scenario("wen-5.1").with_overrides(duration=0.2)
    codec = Codec()
    frames = loops.run_inprocess(scn, "tt-dq", codec, loop="native")
    assert isinstance(frames, FrameArray)
    msgs = list(frames)
    a = analyze_frames(frames, codec, T_s=sample_period(scn), n_p=4)
    b = analyze_frames(msgs, codec, T_s=sample_period(scn), n_p=4)
    assert len(a.table["step"]) == len(b.table["step"]) > 1000
    for k, v in b.table.items():
        assert np.array_equal(a.table[k], v, equal_nan=True), k
    assert plant_status_counters(frames, codec) == plant_status_counters(msgs, codec) is not None
    assert plant_fault(frames, codec) == plant_fault(msgs, codec)
