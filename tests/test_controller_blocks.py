"""The public per-period blocks are bindings of the controller core: each gives the same
outputs and states as its readable Python in ``tests/oracle/blocks.py``, bit for bit
(:data:`tests.oracle.TOLERANCE`: the core repeats the oracle's operations in the same order,
compiled without fused multiply-adds), on random and representative input sequences."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from bench.scenarios._schema import load_scenario
from bench.scenarios._setup import build_controller, build_plant
from controller import (
    MODE_DISABLED,
    MODE_RUN,
    ControlOutput,
    FluxObserver,
    Measurement,
    MotorModel,
    PIController,
    PolarityTest,
    PositionObserver,
    SupervisionPars,
    Supervisor,
    TransitionBand,
    svpwm,
)
from controller._compensation import cross_saturation_offset, smooth_sign
from controller._supervision import (
    MODE_CURRENT_SENSOR,
    MODE_DC_OVERVOLTAGE,
    MODE_DC_UNDERVOLTAGE,
    MODE_OPEN_PHASE,
)
from controller._svpwm import limit_magnitude
from tests.oracle import TOLERANCE
from tests.oracle import blocks as ob
from tests.oracle.blocks import oracle

N = 2000


def _same(a: Any, b: Any) -> None:
    """Equal within the oracle tolerance (0: the same float, nan included)."""
    a_ = np.asarray(a, float)
    b_ = np.asarray(b, float)
    assert a_.shape == b_.shape
    if TOLERANCE == 0.0:
        assert np.array_equal(a_, b_, equal_nan=True), (a, b)
    else:  # pragma: no cover - the tolerance is 0
        np.testing.assert_allclose(a_, b_, rtol=0.0, atol=TOLERANCE)


def _pair(make: Any) -> tuple[Any, Any]:
    """The block as built, and a second one made the oracle (:func:`oracle`)."""
    b = make()
    o = oracle(make())
    assert type(o) is ob.ORACLES[type(b)]
    return b, o


def test_pi_controller_is_the_core() -> None:
    rng = np.random.default_rng(1)
    b, o = _pair(lambda: PIController(2.5, 400.0, 1e-4, 1.7))
    u_max = 3.0
    for j in range(N):
        r, y, u_ff = rng.normal(0.0, 2.0, 3)
        if j % 500 == 250:
            b.reset(1.25)
            o.reset(1.25)
        u_b = b.output(r, y, u_ff)
        u_o = o.output(r, y, u_ff)
        _same(u_b, u_o)
        u_lim = min(max(u_b, -u_max), u_max)  # the anti-windup sees saturation
        b.update(u_lim)
        o.update(u_lim)
        _same((b.u_i, b._e, b._u), (o.u_i, o._e, o._u))


def test_pi_controller_keeps_its_api() -> None:
    pi = PIController(2.0, 3.0, 0.5)
    assert (pi.k_p, pi.k_i, pi.k_t, pi.T_s) == (2.0, 3.0, 2.0, 0.5)  # k_t defaults to k_p
    assert pi.output(r=1.0, y=0.25) == 2.0 * 1.0 - 2.0 * 0.25
    with pytest.raises(AttributeError):
        pi.k_p = 1.0  # type: ignore[misc]
    pi.u_i = 0.75  # a state: writable
    assert pi.output(0.0, 0.0) == 0.75
    with pytest.raises(ValueError, match="k_t"):
        PIController(0.0, 1.0, 1e-3)


def test_svpwm_and_limit_are_the_core() -> None:
    rng = np.random.default_rng(2)
    u_dc = 48.0
    for scale in (0.2, 0.5, 0.58, 0.6, 1.0):  # inside, at and beyond the linear range
        for th, mag in zip(
            rng.uniform(0.0, 2.0 * math.pi, N // 5), rng.uniform(0, 1, N // 5), strict=True
        ):
            u_a = scale * u_dc * mag * math.cos(th)
            u_b = scale * u_dc * mag * math.sin(th)
            _same(svpwm(u_a, u_b, u_dc), ob.svpwm(u_a, u_b, u_dc))
            x_max = 0.4 * u_dc
            _same(limit_magnitude(u_a, u_b, x_max), ob.limit_magnitude(u_a, u_b, x_max))
    # the axes and the hexagon's corners, where the min/max branches tie
    for k in range(12):
        th = k * math.pi / 6.0
        u = u_dc / math.sqrt(3.0)
        _same(
            svpwm(u * math.cos(th), u * math.sin(th), u_dc),
            ob.svpwm(u * math.cos(th), u * math.sin(th), u_dc),
        )
    with pytest.raises(ValueError, match="u_dc"):
        svpwm(1.0, 0.0, 0.0)


def _states(obj: Any, names: tuple[str, ...]) -> tuple[Any, ...]:
    return tuple(getattr(obj, n) for n in names)


PLL_STATES = ("theta_hat", "w_hat", "w_i", "k_p", "k_i", "T_s")


def test_position_observer_is_the_core() -> None:
    rng = np.random.default_rng(3)
    b, o = _pair(lambda: PositionObserver(150.0, 1e-4))
    for j in range(N):
        err = float(rng.normal(0.0, 0.3))
        accel = 0.0 if j % 3 else float(rng.normal(0.0, 500.0))  # with and without
        if j % 700 == 350:  # restarts, at angles outside [0, 2 pi) too
            th0, w0 = rng.uniform(-10.0, 10.0), rng.normal(0.0, 300.0)
            b.reset(th0, w0)
            o.reset(th0, w0)
        b.update(err, accel)
        o.update(err, accel)
        _same(_states(b, PLL_STATES), _states(o, PLL_STATES))
    b.theta_hat = o.theta_hat = 7.5  # a state is writable; the step wraps it
    b.update(0.1)
    o.update(0.1)
    _same(_states(b, PLL_STATES), _states(o, PLL_STATES))
    with pytest.raises(AttributeError):
        b.k_p = 1.0


POLARITY_STATES = ("U", "N", "_n", "_i0", "_i1", "d_i_pos", "d_i_neg", "done", "flip")


@pytest.mark.parametrize("i_pulse", [0.4, 4.0, 40.0])
def test_polarity_test_is_the_core(i_pulse: float) -> None:
    rng = np.random.default_rng(4)
    b, o = _pair(lambda: PolarityTest(2e-3, 1e-4, i_pulse, 0.5))
    for trial in range(3):
        u_dc = 24.0 + 100.0 * trial
        i_d0 = float(rng.normal(0.0, 0.5))
        b.start(u_dc, i_d0)
        o.start(u_dc, i_d0)
        _same(_states(b, POLARITY_STATES), _states(o, POLARITY_STATES))
        assert type(b.N) is int and type(b.done) is bool
        i_d = i_d0
        for _ in range(6 * b.N + 3):
            i_d += float(rng.normal(0.0, 0.1))
            _same(b.step(i_d), o.step(i_d))
            _same(_states(b, POLARITY_STATES), _states(o, POLARITY_STATES))
        assert b.done and b.n_steps == 6 * b.N


def test_polarity_test_refuses_an_undefined_start() -> None:
    with pytest.raises(ValueError, match="u_dc must be positive"):
        PolarityTest(2e-3, 1e-4, 4.0).start(0.0, 0.0)
    with pytest.raises(ValueError, match="i_pulse must be positive"):
        PolarityTest(2e-3, 1e-4, 0.0).start(48.0, 0.0)


FLUX_STATES = (
    "psi_alpha",
    "psi_beta",
    "theta_hat",
    "w_hat",
    "eps",
    "accel",
    "_ia1",
    "_ib1",
    "_th_next",
    "_init",
)


def test_flux_observer_is_the_core() -> None:
    """A rotating flux with noisy samples: sensorless, slaved, restarted, set."""
    rng = np.random.default_rng(5)
    motor = MotorModel(
        n_p=4, R_s=0.2, L_d=2e-3, L_q=3e-3, psi_f=0.05, J=1e-4, b=0.0, i_max=10.0, tau_max=1.0
    )
    T_s = 2e-4
    b, o = _pair(lambda: FluxObserver(motor, T_s, 80.0, 0.2, 60.0))
    for n in ("R_s", "L_d", "L_q", "psi_f", "T_s", "alpha_o", "zeta_f", "w_min", "k_p", "k_i"):
        _same(getattr(b, n), getattr(o, n))
    th, w = 0.3, 0.0
    for j in range(N):
        w += T_s * 2000.0 if j < N // 2 else -T_s * 1500.0  # through zero and back
        th += T_s * w
        i_ab = 5.0 * complex(math.cos(th + 1.8), math.sin(th + 1.8)) + complex(
            *rng.normal(0, 0.05, 2)
        )
        u_ab = complex(*rng.normal(0.0, 3.0, 2)) + 1j * w * 0.05 * complex(
            math.cos(th), math.sin(th)
        )
        args = (i_ab.real, i_ab.imag, u_ab.real, u_ab.imag)
        if j % 400 < 100:  # slaved below a band
            b.update_slaved(*args, th + 0.05, w)
            o.update_slaved(*args, th + 0.05, w)
        else:
            b.update(*args)
            o.update(*args)
        if j % 650 == 300:
            b.reset(th - 7.0, w)
            o.reset(th - 7.0, w)
        if j % 900 == 450:
            b.set_state(0.04, -0.01, 1.0, 2.0)
            o.set_state(0.04, -0.01, 1.0, 2.0)
        _same(_states(b, FLUX_STATES), _states(o, FLUX_STATES))


def _supervised_run(sup: Supervisor, seed: int, fault: int) -> list[tuple[Any, ...]]:
    """A drive's periods through :meth:`Supervisor.wrap`: rotating currents with ``fault``
    after 300 periods (0 none, 1 a stuck sensor, 2 an open phase, 3 rail readings, 4 a
    DC-link sag, 5 a surge; the DC-link ones clear on a new enable every 1000 periods); every
    period's output and the supervision's state."""
    rng = np.random.default_rng(seed)
    T_s, u_dc0, w = 1e-4, 540.0, 2.0 * math.pi * 50.0
    state = {"mode": MODE_RUN}
    out: list[tuple[Any, ...]] = []

    def disable() -> None:
        state["mode"] = MODE_DISABLED

    def step(meas: Measurement) -> ControlOutput:
        th = w * T_s * meas.k
        d = [0.5 + 0.3 * math.cos(th - j * 2.0 * math.pi / 3.0) for j in range(3)]
        on = state["mode"] == MODE_RUN
        return ControlOutput(meas.k, d[0], d[1], d[2], on, th, w, 0.0, state["mode"])

    run = sup.wrap(step, disable)
    for k in range(3000):
        seg = fault
        if k % 1000 == 0:
            state["mode"] = MODE_RUN  # a new enable
        th = w * T_s * k
        i_a = 5.0 * math.cos(th) + float(rng.normal(0.0, 0.01))
        i_b = 5.0 * math.cos(th - 2.0 * math.pi / 3.0) + float(rng.normal(0.0, 0.01))
        u_dc = u_dc0 + float(rng.normal(0.0, 1.0))
        if seg == 1 and k % 1000 > 300:
            i_a = 1.7  # stuck
        elif seg == 2 and k % 1000 > 300:
            i_b = 0.0  # open phase b
        elif seg == 3 and k in (500, 501):
            i_a = 25.0  # at the rail
        elif seg == 4 and 300 < k % 1000 < 600:
            u_dc = 0.7 * u_dc0  # sag
        elif seg == 5 and 300 < k % 1000 < 400:
            u_dc = 1.3 * u_dc0  # surge
        o = run(Measurement(k, i_a, i_b, -i_a - i_b, u_dc))
        out.append((o.d_a, o.d_b, o.d_c, o.enable, o.mode, sup.latched, sup.detected_k))
    return out


def test_supervisor_is_the_core() -> None:
    pars = SupervisionPars.design(
        T_s=1e-4,
        L_q=3e-3,
        u_dc=540.0,
        u_dc_trip=1.2 * 540.0,
        i_max=10.0,
        i_fs=20.0,
        i_lsb=40.0 / 4096,
        i_noise=0.01,
        i_offset=0.01,
        u_lsb=0.5,
        u_noise=1.0,
    )
    modes = set()
    for fault in range(6):
        b, o = _pair(lambda: Supervisor(pars))
        got, want = _supervised_run(b, 6, fault), _supervised_run(o, 6, fault)
        modes |= {r[4] for r in want}
        for g, w_ in zip(got, want, strict=True):
            _same(g, w_)
        for u in (300.0, 540.0, 700.0):
            assert b.release_ok(u) == o.release_ok(u)
    # every detection met
    assert modes == {
        MODE_RUN,
        MODE_CURRENT_SENSOR,
        MODE_OPEN_PHASE,
        MODE_DC_UNDERVOLTAGE,
        MODE_DC_OVERVOLTAGE,
    }


def test_transition_band_is_the_core() -> None:
    rng = np.random.default_rng(7)
    b, o = _pair(lambda: TransitionBand(100.0, 200.0, 300.0, 10.0))
    y_b = y_o = 0.0
    w = 0.0
    for _ in range(N):
        w += float(rng.normal(0.0, 15.0))  # a random walk through the band, both signs
        y_b, y_o = b.play(y_b, w), o.play(y_o, w)
        _same(y_b, y_o)
        _same(b.weights(y_b), o.weights(y_o))
    for y in (-1.0, 0.0, 100.0, 150.0, 200.0, 250.0, 300.0, 1e9):  # the corners
        _same(b.weights(y), o.weights(y))


def test_compensation_laws_are_the_core() -> None:
    rng = np.random.default_rng(8)
    for i_x in np.concatenate([rng.normal(0.0, 1.0, N), [0.0, -0.0, 0.5, -0.5, 2.0, -2.0]]):
        for i_band in (0.0, 0.5, 2.0):
            for sine in (False, True):
                _same(smooth_sign(i_x, i_band, sine), ob.smooth_sign(i_x, i_band, sine))
    for k_dq, i_q in zip(rng.normal(0.0, 1e-3, N), rng.normal(0.0, 10.0, N), strict=True):
        for L_d, L_q in ((2e-3, 3e-3), (3e-3, 2e-3), (2e-3, 2e-3)):
            _same(
                cross_saturation_offset(k_dq, i_q, L_d, L_q),
                ob.cross_saturation_offset(k_dq, i_q, L_d, L_q),
            )


@pytest.mark.parametrize(
    ("block", "steps"),
    [
        (PIController, ("output", "update", "reset")),
        (PositionObserver, ("update", "reset")),
        (FluxObserver, ("update", "update_slaved", "reset", "set_state")),
        (PolarityTest, ("step",)),
        (Supervisor, ("_check", "release_ok", "_reset_windows")),
    ],
)
def test_the_blocks_steps_are_the_cores(block: type, steps: tuple[str, ...]) -> None:
    """Each step is a method of the binding's C type (no Python frame), not a Python copy;
    its Python is the oracle's alone."""
    for name in steps:
        meth = getattr(block, name)
        assert type(meth).__name__ == "method_descriptor", (block, name)
        assert meth.__objclass__.__module__ == "controller._cctl"
        assert callable(getattr(ob.ORACLES[block], name))


PLUGIN = """
import math

from controller import FluxObserver


class BlocksFlux:
    \"\"\"A plug-in composed of a public block: the flux observer, no injection.\"\"\"

    def __init__(self, motor, T_s):
        self.obs = FluxObserver(motor, T_s, 2.0 * math.pi * 20.0, 0.2, 20.0)
        self.theta_hat = self.w_hat = self.err = self.i_alpha_f = self.i_beta_f = 0.0

    def update(self, x):
        self.obs.update(x.i_alpha, x.i_beta, x.u_alpha, x.u_beta)
        self.theta_hat, self.w_hat, self.err = self.obs.theta_hat, self.obs.w_hat, self.obs.eps
        self.i_alpha_f, self.i_beta_f = x.i_alpha, x.i_beta

    def injection(self):
        return 0.0, 0.0

    def reset(self, theta0):
        self.obs.reset(theta0)
        self.theta_hat, self.w_hat = theta0 % (2.0 * math.pi), 0.0


def create(motor, T_s, **options):
    return BlocksFlux(motor, T_s)


def create_oracle(motor, T_s, **options):
    from tests.oracle.blocks import oracle

    e = BlocksFlux(motor, T_s)
    oracle(e.obs)
    return e


create.injection_family = create_oracle.injection_family = "none"
"""


def test_a_plugin_composed_of_the_blocks_runs_as_with_their_oracles(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """A plug-in estimator that composes a public block, run by the controller's core on the
    compiled plant (flux-known-angle, a speed step): the same outputs in every period with
    the block's binding as with its oracle."""
    (tmp_path / "blocks_est.py").write_text(PLUGIN)
    monkeypatch.syspath_prepend(str(tmp_path))
    scn_path = Path(__file__).parents[1] / "docs" / "examples" / "flux-known-angle.toml"
    traces = []
    for factory in ("blocks_est:create", "blocks_est:create_oracle"):
        scn = load_scenario(str(scn_path))
        sim = build_plant(scn, "compiled")
        ctrl = build_controller(scn, factory)
        est: Any = ctrl.estimator
        assert est.obs.__class__.__module__ == (
            "controller._flux_observer" if factory.endswith("create") else "tests.oracle.blocks"
        )
        ctrl.set_enable(True)
        ctrl.set_speed_ref(60.0 * 2.0 * math.pi / 60.0)
        d = (0.5, 0.5, 0.5, False)
        trace = []
        for k in range(3000):
            if k == 1500:
                ctrl.set_speed_ref(-30.0 * 2.0 * math.pi / 60.0)
            s = sim.sample()
            o = ctrl.step(Measurement(s.k, s.i_a, s.i_b, s.i_c, s.u_dc))
            sim.step(*d)
            d = (o.d_a, o.d_b, o.d_c, o.enable)
            trace.append((o.d_a, o.d_b, o.d_c, o.theta_hat, o.w_hat, o.err, o.mode))
        traces.append(trace)
    _same([t[:6] for t in traces[0]], [t[:6] for t in traces[1]])
    assert [t[6] for t in traces[0]] == [t[6] for t in traces[1]]
    assert len({t[4] for t in traces[0]}) > 1000  # the estimate moves
