"""``bench codegen --estimator``: the firmware's core initialised as the bench's controller.

``bench_controller.h`` (:mod:`bench.wire._ctlgen`) holds the core's ``_init`` calls
with the values the Python design gives them. Checked here without CAN: the header's
values are the Python controller's, the ``cc_foc_t`` (and ``cc_sup_t``) it initialises
is byte for byte the one the bench's compiled controller runs, and stepped with the
same commands and samples it gives the same outputs, bit for bit; the firmware builds
with it (``-Werror``). The closed loop on vcan is ``test_firmware_sensorless_vcan.py``.
"""

from __future__ import annotations

import ctypes
import random
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from bench.cli import main
from bench.scenarios._schema import load_scenario
from bench.scenarios._setup import build_controller
from bench.wire._codec import Codec
from bench.wire._ctlgen import c_double
from bench.wire._protocol import RPM_PER_RAD_S
from controller import ControlOutput, Measurement, estimator_spec
from controller._engine import COMPILED_ESTIMATORS
from tests.test_firmware import CC, CFLAGS, FIRMWARE, MAKE

pytestmark = pytest.mark.skipif(CC is None or MAKE is None, reason="needs a C compiler and make")

REPO = Path(__file__).resolve().parent.parent
SCENARIO = Path(__file__).parent / "data" / "firmware-sensorless.toml"
#: every estimator of the compiled core a drive can run (no plant truth)
SENSORLESS = [e for e in COMPILED_ESTIMATORS if not estimator_spec(e).needs_truth]
#: periods stepped: past the alignment (1000) and settling (500) of wen2023 at 10 kHz,
#: so the polarity test and the speed loop run too
N_STEPS = 2500

_HARNESS = r"""
#include <stdint.h>
#include <stdio.h>
#include "bench_controller.h"
static cc_foc_t c;
static cc_sup_t sup;
static void dump(const void *p, size_t n)
{
    printf("%llu ", (unsigned long long)(uintptr_t)p);
    for (size_t i = 0; i < n; i++)
        printf("%02x", ((const unsigned char *)p)[i]);
    printf("\n");
}
/* prints the initialised structs, then for stdin lines "e ON", "w W_M_REF" and
 * "s K I_A I_B U_DC": the command applied, or the step's output */
int main(void)
{
    if (bench_controller_init(&c, &sup) != 0)
        return 3;
    dump(&c, sizeof c);
    dump(&sup, sizeof sup);
    char op[4];
    while (scanf("%3s", op) == 1) {
        if (op[0] == 'e') {
            int on;
            if (scanf("%d", &on) != 1)
                return 4;
            cc_foc_set_enable(&c, on);
        } else if (op[0] == 'w') {
            double w;
            if (scanf("%lf", &w) != 1)
                return 4;
            cc_foc_set_speed_ref(&c, w);
        } else {
            long long k;
            double a, b, u;
            if (scanf("%lld %lf %lf %lf", &k, &a, &b, &u) != 4)
                return 4;
            cc_meas_t m = {k, a, b, -a - b, u, 0, 0.0, 0.0};
            cc_out_t o;
            int rc = cc_foc_step(&c, &m, &o);
#if BENCH_CTL_SUPERVISION
            cc_sup_after(&sup, &c, &m, &o);
#endif
            printf("%d %lld %.17g %.17g %.17g %d %.17g %.17g %.17g %lld %.17g %.17g\n", rc, o.k,
                   o.d_a, o.d_b, o.d_c, o.enable, o.theta_hat, o.w_hat, o.err, o.mode, o.i_d,
                   o.i_q);
        }
    }
    return 0;
}
"""


def _scenario(tmp_path: Path, supervision: bool, measured: bool = False) -> Path:
    """The test scenario, with the supervision on or as it is (off), and with the
    demodulator's ``normalise = "measured"`` or as it is (``"model"``)."""
    if not (supervision or measured):
        return SCENARIO
    p = tmp_path / "variant.toml"
    text = SCENARIO.read_text()
    if supervision:
        text += "\n[controller]\nsupervision = true\n"
    if measured:
        # an empty [motor]: the preset's motor, which the injection settings are for
        text += '\n[motor]\n\n[estimator_options]\nnormalise = "measured"\n'
    p.write_text(text)
    return p


def _harness(tmp_path: Path, scenario: Path, estimator: str) -> Path:
    gen = tmp_path / "gen"
    args = ["codegen", str(gen), "--scenario", str(scenario), "--estimator", estimator]
    assert main(args) == 0
    src = tmp_path / "harness.c"
    src.write_text(_HARNESS)
    exe = tmp_path / "harness"
    core = sorted(str(p) for p in (gen / "core").glob("cc_*.c"))
    res = subprocess.run(
        [CC or "cc", *CFLAGS, f"-I{gen}", f"-I{gen / 'core'}", "-o", str(exe), str(src), *core,
         "-lm"],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    return exe


def _same_struct(dump: str, addr: int) -> None:
    """The struct at ``addr`` (the bench's) equals the harness's ``dump`` ("ADDRESS HEX")
    byte for byte, except a pointer (the links of a hybrid to its parts), which must point
    at the same offset inside its own struct."""
    base, hexed = dump.split()
    c_bytes = bytes.fromhex(hexed)
    py_bytes = ctypes.string_at(addr, len(c_bytes))
    n = len(c_bytes)
    for off in range(0, n - n % 8, 8):
        a, b = c_bytes[off : off + 8], py_bytes[off : off + 8]
        if a != b:
            rel_c = int.from_bytes(a, sys.byteorder) - int(base)
            rel_py = int.from_bytes(b, sys.byteorder) - addr
            assert rel_c == rel_py and 0 <= rel_c < n, f"byte {off}: differs"
    assert c_bytes[n - n % 8 :] == py_bytes[n - n % 8 :]


def _script(seed: int) -> list[tuple]:
    """Commands and samples as a controller node gets them: enable and a speed reference
    at 0, a new reference at 2000, samples with currents up to 3 A and a DC link near
    540 V (their values matter not: the same bits go into both)."""
    rng = random.Random(seed)
    out: list[tuple] = [("e", 1), ("w", 0.0)]
    for k in range(N_STEPS):
        if k == 2000:
            out.append(("w", 100.0 / RPM_PER_RAD_S))
        out.append(("s", k, rng.uniform(-3, 3), rng.uniform(-3, 3), rng.uniform(530, 550)))
    return out


@pytest.mark.parametrize(
    ("estimator", "supervision", "measured"),
    [
        *[(e, False, False) for e in SENSORLESS],
        ("tt-dq", True, False),
        ("square-wave", True, False),
        # normalise = "measured": cc_design_measured and the quadrature LPF in the header
        ("tt-dq", False, True),
        ("epf", False, True),
    ],
)
def test_the_generated_core_is_the_bench_controllers(
    tmp_path: Path, estimator: str, supervision: bool, measured: bool
) -> None:
    """Initialised by bench_controller_init, the firmware's cc_foc_t and cc_sup_t are the
    bench's compiled controller's byte for byte; stepped with the same commands and
    samples, every output is the same double."""
    scn = _scenario(tmp_path, supervision, measured)
    exe = _harness(tmp_path, scn, estimator)
    header = (tmp_path / "gen" / "bench_controller.h").read_text()
    assert ("cc_design_measured(" in header) == measured
    ctrl = build_controller(load_scenario(str(scn)), estimator, engine="compiled")
    assert ctrl.engine == "compiled"
    assert (ctrl.supervisor is not None) == supervision
    script = _script(7)
    text = "".join(" ".join(x if isinstance(x, str) else repr(x) for x in row) + "\n"
                   for row in script)  # fmt: skip
    res = subprocess.run([str(exe)], input=text, capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    lines = res.stdout.splitlines()
    foc_addr, sup_addr = ctrl._core.address()
    _same_struct(lines[0], foc_addr)
    if supervision:
        assert sup_addr
        _same_struct(lines[1], sup_addr)
    modes = set()
    rows = iter(lines[2:])
    for row in script:
        if row[0] == "e":
            ctrl.set_enable(bool(row[1]))
        elif row[0] == "w":
            ctrl.set_speed_ref(row[1])
        else:
            _, k, i_a, i_b, u_dc = row
            o: ControlOutput = ctrl.step(Measurement(k, i_a, i_b, -i_a - i_b, u_dc, None, None))
            got = next(rows).split()
            assert got[0] == "0"
            want = [o.k, o.d_a, o.d_b, o.d_c, int(o.enable), o.theta_hat, o.w_hat, o.err,
                    o.mode, o.i_d, o.i_q]  # fmt: skip
            assert [int(got[1]), *map(float, got[2:5]), int(got[5]), *map(float, got[6:9]),
                    int(got[9]), *map(float, got[10:])] == want, f"period {k}"  # fmt: skip
            modes.add(o.mode)
    assert next(rows, None) is None
    assert len(modes) >= 2  # the start-up and the run (or the supervision's trip) ran


def _inits(header: str, fn: str) -> list[list[Any]]:
    """The arguments after the struct of every call of ``fn`` in the header: a number as
    a float, an array ``(const double[]){...}`` as a list of floats, anything else as its
    text."""

    def value(a: str) -> Any:
        if a.startswith("(const double[]){"):
            return [float(x) for x in a[a.index("{") + 1 : -1].split(",")]
        return float(a.removesuffix("LL")) if re.match(r"^-?[\d.]", a) else a

    out = []
    for args in re.findall(rf"\b{fn}\((.*)\)( < 0\) return -1)?;", header):
        parts = re.findall(r"\(const double\[\]\)\{[^}]*\}|[^,\s][^,]*", args[0])
        out.append([value(a.strip()) for a in parts[1:]])
    return out


def test_the_header_holds_the_python_designs_values(tmp_path: Path) -> None:
    """The PIs, the speed filter, the PLL and the FOC constants in the header are the
    Python controller's attributes, each the same double (read back from its text)."""
    gen = tmp_path / "gen"
    assert main(["codegen", str(gen), "--scenario", str(SCENARIO), "--estimator", "tt-dq"]) == 0
    h = (gen / "bench_controller.h").read_text()
    ctrl = build_controller(load_scenario(str(SCENARIO)), "tt-dq", engine="compiled")
    pis = _inits(h, "cc_design_pi")
    assert pis == [[j, p.k_p, p.k_i, p.T_s, p.k_t]
                   for j, p in enumerate((ctrl.pi_d, ctrl.pi_q, ctrl.pi_w))]  # fmt: skip
    f = ctrl.lpf_w
    assert _inits(h, "cc_design_speed_filter") == [[f.b0, f.b1, f.a1]]
    est: Any = ctrl.estimator
    pll = est.pll
    (rot,) = _inits(h, "cc_design_rotating")
    assert rot[3] == [pll.k_p, pll.k_i, pll.T_s]
    m = ctrl.motor
    (foc,) = _inits(h, "cc_design_foc")
    assert foc[:7] == [m.n_p, m.L_d, m.L_q, m.psi_f, ctrl.i_max, ctrl.tau_max, ctrl.t_delay]
    assert foc[7:9] == [ctrl.n_align, ctrl.n_settle]
    assert '#define BENCH_CTL_ESTIMATOR "tt-dq"' in h
    assert f"#define BENCH_CTL_T_S {c_double(ctrl.pars.T_s)}" in h
    assert "#define BENCH_CTL_NEEDS_TRUTH 0" in h
    assert f"#define BENCH_CTL_RPM_PER_RAD_S {c_double(RPM_PER_RAD_S)}" in h
    # the output encodings are the codec's
    s = next(s for s in Codec()._spec("PwmDuty").sigs if s.name == "duty_a")
    assert re.search(
        rf"#define BENCH_WIRE_PWM_DUTY_DUTY_A \{{{c_double(s.lo)}, {c_double(s.hi)}, "
        rf"{re.escape(c_double(s.scale))}, {c_double(s.offset)}, 0LL\}}",
        h,
    )


@pytest.mark.parametrize(
    ("x", "text"),
    [(0.1, "0.10000000000000001"), (4.0, "4.0"), (-0.0, "-0.0"), (-2.5e-300, "-2.5e-300"), (1 / 3, "0.33333333333333331"),
     (float("inf"), "INFINITY"), (float("-inf"), "(-INFINITY)")],
)  # fmt: skip
def test_c_double_reads_back_exactly(x: float, text: str) -> None:
    assert c_double(x) == text
    if "INF" not in text:
        assert float(text).hex() == x.hex()


def test_firmware_builds_sensorless_with_werror(tmp_path: Path) -> None:
    """make SCENARIO=... ESTIMATOR=... builds the firmware on the generated header with
    firmware/Makefile's -Wall -Wextra -Werror; the sensored estimator (plant truth) is
    refused at compile time with its reason."""
    for est in ("tt-dq", "square-wave"):
        build = tmp_path / est
        res = subprocess.run(
            [MAKE or "make", "-s", "-C", str(FIRMWARE), f"BUILD={build}", f"PYTHON={sys.executable}",
             f"SCENARIO={SCENARIO}", f"ESTIMATOR={est}"],
            capture_output=True, text=True, timeout=300,
        )  # fmt: skip
        assert res.returncode == 0, res.stdout + res.stderr
        assert "-Werror" in (FIRMWARE / "Makefile").read_text()
        assert f'"{est}"' in (build / "gen" / "bench_controller.h").read_text()
        assert (build / "ref_controller").is_file()
    res = subprocess.run(
        [MAKE or "make", "-s", "-C", str(FIRMWARE), f"BUILD={tmp_path / 'sensored'}",
         f"PYTHON={sys.executable}", f"SCENARIO={SCENARIO}", "ESTIMATOR=sensored"],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert res.returncode != 0 and "PlantTruth" in res.stderr


def test_a_build_for_another_estimator_compiles_only_the_program(tmp_path: Path) -> None:
    """In one BUILD, the DBC's code and the core are compiled once (firmware/Makefile's
    objects): `bench codegen` gives a file it writes with unchanged contents (cantools'
    time stamp aside) its time back, so a build for another estimator compiles and links
    the program only, and a build with nothing changed does nothing."""
    build = tmp_path / "build"

    def make(est: str) -> str:
        res = subprocess.run(
            [MAKE or "make", "-C", str(FIRMWARE), f"BUILD={build}", f"PYTHON={sys.executable}",
             f"SCENARIO={SCENARIO}", f"ESTIMATOR={est}"],
            capture_output=True, text=True, timeout=300,
        )  # fmt: skip
        assert res.returncode == 0, res.stdout + res.stderr
        return res.stdout

    def times() -> dict[str, int]:
        files = [*build.glob("obj/**/*.o"), *build.glob("gen/**/*.[ch]"), build / "ref_controller"]
        return {str(f.relative_to(build)): f.stat().st_mtime_ns for f in files}

    make(SENSORLESS[0])
    objects = sorted(build.glob("obj/**/*.o"))
    # the DBC's code, the E2E helper and every core source
    assert len(objects) == 2 + len(list((build / "gen" / "core").glob("cc_*.c")))
    dbc = (build / "gen" / "bench_dbc.c").read_bytes()
    first = times()
    out = make(SENSORLESS[1])
    second = times()
    changed = {f for f in first if first[f] != second[f]}
    assert changed == {"gen/bench_controller.h", "ref_controller"}, changed
    assert (build / "gen" / "bench_dbc.c").read_bytes() == dbc
    assert f'"{SENSORLESS[1]}"' in (build / "gen" / "bench_controller.h").read_text()
    assert " -c " not in out  # no object compiled
    make(SENSORLESS[1])
    assert times() == second


def test_the_sensorless_firmware_reads_no_sensor_or_truth() -> None:
    """In the sensorless build (FW_BENCH_CONTROLLER) the program names neither
    PositionSensor nor PlantTruth: every use of the encoder is outside it."""
    code = re.sub(r"/\*.*?\*/|//[^\n]*", "", (FIRMWARE / "ref_controller.c").read_text(),
                  flags=re.S)  # fmt: skip
    res = subprocess.run(
        [CC or "cc", "-E", "-P", "-DFW_BENCH_CONTROLLER", "-DFW_SAMPLE_TIMEOUT_S=0.05",
         "-nostdinc", "-x", "c", "-"],
        input=re.sub(r"^\s*#\s*include[^\n]*$", "", code, flags=re.M),
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    pre = res.stdout
    assert "cc_foc_step(" in pre and "bench_controller_init(" in pre
    assert not re.search(r"position_sensor|plant_truth", pre, flags=re.I)


def test_codegen_estimator_mistakes_are_one_line(tmp_path: Path, capsys) -> None:
    assert main(["codegen", str(tmp_path / "a"), "--estimator", "tt-dq"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "--estimator" in err and "--scenario" in err
    args = ["codegen", str(tmp_path / "b"), "--scenario", str(SCENARIO), "--estimator", "nope"]
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "nope" in err
