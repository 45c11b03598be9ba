"""C code of the DBC for a drive controller, and a harness that checks it.

A controller in C packs and unpacks the bench's frames with the code cantools
generates from the DBC (:func:`generate_c`: ``bench_dbc.h`` and
``bench_dbc.c``). :func:`generate_harness` writes a small C program that reads
test vectors written by the Python codec (:func:`write_vectors`) and checks,
message by message and signal by signal, that the generated C code and the
Python codec agree byte for byte:

- ``<msg>_<sig>_encode`` of the physical value gives the Python raw value,
  and ``<msg>_pack`` gives the Python payload;
- ``<msg>_unpack`` of the payload gives the raw values and
  ``<msg>_<sig>_decode`` the Python physical values exactly;
- ``<msg>_<sig>_is_in_range`` is false for some signal exactly when the
  Python codec rejects the frame as ``out_of_range``;
- the E2E CRC computed in C (CRC-8 SAE J1850 with the data ID, as in
  :mod:`bench.wire._e2e`) equals the payload's crc byte of every valid frame.

Vector file, one frame per line (whitespace separated)::

    <message index> <expect_in_range 0|1> <payload hex> <n signals>
        (<raw> <physical as C99 hex float>) * n

in DBC signal order; the harness prints one line per mismatch and the closing
line ``N passed, N failed``.
"""

from __future__ import annotations

import random
from collections.abc import Iterator
from pathlib import Path
from typing import Any, cast

from cantools.database.can.c_source import camel_to_snake_case, generate

from bench.wire._codec import REJECT_OUT_OF_RANGE, Codec

__all__ = ["C_PREFIX", "generate_c", "generate_harness", "iter_vectors", "write_vectors"]

C_PREFIX = "bench_dbc"
"""Prefix of every generated C name, and stem of the generated files."""


def generate_c(out_dir: str | Path, codec: Codec) -> tuple[Path, Path]:
    """Write cantools' C code of the DBC: ``bench_dbc.h`` and ``bench_dbc.c``.

    Encode functions round to nearest (``use_round``), as the Python codec
    does.

    Returns
    -------
    header, source : Path
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    header, source, _, _ = generate(
        codec.db,
        C_PREFIX,
        f"{C_PREFIX}.h",
        f"{C_PREFIX}.c",
        f"{C_PREFIX}_fuzzer.c",
        floating_point_numbers=True,
        use_round=True,
    )
    h_path, c_path = out / f"{C_PREFIX}.h", out / f"{C_PREFIX}.c"
    h_path.write_text(header)
    c_path.write_text(source)
    return h_path, c_path


def _physical_points(codec: Codec, name: str) -> list[dict[str, float]]:
    """Signal values at min, max, zero, one LSB and mid-range, plus random ones."""
    message = codec.message(name)
    sigs = [s for s in message.signals if s.name != "crc"]
    points: list[dict[str, float]] = []

    def lim(s: object, which: str) -> float:
        return float(getattr(s, which))

    points.append({s.name: lim(s, "minimum") for s in sigs})
    points.append({s.name: lim(s, "maximum") for s in sigs})
    points.append({s.name: min(max(0.0, lim(s, "minimum")), lim(s, "maximum")) for s in sigs})
    points.append(
        {
            s.name: min(max(float(s.offset) + float(s.scale), lim(s, "minimum")), lim(s, "maximum"))
            for s in sigs
        }
    )
    points.append(
        {s.name: min(max(-float(s.scale), lim(s, "minimum")), lim(s, "maximum")) for s in sigs}
    )
    points.append({s.name: 0.5 * (lim(s, "minimum") + lim(s, "maximum")) for s in sigs})
    rng = random.Random(name)
    for _ in range(20):
        points.append({s.name: rng.uniform(lim(s, "minimum"), lim(s, "maximum")) for s in sigs})
    return points


def _raw_payloads(codec: Codec, name: str, base: dict[str, float]) -> list[bytes]:
    """Payloads with one raw value above the signal's maximum (e.g. an undefined
    enum value), packed by cantools from raw values, with a valid CRC."""
    message = codec.message(name)
    raws = message.decode_simple(
        bytes(codec.encode(name, base).data), decode_choices=False, scaling=False
    )
    out: list[bytes] = []
    for s in message.signals:
        raw_max = (1 << s.length) - 1
        if s.name == "crc" or s.is_signed or s.maximum is None:
            continue
        if s.maximum < raw_max * s.scale + s.offset:
            bad: dict[str, Any] = dict(raws)
            bad[s.name] = raw_max
            data = message.encode(bad, scaling=False, strict=False)
            out.append(codec.with_crc(name, data))
    return out


def iter_vectors(codec: Codec) -> Iterator[tuple[int, bool, bytes, list[tuple[int, float]]]]:
    """Test vectors: (message index, expected in range, payload, (raw, physical) per signal).

    Payloads come from :meth:`Codec.encode` (CRC included); raw values from
    cantools' unscaled decode; physical values from :meth:`Codec.decode`.
    Frames with a raw value above a signal's maximum are packed by cantools
    from raw values, with their CRC, and must be rejected as ``out_of_range``.
    """
    for index, name in enumerate(codec.names):
        message = codec.message(name)
        points = _physical_points(codec, name)
        payloads = [bytes(codec.encode(name, p).data) for p in points]
        payloads += _raw_payloads(codec, name, points[0])
        for data in payloads:
            decoded = codec.decode_data(message.frame_id, data)
            if decoded is None or decoded.reason not in (None, REJECT_OUT_OF_RANGE):
                reason = "unknown id" if decoded is None else decoded.reason
                raise AssertionError(f"{name}: vector rejected ({reason})")
            raws = message.decode_simple(data, decode_choices=False, scaling=False)
            values = [
                (int(cast("int", raws[s.name])), float(decoded.signals[s.name]))
                for s in message.signals
            ]
            yield index, decoded.reason is None, data, values


def write_vectors(path: str | Path, codec: Codec) -> int:
    """Write :func:`iter_vectors` to ``path``; returns the number of frames."""
    lines = []
    for index, in_range, data, values in iter_vectors(codec):
        fields = " ".join(f"{raw} {phys.hex()}" for raw, phys in values)
        lines.append(f"{index} {int(in_range)} {data.hex()} {len(values)} {fields}")
    Path(path).write_text("\n".join(lines) + "\n")
    return len(lines)


_HARNESS_HEAD = r"""/* Checks the generated DBC code against vectors of the Python codec. */
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "bench_dbc.h"

#define MAX_SIGNALS 32

static uint8_t crc8_j1850_table[256];

static void crc8_j1850_init(void)
{
    for (int b = 0; b < 256; b++) {
        uint8_t reg = (uint8_t)b;
        for (int i = 0; i < 8; i++) {
            reg = (reg & 0x80u) ? (uint8_t)((reg << 1) ^ 0x1Du) : (uint8_t)(reg << 1);
        }
        crc8_j1850_table[b] = reg;
    }
}

/* CRC-8 SAE J1850 (init 0xFF, xorout 0xFF). */
static uint8_t crc8_j1850(const uint8_t *data, size_t len)
{
    uint8_t reg = 0xFFu;
    for (size_t i = 0; i < len; i++) {
        reg = crc8_j1850_table[reg ^ data[i]];
    }
    return (uint8_t)(reg ^ 0xFFu);
}

/* E2E CRC: data ID (low, high byte), then the payload without its crc byte. */
static uint8_t e2e_crc(uint16_t data_id, const uint8_t *data, size_t len, size_t crc_index)
{
    uint8_t buf[2 + 64];
    size_t n = 0;
    buf[n++] = (uint8_t)(data_id & 0xFFu);
    buf[n++] = (uint8_t)(data_id >> 8);
    for (size_t i = 0; i < len; i++) {
        if (i != crc_index) {
            buf[n++] = data[i];
        }
    }
    return crc8_j1850(buf, n);
}

static int failed;

#define FAIL(...) do { printf(__VA_ARGS__); printf("\n"); failed++; } while (0)
"""

_HARNESS_MAIN = r"""
static int hexval(int c)
{
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return -1;
}

int main(int argc, char **argv)
{
    if (argc != 2) {
        fprintf(stderr, "usage: %s VECTORS\n", argv[0]);
        return 2;
    }
    crc8_j1850_init();
    if (crc8_j1850((const uint8_t *)"123456789", 9) != 0x4Bu) {
        FAIL("crc8_j1850(123456789) != 0x4B");
    }
    FILE *f = fopen(argv[1], "r");
    if (f == NULL) {
        perror(argv[1]);
        return 2;
    }
    int index, in_range, nsig, frames = 0, frames_failed = 0;
    char hex[2 * 64 + 1];
    while (fscanf(f, "%d %d %128s %d", &index, &in_range, hex, &nsig) == 4) {
        long long raw[MAX_SIGNALS];
        double phys[MAX_SIGNALS];
        uint8_t data[64];
        size_t len = strlen(hex) / 2;
        if (nsig > MAX_SIGNALS) {
            fprintf(stderr, "too many signals\n");
            return 2;
        }
        for (int i = 0; i < nsig; i++) {
            char buf[64];
            if (fscanf(f, "%lld %63s", &raw[i], buf) != 2) {
                fprintf(stderr, "bad vector line %d\n", frames + 1);
                return 2;
            }
            phys[i] = strtod(buf, NULL);
        }
        for (size_t i = 0; i < len; i++) {
            data[i] = (uint8_t)(hexval(hex[2 * i]) * 16 + hexval(hex[2 * i + 1]));
        }
        int before = failed;
        check(index, in_range, data, len, nsig, raw, phys);
        frames++;
        if (failed != before) frames_failed++;
    }
    fclose(f);
    if (failed && frames_failed == 0) frames_failed = 1;
    printf("%d passed, %d failed\n", frames - frames_failed, frames_failed);
    return (failed == 0 && frames > 0) ? 0 : 1;
}
"""


def generate_harness(out_dir: str | Path, codec: Codec) -> Path:
    """Write the C check program ``check_vectors.c`` for this DBC's messages."""
    parts = [_HARNESS_HEAD]
    cases = []
    for index, name in enumerate(codec.names):
        message = codec.message(name)
        m = f"{C_PREFIX}_{camel_to_snake_case(name)}"
        body = [
            f"static void check_{index}(int in_range, const uint8_t *data, size_t len,",
            "                      const long long *raw, const double *phys)",
            "{",
            f"    struct {m}_t s;",
            "    uint8_t buf[64];",
            "    int all_in_range = 1;",
            "    memset(&s, 0, sizeof s);",
        ]
        for i, sig in enumerate(message.signals):
            f_ = camel_to_snake_case(sig.name)
            body += [
                f"    s.{f_} = {m}_{f_}_encode(phys[{i}]);",
                f"    if ((long long)s.{f_} != raw[{i}])",
                f'        FAIL("{name}.{sig.name}: encode(%.17g) = %lld, python %lld",'
                f" phys[{i}], (long long)s.{f_}, raw[{i}]);",
            ]
        body += [
            "    memset(buf, 0, sizeof buf);",
            f"    int n = {m}_pack(buf, &s, sizeof buf);",
            "    if (n != (int)len || memcmp(buf, data, len) != 0)",
            f'        FAIL("{name}: pack differs from python payload");',
            "    memset(&s, 0, sizeof s);",
            f"    if ({m}_unpack(&s, data, len) != 0)",
            f'        FAIL("{name}: unpack failed");',
        ]
        for i, sig in enumerate(message.signals):
            f_ = camel_to_snake_case(sig.name)
            body += [
                f"    if ((long long)s.{f_} != raw[{i}])",
                f'        FAIL("{name}.{sig.name}: unpack raw %lld, python %lld",'
                f" (long long)s.{f_}, raw[{i}]);",
                f"    if ({m}_{f_}_decode(s.{f_}) != phys[{i}])",
                f'        FAIL("{name}.{sig.name}: decode %.17g, python %.17g",'
                f" {m}_{f_}_decode(s.{f_}), phys[{i}]);",
                f"    all_in_range &= {m}_{f_}_is_in_range(s.{f_}) ? 1 : 0;",
            ]
        body += [
            "    if (all_in_range != in_range)",
            f'        FAIL("{name}: is_in_range %d, python %d", all_in_range, in_range);',
        ]
        data_id = message.dbc.attributes.get("E2EDataId") if message.dbc else None
        crc = [s for s in message.signals if s.name == "crc"]
        if data_id is not None and crc:
            idx = crc[0].start // 8
            body += [
                f"    if (e2e_crc({int(data_id.value)}u, data, len, {idx}) != data[{idx}])",
                f'        FAIL("{name}: C E2E CRC %02x, payload %02x",'
                f" e2e_crc({int(data_id.value)}u, data, len, {idx}), data[{idx}]);",
            ]
        body.append("}\n")
        parts.append("\n".join(body))
        cases.append(f"    case {index}: check_{index}(in_range, data, len, raw, phys); break;")
    parts.append(
        "static void check(int index, int in_range, const uint8_t *data, size_t len, int nsig,\n"
        "                  const long long *raw, const double *phys)\n"
        "{\n"
        "    (void)nsig;\n"
        "    switch (index) {\n" + "\n".join(cases) + "\n"
        '    default: FAIL("unknown message index %d", index);\n'
        "    }\n"
        "}\n"
    )
    parts.append(_HARNESS_MAIN)
    path = Path(out_dir) / "check_vectors.c"
    path.write_text("\n".join(parts))
    return path
