"""Generated C code of the DBC agrees byte for byte with the Python codec."""

from __future__ import annotations

import shutil
import subprocess

import pytest

from bench.wire._ccodec import generate_c, generate_harness, iter_vectors, write_vectors
from bench.wire._codec import Codec

CC = shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")
pytestmark = pytest.mark.skipif(CC is None, reason="no C compiler")


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    assert CC is not None
    out = tmp_path_factory.mktemp("ccodec")
    codec = Codec()
    header, source = generate_c(out, codec)
    harness = generate_harness(out, codec)
    exe = out / "check_vectors"
    res = subprocess.run(
        [CC, "-std=c99", "-Wall", "-Wextra", "-Werror", "-O1", "-o", str(exe),
         str(harness), str(source), "-lm"],
        capture_output=True,
        text=True,
        timeout=120,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    return out, exe, codec, header


def test_generated_files(built):
    out, _, _, header = built
    text = header.read_text()
    assert header.name == "bench_dbc.h" and (out / "bench_dbc.c").exists()
    for frame_id, symbol in [
        (0x010, "PWM_DUTY"),
        (0x011, "PHASE_SAMPLES"),
        (0x101, "CTRL_TELEMETRY"),
    ]:
        assert f"BENCH_DBC_{symbol}_FRAME_ID (0x{frame_id:02x}u)" in text
    assert "BENCH_DBC_PLANT_TRUTH_LENGTH (16u)" in text


def test_vectors_cover_every_message(built):
    _, _, codec, _ = built
    vectors = list(iter_vectors(codec))
    assert {v[0] for v in vectors} == set(range(len(codec.names)))
    assert sum(1 for v in vectors if not v[1]) >= 5  # undefined enum values, out of range
    assert len(vectors) > 20 * len(codec.names)


def test_c_agrees_with_python(built, tmp_path):
    _, exe, codec, _ = built
    vectors = tmp_path / "vectors.txt"
    n = write_vectors(vectors, codec)
    res = subprocess.run([str(exe), str(vectors)], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stdout[-2000:]
    assert res.stdout.strip().splitlines()[-1] == f"{n} passed, 0 failed"


def test_harness_detects_a_wrong_vector(built, tmp_path):
    """Changing one payload byte or one physical value must make the C check fail."""
    _, exe, codec, _ = built
    good = tmp_path / "good.txt"
    write_vectors(good, codec)
    lines = good.read_text().splitlines()
    fields = lines[1].split()  # a PwmDuty vector: index, in_range, hex, nsig, ...
    payload = bytearray.fromhex(fields[2])
    payload[3] ^= 0x10  # inside duty_b
    bad_payload = [*fields[:2], payload.hex(), *fields[3:]]
    fields2 = lines[2].split()
    fields2[6] = str(int(fields2[6]) + 1)  # raw of the second signal off by one LSB
    for bad in (bad_payload, fields2):
        path = tmp_path / "bad.txt"
        path.write_text(" ".join(bad) + "\n")
        res = subprocess.run([str(exe), str(path)], capture_output=True, text=True, timeout=60)
        assert res.returncode == 1
        assert res.stdout.strip().splitlines()[-1] == "0 passed, 1 failed"
