"""Bus load of the bench's frame layouts on real CAN buses.

vcan and udp_multicast have no bit rate, so a simulated bench can close its
loop faster than any real bus could carry the frames. This module states what
a real bus would need: for each layout (which frames are sent every PWM
period) and bus (classic CAN at 500 kbit/s and 1 Mbit/s, CAN FD at 1 Mbit/s
arbitration with 2 or 5 Mbit/s data), the wire time per period, the load at
given PWM rates and the highest PWM rate that fits.

Frame lengths on the wire (ISO 11898-1; base format unless ``extended``):

Classic data frame with ``n`` data bytes::

    bits        = 47 + 8 n                  (67 + 8 n, 29-bit identifier)
    stuffed     = 34 + 8 n                  (SOF..CRC; 54 + 8 n extended)
    stuff bits  <= floor((stuffed - 1) / 4)  (Davis et al., 2007)

so 8 bytes take 111 bits plus at most 24 stuff bits: 111-135 us at 1 Mbit/s.
The 47 are SOF 1, identifier 11, RTR 1, IDE 1, r0 1, DLC 4, CRC 15, CRC
delimiter 1, ACK slot and delimiter 2, EOF 7 and the 3-bit intermission.

CAN FD (ISO) frame with ``n`` data bytes: at the arbitration rate, SOF,
identifier, RRS, IDE, FDF, res and BRS (17 bits; 36 extended) plus ACK slot,
ACK delimiter, EOF and intermission (12 bits); at the data rate (after bit-rate
switching), ESI 1, DLC 4, data 8 n, the CRC field (stuff count 4 and CRC 17
for n <= 16, else 21) with its fixed stuff bits (one before the stuff count and
one after every 4 bits: 6 for CRC-17, 7 for CRC-21) and the CRC delimiter 1.
Dynamic stuff bits, at most ``floor((22 + 8 n - 1) / 4)`` (42 + 8 n extended),
fall before the end of the data field: at most ``floor((17 - 1) / 4) = 4`` of
them in the arbitration phase, the rest in the data phase. Without BRS the
whole frame runs at the arbitration rate.

Frames a real bus cannot carry are not hidden: on a classic bus an FD frame of
the DBC is counted as ``ceil(n / 8)`` classic frames (its payload split).
"""

from __future__ import annotations

import json
import math
import shutil
import subprocess
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from bench.wire._codec import Codec

__all__ = [
    "BUSES",
    "LAYOUTS",
    "PRACTICAL_LOAD",
    "Bus",
    "RateFit",
    "bus_of",
    "busload_table",
    "classic_frame_bits",
    "fd_frame_bits",
    "format_busload",
    "frame_time_us",
    "link_bitrates",
    "parse_link_bitrates",
    "rate_fit",
]

PRACTICAL_LOAD = 0.8
"""Load above which a real bus is considered too full (arbitration delays of
lower-priority frames grow without bound as the load approaches 100 %)."""

LAYOUTS: dict[str, tuple[str, ...]] = {
    "control": ("PwmDuty", "PhaseSamples"),
    "control+sensor": ("PwmDuty", "PhaseSamples", "PositionSensor"),
    "control+recorder": ("PwmDuty", "PhaseSamples", "PlantTruth", "CtrlTelemetry"),
}
"""Frames sent every PWM period, by layout name. ``control+sensor`` is a
sensored controller's loop (``PositionSensor`` every period, as
``--controller external`` sends it by default: docs/PROTOCOL.md)."""

_FD_LENGTHS = (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64)


@dataclass(frozen=True, slots=True)
class Bus:
    """A physical CAN bus configuration.

    Parameters
    ----------
    name : str
        Label in the report.
    bitrate : float
        Nominal (arbitration) bit rate (bit/s).
    data_bitrate : float or None
        CAN FD data-phase bit rate (bit/s); None for a classic bus.
    all_fd : bool
        Send every frame as FD with bit-rate switching, also those the DBC
        declares classic (what-if for an FD-only bus).
    """

    name: str
    bitrate: float
    data_bitrate: float | None = None
    all_fd: bool = False

    @property
    def is_fd(self) -> bool:
        """True for a CAN FD bus."""
        return self.data_bitrate is not None


BUSES: tuple[Bus, ...] = (
    Bus("classic 500k", 500e3),
    Bus("classic 1M", 1e6),
    Bus("FD 1M/2M", 1e6, 2e6),
    Bus("FD 1M/5M", 1e6, 5e6),
    Bus("FD 1M/2M all-FD", 1e6, 2e6, all_fd=True),
    Bus("FD 1M/5M all-FD", 1e6, 5e6, all_fd=True),
)
"""Buses of the report: DBC frame formats as declared, plus all-FD what-ifs."""


def classic_frame_bits(n_bytes: int, extended: bool = False) -> tuple[int, int]:
    """Bits of a classic data frame: (without stuff bits, with worst-case stuffing).

    Includes the 3-bit intermission. See the module docstring for the formula.
    """
    if not 0 <= n_bytes <= 8:
        raise ValueError(f"classic CAN carries 0..8 bytes, got {n_bytes}")
    base = (67 if extended else 47) + 8 * n_bytes
    stuffed_region = (54 if extended else 34) + 8 * n_bytes
    return base, base + (stuffed_region - 1) // 4


def fd_frame_bits(n_bytes: int, extended: bool = False) -> tuple[tuple[int, int], tuple[int, int]]:
    """Bits of a CAN FD data frame split by phase.

    Returns
    -------
    (arb, data), (arb_worst, data_worst) : tuple of int
        Bits at the arbitration rate and at the data rate, without dynamic
        stuff bits and with worst-case dynamic stuffing. Fixed stuff bits of
        the CRC field are included in both.
    """
    if n_bytes not in _FD_LENGTHS:
        raise ValueError(f"CAN FD payload must be one of {_FD_LENGTHS}, got {n_bytes}")
    head = 36 if extended else 17  # SOF .. BRS
    tail = 12  # ACK slot, ACK delimiter, EOF 7, intermission 3
    crc_len = 17 if n_bytes <= 16 else 21
    fixed_stuff = 6 if n_bytes <= 16 else 7
    data = 1 + 4 + 8 * n_bytes + 4 + crc_len + fixed_stuff + 1  # ESI .. CRC delimiter
    dyn_total = (head + 5 + 8 * n_bytes - 1) // 4  # dynamic region SOF .. data field
    dyn_arb = (head - 1) // 4
    return (head + tail, data), (head + tail + dyn_arb, data + dyn_total - dyn_arb)


def frame_time_us(
    n_bytes: int,
    *,
    fd: bool,
    bitrate: float,
    data_bitrate: float | None = None,
    extended: bool = False,
    worst: bool = True,
) -> float:
    """Time one frame occupies the bus (us), intermission included.

    Parameters
    ----------
    n_bytes : int
        Payload length (bytes).
    fd : bool
        CAN FD frame (else classic).
    bitrate : float
        Nominal bit rate (bit/s).
    data_bitrate : float or None
        Data bit rate of an FD frame with bit-rate switching; None: no BRS.
    extended : bool
        29-bit identifier.
    worst : bool
        With worst-case stuff bits (else none).
    """
    if not fd:
        bits = classic_frame_bits(n_bytes, extended)[1 if worst else 0]
        return bits / bitrate * 1e6
    arb, data = fd_frame_bits(n_bytes, extended)[1 if worst else 0]
    rate = data_bitrate if data_bitrate is not None else bitrate
    return (arb / bitrate + data / rate) * 1e6


def _message_time_us(length: int, is_fd: bool, extended: bool, bus: Bus, worst: bool) -> float:
    if not bus.is_fd:
        if is_fd or length > 8:
            # Split into classic frames of at most 8 bytes.
            full, rest = divmod(length, 8)
            t = full * frame_time_us(
                8, fd=False, bitrate=bus.bitrate, extended=extended, worst=worst
            )
            if rest:
                t += frame_time_us(
                    rest, fd=False, bitrate=bus.bitrate, extended=extended, worst=worst
                )
            return t
        return frame_time_us(length, fd=False, bitrate=bus.bitrate, extended=extended, worst=worst)
    if is_fd or bus.all_fd:
        return frame_time_us(
            length,
            fd=True,
            bitrate=bus.bitrate,
            data_bitrate=bus.data_bitrate,
            extended=extended,
            worst=worst,
        )
    return frame_time_us(length, fd=False, bitrate=bus.bitrate, extended=extended, worst=worst)


def _background(codec: Codec, bus: Bus) -> float:
    """Load of the messages with a ``GenMsgCycleTime`` (independent of the PWM rate)."""
    background = 0.0
    for m in codec.db.messages:
        if m.cycle_time:
            t = _message_time_us(m.length, m.is_fd, m.is_extended_frame, bus, True)
            background += t / (float(m.cycle_time) * 1e3)
    return background


def _period_us(codec: Codec, frames: Mapping[str, float], bus: Bus, worst: bool) -> float:
    """Wire time per PWM period of ``frames`` (message name to frames per period)."""
    t = 0.0
    for name, per_period in frames.items():
        m = codec.message(name)
        t += per_period * _message_time_us(m.length, m.is_fd, m.is_extended_frame, bus, worst)
    return t


def busload_table(
    codec: Codec,
    rates: Sequence[float] = (1e3, 4e3, 10e3),
    *,
    layouts: dict[str, tuple[str, ...]] | None = None,
    buses: Iterable[Bus] = BUSES,
) -> list[dict[str, Any]]:
    """Bus load of each layout on each bus.

    Frame lengths and formats come from the DBC. Messages with a
    ``GenMsgCycleTime`` (e.g. ``PlantStatus``) add a background load
    independent of the PWM rate; event frames (``BenchCommand``) are left out.

    Parameters
    ----------
    codec : Codec
        Codec of the DBC.
    rates : sequence of float
        PWM rates (Hz) at which to state the load.
    layouts : dict, optional
        Layout name to the messages sent every PWM period; default
        :data:`LAYOUTS`.
    buses : iterable of Bus
        Default :data:`BUSES`.

    Returns
    -------
    list of dict
        One row per (layout, bus): ``layout``, ``frames``, ``bus``,
        ``bitrate``, ``data_bitrate``, ``all_fd``, ``period_us_min`` and
        ``period_us_max`` (wire time per PWM period without and with
        worst-case stuffing), ``background_load`` (fraction), ``load`` (rate
        to worst-case load fraction), ``load_min`` (same without stuffing),
        ``max_rate_hz`` (highest PWM rate at 100 % worst-case load),
        ``max_rate_hz_min`` (same without stuffing) and ``max_rate_hz_practical``
        (at :data:`PRACTICAL_LOAD`, worst case).
    """
    layouts = LAYOUTS if layouts is None else layouts
    rows: list[dict[str, Any]] = []
    for bus in buses:
        background = _background(codec, bus)
        for layout, names in layouts.items():
            once = dict.fromkeys(names, 1.0)
            t_min = _period_us(codec, once, bus, False)
            t_max = _period_us(codec, once, bus, True)
            rows.append(
                {
                    "layout": layout,
                    "frames": list(names),
                    "bus": bus.name,
                    "bitrate": bus.bitrate,
                    "data_bitrate": bus.data_bitrate,
                    "all_fd": bus.all_fd,
                    "period_us_min": t_min,
                    "period_us_max": t_max,
                    "background_load": background,
                    "load": {r: background + r * t_max * 1e-6 for r in rates},
                    "load_min": {r: background + r * t_min * 1e-6 for r in rates},
                    "max_rate_hz": (1.0 - background) / (t_max * 1e-6),
                    "max_rate_hz_min": (1.0 - background) / (t_min * 1e-6),
                    "max_rate_hz_practical": (PRACTICAL_LOAD - background) / (t_max * 1e-6),
                }
            )
    return rows


@dataclass(frozen=True, slots=True)
class RateFit:
    """How a PWM rate fits a bus (worst-case stuffing, low-rate frames included).

    ``load``: fraction of the bus at ``rate_hz``; ``max_rate_hz``: the highest
    PWM rate at 100 % load; ``max_rate_hz_practical``: at :data:`PRACTICAL_LOAD`.
    """

    bus: Bus
    rate_hz: float
    load: float
    max_rate_hz: float
    max_rate_hz_practical: float


def rate_fit(codec: Codec, frames: Mapping[str, float], bus: Bus, rate_hz: float) -> RateFit:
    """The load of ``frames`` (message name to frames per PWM period) at ``rate_hz`` on ``bus``.

    The same figures as :func:`busload_table`, for one layout, bus and rate; a
    fractional count is a frame sent every few periods (``PositionSensor``).
    """
    background = _background(codec, bus)
    t = _period_us(codec, frames, bus, True) * 1e-6
    inf = math.inf
    return RateFit(
        bus,
        rate_hz,
        background + rate_hz * t,
        (1.0 - background) / t if t > 0 else inf,
        (PRACTICAL_LOAD - background) / t if t > 0 else inf,
    )


def bus_of(bitrate: float, data_bitrate: float | None = None) -> Bus:
    """The :class:`Bus` of an interface's bit rates: CAN FD when it has a data bit rate."""

    def short(r: float) -> str:
        return f"{r / 1e6:g}M" if r >= 1e6 else f"{r / 1e3:g}k"

    if data_bitrate:
        return Bus(
            f"FD {short(bitrate)}/{short(data_bitrate)}", float(bitrate), float(data_bitrate)
        )
    return Bus(f"classic {short(bitrate)}", float(bitrate))


def parse_link_bitrates(ip_json: str) -> tuple[int, int | None] | None:
    """Bit rates of a CAN device from ``ip -details -json link show dev DEV``.

    ``(bitrate, data_bitrate)`` (``data_bitrate`` None when CAN FD is off), or
    None for a device without bit timing (vcan, a device that is down and unset).
    """
    try:
        (link,) = json.loads(ip_json)
        data = link["linkinfo"]["info_data"]
        bitrate = int(data["bittiming"]["bitrate"])
    except (ValueError, KeyError, TypeError):
        return None
    if bitrate <= 0:
        return None
    dbt = data.get("data_bittiming") or {}
    data_bitrate = int(dbt.get("bitrate") or 0)
    return bitrate, (data_bitrate if data_bitrate > 0 else None)


def link_bitrates(device: str) -> tuple[int, int | None] | None:
    """Bit rates the kernel has set on a SocketCAN device (``ip link``), or None (vcan,
    no ``ip`` command, unknown device)."""
    ip = shutil.which("ip")
    if ip is None:
        return None
    try:
        res = subprocess.run(
            [ip, "-details", "-json", "link", "show", "dev", device],
            capture_output=True,
            text=True,
            timeout=5,
            check=False,
        )
    except (OSError, subprocess.SubprocessError):
        return None
    return parse_link_bitrates(res.stdout) if res.returncode == 0 else None


def _khz(x: float) -> str:
    return f"{x / 1e3:.2f}"


def format_busload(table: list[dict[str, Any]]) -> str:
    """Plain-text report of :func:`busload_table` (one line per layout and bus)."""
    if not table:
        return "(no layouts)"
    rates = list(table[0]["load"])
    head = (
        f"{'layout':<17} {'bus':<16} {'us/period':>13}  "
        + "  ".join(f"{'@' + _khz(r) + 'k':>9}" for r in rates)
        + f"  {'max kHz (100%)':>14}  {'80%':>5}"
    )
    lines = [
        "CAN bus load per PWM period, worst-case bit stuffing (no stuffing in brackets);",
        "vcan and udp_multicast have no bit rate: these are the limits of a real bus.",
        head,
        "-" * len(head),
    ]
    for row in table:
        loads = "  ".join(
            f"{100 * row['load'][r]:>8.1f}%" + ("!" if row["load"][r] > 1.0 else " ") for r in rates
        )
        period = f"{row['period_us_min']:.0f}-{row['period_us_max']:.0f}"
        max_rate = f"{_khz(row['max_rate_hz'])} ({_khz(row['max_rate_hz_min'])})"
        lines.append(
            f"{row['layout']:<17} {row['bus']:<16} {period:>13}  {loads}"
            f"  {max_rate:>14}  {_khz(row['max_rate_hz_practical']):>5}"
        )
    lines.append(
        "! = over 100 %.  all-FD: every frame sent as FD with bit-rate switching."
        "  Classic buses carry each FD frame as ceil(n/8) classic frames."
    )
    background = max(row["background_load"] for row in table)
    if background > 0:
        lines.append(f"Includes low-rate frames (GenMsgCycleTime): up to {100 * background:.2f} %.")
    if any(math.isinf(row["max_rate_hz"]) for row in table):
        lines.append("inf: layout has no frames.")
    return "\n".join(lines)
