"""End-to-end protection of frames: CRC-8 SAE J1850 with a data ID.

The CRC is the one of AUTOSAR's ``Crc_CalculateCRC8`` (SAE J1850: polynomial
0x1D, initial value 0xFF, final XOR 0xFF, no reflection; check value 0x4B for
the ASCII string ``123456789``). As in AUTOSAR E2E profile 11 with data ID
mode "both", the 16-bit data ID of the message is folded in before the payload
(low byte first), so a frame that arrives under another message's identifier
fails the check even with an identical payload::

    crc = CRC8_J1850(id_lo, id_hi, payload bytes except the crc byte)

Per-frame cost matters (every duty and sample frame is checked), so the CRC is
table driven and the register after the data-ID bytes is precomputed per
message (:func:`e2e_start`).
"""

from __future__ import annotations

from collections.abc import Iterable

__all__ = [
    "CRC8_J1850_POLY",
    "CRC8_J1850_TABLE",
    "crc8_j1850",
    "crc8_j1850_update",
    "e2e_crc",
    "e2e_start",
]

CRC8_J1850_POLY = 0x1D
_INIT = 0xFF
_XOROUT = 0xFF


def _make_table(poly: int) -> tuple[int, ...]:
    table = []
    for byte in range(256):
        reg = byte
        for _ in range(8):
            reg = ((reg << 1) ^ poly) & 0xFF if reg & 0x80 else (reg << 1) & 0xFF
        table.append(reg)
    return tuple(table)


CRC8_J1850_TABLE: tuple[int, ...] = _make_table(CRC8_J1850_POLY)
"""CRC register after shifting each byte value through the polynomial."""


def crc8_j1850_update(reg: int, data: Iterable[int]) -> int:
    """Advance the CRC register ``reg`` over ``data`` (no final XOR)."""
    table = CRC8_J1850_TABLE
    for byte in data:
        reg = table[reg ^ byte]
    return reg


def crc8_j1850(data: Iterable[int]) -> int:
    """CRC-8 SAE J1850 of ``data`` (init 0xFF, final XOR 0xFF)."""
    return crc8_j1850_update(_INIT, data) ^ _XOROUT


def e2e_start(data_id: int) -> int:
    """CRC register after the data ID's low and high byte.

    Parameters
    ----------
    data_id : int
        16-bit data ID of the message (DBC message attribute ``E2EDataId``).
    """
    if not 0 <= data_id <= 0xFFFF:
        raise ValueError(f"E2E data ID must be 0..65535, got {data_id}")
    return crc8_j1850_update(_INIT, (data_id & 0xFF, data_id >> 8))


def e2e_crc(start: int, data: bytes | bytearray, crc_index: int) -> int:
    """E2E CRC of a payload, skipping the CRC byte itself.

    Parameters
    ----------
    start : int
        Register from :func:`e2e_start` for the message's data ID.
    data : bytes
        Whole payload, CRC byte included (its value is ignored).
    crc_index : int
        Index of the CRC byte in ``data``.
    """
    table = CRC8_J1850_TABLE
    reg = start
    for byte in data[:crc_index]:
        reg = table[reg ^ byte]
    for byte in data[crc_index + 1 :]:
        reg = table[reg ^ byte]
    return reg ^ _XOROUT
