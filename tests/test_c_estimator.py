"""A user's estimator written in C (``controller/core/cc_estimator.h``, a shared library
named through a plug-in's factory, :func:`controller.c_estimator`).

docs/examples/my_estimator_c.c is docs/examples/my_estimator.py's flux observer and
PLL in C, operation for operation. Built here with the system's C compiler, it gives
the Python example's trace bit for bit, in the controller's core and in the oracle
(tests/oracle, the Python step, tolerance 0); the core calls its functions with no
Python in the period, so the native controller node serves it. A function that fails
is the same one error in both.
"""

from __future__ import annotations

import math
import os
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from bench.nodes._controller_node import ControllerNode
from bench.scenarios._schema import load_scenario
from bench.scenarios._setup import build_plant
from bench.wire._codec import Codec
from controller import Measurement, c_estimator, core_sources
from controller._cplugin import C_ESTIMATOR_FAILED
from tests import oracle

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "docs" / "examples"
CC = shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")
CORE = core_sources()[0].parent

#: A C estimator whose update fails from period 40 on.
FAILING = r"""
#include <stddef.h>
#include "cc_estimator.h"
typedef struct { cc_est_t out; } st_t;
static int update(void *ctx, const cc_est_in_t *x, cc_est_t *out)
{
    st_t *s = ctx;
    if (x->k >= 40)
        return 1;
    s->out.i_alpha_f = x->i_alpha;
    s->out.i_beta_f = x->i_beta;
    *out = s->out;
    return 0;
}
static int injection(void *ctx, double *a, double *b) { (void)ctx; *a = *b = 0.0; return 0; }
static int reset(void *ctx, double th, cc_est_t *out)
{
    st_t *s = ctx;
    s->out.theta_hat = th;
    *out = s->out;
    return 0;
}
size_t cc_estimator_size(void) { return sizeof(st_t); }
int cc_estimator_init(void *state, cc_est_if_t *f, const cc_est_design_t *d)
{
    (void)d;
    st_t *s = state;
    s->out.theta_hat = s->out.w_hat = s->out.err = s->out.i_alpha_f = s->out.i_beta_f = 0.0;
    f->ctx = s; f->update = update; f->injection = injection; f->reset = reset;
    f->hf_current_next = NULL; f->set_saliency_offset = NULL;
    return 0;
}
"""


def _build(src: Path, out: Path) -> Path:
    """The shared library of ``src``, as docs/examples/my_estimator_c.c says to build it."""
    cmd = [CC or "cc", "-std=c99", "-O2", "-shared", "-fPIC", "-ffp-contract=off"]
    cmd += ["-Wall", "-Wextra", "-Werror", f"-I{CORE}", "-o", str(out), str(src), "-lm"]
    subprocess.run(cmd, check=True, capture_output=True, text=True)
    return out


@pytest.fixture
def c_plugin(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    if CC is None:
        if os.environ.get("CI"):
            pytest.fail("needs a C compiler and the compiled controller")
        pytest.skip("needs a C compiler")
    lib = _build(EXAMPLES / "my_estimator_c.c", tmp_path / "libmy_estimator_c.so")
    monkeypatch.setenv("MY_ESTIMATOR_C_LIB", str(lib))
    monkeypatch.syspath_prepend(str(EXAMPLES))
    monkeypatch.delitem(sys.modules, "my_estimator_c", raising=False)
    yield lib
    sys.modules.pop("my_estimator_c", None)


def _loop(estimator: str, engine: str, n: int) -> tuple[list[tuple[Any, ...]], Any]:
    """flux-known-angle on the compiled plant: a start, a speed step, a second start."""
    scn = load_scenario(str(EXAMPLES / "flux-known-angle.toml"))
    sim = build_plant(scn, "compiled")
    ctrl = oracle.build(scn, estimator, engine)
    ctrl.set_enable(True)
    ctrl.set_speed_ref(2.0 * math.pi)
    d = (0.5, 0.5, 0.5, False)
    out = []
    for k in range(n):
        if k == n // 3:
            ctrl.set_speed_ref(-math.pi)
        if k == (2 * n) // 3:
            ctrl.set_enable(False)
        if k == (2 * n) // 3 + 50:
            ctrl.set_enable(True)
        s = sim.sample()
        o = ctrl.step(Measurement(s.k, s.i_a, s.i_b, s.i_c, s.u_dc))
        sim.step(*d)
        out.append((o.d_a, o.d_b, o.d_c, o.theta_hat, o.w_hat, o.err, o.i_d, o.i_q, o.mode))
        d = (o.d_a, o.d_b, o.d_c, o.enable)
    return out, ctrl


def test_the_c_estimator_gives_the_python_examples_trace_in_core_and_oracle(c_plugin: Path) -> None:
    """The C port, in the oracle (tests/oracle) and in the core, against the Python example
    in the oracle: every output of every period equal, bit for bit (tolerance 0); the core
    calls no Python (``external_estimator`` False), and the design is the example's."""
    n = 4000
    ref, c_ref = _loop("my_estimator:create", "oracle", n)
    py, c_py = _loop("my_estimator_c:create", "oracle", n)
    cc, c_cc = _loop("my_estimator_c:create", "compiled", n)
    assert (c_py.engine, c_cc.engine, c_cc.engine_note) == ("oracle", "compiled", None)
    assert not c_cc.external_estimator
    assert c_cc.gains() == c_ref.gains()
    for name, got in (("oracle", py), ("compiled", cc)):
        first = next((k for k in range(n) if got[k] != ref[k]), None)
        assert first is None, f"the C estimator on the {name} engine parts at period {first}"
    assert len(set(ref)) > n // 2  # the trace moves


def test_the_native_node_serves_a_c_estimator(c_plugin: Path) -> None:
    """No Python in the period: the native controller node may run it (a Python plug-in
    keeps the Python node, tests/test_controller_engine.py)."""
    from bench.nodes.native.controller_node import native_unavailable

    scn = load_scenario(str(EXAMPLES / "flux-known-angle.toml"))
    node = ControllerNode(Codec(), oracle.build(scn, "my_estimator_c:create", "compiled"))
    assert native_unavailable(node, "udp_multicast") is None


def test_a_failing_c_estimator_is_the_same_error_on_both_engines(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """update returns nonzero from period 40: the core and the oracle raise the same RuntimeError in that
    period, after the same outputs; a design init refuses is one line naming the library."""
    if CC is None:
        pytest.skip("needs a C compiler")
    src = tmp_path / "failing.c"
    src.write_text(FAILING)
    lib = _build(src, tmp_path / "libfailing.so")
    (tmp_path / "failing_c.py").write_text(
        f"from controller import c_estimator\ncreate = c_estimator({str(lib)!r})\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    scn = load_scenario(str(EXAMPLES / "flux-known-angle.toml"))
    got = {}
    for engine in ("oracle", "compiled"):
        ctrl = oracle.build(scn, "failing_c:create", engine)
        ctrl.set_enable(True)
        outs = []
        with pytest.raises(RuntimeError) as e:
            for k in range(100):
                m = Measurement(k, 0.1 * math.sin(0.2 * k), 0.0, -0.1 * math.sin(0.2 * k), 300.0)
                outs.append(ctrl.step(m))
        got[engine] = (str(e.value), outs, ctrl.engine)
    assert got["oracle"][0] == got["compiled"][0] == C_ESTIMATOR_FAILED
    assert got["oracle"][1] == got["compiled"][1] and len(got["oracle"][1]) == 40
    assert (got["oracle"][2], got["compiled"][2]) == ("oracle", "compiled")
    refusing = tmp_path / "refusing.c"
    refusing.write_text(FAILING.replace("(void)d;", "(void)d;\n    if (d->T_s > 0.0) return 3;"))
    motor = oracle.build(scn, "tt-dq", "oracle").motor
    with pytest.raises(ValueError, match="refused the design") as r:
        c_estimator(_build(refusing, tmp_path / "librefusing.so"))(motor, 1e-4)
    assert "librefusing.so" in str(r.value) and "\n" not in str(r.value)


#: A C estimator with both optional members: the offset it is handed is its published
#: ``err`` and turns its angle; its predicted HF current is a 20 A phasor turning with
#: k. -DNO_HF / -DNO_SAL build it with that member NULL.
OPTIONAL = r"""
#include <math.h>
#include <stddef.h>
#include "cc_estimator.h"
typedef struct { cc_est_t out; long long k; double off; double w; } st_t;
static int update(void *ctx, const cc_est_in_t *x, cc_est_t *out)
{
    st_t *s = ctx;
    s->k = x->k;
    s->out.theta_hat = remainder(s->w * (double)x->k + s->off, 6.283185307179586);
    s->out.w_hat = s->w / 1e-4;
    s->out.err = s->off;
    s->out.i_alpha_f = x->i_alpha;
    s->out.i_beta_f = x->i_beta;
    *out = s->out;
    return 0;
}
static int injection(void *ctx, double *a, double *b) { (void)ctx; *a = *b = 0.0; return 0; }
static int reset(void *ctx, double th, cc_est_t *out)
{
    st_t *s = ctx;
    s->out.theta_hat = th;
    *out = s->out;
    return 0;
}
#ifndef NO_HF
static int hf_next(void *ctx, double *a, double *b)
{
    st_t *s = ctx;
    *a = 20.0 * cos(0.3 * (double)s->k);
    *b = 20.0 * sin(0.3 * (double)s->k);
    return 0;
}
#endif
#ifndef NO_SAL
static int set_off(void *ctx, double off)
{
    ((st_t *)ctx)->off = off;
    return 0;
}
#endif
size_t cc_estimator_size(void) { return sizeof(st_t); }
int cc_estimator_init(void *state, cc_est_if_t *f, const cc_est_design_t *d)
{
    st_t *s = state;
    s->out.theta_hat = s->out.w_hat = s->out.err = s->out.i_alpha_f = s->out.i_beta_f = 0.0;
    s->k = 0; s->off = 0.0; s->w = 2e-3 * d->T_s / 1e-4;
    f->ctx = s; f->update = update; f->injection = injection; f->reset = reset;
#ifdef NO_HF
    f->hf_current_next = NULL;
#else
    f->hf_current_next = hf_next;
#endif
#ifdef NO_SAL
    f->set_saliency_offset = NULL;
#else
    f->set_saliency_offset = set_off;
#endif
    return 0;
}
"""


def test_a_c_estimators_optional_members_are_wired_on_both_engines(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``hf_current_next`` and ``set_saliency_offset`` of cc_est_if_t: with dead-time and
    cross-saturation compensation on, the core and the oracle call them (the offset handed is the
    estimator's ``err``, nonzero once the speed loop asks for torque; the predicted HF
    current moves the duties) and give the same trace bit for bit; a library with either
    NULL gives another trace, and its estimator has no such member."""
    if CC is None:
        pytest.skip("needs a C compiler")
    src = tmp_path / "optional.c"
    src.write_text(OPTIONAL)
    scn_path = tmp_path / "comp.toml"
    scn_path.write_text(
        f'extends = "{EXAMPLES / "flux-known-angle.toml"}"\n'
        "[controller]\ndead_time_compensation = true\nt_dead = 2e-6\n"
        "cross_saturation_compensation = true\n"
    )
    scn = load_scenario(str(scn_path))
    traces: dict[str, dict[str, list[tuple[Any, ...]]]] = {}
    for variant, flags in (("both", []), ("no_hf", ["-DNO_HF"]), ("no_sal", ["-DNO_SAL"])):
        out = tmp_path / f"lib{variant}.so"
        cmd = [CC, "-std=c99", "-O2", "-shared", "-fPIC", "-ffp-contract=off", *flags]
        cmd += ["-Wall", "-Wextra", "-Werror", f"-I{CORE}", "-o", str(out), str(src), "-lm"]
        subprocess.run(cmd, check=True, capture_output=True, text=True)
        (tmp_path / f"opt_{variant}.py").write_text(
            f"from controller import c_estimator\n"
            f"create = c_estimator({str(out)!r}, family='rotating')\n"
        )
        monkeypatch.syspath_prepend(str(tmp_path))
        traces[variant] = {}
        for engine in ("oracle", "compiled"):
            ctrl = oracle.build(scn, f"opt_{variant}:create", engine)
            assert ctrl.engine == engine and not ctrl.external_estimator
            assert ctrl.dead_time is not None and ctrl.cross_sat
            est = ctrl.estimator
            assert hasattr(est, "hf_current_next") == (variant != "no_hf")
            assert hasattr(est, "saliency_offset") == (variant != "no_sal")
            ctrl.set_enable(True)
            ctrl.set_speed_ref(2.0 * math.pi)
            rows = []
            for k in range(300):
                m = Measurement(k, 2.0 * math.sin(0.01 * k), 0.0, -2.0 * math.sin(0.01 * k), 540.0)
                o = ctrl.step(m)
                rows.append((o.d_a, o.d_b, o.d_c, o.theta_hat, o.err, o.i_d, o.i_q))
            traces[variant][engine] = rows
    for variant, by_engine in traces.items():
        assert by_engine["oracle"] == by_engine["compiled"], variant
    both = traces["both"]["oracle"]
    assert any(r[4] != 0.0 for r in both)  # the offset reached the library
    assert all(r[4] == 0.0 for r in traces["no_sal"]["oracle"])
    assert traces["no_hf"]["oracle"] != both
    assert [r[:3] for r in traces["no_sal"]["oracle"]] != [r[:3] for r in both]
