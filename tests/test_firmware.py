"""`bench codegen` and the reference C controller's build, E2E helper and control law.

The closed loop of the C controller against the plant on vcan is in
``test_firmware_vcan.py``; these tests need only a C compiler and make.
"""

from __future__ import annotations

import math
import random
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from bench.cli import main
from bench.wire._ccodec import iter_vectors
from bench.wire._codec import Codec
from bench.wire._e2e import crc8_j1850, e2e_crc, e2e_start
from controller import core_sources
from controller._svpwm import svpwm
from plant_rt import preset

REPO = Path(__file__).resolve().parent.parent
FIRMWARE = REPO / "firmware"
CC = shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")
MAKE = shutil.which("make")
pytestmark = pytest.mark.skipif(CC is None or MAKE is None, reason="needs a C compiler and make")
CFLAGS = ["-std=c99", "-D_DEFAULT_SOURCE", "-O1", "-Wall", "-Wextra", "-Werror"]


def build_firmware(out: Path) -> Path:
    """Build ``ref_controller`` with firmware/Makefile into ``out``; returns the program."""
    res = subprocess.run(
        [MAKE or "make", "-s", "-C", str(FIRMWARE), f"BUILD={out}", f"PYTHON={sys.executable}"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert res.returncode == 0, res.stdout + res.stderr
    exe = out / "ref_controller"
    assert exe.is_file()
    return exe


@pytest.fixture(scope="module")
def build(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("firmware")
    build_firmware(out)
    return out


def test_codegen_writes_dbc_code_and_e2e_helper(tmp_path: Path, capsys) -> None:
    out = tmp_path / "gen"
    assert main(["codegen", str(out)]) == 0
    names = sorted(p.name for p in out.iterdir())
    assert names == [
        "bench_dbc.c",
        "bench_dbc.h",
        "bench_e2e.c",
        "bench_e2e.h",
        "bench_wire.h",
        "core",
    ]
    # the controller core a firmware builds on, byte for byte the bench's own
    core = sorted((out / "core").iterdir())
    assert [p.name for p in core] == [p.name for p in core_sources()]
    assert {p.name for p in core} >= {"cc_foc.h", "cc_foc.c", "cc_pi.c", "cc_svpwm.c"}
    for shipped, src in zip(core, core_sources(), strict=True):
        assert shipped.read_bytes() == src.read_bytes(), src.name
    header = (out / "bench_e2e.h").read_text()
    codec = Codec()
    for name, ident in [("PwmDuty", "PWM_DUTY"), ("PhaseSamples", "PHASE_SAMPLES")]:
        dbc = codec.message(name).dbc
        assert dbc is not None
        data_id = int(dbc.attributes["E2EDataId"].value)
        assert f"#define BENCH_E2E_{ident}_DATA_ID ({data_id}u)" in header
        assert f"#define BENCH_E2E_{ident}_CRC_INDEX (0u)" in header
    # DBC 2.1: the recorder frames carry a CRC too (the analysis trusts them)
    for name, ident in [("PlantTruth", "PLANT_TRUTH"), ("CtrlTelemetry", "CTRL_TELEMETRY")]:
        dbc = codec.message(name).dbc
        assert dbc is not None
        data_id = int(dbc.attributes["E2EDataId"].value)
        assert f"#define BENCH_E2E_{ident}_DATA_ID ({data_id}u)" in header
    assert "BENCH_DBC_PWM_DUTY_FRAME_ID (0x10u)" in (out / "bench_dbc.h").read_text()


def test_codegen_into_a_file_is_one_line_error(tmp_path: Path, capsys) -> None:
    target = tmp_path / "afile"
    target.write_text("x")
    assert main(["codegen", str(target)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and str(target) in err and "not a folder" in err


_E2E_HARNESS = r"""
#include <stdio.h>
#include <stdlib.h>
#include "bench_e2e.h"
/* stdin lines: data_id crc_index hex; prints the C CRC and the check result */
int main(void)
{
    unsigned id, idx;
    char hex[129];
    printf("%02x\n", bench_e2e_crc8_j1850((const uint8_t *)"123456789", 9));
    while (scanf("%u %u %128s", &id, &idx, hex) == 3) {
        uint8_t d[64];
        size_t n = 0;
        for (; hex[2 * n]; n++) {
            unsigned b;
            sscanf(hex + 2 * n, "%2x", &b);
            d[n] = (uint8_t)b;
        }
        printf("%02x %d\n", bench_e2e_crc((uint16_t)id, d, n, idx),
               bench_e2e_check((uint16_t)id, d, n, idx) ? 1 : 0);
    }
    return 0;
}
"""


def test_c_e2e_helper_agrees_with_python(tmp_path: Path) -> None:
    """Every protected vector (all messages, signals at their limits): same CRC in C;
    a flipped payload bit fails the C check."""
    gen = tmp_path / "gen"
    assert main(["codegen", str(gen)]) == 0
    src = tmp_path / "e2e_check.c"
    src.write_text(_E2E_HARNESS)
    exe = tmp_path / "e2e_check"
    res = subprocess.run(
        [CC or "cc", *CFLAGS, f"-I{gen}", "-o", str(exe), str(src), str(gen / "bench_e2e.c")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert res.returncode == 0, res.stderr
    codec = Codec()
    lines, expect = [], []
    rng = random.Random(5)
    for index, _, data, _ in iter_vectors(codec):
        message = codec.message(codec.names[index])
        assert message.dbc is not None
        attr = message.dbc.attributes.get("E2EDataId")
        if attr is None:
            continue
        data_id = int(attr.value)
        crc = e2e_crc(e2e_start(data_id), data, 0)
        assert crc == data[0]
        lines.append(f"{data_id} 0 {data.hex()}")
        expect.append((crc, 1))
        bad = bytearray(data)
        bad[rng.randrange(1, len(bad))] ^= 1 << rng.randrange(8)
        lines.append(f"{data_id} 0 {bytes(bad).hex()}")
        expect.append((e2e_crc(e2e_start(data_id), bad, 0), 0))
    assert len(expect) > 200
    res = subprocess.run(
        [str(exe)], input="\n".join(lines) + "\n", capture_output=True, text=True, timeout=60
    )
    out = res.stdout.split("\n")
    assert int(out[0], 16) == crc8_j1850(b"123456789") == 0x4B
    got = [(int(a, 16), int(b)) for a, b in (ln.split() for ln in out[1 : 1 + len(expect)])]
    assert got == expect


def _c_defines(path: Path) -> dict[str, str]:
    return dict(re.findall(r"^#define (\w+) (.+)$", path.read_text(), flags=re.M))


def test_firmware_params_are_the_wen2023_preset() -> None:
    d = _c_defines(FIRMWARE / "motor_params.h")
    p = preset("wen2023")
    m = p.motor
    assert float(d["PWM_FREQ_HZ"]) == p.f_sw
    assert int(d["MOTOR_N_P"]) == m.n_p
    for key, value in [
        ("MOTOR_R_S", m.R_s),
        ("MOTOR_L_D", m.L_d),
        ("MOTOR_L_Q", m.L_q),
        ("MOTOR_PSI_F", m.psi_f),
        ("MOTOR_J", m.J),
        ("MOTOR_I_MAX", m.i_max),
        ("MOTOR_TAU_MAX", 1.5 * m.tau_rated),
    ]:
        assert float(d[key]) == pytest.approx(value, rel=1e-12), key


_FOC_HARNESS = r"""
#include <stdio.h>
#include "cc_svpwm.h"
#include "foc.h"
#include "motor_params.h"
/* Prints the PI gains foc_init gives the core, then the core's SVPWM duties of each
 * stdin line "u_alpha u_beta u_dc". */
int main(void)
{
    foc_t f;
    foc_init(&f, 1.0 / PWM_FREQ_HZ, MOTOR_N_P, MOTOR_R_S, MOTOR_L_D, MOTOR_L_Q, MOTOR_PSI_F,
             MOTOR_J, MOTOR_I_MAX, MOTOR_TAU_MAX, ALPHA_C, ALPHA_S);
    const cc_pi_t *pis[3] = {&f.core.pi_d, &f.core.pi_q, &f.core.pi_w};
    for (int i = 0; i < 3; i++) {
        printf("%.17g %.17g %.17g\n", pis[i]->k_p, pis[i]->k_i, pis[i]->k_t);
    }
    double a, b, u;
    while (scanf("%lf %lf %lf", &a, &b, &u) == 3) {
        double d[3];
        cc_svpwm(a, b, u, d);
        printf("%.17g %.17g %.17g\n", d[0], d[1], d[2]);
    }
    return 0;
}
"""


def test_the_controller_core_compiles_standalone(tmp_path: Path) -> None:
    """The core (controller/core/) is plain C99: every file compiles on its own, without
    Python's headers, with every warning an error."""
    srcs = [str(p) for p in core_sources() if p.suffix == ".c"]
    assert len(srcs) > 10
    res = subprocess.run(
        [CC or "cc", "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-c", *srcs],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=tmp_path,
    )
    assert res.returncode == 0, res.stderr
    assert len(list(tmp_path.glob("cc_*.o"))) == len(srcs)
    for p in core_sources():
        assert not re.search(r'#\s*include\s*[<"]Python\.h', p.read_text()), p.name


def test_the_firmware_has_no_control_law_of_its_own() -> None:
    """firmware/foc.c runs the core's cc_foc_step: no PI, SVPWM, Clarke or Park of its own
    (no sin/cos, no PI integrator, no duty arithmetic), comments left out."""
    code = re.sub(r"/\*.*?\*/|//[^\n]*", "", (FIRMWARE / "foc.c").read_text(), flags=re.S)
    assert "cc_foc_step(" in code
    for own in ("sin(", "cos(", "u_i", "fmax(", "fmin(", "sqrt("):
        assert own not in code, own


def test_c_control_law_gains_and_svpwm(tmp_path: Path) -> None:
    """The gains the firmware gives the core follow the bandwidth formulas; the core's
    SVPWM equals the Python SVPWM."""
    src = tmp_path / "foc_check.c"
    src.write_text(_FOC_HARNESS)
    exe = tmp_path / "foc_check"
    core = REPO / "controller" / "core"
    res = subprocess.run(
        [CC or "cc", *CFLAGS, f"-I{FIRMWARE}", f"-I{core}", "-o", str(exe), str(src),
         str(FIRMWARE / "foc.c"), *[str(p) for p in core_sources() if p.suffix == ".c"],
         "-lm"],
        capture_output=True,
        text=True,
        timeout=120,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    rng = random.Random(7)
    vecs = []
    for _ in range(300):
        mag = rng.uniform(0.0, 1.2) * 540.0 / math.sqrt(3.0)  # into overmodulation
        ang = rng.uniform(-math.pi, math.pi)
        vecs.append((mag * math.cos(ang), mag * math.sin(ang), 540.0))
    res = subprocess.run(
        [str(exe)],
        input="".join(f"{a!r} {b!r} {u!r}\n" for a, b, u in vecs),
        capture_output=True,
        text=True,
        timeout=60,
    )
    rows = [[float(x) for x in ln.split()] for ln in res.stdout.strip().splitlines()]
    m = preset("wen2023").motor
    a_c, a_s = 2 * math.pi * 100.0, 2 * math.pi * 5.0
    for row, L in zip(rows[:2], (m.L_d, m.L_q), strict=True):
        assert row == pytest.approx([2 * a_c * L - m.R_s, a_c * a_c * L, a_c * L], rel=1e-12)
    assert rows[2] == pytest.approx([2 * a_s * m.J, a_s * a_s * m.J, a_s * m.J], rel=1e-12)
    assert len(rows) == 3 + len(vecs)
    for (a, b, u), row in zip(vecs, rows[3:], strict=True):
        assert row == pytest.approx(list(svpwm(a, b, u)), abs=1e-12)


def test_the_firmware_reads_no_plant_truth() -> None:
    """A sensored controller reads PositionSensor; PlantTruth is the recorder's (DBC 2.2):
    the C code (comments left out) names neither the frame nor its codec."""
    code = re.sub(
        r"/\*.*?\*/|//[^\n]*", "", (FIRMWARE / "ref_controller.c").read_text(), flags=re.S
    )
    assert "BENCH_DBC_POSITION_SENSOR_FRAME_ID" in code
    assert "bench_dbc_position_sensor_theta_m_decode" in code
    assert not re.search(r"plant_truth", code, flags=re.I)


def test_firmware_builds_with_the_makefile(build: Path) -> None:
    """firmware/Makefile runs `bench codegen` and compiles with -Wall -Wextra -Werror."""
    assert (build / "ref_controller").is_file()
    for f in ("bench_dbc.h", "bench_dbc.c", "bench_e2e.h", "bench_e2e.c", "core/cc_foc.c"):
        assert (build / "gen" / f).is_file()
    res = subprocess.run(
        [str(build / "ref_controller"), "-e", "0"], capture_output=True, text=True, timeout=30
    )
    assert res.returncode == 2 and "-e must be >= 1" in res.stderr
