"""Encoding and decoding of the bench's frames with the DBC.

One :class:`Codec` wraps one cantools database. Signals cross it as physical
values (``dict`` of name to number); bytes are packed and unpacked from the
DBC's scalings by functions compiled from the DBC when it is loaded
(:mod:`bench.wire._hotcodec`) and checked there to give cantools' bytes and
values exactly (cantools itself packs any message they do not handle). On
top of that the codec adds what the wire contract (``dbc/bench.dbc``) asks for:

- the E2E CRC (CRC-8 SAE J1850 with the message's ``E2EDataId``, see
  :mod:`bench.wire._e2e`) is filled in on encode and checked on decode;
- values outside a signal's ``[min|max]`` are clipped on encode, except for
  signals with ``SigModular = 1`` (step counters, alive counter, angles), which
  are taken modulo their range so that ``step = k`` sends the low bits of ``k``
  and ``theta = -0.1`` sends ``2 pi - 0.1``;
- decoded ``PhaseSamples`` carry ``i_c = -i_a - i_b`` (three-wire machine; the
  frame does not send it);
- a frame that cannot be trusted is not dropped silently but returned with a
  rejection reason (one of :data:`REJECT_REASONS`) that the caller counts.

Step counters are unwrapped with :func:`unwrap_step`.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import can
import cantools
from cantools.database.can import Database, Message

from bench._errors import DbcError
from bench.wire._e2e import CRC8_J1850_TABLE, e2e_crc, e2e_start
from bench.wire._hotcodec import agrees_with_cantools, compile_message

__all__ = [
    "REJECT_BAD_CRC",
    "REJECT_BAD_LENGTH",
    "REJECT_DECODE_ERROR",
    "REJECT_OUT_OF_RANGE",
    "REJECT_REASONS",
    "Codec",
    "Decoded",
    "default_codec",
    "unwrap_step",
]

REJECT_BAD_CRC = "bad_crc"
REJECT_BAD_LENGTH = "bad_length"
REJECT_DECODE_ERROR = "decode_error"
REJECT_OUT_OF_RANGE = "out_of_range"
REJECT_REASONS: tuple[str, ...] = (
    REJECT_BAD_CRC,
    REJECT_BAD_LENGTH,
    REJECT_DECODE_ERROR,
    REJECT_OUT_OF_RANGE,
)
"""Every reason :meth:`Codec.decode` can give for rejecting a frame."""

_CRC_SIGNAL = "crc"
_EXTENDED = 1 << 31  # lookup-key flag of 29-bit identifiers


def _key(frame_id: int, is_extended_id: bool) -> int:
    return frame_id | _EXTENDED if is_extended_id else frame_id


@dataclass(frozen=True, slots=True)
class Decoded:
    """A decoded frame of a message of the DBC.

    Parameters
    ----------
    name : str
        Message name.
    signals : dict of str to float
        Physical values by signal name (counters and enums as ``int``). Empty
        when the payload could not be unpacked (``bad_length``,
        ``decode_error``); present but untrustworthy for ``bad_crc`` and
        ``out_of_range``.
    reason : str or None
        None for a valid frame, else one of :data:`REJECT_REASONS`.
    """

    name: str
    signals: dict[str, float]
    reason: str | None = None

    @property
    def ok(self) -> bool:
        """True when the frame passed every check."""
        return self.reason is None


def unwrap_step(raw: int, expected: int, bits: int) -> int:
    """Full step number from a ``bits``-wide counter, nearest to ``expected``.

    The result is congruent to ``raw`` modulo ``2**bits`` and lies in
    ``[expected - 2**(bits-1), expected + 2**(bits-1) - 1]``: a frame up to
    ``2**(bits-1)`` periods late or ``2**(bits-1) - 1`` early is placed right;
    beyond that window it is mistaken for one a whole counter period away.

    Parameters
    ----------
    raw : int
        Counter value received.
    expected : int
        Step number the receiver expects (e.g. its own period counter).
    bits : int
        Width of the counter signal (:meth:`Codec.step_bits`).
    """
    mod = 1 << bits
    diff = (int(raw) - expected) % mod
    if diff >= mod >> 1:
        diff -= mod
    return expected + diff


class _Sig:
    """Encode-side description of one signal (precomputed once)."""

    __slots__ = ("hi", "initial", "lo", "modulus", "name", "offset", "scale")

    def __init__(
        self,
        name: str,
        lo: float,
        hi: float,
        scale: float,
        offset: float,
        mod: int,
        initial: float | None = None,
    ):
        self.name = name
        self.initial = initial  # GenSigStartValue (physical): used when the caller omits it
        self.lo = lo
        self.hi = hi
        self.scale = scale
        self.offset = offset
        self.modulus = mod  # 0: clip to [lo, hi]; else raw value taken modulo this


class _Spec:
    """Everything the codec needs about one message, precomputed once."""

    __slots__ = (
        "brs",
        "checked",
        "crc_index",
        "derive_i_c",
        "e2e_start",
        "frame_id",
        "is_extended",
        "is_fd",
        "length",
        "message",
        "name",
        "pack",
        "sigs",
        "step_bits",
        "unpack",
    )

    def __init__(self, message: Message, path: Path):
        self.message = message
        self.name: str = message.name
        self.frame_id: int = message.frame_id
        self.is_extended: bool = bool(message.is_extended_frame)
        self.is_fd: bool = bool(message.is_fd)
        self.length: int = message.length
        self.brs: bool = self.is_fd and _attribute(message, "CANFD_BRS", 1) == 1
        self.crc_index = -1
        self.e2e_start = 0
        self.step_bits = 0
        sigs: list[_Sig] = []
        checked: list[tuple[str, float, float]] = []
        where = f"DBC {path}: message {message.name}"
        for s in message.signals:
            if s.is_float or s.is_multiplexer or s.multiplexer_ids:
                raise DbcError(
                    f"{where}: signal {s.name}: float and multiplexed signals unsupported"
                )
            lo = float(s.minimum) if s.minimum is not None else None
            hi = float(s.maximum) if s.maximum is not None else None
            scale, offset = float(s.scale), float(s.offset)
            raw_lo = -(1 << (s.length - 1)) if s.is_signed else 0
            raw_hi = (1 << (s.length - 1)) - 1 if s.is_signed else (1 << s.length) - 1
            phys = sorted((raw_lo * scale + offset, raw_hi * scale + offset))
            lo = phys[0] if lo is None else lo
            hi = phys[1] if hi is None else hi
            if s.name == "step":
                self.step_bits = s.length
            if s.name == _CRC_SIGNAL:
                if s.length != 8 or s.start % 8 or s.scale != 1 or s.offset != 0:
                    raise DbcError(f"{where}: signal crc: must be one whole byte, unscaled")
                self.crc_index = s.start // 8
                data_id = _attribute(message, "E2EDataId", None, use_default=False)
                if not isinstance(data_id, int) or not 0 <= data_id <= 0xFFFF:
                    raise DbcError(f"{where}: attribute E2EDataId: needed (0..65535) with crc")
                self.e2e_start = e2e_start(data_id)
                continue
            modular = _attribute(s, "SigModular", 0) == 1
            if modular and (s.is_signed or offset != 0):
                raise DbcError(f"{where}: signal {s.name}: SigModular needs unsigned, offset 0")
            initial = float(s.initial) if isinstance(s.initial, int | float) else None
            mod = (1 << s.length) if modular else 0
            sigs.append(_Sig(s.name, lo, hi, scale, offset, mod, initial))
            # Only signals whose raw range exceeds [min|max] can decode out of range.
            tol = 1e-9 * abs(scale)
            if phys[0] < lo - tol or phys[1] > hi + tol:
                checked.append((s.name, lo - tol, hi + tol))
        self.sigs: tuple[_Sig, ...] = tuple(sigs)
        self.checked: tuple[tuple[str, float, float], ...] = tuple(checked)
        names = {s.name for s in sigs}
        self.derive_i_c = message.name == "PhaseSamples" and {"i_a", "i_b"} <= names
        compiled = compile_message(message)
        if compiled is not None and agrees_with_cantools(message, compiled):
            self.pack: Callable[[Mapping[str, float]], bytearray] = compiled.pack
            self.unpack: Callable[[bytes | bytearray], dict[str, float]] = compiled.unpack
        else:
            self.pack = functools.partial(_cantools_pack, message)
            self.unpack = _make_unpack(message)


def _cantools_pack(message: Message, values: Mapping[str, float]) -> bytearray:
    return bytearray(message.encode(dict(values), strict=False))


def _make_unpack(message: Message) -> Callable[[bytes | bytearray], dict[str, float]]:
    """Payload (of the right length) to physical values, as cantools decodes it.

    ``Message.decode_simple(data, decode_choices=False)`` costs about 2 us per
    frame, mostly in its generic per-signal scaling. When every signal is little
    endian and cantools has compiled its bit-field layout (``bitstruct.c``), the
    same compiled layout is called directly and only the scaled signals are
    converted, with cantools' own ``raw * scale + offset`` (same numbers, same
    types); about twice as fast. Otherwise ``decode_simple`` is used.
    """

    def generic(data: bytes | bytearray) -> dict[str, float]:
        return cast("dict[str, float]", message.decode_simple(bytes(data), decode_choices=False))

    codecs = getattr(message, "_codecs", None)
    formats = codecs.get("formats") if isinstance(codecs, dict) else None
    little = getattr(formats, "little_endian", None)
    if (
        little is None
        or not hasattr(little, "unpack")
        or codecs is None
        or codecs.get("multiplexers")
        or any(s.byte_order != "little_endian" for s in message.signals)
    ):
        return generic
    unpack_le = little.unpack
    scaled = tuple(
        (s.name, s.conversion.scale, s.conversion.offset)
        for s in message.signals
        if not (s.conversion.scale == 1 and s.conversion.offset == 0 and not s.is_float)
    )

    def fast(data: bytes | bytearray) -> dict[str, float]:
        raw: dict[str, float] = unpack_le(data[::-1])
        for name, scale, offset in scaled:
            raw[name] = raw[name] * scale + offset
        return raw

    return fast


def _attribute(obj: Any, name: str, default: Any, use_default: bool = True) -> Any:
    """A DBC attribute of a message or signal, or its definition's default."""
    dbc = getattr(obj, "dbc", None)
    if dbc is None:
        return default
    attr = dbc.attributes.get(name)
    if attr is not None:
        return attr.value
    if not use_default:
        return default
    definition = dbc.attribute_definitions.get(name) if dbc.attribute_definitions else None
    if definition is not None and definition.default_value is not None:
        value = definition.default_value
        if definition.type_name == "ENUM" and isinstance(value, str):
            return definition.choices.index(value) if value in definition.choices else default
        return value
    return default


class Codec:
    """Encoder and decoder of the bench's frames for one DBC.

    Parameters
    ----------
    dbc_path : str or Path, optional
        DBC file; defaults to the bench's own ``dbc/bench.dbc``.

    Raises
    ------
    DbcError
        The file is missing, does not parse, or breaks the bench's rules
        (crc signal not a whole byte, crc without ``E2EDataId``).
    """

    def __init__(self, dbc_path: str | Path | None = None):
        if dbc_path is None:
            from dbc import DBC_PATH

            dbc_path = DBC_PATH
        self.path = Path(dbc_path)
        try:
            db = cantools.database.load_file(str(self.path), prune_choices=False)
        except FileNotFoundError:
            raise DbcError(f"DBC {self.path}: file not found") from None
        except Exception as e:  # cantools raises several unrelated types
            reason = str(e).splitlines()[0] if str(e) else type(e).__name__
            raise DbcError(f"DBC {self.path}: cannot load: {reason}") from None
        if not isinstance(db, Database):
            raise DbcError(f"DBC {self.path}: not a CAN database")
        self.db: Database = db
        specs = [_Spec(m, self.path) for m in db.messages]
        self._by_name: dict[str, _Spec] = {s.name: s for s in specs}
        self._by_id: dict[int, _Spec] = {_key(s.frame_id, s.is_extended): s for s in specs}

    # -- lookup ------------------------------------------------------------

    def _spec(self, name: str) -> _Spec:
        try:
            return self._by_name[name]
        except KeyError:
            raise DbcError(f"DBC {self.path}: no message named {name!r}") from None

    @property
    def version(self) -> str:
        """The DBC's version: its ``ProtocolVersion`` attribute, else its ``VERSION`` line."""
        attrs = self.db.dbc.attributes if self.db.dbc is not None else {}
        attr = attrs.get("ProtocolVersion")
        return str(attr.value) if attr is not None else str(self.db.version or "")

    @property
    def names(self) -> tuple[str, ...]:
        """Message names, in DBC order."""
        return tuple(self._by_name)

    def message(self, name: str) -> Message:
        """The cantools message ``name``."""
        return self._spec(name).message

    def frame_id(self, name: str) -> int:
        """Arbitration ID of message ``name``."""
        return self._spec(name).frame_id

    def name_of(self, frame_id: int, is_extended_id: bool = False) -> str | None:
        """Message name of an arbitration ID, or None when not in the DBC."""
        spec = self._by_id.get(_key(frame_id, is_extended_id))
        return None if spec is None else spec.name

    def length(self, name: str) -> int:
        """Payload length of message ``name`` (bytes)."""
        return self._spec(name).length

    def is_fd(self, name: str) -> bool:
        """True when message ``name`` is a CAN FD frame."""
        return self._spec(name).is_fd

    def signal_names(self, name: str) -> tuple[str, ...]:
        """Signals the caller provides to :meth:`encode` (``crc`` excluded)."""
        return tuple(s.name for s in self._spec(name).sigs)

    def step_bits(self, name: str) -> int:
        """Width of the ``step`` counter of message ``name`` (0 if it has none)."""
        return self._spec(name).step_bits

    # -- encode / decode ---------------------------------------------------

    def encode(self, name: str, signals: Mapping[str, float]) -> can.Message:
        """Frame of message ``name`` carrying ``signals`` (physical values).

        Every signal of the message except ``crc`` and those with a
        ``GenSigStartValue`` (``run_id``: that value) must be given (extra keys,
        e.g. ``i_c``, are ignored). Values are clipped to the signal's range,
        or wrapped for ``SigModular`` signals; ``crc`` is computed.

        Raises
        ------
        DbcError
            Unknown message, missing signal, or a NaN or infinite value.
        """
        spec = self._spec(name)
        values: dict[str, float] = {}
        for sig in spec.sigs:
            try:
                v = float(signals[sig.name])
            except KeyError:
                if sig.initial is not None:  # GenSigStartValue: may be omitted (run_id)
                    values[sig.name] = sig.initial
                    continue
                raise DbcError(
                    f"DBC {self.path}: message {name}: signal {sig.name} missing"
                ) from None
            if not math.isfinite(v):
                raise DbcError(f"DBC {self.path}: message {name}: signal {sig.name} is {v}")
            if sig.modulus:
                v = (round((v - sig.offset) / sig.scale) % sig.modulus) * sig.scale + sig.offset
            elif v < sig.lo:
                v = sig.lo
            elif v > sig.hi:
                v = sig.hi
            values[sig.name] = v
        if spec.crc_index >= 0:
            values[_CRC_SIGNAL] = 0
            data = spec.pack(values)
            data[spec.crc_index] = e2e_crc(spec.e2e_start, data, spec.crc_index)
        else:
            data = spec.pack(values)
        return can.Message(
            arbitration_id=spec.frame_id,
            is_extended_id=spec.is_extended,
            is_fd=spec.is_fd,
            bitrate_switch=spec.brs,
            data=data,
            check=False,
        )

    def signal_table(self, name: str) -> dict[str, tuple[float, ...]]:
        """How :meth:`encode` and :meth:`decode` treat each signal of message ``name``.

        By signal name: ``(lo, hi, scale, offset, modulus, chk_lo, chk_hi)``:
        the clip range of :meth:`encode` (``modulus`` > 0: the raw value is
        wrapped instead), and the range a decoded value must lie in
        (``chk_lo > chk_hi``: not checked).  A C encoder (the native plant
        node) takes the same arithmetic from here.
        """
        spec = self._spec(name)
        checked = {n: (lo, hi) for n, lo, hi in spec.checked}
        return {
            s.name: (
                s.lo,
                s.hi,
                s.scale,
                s.offset,
                float(s.modulus),
                *checked.get(s.name, (math.inf, -math.inf)),
            )
            for s in spec.sigs
        }

    def frame_kind(self, name: str) -> tuple[bool, bool]:
        """``(is_fd, bitrate_switch)`` of the frames :meth:`encode` makes for ``name``."""
        spec = self._spec(name)
        return spec.is_fd, spec.brs

    def with_crc(self, name: str, data: bytes | bytearray) -> bytes:
        """``data`` with the E2E CRC of message ``name`` filled in (unchanged if none)."""
        spec = self._spec(name)
        if spec.crc_index < 0 or len(data) != spec.length:
            return bytes(data)
        buf = bytearray(data)
        buf[spec.crc_index] = e2e_crc(spec.e2e_start, buf, spec.crc_index)
        return bytes(buf)

    def decode(self, msg: can.Message) -> Decoded | None:
        """Decode and check a received frame.

        Returns
        -------
        Decoded or None
            None only when the arbitration ID is not in the DBC; otherwise
            the signals with ``reason`` None, or a rejection reason:
            ``bad_length`` (DLC differs from the DBC), ``decode_error``
            (remote or error frame, or cantools could not unpack),
            ``bad_crc`` (E2E CRC mismatch), ``out_of_range`` (a value
            outside the signal's ``[min|max]``, e.g. an undefined enum).
        """
        spec = self._by_id.get(
            msg.arbitration_id | _EXTENDED if msg.is_extended_id else msg.arbitration_id
        )
        if spec is None:
            return None
        if msg.is_remote_frame or msg.is_error_frame:
            return Decoded(spec.name, {}, REJECT_DECODE_ERROR)
        return self._decode(spec, msg.data)

    def decode_data(
        self, frame_id: int, data: bytes, is_extended_id: bool = False
    ) -> Decoded | None:
        """:meth:`decode` for a bare identifier and payload (log analysis)."""
        spec = self._by_id.get(_key(frame_id, is_extended_id))
        return None if spec is None else self._decode(spec, data)

    def _decode(self, spec: _Spec, data: bytes | bytearray) -> Decoded:
        if len(data) != spec.length:
            return Decoded(spec.name, {}, REJECT_BAD_LENGTH)
        try:
            signals = spec.unpack(data)
        except Exception:
            return Decoded(spec.name, {}, REJECT_DECODE_ERROR)
        reason = None
        crc_index = spec.crc_index
        if crc_index >= 0:
            reg = spec.e2e_start
            table = CRC8_J1850_TABLE
            if crc_index == 0:
                for byte in data[1:]:
                    reg = table[reg ^ byte]
                crc_ok = reg ^ 0xFF == data[0]
            else:
                crc_ok = e2e_crc(reg, data, crc_index) == data[crc_index]
            if not crc_ok:
                reason = REJECT_BAD_CRC
        if reason is None:
            for sname, lo, hi in spec.checked:
                v = signals[sname]
                if v < lo or v > hi:
                    reason = REJECT_OUT_OF_RANGE
                    break
        if spec.derive_i_c:
            signals["i_c"] = -signals["i_a"] - signals["i_b"]
        return Decoded(spec.name, signals, reason)

    def quantize(self, name: str, signals: Mapping[str, float]) -> dict[str, float]:
        """Signals as a receiver sees them: ``decode(encode(name, signals))``.

        In-process runs pass their values through this to apply exactly the
        wire's quantization, clipping and wrapping. The ``crc`` entry is
        dropped.
        """
        decoded = self.decode(self.encode(name, signals))
        if decoded is None or not decoded.ok:  # only a DBC that contradicts itself gets here
            reason = "unknown id" if decoded is None else decoded.reason
            raise DbcError(f"DBC {self.path}: message {name}: own frame rejected ({reason})")
        out = decoded.signals
        out.pop(_CRC_SIGNAL, None)
        return out


@functools.cache
def default_codec() -> Codec:
    """The codec of the bench's own DBC, loaded once per process."""
    return Codec()
