"""The two writings of the design's mapping onto the core's ``_init`` calls agree.

``controller/_cctl.c`` (the binding: each ``Core`` method's arguments to the core's
``_init`` calls) and ``bench/wire/_ctlgen.py``'s ``_Recorder`` (the same calls as C text for
``bench_controller.h``) map the same :func:`controller._compiled.build_core` calls. These
tests fail when the two could disagree: every design method of the binding has its
recorder twin, and over a set of designs that makes every recorder method run (every
countermeasure, the supervision, raw current feedback, the tracking BPF, every sensorless
estimator of the core) the header's ``cc_foc_t`` and ``cc_sup_t`` are the binding's byte
for byte (``tests/test_firmware_sensorless.py``'s harness and comparison).
"""

from __future__ import annotations

import subprocess
from pathlib import Path
from typing import Any

import pytest

from bench.scenarios._schema import load_scenario
from bench.scenarios._setup import build_controller
from bench.wire._ctlgen import _Recorder
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
#: Recorder methods that refuse (a plug-in's estimator: no firmware header).
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


def test_every_design_method_of_the_binding_has_its_recorder_twin() -> None:
    missing = sorted(n for n in _design_methods() if not callable(getattr(_Recorder, n, None)))
    assert missing == [], f"bench/wire/_ctlgen.py _Recorder lacks {missing}"
    extra = sorted(
        n
        for n in vars(_Recorder)
        if not n.startswith("_") and callable(vars(_Recorder)[n]) and n not in _design_methods()
    )
    assert extra == [], f"_Recorder maps methods the binding has not: {extra}"


def _calls(ctrl: Any) -> set[str]:
    """The recorder methods :func:`build_core` (and the header's supervision) call."""
    names: set[str] = set()

    class Spy(_Recorder):
        def __getattribute__(self, name: str) -> Any:
            v = super().__getattribute__(name)
            if not name.startswith("_") and callable(v):
                names.add(name)
            return v

    rec, why = build_core(ctrl, Spy)
    assert rec is not None, why
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
    # every mapping the recorder writes was compared at least once
    assert sorted(_design_methods() - REFUSING - covered) == []
