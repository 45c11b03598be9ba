"""The per-period hot path of the codec: pack and unpack compiled from the DBC once.

cantools encodes a frame through dictionaries of raw values and two generic
bit-field packers (about 9 us per frame here) and decodes through its
generic scaling (about 2-4 us).  For a message whose signals are all little
endian integers (every message of ``dbc/bench.dbc``), this module writes one
Python function per message, from the DBC's own start bits, lengths,
signedness, scales and offsets, that packs the payload as one integer with
shifts and masks (``int.to_bytes``) or unpacks it the same way.  The raw
value of a signal is cantools' own ``numeric_scaled_to_raw`` arithmetic
(``divmod`` by the scale, then ``round``), written out, and a decoded value is
``raw * scale + offset`` as cantools computes it, so both give cantools'
bytes and numbers exactly.

:func:`compile_message` returns ``None`` for a message it does not handle
(big endian, float or multiplexed signals); :class:`bench.wire._codec.Codec`
then keeps cantools for it.  ``Codec`` also checks every compiled message
against cantools when it loads a DBC (:func:`agrees_with_cantools`), with
every signal at its limits, at zero and in between, and keeps cantools for
a message where they differ.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

from cantools.database.can import Message

#: Packs the physical values of the signals (clipped or wrapped already) into the payload.
Pack = Callable[[Mapping[str, float]], bytearray]
#: Unpacks a payload of the message's length into physical values.
Unpack = Callable[[bytes | bytearray], dict[str, float]]


@dataclass(frozen=True, slots=True)
class CompiledMessage:
    """The generated pack and unpack of one message, and their source (for reading)."""

    pack: Pack
    unpack: Unpack
    source: str


def _handled(message: Message) -> bool:
    """Little-endian integer signals only, none multiplexed."""
    return bool(message.signals) and all(
        s.byte_order == "little_endian"
        and not s.is_float
        and not s.is_multiplexer
        and not s.multiplexer_ids
        for s in message.signals
    )


def _raw_expr(name: str, scale: float, offset: float) -> list[str]:
    """Statements that set ``r`` to cantools' raw value of signal ``name`` (from ``v``)."""
    v = f"v[{name!r}]"
    if scale == 1 and offset == 0:
        return [f"r = round({v})"]
    return [
        f"x = {v} - {offset!r}",
        f"q, m = divmod(x, {scale!r})",
        f"r = round(q if m == 0 else x / {scale!r})",
    ]


def compile_message(message: Message) -> CompiledMessage | None:
    """Pack and unpack of ``message`` as generated Python, or None when not handled."""
    if not _handled(message):
        return None
    n = message.length
    pack = [f"def pack_{message.name}(v):", "    p = 0"]
    unpack = [f"def unpack_{message.name}(data):", "    x = int.from_bytes(data, 'little')"]
    out: list[str] = []
    for s in message.signals:
        mask = (1 << s.length) - 1
        scale = s.conversion.scale
        offset = s.conversion.offset
        pack += ["    " + line for line in _raw_expr(s.name, scale, offset)]
        pack.append(f"    p |= (r & {mask:#x}) << {s.start}")
        var = f"s_{len(out)}"
        unpack.append(f"    {var} = (x >> {s.start}) & {mask:#x}")
        if s.is_signed:
            half = 1 << (s.length - 1)
            unpack.append(f"    if {var} >= {half:#x}: {var} -= {1 << s.length:#x}")
        if not (scale == 1 and offset == 0):
            unpack.append(f"    {var} = {var} * {scale!r} + {offset!r}")
        out.append(f"{s.name!r}: {var}")
    pack.append(f"    return bytearray(p.to_bytes({n}, 'little'))")
    unpack.append("    return {" + ", ".join(out) + "}")
    source = "\n".join(pack) + "\n\n\n" + "\n".join(unpack) + "\n"
    namespace: dict[str, object] = {}
    exec(compile(source, f"<hot codec of {message.name}>", "exec"), namespace)
    return CompiledMessage(
        pack=namespace[f"pack_{message.name}"],  # type: ignore[arg-type]
        unpack=namespace[f"unpack_{message.name}"],  # type: ignore[arg-type]
        source=source,
    )


def limit_vectors(message: Message) -> list[dict[str, float]]:
    """Physical values of every signal at its minimum, its maximum, zero and in between.

    The limits are the DBC's ``[min|max]`` where given, else the raw range.
    """
    lows: dict[str, float] = {}
    highs: dict[str, float] = {}
    for s in message.signals:
        raw_lo = -(1 << (s.length - 1)) if s.is_signed else 0
        raw_hi = (1 << (s.length - 1)) - 1 if s.is_signed else (1 << s.length) - 1
        scale, offset = s.conversion.scale, s.conversion.offset
        lo_hi = sorted((raw_lo * scale + offset, raw_hi * scale + offset))
        lows[s.name] = float(s.minimum) if s.minimum is not None else lo_hi[0]
        highs[s.name] = float(s.maximum) if s.maximum is not None else lo_hi[1]
    vectors = [dict(lows), dict(highs)]
    vectors.append({k: min(max(0.0, lows[k]), highs[k]) for k in lows})
    for frac in (0.25, 1.0 / 3.0, 0.5, 0.7071):
        vectors.append({k: lows[k] + frac * (highs[k] - lows[k]) for k in lows})
    return vectors


def agrees_with_cantools(message: Message, compiled: CompiledMessage) -> bool:
    """Whether ``compiled`` gives cantools' bytes and values on :func:`limit_vectors`."""
    for vec in limit_vectors(message):
        try:
            want = message.encode(vec, strict=False, scaling=True)
        except Exception:
            continue  # a vector cantools cannot encode is not a comparison
        got = bytes(compiled.pack(vec))
        if got != want:
            return False
        back = message.decode_simple(want, decode_choices=False)
        mine = compiled.unpack(want)
        if mine.keys() != back.keys() or any(
            type(mine[k]) is not type(back[k]) or mine[k] != back[k] for k in back
        ):
            return False
    return True
