"""Discrete realisations of Wen's filters, eqs. (11)-(13), against the continuous prototypes."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from controller import BPF_WEN, HPF_WEN, LPF_WEN
from tests.loop_helpers import motor_model
from tests.oracle.blocks import OracleBiquad2, OracleFirstOrder
from tests.oracle.estimators import make_oracle_estimator

T_S = 1e-4  # wen2023: 10 kHz


def _phase_deg(b: tuple[float, ...], a: tuple[float, ...], f: float, T_s: float) -> float:
    _, h = signal.freqz(b, a, worN=[2.0 * math.pi * f * T_s])
    return float(np.degrees(np.angle(h[0])))


@pytest.mark.parametrize("f", [500.0, 20.0])
@pytest.mark.parametrize("which", ["bpf", "hpf", "lpf"])
def test_discrete_phase_matches_continuous(which: str, f: float) -> None:
    """Phase of each discrete filter at 500 Hz and 20 Hz equals ``scipy.signal.freqs`` of
    eqs. (11)-(13) within 0.5 degree (Wen Fig. 5: BPF ~0 at 500 Hz, HPF ~22, LPF ~-2.3 at
    20 Hz)."""
    from plant_rt import preset

    est = make_oracle_estimator("sfhf", motor_model(preset("wen2023")), T_S)
    proto = {"bpf": BPF_WEN, "hpf": HPF_WEN, "lpf": LPF_WEN}[which]
    disc = {"bpf": est.bpf_z, "hpf": est.hpf_z, "lpf": est.lpf_z}[which]  # type: ignore[attr-defined]
    _, h = signal.freqs(proto[0], proto[1], worN=[2.0 * math.pi * f])
    want = float(np.degrees(np.angle(h[0])))
    assert _phase_deg(disc[0], disc[1], f, T_S) == pytest.approx(want, abs=0.5)


def test_filter_classes_run_the_coefficients() -> None:
    """The per-step filters reproduce ``scipy.signal.lfilter`` sample by sample."""
    from controller import discretize

    rng = np.random.default_rng(3)
    x1, x2 = rng.standard_normal(300), rng.standard_normal(300)
    bz, az = discretize(*BPF_WEN, T_S, 2 * math.pi * 500)
    bq = OracleBiquad2(bz, az)
    y = np.array([bq.update(a, b) for a, b in zip(x1, x2, strict=True)])
    assert y[:, 0] == pytest.approx(signal.lfilter(bz, az, x1), abs=1e-12)
    assert y[:, 1] == pytest.approx(signal.lfilter(bz, az, x2), abs=1e-12)
    bl, al = discretize(*LPF_WEN, T_S, 628.0)
    lp = OracleFirstOrder(bl, al)
    y1 = np.array([lp.update(a) for a in x1])
    assert y1 == pytest.approx(signal.lfilter(bl, al, x1), abs=1e-12)
    # Pre-warping: exact at the warping frequency.
    _, h = signal.freqs(*BPF_WEN, worN=[2 * math.pi * 500])
    _, hz = signal.freqz(bz, az, worN=[2 * math.pi * 500 * T_S])
    assert abs(hz[0] - h[0]) < 1e-9
