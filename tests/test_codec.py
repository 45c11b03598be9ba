"""The DBC codec: round trips, clipping and wrapping, E2E checks, rejections."""

from __future__ import annotations

import math
from typing import Any

import can
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bench._errors import BenchError, DbcError
from bench.wire._codec import (
    REJECT_BAD_CRC,
    REJECT_BAD_LENGTH,
    REJECT_DECODE_ERROR,
    REJECT_OUT_OF_RANGE,
    Codec,
    default_codec,
    unwrap_step,
)
from dbc import DBC_PATH


@pytest.fixture(scope="module")
def codec() -> Codec:
    return Codec()


def _range(s: Any) -> tuple[float, float]:
    """A signal's [minimum, maximum]: every signal of the bench's DBC declares both."""
    assert s.minimum is not None and s.maximum is not None, s.name
    return float(s.minimum), float(s.maximum)


def _mid(codec: Codec, name: str) -> dict[str, float]:
    m = codec.message(name)
    return {
        s.name: round(0.5 * sum(_range(s)) / s.scale) * s.scale
        for s in m.signals
        if s.name != "crc"
    }


def _cases(codec: Codec):
    for name in codec.names:
        for s in codec.message(name).signals:
            if s.name == "crc":
                continue
            lo, hi = _range(s)
            points = {"min": lo, "max": hi, "one_lsb": s.scale}
            if lo <= 0 <= hi:
                points["zero"] = 0.0
            if lo < 0:
                points["minus_one_lsb"] = -s.scale
            for label, v in points.items():
                yield name, s.name, label, float(v), float(s.scale)


CASES = list(_cases(Codec()))


@pytest.mark.parametrize(("name", "sig", "label", "value", "lsb"), CASES)
def test_round_trip_each_signal_at_limits(codec, name, sig, label, value, lsb):
    signals = _mid(codec, name)
    signals[sig] = value
    msg = codec.encode(name, signals)
    decoded = codec.decode(msg)
    assert decoded is not None and decoded.ok, decoded
    assert decoded.name == name
    for k, v in signals.items():
        tol = 1e-9 * max(1.0, abs(v))
        assert decoded.signals[k] == pytest.approx(v, abs=tol), (k, label)


def test_round_trip_counts(codec):
    # Every message and every non-crc signal is covered by the parametrized test above.
    covered = {(n, s) for n, s, *_ in CASES}
    expected = {(n, s) for n in codec.names for s in codec.signal_names(n)}
    assert covered == expected and len(codec.names) == 8


@settings(max_examples=200, deadline=None)
@given(st.data())
def test_quantization_within_half_lsb(data):
    codec = default_codec()
    name = data.draw(st.sampled_from(codec.names))
    m = codec.message(name)
    values = {s.name: data.draw(st.floats(*_range(s))) for s in m.signals if s.name != "crc"}
    got = codec.quantize(name, values)
    for s in m.signals:
        if s.name == "crc":
            continue
        err = abs(got[s.name] - values[s.name])
        if s.dbc and s.dbc.attributes.get("SigModular"):
            period = (1 << s.length) * s.scale
            err = min(err, abs(err - period))
        assert err <= 0.5 * s.scale * (1 + 1e-9) + 1e-12, s.name


def test_clipping_to_signal_range(codec):
    got = codec.quantize(
        "PwmDuty", {"duty_a": 1.5, "duty_b": -0.2, "duty_c": 1.0, "enable": 1, "step": 0}
    )
    assert got["duty_a"] == got["duty_c"] == 1.0  # duty 1.0 is in the DBC range (raw 16384)
    assert got["duty_b"] == 0.0
    got = codec.quantize(
        "PhaseSamples", {"i_a": 1e3, "i_b": -1e3, "u_dc": 2000.0, "status": 1, "step": 0}
    )
    assert got["i_a"] == pytest.approx(64 - 2**-9) and got["i_b"] == -64.0
    assert got["u_dc"] == 1023.5


def test_counters_and_angles_wrap(codec):
    got = codec.quantize(
        "PwmDuty", {"duty_a": 0.5, "duty_b": 0.5, "duty_c": 0.5, "enable": 1, "step": 1030}
    )
    assert got["step"] == 1030 % 1024
    got = codec.quantize(
        "PwmDuty", {"duty_a": 0.5, "duty_b": 0.5, "duty_c": 0.5, "enable": 1, "step": -1}
    )
    assert got["step"] == 1023
    truth = {
        "theta_e": -0.1,
        "w_m": 0.0,
        "tau_e": 0.0,
        "tau_L": 0.0,
        "step": 2**32 + 7,
        "duty_age": 0,
    }
    got = codec.quantize("PlantTruth", truth)
    assert got["theta_e"] == pytest.approx(2 * math.pi - 0.1, abs=math.pi / 65536)
    assert got["step"] == 7
    truth["theta_e"] = 2 * math.pi - 1e-9  # rounds to 65536 LSB: wraps to 0, not clipped
    assert codec.quantize("PlantTruth", truth)["theta_e"] == 0.0
    cmd = {"cmd": 1, "seq": 17, "step": 70000, "speed_ref": 100.0, "load_torque": -7.5}
    got = codec.quantize("BenchCommand", cmd)
    assert got["seq"] == 1 and got["step"] == 70000 - 65536
    assert got["speed_ref"] == pytest.approx(100.0)
    assert got["load_torque"] == pytest.approx(-7.5)


def test_i_c_computed_from_three_wire_constraint(codec):
    got = codec.quantize(
        "PhaseSamples", {"i_a": 1.234, "i_b": -0.5, "u_dc": 540.0, "status": 1, "step": 3}
    )
    assert got["i_c"] == -(got["i_a"] + got["i_b"])
    assert got["i_a"] == pytest.approx(1.234, abs=2**-10)
    assert "crc" not in got


def test_frame_flags_follow_dbc(codec):
    duty = codec.encode(
        "PwmDuty", {"duty_a": 0.1, "duty_b": 0.2, "duty_c": 0.3, "enable": 0, "step": 1}
    )
    assert duty.arbitration_id == codec.frame_id("PwmDuty") == 0x010
    assert not duty.is_fd and not duty.bitrate_switch and not duty.is_extended_id
    assert duty.dlc == 8
    truth = codec.encode(
        "PlantTruth", {"theta_e": 1, "w_m": 2, "tau_e": 3, "tau_L": 4, "step": 5, "duty_age": 0}
    )
    assert truth.is_fd and truth.bitrate_switch and truth.dlc == 16


def test_crc_filled_and_every_bit_flip_rejected(codec):
    msg = codec.encode(
        "PwmDuty", {"duty_a": 0.25, "duty_b": 0.5, "duty_c": 0.75, "enable": 1, "step": 77}
    )
    assert codec.decode(msg).ok
    for bit in range(64):
        data = bytearray(msg.data)
        data[bit // 8] ^= 1 << (bit % 8)
        bad = can.Message(arbitration_id=msg.arbitration_id, is_extended_id=False, data=data)
        decoded = codec.decode(bad)
        assert decoded is not None and decoded.reason == REJECT_BAD_CRC, bit


def test_frame_under_other_id_fails_crc(codec):
    # Same payload layout would decode, but the data ID differs.
    samples = codec.encode(
        "PhaseSamples", {"i_a": 0.0, "i_b": 0.0, "u_dc": 0.0, "status": 0, "step": 0}
    )
    moved = can.Message(
        arbitration_id=codec.frame_id("PwmDuty"), is_extended_id=False, data=samples.data
    )
    assert codec.decode(moved).reason == REJECT_BAD_CRC


@pytest.mark.parametrize("length", [0, 7, 9, 12])
def test_wrong_length_rejected(codec, length):
    msg = codec.encode(
        "PwmDuty", {"duty_a": 0.25, "duty_b": 0.5, "duty_c": 0.75, "enable": 1, "step": 77}
    )
    data = (bytes(msg.data) + bytes(8))[:length]
    bad = can.Message(arbitration_id=msg.arbitration_id, is_extended_id=False, data=data)
    decoded = codec.decode(bad)
    assert decoded.reason == REJECT_BAD_LENGTH and decoded.signals == {}
    assert codec.decode_data(msg.arbitration_id, data).reason == REJECT_BAD_LENGTH


def test_fd_frame_wrong_length(codec):
    msg = codec.encode(
        "CtrlTelemetry", {"theta_hat": 1, "w_hat": 1, "err": 0, "mode": 3, "step": 1}
    )
    short = can.Message(
        arbitration_id=msg.arbitration_id, is_extended_id=False, is_fd=True, data=msg.data[:8]
    )
    assert codec.decode(short).reason == REJECT_BAD_LENGTH


def test_out_of_range_enum_rejected(codec):
    m = codec.message("PhaseSamples")
    raw = m.encode(
        {"crc": 0, "i_a": 0, "i_b": 0, "u_dc": 0, "status": 7, "step": 0},
        scaling=False,
        strict=False,
    )
    data = codec.with_crc("PhaseSamples", raw)
    decoded = codec.decode_data(codec.frame_id("PhaseSamples"), data)
    assert decoded.reason == REJECT_OUT_OF_RANGE and decoded.signals["status"] == 7
    # The same payload with a defined value passes.
    raw = m.encode(
        {"crc": 0, "i_a": 0, "i_b": 0, "u_dc": 0, "status": 2, "step": 0},
        scaling=False,
        strict=False,
    )
    assert codec.decode_data(0x011, codec.with_crc("PhaseSamples", raw)).ok
    cmd = codec.message("BenchCommand")
    raw = cmd.encode(
        {"crc": 0, "cmd": 7, "seq": 0, "step": 0, "speed_ref": 0, "load_torque": 0},
        scaling=False,
        strict=False,
    )
    assert codec.decode_data(0x020, codec.with_crc("BenchCommand", raw)).reason == (
        REJECT_OUT_OF_RANGE
    )


def test_unknown_id_and_remote_frame(codec):
    assert (
        codec.decode(can.Message(arbitration_id=0x7FF, is_extended_id=False, data=bytes(8))) is None
    )
    # Same number as an 11-bit ID of the DBC, but a 29-bit identifier: not ours.
    assert (
        codec.decode(can.Message(arbitration_id=0x010, is_extended_id=True, data=bytes(8))) is None
    )
    remote = can.Message(arbitration_id=0x010, is_extended_id=False, is_remote_frame=True, dlc=8)
    assert codec.decode(remote).reason == REJECT_DECODE_ERROR


def test_encode_errors_name_message_and_signal(codec):
    with pytest.raises(DbcError, match=r"PwmDuty: signal duty_c missing"):
        codec.encode("PwmDuty", {"duty_a": 0.1, "duty_b": 0.1, "enable": 1, "step": 0})
    with pytest.raises(DbcError, match=r"PwmDuty: signal duty_a is nan"):
        codec.encode(
            "PwmDuty", {"duty_a": math.nan, "duty_b": 0.1, "duty_c": 0.1, "enable": 1, "step": 0}
        )
    with pytest.raises(DbcError, match=r"no message named 'Nope'"):
        codec.encode("Nope", {})
    assert issubclass(DbcError, BenchError)


def test_lookup(codec):
    assert codec.name_of(0x011) == "PhaseSamples" and codec.name_of(0x7FF) is None
    assert codec.step_bits("PwmDuty") == 10 and codec.step_bits("PlantTruth") == 32
    assert codec.step_bits("BenchCommand") == 16 and codec.step_bits("CtrlTelemetry") == 32
    assert codec.signal_names("PwmDuty") == ("duty_a", "duty_b", "duty_c", "enable", "step")
    assert codec.length("CtrlTelemetry") == 16 and codec.is_fd("CtrlTelemetry")
    assert Codec(DBC_PATH).names == codec.names


@pytest.mark.parametrize(
    ("raw", "expected", "bits", "full"),
    [
        (5, 1029, 10, 1029),
        (5, 1029 + 512, 10, 1029),  # 512 late: still placed
        (3, 1024 + 4 + 512, 10, 1027 + 1024),  # 513 late: mistaken for one period on
        (1023, 1024, 10, 1023),
        (0, 1023, 10, 1024),
        (2, 0, 10, 2),
        (1023, 0, 10, -1),
        (65535, 65536 * 3, 16, 65536 * 3 - 1),
    ],
)
def test_unwrap_step(raw, expected, bits, full):
    assert unwrap_step(raw, expected, bits) == full


def test_unwrap_window_edges():
    for exp in (0, 1000, 123456):
        for delta in range(-512, 512):
            assert unwrap_step((exp + delta) % 1024, exp, 10) == exp + delta
        assert unwrap_step((exp + 512) % 1024, exp, 10) == exp - 512


def test_missing_and_broken_dbc(tmp_path):
    with pytest.raises(DbcError, match="file not found"):
        Codec(tmp_path / "nope.dbc")
    bad = tmp_path / "bad.dbc"
    bad.write_text('VERSION ""\nBO_ 16 X: 8 Y\n SG_ a : 0|8@1+ (1,0 [0|1] "" Z\n')
    with pytest.raises(DbcError, match=r"bad\.dbc: cannot load"):
        Codec(bad)
    text = DBC_PATH.read_text().replace('BA_ "E2EDataId" BO_ 17 4113;\n', "")
    no_id = tmp_path / "no_id.dbc"
    no_id.write_text(text)
    with pytest.raises(DbcError, match=r"message PhaseSamples: attribute E2EDataId"):
        Codec(no_id)


@settings(max_examples=300, deadline=None)
@given(st.data())
def test_decode_equals_cantools_decode_simple(data):
    """The precompiled decode path gives exactly cantools' values and types."""
    codec = default_codec()
    name = data.draw(st.sampled_from(codec.names))
    m = codec.message(name)
    payload = data.draw(st.binary(min_size=m.length, max_size=m.length))
    decoded = codec.decode_data(m.frame_id, payload)
    reference = m.decode_simple(payload, decode_choices=False)
    assert decoded is not None
    got = {k: v for k, v in decoded.signals.items() if k != "i_c"}
    assert got == reference
    assert [type(v) for v in got.values()] == [type(reference[k]) for k in got]
