"""The compiled hot-path codec gives cantools' bytes and values exactly, on every message."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bench.wire._codec import Codec
from bench.wire._hotcodec import agrees_with_cantools, compile_message, limit_vectors

DB = Codec().db
MESSAGES = [m.name for m in DB.messages]


@pytest.mark.parametrize("name", MESSAGES)
def test_every_message_of_the_dbc_is_compiled_and_used(name: str) -> None:
    msg = DB.get_message_by_name(name)
    compiled = compile_message(msg)
    assert compiled is not None
    assert agrees_with_cantools(msg, compiled)
    assert Codec()._spec(name).pack.__name__ == f"pack_{name}"


@pytest.mark.parametrize("name", MESSAGES)
def test_signals_at_their_limits_pack_and_unpack_as_cantools(name: str) -> None:
    msg = DB.get_message_by_name(name)
    compiled = compile_message(msg)
    assert compiled is not None
    vectors = limit_vectors(msg)
    assert len(vectors) >= 3
    for vec in vectors:
        want = msg.encode(vec, strict=False)
        assert bytes(compiled.pack(vec)) == want, vec
        assert compiled.unpack(want) == msg.decode_simple(want, decode_choices=False)


@settings(max_examples=300, deadline=None)
@given(st.sampled_from(MESSAGES), st.data())
def test_random_payloads_unpack_and_random_values_pack_as_cantools(
    name: str, data: st.DataObject
) -> None:
    msg = DB.get_message_by_name(name)
    compiled = compile_message(msg)
    assert compiled is not None
    payload = data.draw(st.binary(min_size=msg.length, max_size=msg.length))
    want = msg.decode_simple(payload, decode_choices=False)
    got = compiled.unpack(payload)
    assert got == want
    assert {k: type(v) for k, v in got.items()} == {k: type(v) for k, v in want.items()}
    lo, hi = limit_vectors(msg)[:2]
    vec = {k: data.draw(st.floats(lo[k], hi[k])) for k in lo}
    assert bytes(compiled.pack(vec)) == msg.encode(vec, strict=False)


def test_a_message_the_compiler_does_not_handle_stays_with_cantools(tmp_path: Path) -> None:
    dbc = tmp_path / "big.dbc"
    dbc.write_text(
        'VERSION ""\n\nBU_: A B\n\nBO_ 5 Big: 8 A\n'
        ' SG_ x : 7|16@0+ (0.5,0) [0|100] "" B\n'
        ' SG_ y : 23|8@0- (1,0) [-128|127] "" B\n'
    )
    big = Codec(dbc).db.get_message_by_name("Big")
    assert compile_message(big) is None
    codec = Codec(dbc)
    assert codec._spec("Big").pack.__class__.__name__ == "partial"
    frame = codec.encode("Big", {"x": 12.5, "y": -3})
    assert bytes(frame.data) == big.encode({"x": 12.5, "y": -3})
    decoded = codec.decode(frame)
    assert decoded is not None and decoded.signals == {"x": 12.5, "y": -3}


def test_a_compiled_message_that_disagrees_is_not_used(monkeypatch: pytest.MonkeyPatch) -> None:
    import bench.wire._codec as codec_mod

    monkeypatch.setattr(codec_mod, "agrees_with_cantools", lambda message, compiled: False)
    codec = Codec()
    assert codec._spec("PwmDuty").pack.__class__.__name__ == "partial"
    sig = {"duty_a": 0.25, "duty_b": 0.5, "duty_c": 0.75, "enable": 1, "step": 7}
    assert bytes(codec.encode("PwmDuty", sig).data) == bytes(Codec().encode("PwmDuty", sig).data)


def test_the_agreement_check_finds_one_wrong_bit_or_one_wrong_type() -> None:
    from bench.wire._hotcodec import CompiledMessage

    msg = DB.get_message_by_name("PhaseSamples")
    good = compile_message(msg)
    assert good is not None

    def off_by_one_bit(v: Mapping[str, float]) -> bytearray:
        b = good.pack(v)
        b[7] ^= 0x80
        return b

    def float_step(data: bytes | bytearray) -> dict[str, float]:
        d = good.unpack(data)
        d["step"] = float(d["step"])
        return d

    assert not agrees_with_cantools(msg, CompiledMessage(off_by_one_bit, good.unpack, ""))
    assert not agrees_with_cantools(msg, CompiledMessage(good.pack, float_step, ""))
