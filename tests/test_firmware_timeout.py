"""The firmware's sample timeout (firmware/ref_controller.c, "Sample timeout"), without CAN
and without a clock.

A harness includes ``ref_controller.c`` itself (its ``main`` renamed), built sensorless with
the bench's tt-dq controller as firmware/Makefile builds it, and drives it frame by frame:
PhaseSamples and BenchCommand frames, packed and protected by the generated codec, go to
the firmware's own ``on_frame``; the periods passed since the newest sample go to its
``sample_watch`` as numbers (the main loop counts them on the monotonic clock); its frames
come back through a socket pair. So the rule is checked to the period: armed (``-r``, real
time) it gates the PWM off after ``ceil(SAMPLE_TIMEOUT_S / T_s)`` periods, not one
before, counts the timeout once, keeps enable 0 on the samples that come again and
after a speed reference, and resumes on an enable command; a stop due with the missing
sample ends the program instead; not armed (lockstep) it never trips.
"""

from __future__ import annotations

import math
import subprocess
from pathlib import Path

import pytest

from bench.cli import main
from bench.nodes._loops import SAMPLE_TIMEOUT_S
from bench.scenarios._schema import load_scenario
from bench.scenarios._setup import sample_period
from tests.test_firmware import CC, CFLAGS, FIRMWARE, MAKE

pytestmark = pytest.mark.skipif(CC is None or MAKE is None, reason="needs a C compiler and make")

SCENARIO = Path(__file__).parent / "data" / "firmware-sensorless.toml"

_HARNESS = r"""
#define main ref_controller_main
#include "ref_controller.c"
#undef main
#include <fcntl.h>

static int peer;

/* the firmware's PwmDuty frames sent since the last call: "duty STEP ENABLE" */
static void drain(void)
{
    struct canfd_frame fr;
    while (read(peer, &fr, sizeof fr) > 0) {
        if (fr.can_id == BENCH_DBC_PWM_DUTY_FRAME_ID) {
            struct bench_dbc_pwm_duty_t d;
            if (bench_dbc_pwm_duty_unpack(&d, fr.data, fr.len) != 0)
                printf("bad\n");
            printf("duty %u %u\n", (unsigned)d.step, (unsigned)d.enable);
        }
    }
}

static void feed(int sock, node_t *n, law_t *law, uint32_t id, uint8_t *buf, int len,
                 unsigned data_id)
{
    struct canfd_frame fr;
    bench_e2e_protect(data_id, buf, (size_t)len, 0u);
    make_frame(&fr, id, buf, (size_t)len);
    sensor_t sen = {1, 65536.0, 0.0, 0.0};
    on_frame(sock, n, law, &fr, &sen);
}

/* argv[1]: "r" armed (real time), "l" not (lockstep).  stdin: "s K" a sample of period
 * K; "c CMD SEQ STEP RPM" a command; "t P" P periods since the newest sample. */
int main(int argc, char **argv)
{
    static node_t node;
    static law_t law;
    int sv[2];
    if (argc != 2 || socketpair(AF_UNIX, SOCK_DGRAM, 0, sv) != 0)
        return 2;
    peer = sv[1];
    fcntl(peer, F_SETFL, O_NONBLOCK);
    node_init(&node, argv[1][0] == 'r' ? FW_SAMPLE_TIMEOUT_S : 0.0);
    if (bench_controller_init(&law.core, &law.sup) != 0)
        return 3;
    printf("limit %lld\n", (long long)node.timeout_periods);
    char op[4];
    uint8_t buf[64];
    while (scanf("%3s", op) == 1) {
        if (op[0] == 's') {
            long long k;
            if (scanf("%lld", &k) != 1)
                return 4;
            struct bench_dbc_phase_samples_t s;
            bench_dbc_phase_samples_init(&s);
            s.i_a = bench_dbc_phase_samples_i_a_encode(0.1);
            s.i_b = bench_dbc_phase_samples_i_b_encode(-0.05);
            s.u_dc = bench_dbc_phase_samples_u_dc_encode(540.0);
            s.status = 1;
            s.step = (uint16_t)(k & 1023);
            int len = bench_dbc_phase_samples_pack(buf, &s, sizeof buf);
            feed(sv[0], &node, &law, BENCH_DBC_PHASE_SAMPLES_FRAME_ID, buf, len,
                 BENCH_E2E_PHASE_SAMPLES_DATA_ID);
        } else if (op[0] == 'c') {
            int cmd, seq;
            long long step;
            double rpm;
            if (scanf("%d %d %lld %lf", &cmd, &seq, &step, &rpm) != 4)
                return 4;
            struct bench_dbc_bench_command_t c;
            bench_dbc_bench_command_init(&c);
            c.cmd = (uint8_t)cmd;
            c.seq = (uint8_t)seq;
            c.step = (uint16_t)(step & 65535);
            c.speed_ref = bench_dbc_bench_command_speed_ref_encode(rpm);
            int len = bench_dbc_bench_command_pack(buf, &c, sizeof buf);
            feed(sv[0], &node, &law, BENCH_DBC_BENCH_COMMAND_FRAME_ID, buf, len,
                 BENCH_E2E_BENCH_COMMAND_DATA_ID);
        } else {
            long long p;
            if (scanf("%lld", &p) != 1)
                return 4;
            sample_watch(&node, &law, p);
            printf("watch %d %ld %d\n", node.faulted ? 1 : 0, node.sample_timeouts,
                   node.stop ? 1 : 0);
        }
        drain();
    }
    return 0;
}
"""


@pytest.fixture(scope="module")
def harness(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("fw_timeout")
    gen = tmp / "gen"
    assert main(["codegen", str(gen), "--scenario", str(SCENARIO), "--estimator", "tt-dq"]) == 0
    src = tmp / "harness.c"
    src.write_text(_HARNESS)
    exe = tmp / "harness"
    c_files = [str(FIRMWARE / "foc.c"), str(gen / "bench_dbc.c"), str(gen / "bench_e2e.c")]
    c_files += sorted(str(p) for p in (gen / "core").glob("cc_*.c"))
    res = subprocess.run(
        [CC or "cc", *CFLAGS, "-DFW_BENCH_CONTROLLER", f"-DFW_SAMPLE_TIMEOUT_S={SAMPLE_TIMEOUT_S!r}",
         f"-I{gen}", f"-I{gen / 'core'}", f"-I{FIRMWARE}", "-o", str(exe), str(src), *c_files,
         "-lm"],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    return exe


def _run(exe: Path, mode: str, script: list[str]) -> tuple[list[list[str]], str]:
    res = subprocess.run(
        [str(exe), mode], input="\n".join(script) + "\n", capture_output=True, text=True,
        timeout=60,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    return [ln.split() for ln in res.stdout.splitlines()], res.stderr


def _limit() -> int:
    """The timeout in periods as the header comment states it: ceil(SAMPLE_TIMEOUT_S / T_s)."""
    return math.ceil(SAMPLE_TIMEOUT_S / sample_period(load_scenario(str(SCENARIO))) - 1e-9)


def _enables(rows: list[list[str]], steps: range) -> list[int]:
    got = {int(r[1]): int(r[2]) for r in rows if r[0] == "duty"}
    return [got[k + 1] for k in steps]  # PwmDuty.step = k + 1


def test_the_sample_timeout_gates_the_pwm_off_until_an_enable(harness: Path) -> None:
    n = _limit()
    assert n == 500  # 50 ms at the scenario's 10 kHz
    script = ["c 1 0 0 100"] + [f"s {k}" for k in range(20)]
    script += [f"t {n - 1}", f"t {n}", f"t {n + 100}"]
    script += [f"s {k}" for k in range(20, 30)]  # the samples come again: still off
    script += ["c 0 1 30 200"] + [f"s {k}" for k in range(30, 35)]  # a speed reference alone
    script += ["c 4 2 35 200"] + [f"s {k}" for k in range(35, 40)]  # enable: on again
    script += [f"t {n}"]
    rows, err = _run(harness, "r", script)
    assert rows[0] == ["limit", str(n)]
    watches = [r[1:] for r in rows if r[0] == "watch"]
    # not one period early; tripped once and counted once; the enable clears it
    assert watches == [["0", "0", "0"], ["1", "1", "0"], ["1", "1", "0"], ["1", "2", "0"]]
    assert _enables(rows, range(20)) == [1] * 20
    assert _enables(rows, range(20, 35)) == [0] * 15
    assert _enables(rows, range(35, 40)) == [1] * 5
    assert err.count("no PhaseSamples for") == 2 and "until a start, enable or reset" in err


def test_a_stop_due_with_the_missing_sample_ends_the_program(harness: Path) -> None:
    n = _limit()
    script = ["c 1 0 0 100"] + [f"s {k}" for k in range(40)] + ["c 2 1 41 0", "s 40", f"t {n}"]
    rows, err = _run(harness, "r", script)
    assert [r[1:] for r in rows if r[0] == "watch"] == [["0", "0", "1"]]
    assert err == ""


def test_in_lockstep_the_timeout_is_not_armed(harness: Path) -> None:
    script = ["c 1 0 0 100"] + [f"s {k}" for k in range(5)] + [f"t {100 * _limit()}", "s 5"]
    rows, _ = _run(harness, "l", script)
    assert rows[0] == ["limit", "0"]
    assert [r[1:] for r in rows if r[0] == "watch"] == [["0", "0", "0"]]
    assert _enables(rows, range(6)) == [1] * 6


def test_no_sample_is_answered_before_the_start_is_held(harness: Path) -> None:
    """docs/PROTOCOL.md: a controller that joined the bus after the start answers no sample
    before it holds it.  Sample 0 before the start gets no duty (the plant sends it again);
    the start then answers it at once, enabled, and a copy of sample 0 gets that answer
    again (the protocol's rule for a repeated sample)."""
    rows, _ = _run(harness, "l", ["s 0", "c 1 0 0 100", "s 0", "s 1"])
    duties = [r[1:] for r in rows if r[0] == "duty"]
    assert duties == [["1", "1"], ["1", "1"], ["2", "1"]]
    # a command beyond a gap (seq 1 without seq 0, the start) is not the start
    rows, _ = _run(harness, "l", ["c 0 1 5 100", "s 0", "c 1 0 0 100"])
    assert [r[1:] for r in rows if r[0] == "duty"] == [["1", "1"]]
