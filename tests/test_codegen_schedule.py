"""``bench codegen --scenario``: the schedule as segments a firmware can evaluate, the
start-up and scoring macros, and every frame only with ``--commands``."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

from bench.cli import main
from bench.scenarios._describe import schedule
from bench.scenarios._schema import load_scenario

TIMES = (0.0, 0.25, 0.3, 0.45, 0.8, 1.0, 2.5, 3.0, 4.0, 5.9, 7.0, 8.9)

PROGRAM = """#include <stdio.h>
#include "bench_scenario.h"
static const bench_scn_segment_t speed[] = BENCH_SCN_SPEED_SEGMENTS;
static const bench_scn_segment_t load[] = BENCH_SCN_LOAD_SEGMENTS;
static double at(const bench_scn_segment_t *s, int n, double t)
{
    double v = s[0].v0;
    for (int i = 0; i < n && t >= s[i].t0_s; i++) {
        if (s[i].t1_s == s[i].t0_s || t >= s[i].t1_s) {
            v = s[i].v1;
        } else {
            v = s[i].v0 + (s[i].v1 - s[i].v0) * (t - s[i].t0_s) / (s[i].t1_s - s[i].t0_s);
        }
    }
    return v;
}
int main(void)
{
    static const double times[] = {%s};
    printf("%%g %%d %%g\\n", BENCH_SCN_THETA_E0_DEG, BENCH_SCN_KNOWN_INITIAL_ANGLE,
           BENCH_SCN_SCORE_FROM_S);
    for (unsigned i = 0; i < sizeof times / sizeof times[0]; i++) {
        printf("%%.9g %%.9g\\n", at(speed, BENCH_SCN_N_SPEED_SEGMENTS, times[i]),
               at(load, BENCH_SCN_N_LOAD_SEGMENTS, times[i]));
    }
    printf("%%ld\\n", (long)BENCH_SCN_N_COMMANDS);
    return 0;
}
"""


@pytest.mark.skipif(shutil.which("cc") is None, reason="needs a C compiler")
def test_the_segments_give_the_scenarios_profiles_in_c(tmp_path: Path) -> None:
    assert main(["codegen", str(tmp_path), "--scenario", "wen-5.3"]) == 0
    header = (tmp_path / "bench_scenario.h").read_text()
    assert "BENCH_SCN_COMMANDS " not in header  # every frame only with --commands
    assert len(header.splitlines()) < 80  # 4602 frames, ten segments
    assert "ramp 100 -> -100 rpm (2000 frames)" in header  # the schedule as bench show prints it
    (tmp_path / "main.c").write_text(PROGRAM % ", ".join(map(repr, TIMES)))
    exe = tmp_path / "main"
    subprocess.run(
        ["cc", "-std=c99", "-Wall", "-Wextra", "-Werror", "-I", str(tmp_path), "-o", str(exe),
         str(tmp_path / "main.c")],
        check=True,
    )  # fmt: skip
    out = subprocess.run([str(exe)], capture_output=True, text=True, check=True).stdout
    lines = out.split("\n")
    scn = load_scenario("wen-5.3")
    theta, known, score = lines[0].split()
    assert float(theta) == scn.theta_e0_deg and int(known) == int(scn.known_initial_angle)
    assert float(score) == scn.score_from_s
    for t, line in zip(TIMES, lines[1:], strict=False):
        w, tau = map(float, line.split())
        assert w == pytest.approx(scn.speed_rpm(t), abs=1e-6), t
        assert tau == pytest.approx(scn.load_nm(t), abs=1e-6), t
    assert int(lines[len(TIMES) + 1]) == schedule(scn)["frames"] == 4602


def test_commands_option_writes_every_frame(tmp_path: Path) -> None:
    assert main(["codegen", str(tmp_path), "--scenario", "xue-fig17", "--commands"]) == 0
    header = (tmp_path / "bench_scenario.h").read_text()
    assert "#define BENCH_SCN_COMMANDS \\" in header
    rows = [ln for ln in header.splitlines() if ln.strip().startswith("{") and "L, " in ln]
    assert len(rows) == 5 and "/* stop */" in rows[-1]
