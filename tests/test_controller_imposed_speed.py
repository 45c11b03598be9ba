"""Rotating-injection estimators on the plant with the speed imposed (dynamometer).

Closed current loop (references zero), estimator started 30 degrees off, plant
``wen2023`` at 10 kHz with saturation. All three demodulators use the same
filters (eqs. 11-13), the same ``V_h`` and the same observer bandwidth.

What is asserted (electrical degrees, mean over the last 0.2 s of 0.5 s):

- ``tt-dq`` converges to within 3 degrees at 0 and 100 rpm, and its error
  does not grow with speed (0 vs 300 rpm within 1.5 degrees): the BPF acts
  in the estimated frame, where the two sequences sit at +-(w_h - w_e), so
  its phase shifts cancel (Wen Table 2/3).
- ``sfhf`` and ``tt-ab`` converge to the offset their filters predict
  (Wen Table 3): ``sfhf`` ``-(arg H_B(w_n) + arg H_H(w_n - w_h))/2``,
  ``tt-ab`` ``-(arg H_B(w_h) + arg H_B(w_n) + arg H_L(2 w_e))/2`` with
  ``w_n = -w_h + 2 w_e``, within 1.5 degrees at 0 and 100 rpm. These
  offsets (5.4 and 13.1 degrees for sfhf, 0 and 11.5 for tt-ab) are the
  paper's point, not a defect to tune away, so the 3-degree bound holds for
  them only where their closed-form offset is below it (tt-ab at 0 rpm).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from plant_rt import preset
from tests.loop_helpers import RPM, make_loop, run

P = preset("wen2023")


def _arg(z: tuple[tuple[float, ...], tuple[float, ...]], w: float) -> float:
    _, h = signal.freqz(*z, worN=[abs(w) * P.T_s])
    a = float(np.angle(h[0]))
    return a if w >= 0 else -a


def _settled_error_deg(name: str, rpm: float) -> tuple[float, float, object]:
    theta0 = 1.3
    plant, ctrl = make_loop(
        P, name, theta_e0=theta0, startup=False, theta0=theta0 - math.radians(30.0)
    )
    ctrl.set_current_ref((0.0, 0.0))
    plant.impose_speed(rpm * RPM)
    tr = run(plant, ctrl, 5000)
    # modulo pi: the saliency repeats every pi. At 300 rpm the PLL (58.5 rad/s, from its
    # phase margin) pulls in the 126 rad/s step from w_hat = 0 with a transient of about
    # 45 degrees on top of the 30 it starts from, so it may settle half a turn away; the
    # start-up's polarity test is what removes that ambiguity in a real start
    e = np.degrees((tr.err[-2000:] + np.pi / 2) % np.pi - np.pi / 2)
    return float(e.mean()), float(np.abs(e).max()), ctrl.estimator


def _predicted_deg(name: str, rpm: float, est: object) -> float:
    w_h = 2 * math.pi * 500.0
    w_e = P.motor.n_p * rpm * RPM
    w_n = -w_h + 2 * w_e
    if name == "sfhf":
        return -math.degrees(_arg(est.bpf_z, w_n) + _arg(est.hpf_z, w_n - w_h)) / 2  # type: ignore[attr-defined]
    if name == "tt-ab":
        s = _arg(est.bpf_z, w_h) + _arg(est.bpf_z, w_n) + _arg(est.lpf_z, 2 * w_e)  # type: ignore[attr-defined]
        return -math.degrees(s) / 2
    return 0.0


@pytest.mark.parametrize("rpm", [0.0, 100.0])
@pytest.mark.parametrize("name", ["tt-dq", "tt-ab", "sfhf"])
def test_converges_from_30_degrees(name: str, rpm: float) -> None:
    mean, peak, est = _settled_error_deg(name, rpm)
    want = _predicted_deg(name, rpm, est)
    assert abs(mean - want) < 1.5, (mean, want)
    assert peak - abs(mean) < 1.5  # settled: no residual swing
    if abs(want) < 1.0:
        assert peak < 3.0


def test_tt_dq_error_does_not_grow_with_speed() -> None:
    """The paper's claim (Sec. 4.3, Table 6): no speed correlation for ``tt-dq``,
    while ``tt-ab`` and ``sfhf`` at 300 rpm are off by more than 20 degrees."""
    m0, _, _ = _settled_error_deg("tt-dq", 0.0)
    m3, p3, _ = _settled_error_deg("tt-dq", 300.0)
    assert abs(m3 - m0) < 1.5
    assert p3 < 3.0
    for name in ("tt-ab", "sfhf"):
        m, _, _ = _settled_error_deg(name, 300.0)
        assert m > 20.0
