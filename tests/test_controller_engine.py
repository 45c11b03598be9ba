"""Oracle tests: the controller's core gives the oracle's trace, at tolerance 0.

The controller runs on one engine, the portable C core (``controller/core/``,
bound by ``controller/_cctl.c``); the Python step of ``tests/oracle/``
(:class:`tests.oracle.OracleController`, with the estimators' modules) is the
readable reference it is checked against, for every shipped estimator and a
plug-in's. The tolerance is :data:`tests.oracle.TOLERANCE`, 0: equal bits
(not 1e-9 rad or A): the C functions repeat the Python operations in the same
order, built without fused multiply-adds, and call the same ``libm``
``sin``/``cos``/``sqrt``. Every shipped scenario's first second, each of its
estimators, in the in-process loop (alignment, polarity test, speed steps), on
the papers' plant and on the suite's ``drive`` plant with the drive's
countermeasures on (dead-time feed-forward, cross-saturation correction,
offset calibration): the same :class:`controller.ControlOutput` in every
period. Then commands in the middle of a run, the states read back, the CIC's
re-anchoring, the seam's records as structs, and the engine names: each runs
the core.
"""

from __future__ import annotations

import math
import struct
from dataclasses import fields, replace
from pathlib import Path
from typing import Any

import pytest

import bench.nodes._loops as loops
from bench.cli._common import ENGINES as CLI_ENGINES
from bench.scenarios._schema import load_scenario
from bench.scenarios._setup import ENGINE_ENV, build_controller, build_plant, sample_period
from bench.studies._plants import plant_variant
from bench.wire._codec import Codec
from controller import (
    ENGINES,
    CompensationPars,
    Controller,
    ControllerPars,
    ControlOutput,
    Measurement,
    resolve_controller_engine,
)
from controller._registry import SPECS
from tests import oracle
from tests.oracle import TOLERANCE, OracleController

SCENARIOS = sorted(p.stem for p in (Path(loops.__file__).parents[1] / "scenarios").glob("*.toml"))
COMPILED = (
    "tt-dq",
    "tt-ab",
    "sfhf",
    "square-wave",
    "square-wave-nocic",
    "sensored",
    "hybrid-tt-dq",
    "hybrid-square-wave",
    "self-demod",
    "epf",
)


def _bits(o: ControlOutput) -> bytes:
    """Every field of an output as bits (and its types: an int stays an int): the
    comparison at the oracle's tolerance, 0."""
    assert TOLERANCE == 0.0  # a tolerance > 0 would compare the values, not the bits
    vals = [getattr(o, f.name) for f in fields(o)]
    types = "".join(type(v).__name__[0] for v in vals)
    return types.encode() + struct.pack(f"{len(vals)}d", *(float(v) for v in vals))


#: The plants the parity runs on: the shipped scenario's, and the suite's drive plant with
#: every countermeasure on (bench.studies._plants).
PLANTS = ("shipped", "drive")
#: The countermeasures' flags in Controller.gains()
COMP_KEYS = ("comp.dead_time", "comp.cross_saturation", "comp.offset_calibration")


def _scenario(name: str, plant: str = "shipped") -> Any:
    scn = load_scenario(name)
    return scn if plant == "shipped" else plant_variant(scn, plant)


def _pairs() -> list[tuple[str, str, str]]:
    out = []
    for plant in PLANTS:
        for name in SCENARIOS:
            scn = load_scenario(name)
            for est in dict.fromkeys((scn.estimator, *scn.estimators)):
                out.append((plant, name, est))
    return out


@pytest.mark.parametrize(("plant", "name", "estimator"), _pairs())
def test_every_scenario_first_second_same_on_both_engines(
    plant: str, name: str, estimator: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Each shipped scenario's first second in the in-process loop with each of its
    estimators, on its own plant and on the drive plant with the countermeasures on: the
    same output in every period, bit for bit, and the same frames."""
    scn = _scenario(name, plant).with_overrides(duration=1.0)
    codec = Codec()
    runs: dict[str, tuple[list[bytes], list[tuple[int, bytes]], str]] = {}
    comp: dict[str, float] = {}
    for engine in ("oracle", "compiled"):
        outs: list[bytes] = []
        used: list[str] = []

        def build_recorded(
            s: Any, e: str, *a: Any, eng: str = engine, outs: list[bytes] = outs, used: Any = used
        ) -> Controller:
            ctrl = oracle.build(s, e, eng)
            step = ctrl.step

            def recorded(meas: Measurement, step: Any = step) -> ControlOutput:
                o: ControlOutput = step(meas)
                outs.append(_bits(o))
                return o

            ctrl.step = recorded
            used.append(ctrl.engine)
            comp.update({k: ctrl.gains()[k] for k in COMP_KEYS})
            return ctrl

        monkeypatch.setattr(loops, "build_controller", build_recorded)
        frames = loops.run_inprocess(scn, estimator, codec, engine="compiled", loop="python")
        runs[engine] = (outs, [(m.arbitration_id, bytes(m.data)) for m in frames], used[0])
    (py, f_py, e_py), (cc, f_cc, e_cc) = runs["oracle"], runs["compiled"]
    assert e_py == "oracle"
    assert e_cc == "compiled"
    assert len(py) >= 0.99 / sample_period(scn)  # every period of the second
    # on the drive plant the countermeasures ran (cross-saturation: the HF estimators)
    on = 1.0 if plant == "drive" else 0.0
    assert comp["comp.dead_time"] == comp["comp.offset_calibration"] == on
    hf = SPECS[estimator].family != "none"  # an HF estimator: the offset is corrected
    assert comp["comp.cross_saturation"] == (on if hf else 0.0)
    first = next((k for k in range(len(py)) if py[k] != cc[k]), None)
    assert first is None, f"the engines part at period {first}"
    assert len(py) == len(cc) and f_py == f_cc


def _loop(
    scn_name: str,
    estimator: str,
    engine: str,
    n: int,
    events: dict[int, Any] | None = None,
    speed_rpm: float = 200.0,
    plant: str = "shipped",
) -> tuple[list[bytes], Controller]:
    """A closed loop on the compiled plant; ``events[k](ctrl)`` runs before period ``k``."""
    scn = _scenario(scn_name, plant)
    sim = build_plant(scn, "compiled")
    ctrl = oracle.build(scn, estimator, engine)
    ctrl.set_enable(True)
    ctrl.set_speed_ref(speed_rpm * 2.0 * math.pi / 60.0)
    d = (0.5, 0.5, 0.5, False)
    out: list[bytes] = []
    truth = estimator == "sensored"
    for k in range(n):
        if events and k in events:
            events[k](ctrl)
        s = sim.sample()
        tr = sim.truth() if truth else None
        m = Measurement(
            s.k, s.i_a, s.i_b, s.i_c, s.u_dc, tr.theta_e if tr else None, tr.w_e if tr else None
        )
        o = ctrl.step(m)
        sim.step(*d)
        out.append(_bits(o))
        d = (o.d_a, o.d_b, o.d_c, o.enable)
    return out, ctrl


def _events(n: int) -> dict[int, Any]:
    """Commands and reads in the middle of a run (a read of the Python objects changes
    nothing on either engine)."""
    return {
        n // 5: lambda c: c.set_speed_ref(-100.0),
        n // 4: lambda c: c.w_m_hat,  # a read: the core keeps stepping
        n // 3: lambda c: c.set_current_ref((0.0, 1.0)),
        n // 3 + 7: lambda c: c.estimator.theta_hat,  # a taken object: handed to Python
        n // 2: lambda c: c.set_current_ref(None),
        (2 * n) // 3: lambda c: c.set_enable(False),
        (2 * n) // 3 + 20: lambda c: c.set_enable(True),  # a second start-up
    }


def _state_bits(states: dict[str, Any]) -> dict[str, Any]:
    """``states`` with each float as its bytes: the same bits compare equal, NaN included
    (no run should end in one: the plant stays finite beyond its flux map's range)."""
    return {k: struct.pack("<d", v) if isinstance(v, float) else v for k, v in states.items()}


@pytest.mark.parametrize(
    ("scn_name", "estimator", "n", "plant"),
    [
        ("wen-5.1", "tt-dq", 9000, "shipped"),
        ("wen-5.1", "sfhf", 6000, "shipped"),
        ("wen-5.1", "tt-ab", 6000, "shipped"),
        ("wen-5.1", "sensored", 3000, "shipped"),
        ("wen-5.1", "self-demod", 6000, "shipped"),
        ("wen-5.1", "epf", 6000, "shipped"),
        ("xue-fig13", "square-wave", 9000, "shipped"),  # past the CIC's re-anchoring at 4096
        ("xue-fig13", "square-wave-nocic", 3000, "shipped"),
        # the countermeasures: the second start calibrates the offsets again
        ("wen-5.1", "tt-dq", 9000, "drive"),
    ],
)
def test_commands_and_reads_between_engines_keep_the_trace(
    scn_name: str, estimator: str, n: int, plant: str
) -> None:
    """Commands, reads, a stop and a second start in the middle of a run: the same trace
    on both engines (the core runs the start-up, the polarity test, the CIC's
    re-anchoring and the offset calibration itself), and the states read from the core
    are Python's."""
    py, c_py = _loop(scn_name, estimator, "oracle", n, _events(n), plant=plant)
    cc, c_cc = _loop(scn_name, estimator, "compiled", n, _events(n), plant=plant)
    assert (c_py.engine, c_cc.engine) == ("oracle", "compiled")
    first = next((k for k in range(n) if py[k] != cc[k]), None)
    assert first is None, f"the engines part at period {first}"
    # the states after the run, read from the compiled core, are the same bits
    s_py, s_cc = c_py.states(), c_cc.states()
    assert _state_bits(s_cc) == _state_bits(s_py)
    # finite, also where the rotor is lost and the current runs away (xue-fig13 with
    # square-wave: the speed reference reversed, 2,000 A on the 20 A motor, its plant
    # beyond its flux map's range, plant_rt/core/plant_rk4.h)
    assert all(math.isfinite(v) for v in s_py.values() if isinstance(v, float))
    # one design for both engines: the same gains, bandwidths and corners
    assert c_cc.gains() == c_py.gains()
    assert [type(v) for v in s_cc.values()] == [type(v) for v in s_py.values()]
    # the square-wave's quadrature signal (the CIC study reads it) is the oracle's too
    assert c_cc.quadrature() == c_py.quadrature()
    assert (c_cc.quadrature() != (0.0, 0.0)) == (SPECS[estimator].family == "square")
    # and the run was a closed loop that ran: speed control reached, the estimate moved
    assert s_py["mode"] == 3 and s_py["w_hat"] != 0.0


@pytest.mark.parametrize("plant", PLANTS)
@pytest.mark.parametrize(
    ("scn_name", "estimator", "top_rpm", "t_ramp", "observer"),
    [
        ("wide-speed-wen", "hybrid-tt-dq", 1300.0, 1.0, "pll"),
        # tt-dq's mechanical observer as the hybrid's tracker (slaved above the band with
        # its load state, its speed the schedule's below it)
        ("wide-speed-wen", "hybrid-tt-dq", 1300.0, 1.0, "mechanical"),
        ("wide-speed-xue", "hybrid-square-wave", 800.0, 1.5, None),
    ],
)
def test_hybrids_through_their_band_and_back_same_on_both_engines(
    scn_name: str,
    estimator: str,
    top_rpm: float,
    t_ramp: float,
    observer: str | None,
    plant: str,
    tmp_path: Path,
) -> None:
    """A hybrid from standstill up through its whole hand-over band (the flux observer
    slaved, blended, alone with the injection off and the injection estimator slaved)
    and back into it, the reference a 100 Hz staircase: the same trace on both engines,
    on the drive plant with the cross-saturation offset taken from the injection estimate
    alone and the dead-time sign from its faded HF current. hybrid-tt-dq with either
    position observer of tt-dq (``observer``)."""
    if observer is not None:
        f = tmp_path / f"{observer}.toml"
        f.write_text(f'extends = "{scn_name}"\n[estimator_options]\nobserver = "{observer}"\n')
        scn_name = str(f)
    scn = _scenario(scn_name, plant)
    T = sample_period(scn)
    n0, n_up, n_top = round(0.4 / T), round(t_ramp / T), round(0.3 / T)
    n = n0 + 2 * n_up + n_top

    def ref(k: int) -> float:
        if k < n0:
            return 0.0
        if k < n0 + n_up:
            return top_rpm * (k - n0) / n_up
        if k < n0 + n_up + n_top:
            return top_rpm
        return max(0.0, top_rpm * (1.0 - (k - n0 - n_up - n_top) / n_up))

    every = round(0.01 / T)
    rpm = 2.0 * math.pi / 60.0
    weights: list[float] = []

    def set_ref(k: int) -> Any:
        def ev(c: Controller) -> None:
            c.set_speed_ref(ref(k) * rpm)
            if c.engine == "oracle":
                weights.append(c.estimator.weight)  # type: ignore[attr-defined]

        return ev

    events = {k: set_ref(k) for k in range(0, n, every)}
    py, c_py = _loop(scn_name, estimator, "oracle", n, events, speed_rpm=0.0, plant=plant)
    cc, c_cc = _loop(scn_name, estimator, "compiled", n, events, speed_rpm=0.0, plant=plant)
    assert (c_py.engine, c_cc.engine) == ("oracle", "compiled")
    if observer is not None:  # the option reached the injection estimator
        hf: Any = c_py.estimator.hf  # type: ignore[attr-defined]
        assert hf.mechanical == (observer == "mechanical")
    first = next((k for k in range(n) if py[k] != cc[k]), None)
    assert first is None, f"the engines part at period {first}"
    # the run crossed the band both ways: the observer alone, then the injection back
    assert max(weights) == 1.0 and 0.0 < min(w for w in weights if w > 0.0) < 1.0
    assert weights[-1] < 1.0


def test_every_engine_name_runs_the_core() -> None:
    """Every estimator of every shipped scenario, under every engine name (kept for
    compatibility, the CLI's), runs in the core with no note; an unknown name is refused;
    the square-wave estimators' CIC delay M is a typed range, 1 .. the core's delay line."""
    from controller._cctl import CIC_MAX

    assert ENGINES == CLI_ENGINES
    for name in SCENARIOS:
        for est in load_scenario(name).estimators:
            for engine in ENGINES:
                c = build_controller(load_scenario(name), est, engine)
                assert (c.engine, c.engine_note, c._core is not None) == ("compiled", None, True)
    scn = load_scenario("wen-5.1")
    pars = build_controller(scn, "tt-dq").pars
    for opts in ({"normalise": "measured"}, {"observer": "mechanical"}):
        assert resolve_controller_engine("python", replace(pars, estimator_options=opts)) == (
            "compiled",
            None,
        )
    comp = CompensationPars(dead_time=True, cross_saturation=True, offset_calibration=True)
    c = Controller(replace(pars, compensation=comp), "python")
    assert (c.engine, c.engine_note) == ("compiled", None)
    with pytest.raises(ValueError, match="unknown controller engine"):
        resolve_controller_engine("fast", pars)
    with pytest.raises(ValueError, match="unknown controller engine"):
        Controller(pars, "fast")
    assert CIC_MAX == 64
    xue = build_controller(load_scenario("xue-fig13"), "square-wave").pars
    for est in ("square-wave", "square-wave-nocic", "hybrid-square-wave"):
        cic = replace(xue, estimator=est, estimator_options={"M": CIC_MAX})
        assert Controller(cic).engine == "compiled"
        with pytest.raises(ValueError, match=r"M \(the CIC delay\) must be in 1 \.\. 64, got 65"):
            Controller(replace(cic, estimator_options={"M": CIC_MAX + 1}))


def test_the_python_step_is_only_the_oracles() -> None:
    """The controller's period runs in the core and nowhere else in ``controller/``: its
    instance's ``step`` is the core's (a C function, no Python frame), the Python step's
    methods are the oracle's alone, and the reference model keeps only its design."""
    from controller._controller import ReferenceModel
    from tests.oracle.blocks import OracleReferenceModel

    c = build_controller(load_scenario("wen-5.1"), "tt-dq", "python")
    assert type(c.step).__name__ == "builtin_function_or_method"
    assert getattr(c.step, "__self__", None) is c._core
    python_step = ("_step", "_polarity_step", "_advance_mode", "_restart")
    assert not any(hasattr(Controller, name) for name in python_step)
    assert all(callable(getattr(OracleController, name)) for name in python_step)
    assert not hasattr(ReferenceModel, "update") and not hasattr(ReferenceModel, "reset")
    assert callable(OracleReferenceModel.update)
    o = oracle.build(load_scenario("wen-5.1"), "tt-dq", "oracle")
    assert (o.engine, o._core) == ("oracle", None)


def test_the_environment_carries_the_engine_name(monkeypatch: pytest.MonkeyPatch) -> None:
    """``--engine`` reaches the controllers built without an engine through the environment:
    each known name builds the core, an unknown one is refused."""
    scn = load_scenario("wen-5.1")
    for name in ENGINES:
        monkeypatch.setenv(ENGINE_ENV, name)
        assert build_controller(scn, "tt-dq").engine == "compiled"
    monkeypatch.setenv(ENGINE_ENV, "fast")
    with pytest.raises(ValueError, match="unknown controller engine 'fast'"):
        build_controller(scn, "tt-dq")
    monkeypatch.delenv(ENGINE_ENV)
    assert build_controller(scn, "tt-dq").engine == "compiled"


def test_purity_the_core_never_reads_the_truth_of_a_sensorless_measurement() -> None:
    """A sensorless estimator's compiled step does not use ``theta_e``/``w_e``: a
    measurement whose truth is garbage steps as one without truth, bit for bit."""
    pars = ControllerPars(
        motor=build_controller(load_scenario("wen-5.1"), "tt-dq").pars.motor,
        T_s=1e-4,
        startup=False,
    )
    ctrl = Controller(pars, "compiled")
    ctrl.set_enable(True)
    ref = OracleController(pars)
    ref.set_enable(True)
    for k in range(50):
        m = Measurement(k, 0.1 * math.sin(k), -0.05, 0.05 - 0.1 * math.sin(k), 300.0)
        bad = replace(m, theta_e=math.nan, w_e=1e300)
        assert _bits(ctrl.step(bad)) == _bits(ref.step(m))
    assert ctrl.engine == "compiled"


def test_the_core_takes_the_seam_records_as_structs() -> None:
    """The binding reads a Measurement's slots and fills a ControlOutput's in the order of
    their fields: any other object is refused with one line, and the sensored core refuses
    a measurement without truth as the Python estimator does."""
    scn = load_scenario("wen-5.1")
    ctrl = build_controller(scn, "tt-dq", "compiled")
    ctrl.set_enable(True)
    with pytest.raises(TypeError, match=r"takes a .*Measurement"):
        ctrl.step((0, 0.0, 0.0, 0.0, 300.0))  # type: ignore[arg-type]
    with pytest.raises(ZeroDivisionError):
        ctrl.step(Measurement(0, 0.0, 0.0, 0.0, 0.0))
    o = ctrl.step(Measurement(7, 0.5, -0.25, -0.25, 300.0))
    assert o.k == 7 and o.enable is True and o.mode == 1 and 0.0 <= o.d_a <= 1.0
    sens = build_controller(scn, "sensored", "compiled")
    assert sens.engine == "compiled"
    sens.set_enable(True)
    with pytest.raises(ValueError, match="theta_e and w_e"):
        sens.step(Measurement(0, 0.0, 0.0, 0.0, 300.0))
    o = sens.step(Measurement(1, 0.0, 0.0, 0.0, 300.0, 1.25, 0.0))
    assert o.theta_hat == 1.25


def test_a_compiled_controller_is_freed() -> None:
    """A controller and its core are freed (controllers are built by the thousand)."""
    import gc
    import weakref

    ctrl = build_controller(load_scenario("wen-5.1"), "tt-dq", "compiled")
    ctrl.set_enable(True)
    ctrl.step(Measurement(0, 0.0, 0.0, 0.0, 300.0))
    ref = weakref.ref(ctrl)
    del ctrl
    gc.collect()
    assert ref() is None


@pytest.mark.parametrize("estimator", ["tt-dq", "tt-ab", "sfhf", "self-demod", "epf"])
def test_the_mechanical_observer_same_on_both_engines(estimator: str, tmp_path: Path) -> None:
    """``observer = "mechanical"`` (the Luenberger observer with the torque feed-forward in
    place of the PLL): wen-5.1's start-up and two speed steps, the same output on both
    engines in every period, and not the PLL's trace."""
    f = tmp_path / "mech.toml"
    f.write_text('extends = "wen-5.1"\n[estimator_options]\nobserver = "mechanical"\n')
    n = 6000
    events = {
        n // 3: lambda c: c.set_speed_ref(30.0),
        (2 * n) // 3: lambda c: c.set_speed_ref(-20.0),
    }
    py, c_py = _loop(str(f), estimator, "oracle", n, events, speed_rpm=0.0)
    cc, c_cc = _loop(str(f), estimator, "compiled", n, events, speed_rpm=0.0)
    assert (c_py.engine, c_cc.engine, c_cc.engine_note) == ("oracle", "compiled", None)
    first = next((k for k in range(n) if py[k] != cc[k]), None)
    assert first is None, f"the engines part at period {first}"
    pll, _ = _loop("wen-5.1", estimator, "compiled", n, events, speed_rpm=0.0)
    assert pll != cc


#: The estimators with the option ``normalise`` (the registry's options), each with a
#: scenario it runs in: the hybrid's own for a hybrid (speed_band), else wen-5.1.
NORMALISE = [
    (s.name, "wide-speed-wen" if s.speed_band else "wen-5.1")
    for s in SPECS.values()
    if s.options is not None and "normalise" in {f.name for f in fields(s.options)}
]


def test_every_demodulator_with_normalise_is_tested() -> None:
    """The parity below covers the six rotating demodulators, the hybrid's tt-dq among
    them (an estimator with the option is never left out of it)."""
    assert len(NORMALISE) == 6 and any(scn == "wide-speed-wen" for _, scn in NORMALISE)


@pytest.mark.parametrize(("estimator", "scn_name"), NORMALISE)
def test_normalise_measured_same_on_both_engines(
    estimator: str, scn_name: str, tmp_path: Path
) -> None:
    """``normalise = "measured"`` (the error normalised by the measured HF amplitude, its
    ``math.hypot`` the core's ``cc_hypot``) runs in the core: start-up, two speed steps, a
    stop and a second start (the quadrature LPF reset), the same output in every period
    and the same states, and not the trace of the model normalisation."""
    f = tmp_path / "measured.toml"
    f.write_text(f'extends = "{scn_name}"\n[estimator_options]\nnormalise = "measured"\n')
    n = 6000
    events = {
        n // 4: lambda c: c.set_speed_ref(30.0),
        n // 2: lambda c: c.set_speed_ref(-20.0),
        (2 * n) // 3: lambda c: c.set_enable(False),
        (2 * n) // 3 + 20: lambda c: c.set_enable(True),
    }
    py, c_py = _loop(str(f), estimator, "oracle", n, events, speed_rpm=0.0)
    cc, c_cc = _loop(str(f), estimator, "compiled", n, events, speed_rpm=0.0)
    assert (c_py.engine, c_cc.engine, c_cc.engine_note) == ("oracle", "compiled", None)
    first = next((k for k in range(n) if py[k] != cc[k]), None)
    assert first is None, f"the engines part at period {first}"
    assert c_cc.states() == c_py.states()
    assert c_py.states()["mode"] == 3  # it reached speed control
    model, _ = _loop(scn_name, estimator, "compiled", n, events, speed_rpm=0.0)
    assert model != cc


#: A plug-in around docs/examples/my_estimator.py that raises in its update at period 40,
#: and one whose injection() returns three values.
RAISING = """
import my_estimator


class Raising(my_estimator.FluxPLL):
    def update(self, x):
        if x.k >= 40:
            raise RuntimeError(f"flux lost at k={x.k}")
        super().update(x)

    def injection(self):
        return (0.0, 0.0, 0.0) if self.err == 1.0 else (0.0, 0.0)


def create(motor, T_s, **options):
    e = my_estimator.create(motor, T_s, **options)
    e.__class__ = Raising
    return e


create.injection_family = "none"
create.options = my_estimator.create.options
"""


def test_a_plugin_estimator_runs_in_the_core_bit_for_bit(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """Every shipped estimator has its kind in the core; a plug-in's Python estimator runs in
    it too: the core calls its methods each period (``controller/core/cc_estimator.h``).
    The example plug-in over flux-known-angle's first 0.4 s, with a speed step and a second
    start: the Python engine's output bit for bit, its states read back the same; the node's
    report says compiled, and the native node falls back with one line naming it."""
    from bench.nodes._controller_node import ControllerNode
    from bench.nodes.native.controller_node import native_unavailable
    from controller import ESTIMATOR_NAMES
    from controller._cctl import KIND_EXTERNAL as C_KIND
    from controller._engine import COMPILED_ESTIMATORS, KIND_EXTERNAL

    examples = Path(loops.__file__).parents[2] / "docs" / "examples"
    monkeypatch.syspath_prepend(str(examples))
    assert set(COMPILED) == set(COMPILED_ESTIMATORS) == set(ESTIMATOR_NAMES)
    assert KIND_EXTERNAL == C_KIND
    est = "my_estimator:create"
    path = str(examples / "flux-known-angle.toml")
    n = 4000
    events = {
        1500: lambda c: c.set_speed_ref(-5.0),
        2500: lambda c: c.set_enable(False),
        2600: lambda c: c.set_enable(True),
    }
    cc, c = _loop(path, est, "compiled", n, events, speed_rpm=60.0)
    py, ref = _loop(path, est, "oracle", n, events, speed_rpm=60.0)
    assert (c.engine, c.engine_note, c.external_estimator) == ("compiled", None, True)
    assert (ref.engine, ref.external_estimator) == ("oracle", False)
    first = next((k for k in range(n) if py[k] != cc[k]), None)
    assert first is None, f"the engines part at period {first}"
    assert len({o for o in cc}) > n // 2  # the trace moves
    assert c.states() == ref.states()
    rep = ControllerNode(Codec(), c).report()
    assert (rep["engine"], rep["engine_note"]) == ("compiled", None)
    why = native_unavailable(ControllerNode(Codec(), c), None)
    assert why is not None and est in why and "Python process" in why and "\n" not in why


def test_a_plugin_that_raises_raises_the_same_on_both_engines(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """An exception in a plug-in's update reaches the caller of ``step`` unchanged on the
    compiled engine, in the same period, after the same outputs, as on the Python engine
    (the controller process then ends with that one line); a malformed ``injection()``
    result is the same error on both."""
    examples = Path(loops.__file__).parents[2] / "docs" / "examples"
    monkeypatch.syspath_prepend(str(examples))
    monkeypatch.syspath_prepend(str(tmp_path))
    (tmp_path / "raising_plugin.py").write_text(RAISING)
    scn = load_scenario(str(examples / "flux-known-angle.toml"))
    got = {}
    for engine in ("oracle", "compiled"):
        c = oracle.build(scn, "raising_plugin:create", engine)
        assert c.engine == engine
        c.set_enable(True)
        c.set_speed_ref(10.0)
        outs = []
        with pytest.raises(RuntimeError) as e:
            for k in range(100):
                m = Measurement(
                    k, 0.2 * math.sin(0.3 * k), -0.1, 0.1 - 0.2 * math.sin(0.3 * k), 300.0
                )
                outs.append(_bits(c.step(m)))
        c.estimator.err = 1.0  # injection() now returns three values
        with pytest.raises(ValueError) as v:
            c.injection()
        got[engine] = (str(e.value), outs, str(v.value))
    assert got["oracle"][0] == got["compiled"][0] == "flux lost at k=40"
    assert got["oracle"][2] == got["compiled"][2] == "too many values to unpack (expected 2)"
    assert got["oracle"][1] == got["compiled"][1] and len(got["oracle"][1]) == 40


def test_bench_run_refuses_a_cic_delay_longer_than_the_cores_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """``bench run`` of square-wave with a CIC delay ``M = 65`` (longer than the core's
    delay line, once the one option outside the core): a scenario error of one line naming
    the file, the field and the bound, exit code 2, and no run started."""
    from bench.cli import main
    from tests.ports import free_port

    monkeypatch.setenv(ENGINE_ENV, "auto")  # restored after main() sets it to --engine
    out = tmp_path / "run"
    scn = tmp_path / "long-cic.toml"
    scn.write_text('extends = "xue-fig13"\n[estimator_options]\nM = 65\n')
    argv = ["run", str(scn), "-e", "square-wave", "--engine", "python", "--duration", "0.05"]
    argv += ["--port", str(free_port()), "--out", str(out), "--quiet"]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"bench: error: {scn}: field 'estimator_options.M': must be <= 64, got 65"]
    assert not (out / "meta.json").exists()
