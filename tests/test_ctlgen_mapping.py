"""The design's mapping onto the core's ``_init`` calls has one home: ``cc_design.h``.

``controller/_cctl.c`` (the binding) turns each design call of
:func:`controller._compiled.build_core` into the call of its ``cc_design_*`` function
(``controller/core/cc_design.h``); ``bench/wire/_ctlgen.py``'s ``_Recorder`` records the
same calls and arguments as calls of the same functions for ``bench_controller.h``. These
tests fail when the two could part: a design method of the binding without its
``cc_design_*`` function (or one the binding has not), a recorded argument of a type the
header cannot print, and, over a set of designs that makes every design call run (every
countermeasure, the supervision, raw current feedback, the tracking BPF, every sensorless
estimator of the core), a header whose ``cc_foc_t`` and ``cc_sup_t`` are not the
binding's byte for byte (``tests/test_firmware_sensorless.py``'s harness and comparison).
"""

from __future__ import annotations

import subprocess
from pathlib import Path
from typing import Any

import pytest

from bench.cli import main
from bench.scenarios._schema import load_scenario
from bench.scenarios._setup import build_controller
from bench.wire._ctlgen import _C_TYPES, _c_arg, _Recorder, design_signatures
from controller import compiled_controller_missing
from controller._compiled import build_core
from tests.test_firmware import CC, MAKE
from tests.test_firmware_sensorless import SCENARIO, SENSORLESS, _harness, _same_struct

pytestmark = pytest.mark.skipif(
    CC is None or MAKE is None or compiled_controller_missing() is not None,
    reason="needs a C compiler, make and the compiled controller",
)

#: ``Core`` methods that run the controller, not design it (build_core never calls them).
RUNTIME = {"step", "injection", "set_enable", "set_speed_ref", "set_current_ref", "address"}
#: Design methods a firmware has no C function for (a plug-in's estimator: the recorder
#: refuses them).
REFUSING = {"external", "external_c"}

#: Every countermeasure on, the supervision, and the raw current feedback.
ALL_ON = """
[controller]
dead_time_compensation = true
t_dead = 2e-6
cross_saturation_compensation = true
offset_calibration = true
offset_periods = 50
current_feedback = "raw"
supervision = true
"""
#: tt-dq with its tracking BPF and its acceleration feed-forward; sfhf with the
#: mechanical observer.
OPTIONS = "\n[motor]\n[estimator_options]\n"
TRACKING = OPTIONS + "bpf_tracking = true\naccel_ff = true\n"
MECHANICAL = OPTIONS + 'observer = "mechanical"\n'
MEASURED = OPTIONS + 'normalise = "measured"\n'


def _design_methods() -> set[str]:
    from controller import _cctl

    return {
        n
        for n in dir(_cctl.Core)
        if not n.startswith("_") and callable(getattr(_cctl.Core, n)) and n not in RUNTIME
    }


def test_every_design_method_of_the_binding_is_one_cc_design_function() -> None:
    sigs = design_signatures()
    methods = _design_methods()
    missing = sorted(methods - REFUSING - set(sigs))
    assert missing == [], f"controller/core/cc_design.h lacks cc_design_{missing}"
    # init is the binding's constructor (Core(kind, ...)); the rest are its methods
    extra = sorted(set(sigs) - {"init"} - methods)
    assert extra == [], f"cc_design.h has functions the binding has not: {extra}"
    # the binding calls each one, and the recorder maps none itself
    binding = (Path(__file__).parents[1] / "controller" / "_cctl.c").read_text()
    for name in sigs:
        assert f"cc_design_{name}(" in binding, name
    assert sorted(n for n in vars(_Recorder) if n in sigs) == []
    # every parameter is of a type the recorder prints
    for name, (_, ctypes) in sigs.items():
        for t in ctypes:
            assert t in _C_TYPES, (name, t)


def test_the_recorder_prints_each_argument_as_its_parameter_type() -> None:
    assert _c_arg("double", 2) == "2.0"
    assert _c_arg("double", -0.0) == "-0.0"
    assert _c_arg("long long", 50) == "50LL"
    assert _c_arg("int", True) == "1"
    assert _c_arg("const double *", None) == "NULL"
    assert _c_arg("const double *", (0.5, True, 3)) == "(const double[]){0.5, 1.0, 3.0}"
    assert _c_arg("const long long *", 7) == "&(const long long){7LL}"
    with pytest.raises(ValueError, match="float"):
        _c_arg("float", 1.0)


def test_the_recorder_refuses_what_the_binding_refuses(tmp_path: Path) -> None:
    """A value the core refuses (here the offset calibration's periods) stops the header
    with the binding's own error, not a header whose init returns -1."""
    ctrl = build_controller(load_scenario(str(SCENARIO)), "tt-dq", engine="compiled")
    rec, why = build_core(ctrl, _Recorder)
    assert rec is not None, why
    with pytest.raises(ValueError, match="0 offset periods"):
        rec.compensation(None, None, 0, None)
    assert not any("cc_design_compensation(c, NULL, NULL, &" in ln for ln in rec.lines)
    with pytest.raises(AttributeError):
        rec.step  # noqa: B018 (a run-time method: no design function)


def _calls(ctrl: Any) -> set[str]:
    """The design methods :func:`build_core` (and the header's supervision) call."""
    rec, why = build_core(ctrl, _Recorder)
    assert rec is not None, why
    names = {ln.split("cc_design_", 1)[1].split("(", 1)[0] for ln in rec.lines}
    if ctrl.supervisor is not None:
        names.add("supervision")
    return names


def _cases(tmp_path: Path) -> list[tuple[Path, str]]:
    base = SCENARIO.read_text()
    all_on = tmp_path / "all_on.toml"
    all_on.write_text(base + ALL_ON)
    tracking = tmp_path / "tracking.toml"
    tracking.write_text(base + TRACKING)
    mechanical = tmp_path / "mechanical.toml"
    mechanical.write_text(base + MECHANICAL)
    measured = tmp_path / "measured.toml"
    measured.write_text(base + MEASURED)
    return [(all_on, e) for e in SENSORLESS] + [
        (tracking, "tt-dq"),
        (mechanical, "sfhf"),
        (measured, "tt-dq"),
    ]


def test_the_header_maps_every_design_as_the_binding(tmp_path: Path) -> None:
    covered: set[str] = set()
    for i, (scn, estimator) in enumerate(_cases(tmp_path)):
        ctrl = build_controller(load_scenario(str(scn)), estimator, engine="compiled")
        assert ctrl.engine == "compiled", (scn.name, estimator)
        covered |= _calls(ctrl)
        out = tmp_path / f"case{i}"
        out.mkdir()
        exe = _harness(out, scn, estimator)
        res = subprocess.run([str(exe)], input="", capture_output=True, text=True, timeout=60)
        assert res.returncode == 0, res.stderr
        lines = res.stdout.splitlines()
        foc_addr, sup_addr = ctrl._core.address()
        _same_struct(lines[0], foc_addr)
        if sup_addr:
            _same_struct(lines[1], sup_addr)
    # every design function was compared at least once
    assert sorted(set(design_signatures()) - covered) == []


def test_the_headers_compile_alone_in_strict_c99(tmp_path: Path) -> None:
    """``bench_controller.h`` (and ``bench_wire.h`` and ``cc_design.h`` it includes) needs
    no include before it: a program of that one include builds with ``-pedantic``."""
    gen = tmp_path / "gen"
    args = ["codegen", str(gen), "--scenario", str(SCENARIO), "--estimator", "tt-dq"]
    assert main(args) == 0
    src = tmp_path / "alone.c"
    src.write_text(
        '#include "bench_controller.h"\n'
        "static cc_foc_t c;\nstatic cc_sup_t sup;\n"
        "int main(void) { return bench_controller_init(&c, &sup); }\n"
    )
    exe = tmp_path / "alone"
    cmd = [str(CC), "-std=c99", "-pedantic", "-Wall", "-Wextra", "-Werror", f"-I{gen}"]
    cmd += [f"-I{gen / 'core'}", "-o", str(exe), str(src), *map(str, (gen / "core").glob("*.c"))]
    res = subprocess.run([*cmd, "-lm"], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    assert subprocess.run([str(exe)], timeout=30).returncode == 0
