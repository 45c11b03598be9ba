"""Closed speed loop in-process (no CAN): plant ``wen2023`` and the FOC controller."""

from __future__ import annotations

import math

import numpy as np
import pytest

from controller import MODE_ALIGN, MODE_POLARITY, MODE_RUN
from plant_rt import preset
from tests.loop_helpers import RPM, make_loop, run

P = preset("wen2023")


def test_wen_5_1_tt_dq_holds_100_rpm() -> None:
    """Wen 5.1: 100 rpm, no load, ``tt-dq``, 1.5 s from an unknown angle (start-up
    included). Paper, Table 5: mean |dtheta| 2.0, max 4.0 degrees. Scored over the
    last second. The plant has no dead time and no sensor noise, so the error here
    is the estimator's own (resistance and rotor-frame coupling, below 1 degree)."""
    plant, ctrl = make_loop(P, "tt-dq", theta_e0=2.5)
    tr = run(plant, ctrl, 15000, 100 * RPM)
    sel = tr.t >= 0.5
    e = np.degrees(np.abs(tr.err[sel]))
    # the paper's bounds (2.0 / 4.0 deg) would pass without the delay
    # compensation (0.36 deg at 100 rpm); the bench's own figure is checked
    # (0.37 deg mean, 0.71 deg max when written)
    assert e.mean() <= 0.6
    assert e.max() <= 1.0
    assert np.abs(tr.w_m[sel] / RPM - 100.0).max() < 2.0
    assert (tr.mode[sel] == MODE_RUN).all()


def test_sensored_baseline_holds_100_rpm() -> None:
    """Sensored FOC: starts in MODE_RUN, reaches 100 rpm, angle error zero."""
    plant, ctrl = make_loop(P, "sensored", theta_e0=1.0)
    tr = run(plant, ctrl, 6000, 100 * RPM, sensored=True)
    assert (tr.mode == MODE_RUN).all()
    assert np.abs(tr.err).max() == 0.0
    assert np.abs(tr.w_m[-1000:] / RPM - 100.0).max() < 1.0


def test_startup_from_random_angles_reaches_speed_in_the_right_direction() -> None:
    """20 seeded random initial rotor angles, half with +100 rpm and half with -100 rpm:
    the HF estimator converges at standstill (to theta or theta + pi), the polarity
    test resolves the ambiguity with the d-axis saturation, and the drive reaches
    the commanded speed in the commanded direction every time, within 0.5 s."""
    rng = np.random.default_rng(2023)
    angles = rng.uniform(0.0, 2.0 * math.pi, 20)
    flips = 0
    for n, th0 in enumerate(angles):
        ref = 100.0 if n % 2 == 0 else -100.0
        plant, ctrl = make_loop(P, "tt-dq", theta_e0=float(th0))
        tr = run(plant, ctrl, 5000, ref * RPM)
        t_run = tr.t[np.argmax(tr.mode == MODE_RUN)]
        assert 0.0 < t_run < 0.25
        assert MODE_POLARITY in tr.mode and MODE_ALIGN in tr.mode
        flips += int(ctrl.states()["polarity_flip"])  # the engine's own test
        last = tr.t >= 0.4
        assert np.abs(tr.w_m[last] / RPM - ref).max() < 5.0, (th0, ref)
        assert np.degrees(np.abs(tr.err[last])).max() < 5.0
    # Both outcomes of the polarity test occur, so the test exercises the flip.
    assert 0 < flips < 20


@pytest.mark.parametrize("name", ["sfhf", "tt-ab"])
def test_other_demodulators_run_the_same_loop(name: str) -> None:
    """``sfhf`` and ``tt-ab`` with identical settings also start and hold 100 rpm; their
    mean error is their speed-dependent offset (Wen Table 3), larger than ``tt-dq``'s."""
    plant, ctrl = make_loop(P, name, theta_e0=2.5)
    tr = run(plant, ctrl, 8000, 100 * RPM)
    sel = tr.t >= 0.5
    assert np.abs(tr.w_m[sel] / RPM - 100.0).max() < 5.0
    assert np.degrees(np.abs(tr.err[sel])).mean() > 5.0


def test_default_pars_work_at_one_kilohertz() -> None:
    """``xue2022`` at 1 kHz with default ControllerPars: the sensored baseline holds
    300 rpm; a 500 Hz rotating injection is refused (at the Nyquist frequency) with
    one clear message."""
    px = preset("xue2022")
    plant, ctrl = make_loop(px, "sensored", theta_e0=0.3)
    tr = run(plant, ctrl, 1500, 300 * RPM, sensored=True)
    assert np.abs(tr.w_m[-300:] / RPM - 300.0).max() < 2.0
    with pytest.raises(ValueError, match="Nyquist"):
        make_loop(px, "tt-dq")
