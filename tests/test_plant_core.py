"""The plant's portable C core (plant_rt/core/): standalone, pure, and the code Plant runs.

The core must build and run without Python (the native node of issue 29
links it): these tests compile it on its own with ``-std=c99 -Wall -Wextra
-Werror``, check that its objects hold no mutable global state and call
nothing but libm and the C library's memcpy/memset (no allocation),
and run a C program that steps it, whose trace must be Plant's bit for bit.
They also cover what the binding adds: ``Plant.step_n`` (many periods in
one C call) and ``Plant.set_parameters`` (a change between two periods).
"""

from __future__ import annotations

import os
import shutil
import subprocess
from dataclasses import replace
from pathlib import Path

import pytest

from plant_rt import Plant, drive_profile, ideal_profile, preset

CORE = Path(__file__).resolve().parents[1] / "plant_rt" / "core"
SOURCES = sorted(CORE.glob("*.c"))
# what the core may call: libm and a few functions of the C library, none of which allocates
ALLOWED_CALLS = {
    *("cos", "sin", "sincos", "sqrt", "exp", "fmod", "floor", "copysign"),
    *("memcpy", "memmove", "memset"),  # the compiler may emit these for copies
}


@pytest.fixture()
def cc() -> str:
    """The C compiler: a skip off CI, a failure in CI (never a silent pass)."""
    path = shutil.which("gcc") or shutil.which("cc")
    if path is None:
        if os.environ.get("CI"):
            pytest.fail("no C compiler (tools/need-cc installs one)")
        pytest.skip("no C compiler (tools/need-cc installs one)")
    return path


def test_core_compiles_standalone_as_c99(cc: str, tmp_path: Path) -> None:
    """``gcc -std=c99 -Wall -Wextra -Werror -c plant_rt/core/*.c`` builds, warning-free."""
    assert len(SOURCES) >= 7, SOURCES
    r = subprocess.run(
        [cc, "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O2", "-c", *SOURCES],
        cwd=tmp_path,
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr
    assert len(list(tmp_path.glob("*.o"))) == len(SOURCES)


def test_core_has_no_python_no_state_no_allocation(cc: str, tmp_path: Path) -> None:
    """No Python.h; no writable global (nm: no data or bss symbol); calls only libm and libc's few."""
    for f in [*SOURCES, *CORE.glob("*.h")]:
        assert "Python.h" not in f.read_text(), f
    subprocess.run([cc, "-std=c99", "-O2", "-c", *SOURCES], cwd=tmp_path, check=True)
    nm = shutil.which("nm")
    if nm is None:
        pytest.skip("no nm")
    for obj in sorted(tmp_path.glob("*.o")):
        rows = subprocess.run([nm, str(obj)], capture_output=True, text=True, check=True).stdout
        for row in rows.splitlines():
            kind, name = row.split()[-2:]
            assert kind not in "DdBbCG", f"{obj.name}: global state {name} ({kind})"
            if kind == "U" and not name.startswith("plant_"):
                assert name in ALLOWED_CALLS, f"{obj.name} calls {name}"


DRIVER = r"""
#include <stdio.h>
#include <stdlib.h>
#include "plant.h"

static plant pl; /* the program's, not the core's */

int main(int argc, char **argv)
{
    double v[24];
    if (argc != 26) return 2;
    for (int i = 0; i < 24; i++) v[i] = strtod(argv[1 + i], NULL);
    plant_pars p;
    plant_machine_pars *m = &p.machine;
    m->n_p = v[0]; m->R_s = v[1]; m->L_d = v[2]; m->L_q = v[3]; m->psi_f = v[4]; m->J = v[5];
    m->b = v[6]; m->i_max = v[7]; m->sat_sigma = v[8]; m->sat_i_sat = v[9]; m->c_dq = v[10];
    m->saturation = (int)v[11]; m->cross = (int)v[12];
    p.T_s = v[13]; p.substeps = (int)v[14]; p.t_delay = v[15]; p.switching = (int)v[16];
    p.peak = (int)v[17]; p.u_dc = v[18]; p.t_dead = v[19]; p.v_ce = v[20]; p.v_f = v[21];
    p.r_dc = v[22]; p.c_dc = v[23];
    long n = atol(argv[25]);
    if (plant_init(&pl, &p) != PLANT_OK) return 3;
    for (long k = 0; k < n; k++)
        if (plant_step(&pl, 0.5 + 0.01 * (k % 7), 0.5 - 0.01 * (k % 5), 0.5, k * p.T_s)) return 4;
    printf("%a %a %a %a %a\n", pl.x.i_d, pl.x.i_q, pl.x.w_m, pl.x.th_m, pl.u_dc);
    return 0;
}
"""


@pytest.mark.parametrize("profile", ["ideal", "drive"])
def test_c_program_steps_the_core_as_plant_does(cc: str, tmp_path: Path, profile: str) -> None:
    """A C program without Python steps the core: its state after 300 periods is Plant's, bit for bit."""
    pre = preset("wen2023")
    prof = (ideal_profile if profile == "ideal" else drive_profile)(pre)
    plant = Plant(
        pre.motor,
        prof.inverter,
        pre.T_s,
        sensors=prof.sensors,
        saturation=prof.saturation,
        cross_saturation=prof.cross_saturation,
    )
    n = 300
    for k in range(n):
        plant.step(0.5 + 0.01 * (k % 7), 0.5 - 0.01 * (k % 5), 0.5)
    src = tmp_path / "drive.c"
    src.write_text(DRIVER)
    exe = tmp_path / "drive"
    build: list[str | Path] = [
        cc,
        "-std=c99",
        "-O2",
        "-ffp-contract=off",
        f"-I{CORE}",
        str(src),
        *SOURCES,
        "-lm",
    ]
    subprocess.run([*build, "-o", str(exe)], check=True)
    pars = [float(v).hex() for v in plant._core_pars()]
    out = subprocess.run([str(exe), *pars, str(n)], capture_output=True, text=True, check=True)
    got = [float.fromhex(x) for x in out.stdout.split()]
    tr = plant.truth()
    assert got == [tr.i_d, tr.i_q, tr.w_m, tr.theta_m, tr.u_dc]
    assert abs(tr.w_m) > 1.0  # the machine turned: the comparison saw real dynamics


def _drive_plant(**kw: object) -> Plant:
    pre = preset("xue2022")
    prof = drive_profile(pre)
    return Plant(
        pre.motor,
        prof.inverter,
        pre.T_s,
        sensors=prof.sensors,
        saturation=prof.saturation,
        cross_saturation=prof.cross_saturation,
        **kw,  # type: ignore[arg-type]
    )


def _duties(n: int) -> list[tuple[float, float, float]]:
    return [(0.5 + 0.02 * (k % 9), 0.5 - 0.015 * (k % 4), 0.48) for k in range(n)]


def test_step_n_is_n_steps_bit_for_bit() -> None:
    """``Plant.step_n`` gives the trace of ``n`` calls of ``step``, and the same sample after."""
    a = _drive_plant()
    b = _drive_plant()
    duties = _duties(250)
    trace: list[float] = []
    for d in duties:
        a.step(*d)
        trace.extend((a._i_d, a._i_q, a._w_m, a._th_m, a._u_dc, *a.u_s_ab))
    out = b.step_n(duties)
    assert len(out) == 7 * 250
    assert list(out) == trace
    assert b.k == a.k == 250
    assert b.truth() == a.truth()
    assert b.sample() == a.sample()
    assert b.step_n([]) == out[:0]
    with pytest.raises(ValueError, match="three duties"):
        b.step_n([(0.5, 0.5)])


@pytest.mark.parametrize("engine", ["compiled", "python"])
def test_set_parameters_between_two_steps(engine: str) -> None:
    """A changed R_s, psi_f and u_dc take effect at the next step, the states kept.

    The plant changed after 100 periods continues bit for bit as a plant
    built with the new parameters from the state it had reached (the
    switching model's PWM timeline ends every period with duties inside
    (0, 1) where it starts, low and out of its dead interval), and
    differs from the plant left unchanged.
    """
    a = _drive_plant(engine=engine)
    unchanged = _drive_plant(engine=engine)
    for d in _duties(100):
        a.step(*d)
        unchanged.step(*d)
    motor = replace(a.motor, R_s=1.3 * a.motor.R_s, psi_f=0.9 * a.motor.psi_f)
    inverter = replace(a.inverter, u_dc=0.8 * a.inverter.u_dc)
    tr = a.truth()
    a.set_parameters(motor=motor, inverter=inverter)
    assert a.motor is motor and a.inverter is inverter
    assert a.truth().u_dc == inverter.u_dc  # a stiff link follows its source at once
    assert (a.truth().i_d, a.truth().w_m, a.truth().theta_m) == (tr.i_d, tr.w_m, tr.theta_m)
    pre = preset("xue2022")
    prof = drive_profile(pre)
    fresh = Plant(
        motor,
        inverter,
        pre.T_s,
        sensors=prof.sensors,
        saturation=True,
        cross_saturation=True,
        theta_m0=tr.theta_m,
        w_m0=tr.w_m,
        i_d0=tr.i_d,
        i_q0=tr.i_q,
        engine=engine,
    )
    fresh.k = a.k
    for d in _duties(50):
        a.step(*d)
        fresh.step(*d)
        unchanged.step(*d)
    assert a.truth() == fresh.truth()
    assert a.truth().i_q != unchanged.truth().i_q
    assert a.truth().w_m != unchanged.truth().w_m
    with pytest.raises(ValueError, match="model and sample_at"):
        a.set_parameters(inverter=replace(a.inverter, model="average"))


def test_substeps_beyond_the_core_grid_is_one_clear_error() -> None:
    """The core's grid is fixed-size (no allocation): 64 substeps run, 65 are refused."""
    pre = preset("wen2023")
    plant = Plant(pre.motor, pre.inverter, pre.T_s, substeps=64, w_m0=10.0)
    plant.step(0.6, 0.4, 0.5)
    assert plant.truth().i_d != 0.0
    with pytest.raises(ValueError, match=r"substeps must be an integer in 1\.\.64, got 65"):
        Plant(pre.motor, pre.inverter, pre.T_s, substeps=65)
