"""CRC-8 SAE J1850 and the E2E data-ID scheme."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from bench.wire._e2e import CRC8_J1850_TABLE, crc8_j1850, e2e_crc, e2e_start

# AUTOSAR SWS CRC Library, CRC8 (SAE J1850) check values; and the catalogue check value.
PUBLISHED = [
    ("00000000", 0x59),
    ("F20183", 0x37),
    ("0FAA0055", 0x79),
    ("00FF5511", 0xB8),
    ("332255AABBCCDDEEFF", 0xCB),
    ("926B55", 0x8C),
    ("FFFFFFFF", 0x74),
]


def _crc_bitwise(data: bytes) -> int:
    reg = 0xFF
    for byte in data:
        reg ^= byte
        for _ in range(8):
            reg = ((reg << 1) ^ 0x1D) & 0xFF if reg & 0x80 else (reg << 1) & 0xFF
    return reg ^ 0xFF


def test_check_value():
    assert crc8_j1850(b"123456789") == 0x4B


@pytest.mark.parametrize(("hexdata", "expected"), PUBLISHED)
def test_autosar_check_values(hexdata, expected):
    assert crc8_j1850(bytes.fromhex(hexdata)) == expected


def test_table():
    assert len(CRC8_J1850_TABLE) == 256
    assert CRC8_J1850_TABLE[0] == 0 and CRC8_J1850_TABLE[1] == 0x1D  # x^8 mod poly
    assert len(set(CRC8_J1850_TABLE)) == 256  # a permutation for a polynomial with x^0 term


@given(st.binary(max_size=70))
def test_table_matches_bitwise(data):
    assert crc8_j1850(data) == _crc_bitwise(data)


@given(st.integers(0, 0xFFFF), st.binary(min_size=2, max_size=64), st.data())
def test_e2e_is_crc_over_data_id_then_payload(data_id, payload, draw):
    idx = draw.draw(st.integers(0, len(payload) - 1))
    rest = payload[:idx] + payload[idx + 1 :]
    expected = _crc_bitwise(bytes((data_id & 0xFF, data_id >> 8)) + rest)
    assert e2e_crc(e2e_start(data_id), payload, idx) == expected
    # The crc byte itself does not enter the CRC.
    flipped = bytearray(payload)
    flipped[idx] ^= 0xFF
    assert e2e_crc(e2e_start(data_id), flipped, idx) == expected


def test_data_id_separates_messages():
    payload = bytes(range(8))
    crcs = {e2e_crc(e2e_start(d), payload, 0) for d in (0x1210, 0x1011, 0x1020, 0x10F0)}
    assert len(crcs) == 4


def test_single_bit_errors_detected():
    payload = bytearray(b"\x00\x12\x34\x56\x78\x9a\xbc\xde")
    start = e2e_start(0x1210)
    good = e2e_crc(start, payload, 0)
    for bit in range(8, 64):
        bad = bytearray(payload)
        bad[bit // 8] ^= 1 << (bit % 8)
        assert e2e_crc(start, bad, 0) != good


def test_data_id_range():
    with pytest.raises(ValueError):
        e2e_start(0x10000)
