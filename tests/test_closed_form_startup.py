"""Magnet-polarity test (controller._startup.PolarityTest) against closed forms.

The d axis is modelled in the test, per PWM period of length ``T`` with the
controller's one-period delay (the voltage returned at sample ``k`` acts in
period ``k + 1``):

- linear RL: ``i[k+1] = q i[k] + (1 - q) u[k] / R``, ``q = exp(-R T / L)``
  (exact for a voltage constant over the period; ``R = 0`` is a pure inductor);
- saturated, at R = 0: flux ``psi[k+1] = psi[k] + T u[k]`` with the piecewise
  linear ``psi = L_+ i`` for ``i >= 0`` and ``L_- i`` for ``i < 0``
  (``L_+ < L_-``: current along the magnet's north saturates the iron).

For an N-period pulse of U volts a pure inductance L moves the current by
``N U T / L``; that is the closed form of both peaks.
"""

from __future__ import annotations

import math

import pytest

from controller import PolarityTest
from plant_rt import Preset, preset

WEN = preset("wen2023")
XUE = preset("xue2022")
U_DC = 540.0


def _run_rl(pt: PolarityTest, L: float, R: float, i0: float) -> tuple[list[float], list[float]]:
    """Run a started test on a linear RL d axis; return the voltages returned and the currents."""
    q = math.exp(-R * pt.T_s / L)
    i = i0
    u_now = 0.0  # voltage acting in the present period
    us: list[float] = []
    cur: list[float] = []
    while not pt.done:
        cur.append(i)
        u_next = pt.step(i)
        us.append(u_next)
        # exact RL step over the period (pure inductor when R = 0)
        i = q * i + (1.0 - q) * u_now / R if R > 0.0 else i + pt.T_s * u_now / L
        u_now = u_next
    cur.append(i)
    return us, cur


def _run_saturated(pt: PolarityTest, L_pos: float, L_neg: float, L_q: float, dtheta: float) -> None:
    """Run a started test at R = 0, estimated d axis at ``theta_e - dtheta``.

    Rotor-frame voltage ``u e^{-j dtheta}``; the test sees the projection of the
    rotor-frame current on the estimated axis, ``i_d cos(dtheta) - i_q sin(dtheta)``.
    """
    c, s = math.cos(dtheta), math.sin(dtheta)
    psi_d = psi_q = 0.0
    u_now = 0.0
    while not pt.done:
        i_d = psi_d / (L_pos if psi_d >= 0.0 else L_neg)
        i_q = psi_q / L_q
        u_next = pt.step(c * i_d - s * i_q)
        psi_d += pt.T_s * c * u_now
        psi_q -= pt.T_s * s * u_now
        u_now = u_next


@pytest.mark.parametrize(
    ("pre", "i_pulse", "voltage_limited"),
    [(WEN, 4.0, True), (XUE, 10.0, False)],
    ids=["wen-voltage-limited", "xue-two-periods"],
)
def test_pulse_voltage_and_length_formulas(
    pre: Preset, i_pulse: float, voltage_limited: bool
) -> None:
    """U = min(u_frac u_dc / sqrt(3), L_d i_pulse / (2 T)), N = ceil(L_d i_pulse / (U T)) >= 2.

    wen2023 at 10 kHz (4 A): limited by 0.5 * 540 / sqrt(3) = 155.9 V, N = 15;
    xue2022 at 1 kHz (10 A): limited by L_d i_pulse / (2 T) = 17.65 V, N = 2. A
    missing sqrt(3), a floor instead of a ceil or a missing factor 2 changes U or N.
    """
    L, T = pre.motor.L_d, pre.T_s
    pt = PolarityTest(L, T, i_pulse)
    pt.start(U_DC, 0.0)
    u_lim = 0.5 * U_DC / math.sqrt(3.0)
    flux = L * i_pulse
    assert (u_lim < flux / (2.0 * T)) is voltage_limited
    u_pulse, n_pulse = pt.U, pt.N
    assert u_pulse == pytest.approx(min(u_lim, flux / (2.0 * T)), rel=1e-12)
    assert n_pulse == max(2, math.ceil(flux / (u_pulse * T)))
    assert n_pulse == (15 if voltage_limited else 2)
    assert pt.n_steps == 6 * n_pulse
    # Linear-model peak N U T / L: at least i_pulse, less than one period's step above it.
    peak = pt.N * pt.U * T / L
    assert i_pulse - 1e-9 <= peak < i_pulse + pt.U * T / L


def test_pulse_sequence_volt_second_balanced_and_returns_current() -> None:
    """+U N, -U N, 0 N, -U N, +U N, 0 N, then 0 (done). On a pure inductor (R = 0)
    the current comes back to i_d0 (here 0.7 A, not zero, so peaks measured from zero
    instead of from i_d0 would fail) after each half, and both peaks are N U T / L."""
    L, T = WEN.motor.L_d, WEN.T_s
    pt = PolarityTest(L, T, 4.0)
    i0 = 0.7
    pt.start(U_DC, i0)
    us, cur = _run_rl(pt, L, 0.0, i0)
    N, U = pt.N, pt.U
    want = [U] * N + [-U] * N + [0.0] * N + [-U] * N + [U] * N + [0.0] * N + [0.0]
    assert us == want  # catches an off-by-one in the phase schedule or a missing rest
    assert cur[3 * N + 1] == pytest.approx(i0, abs=1e-12)  # back to start after half 1
    assert cur[-1] == pytest.approx(i0, abs=1e-12)  # and after half 2
    step = N * U * T / L
    assert pt.d_i_pos == pytest.approx(step, rel=1e-12)
    assert pt.d_i_neg == pytest.approx(step, rel=1e-12)
    assert max(cur) == pytest.approx(i0 + step, rel=1e-12)  # peak at sample N + 1
    assert cur.index(max(cur)) == N + 1


@pytest.mark.parametrize("pre", [WEN, XUE], ids=["wen", "xue"])
def test_rl_return_residual_is_resistive_drop(pre: Preset) -> None:
    """With R_s > 0 (q = exp(-R T / L)) half 1 leaves ``-(U/R)(1 - q^N)^2`` at the end of
    its -U pulse and half 2 ``+(U/R)(1 - q^N)^2``; they decay for 4N and N periods, so
    the end current is ``(U/R)(1 - q^N)^2 (q^N - q^{4N})``, to leading order
    ``3 i_peak (R N T / L)^2``: a few per cent of the pulse (1.3 % wen, 2.5 % xue).
    An unbalanced or reordered schedule leaves a residual of order i_peak."""
    L, R, T = pre.motor.L_d, pre.motor.R_s, pre.T_s
    pt = PolarityTest(L, T, 0.5 * pre.motor.i_max)
    pt.start(U_DC, 0.0)
    _, cur = _run_rl(pt, L, R, 0.0)
    N, U = pt.N, pt.U
    q = math.exp(-R * T / L)
    want = U / R * (1.0 - q**N) ** 2 * (q**N - q ** (4 * N))
    assert cur[-1] == pytest.approx(want, rel=1e-9)
    i_peak = N * U * T / L
    x = R * N * T / L
    # series in x: 3 i_peak x^2 (1 - 3.5 x + O(x^2))
    assert want == pytest.approx(3.0 * i_peak * x * x * (1.0 - 3.5 * x), rel=10.0 * x * x)
    # Peaks with R: dI_+ = (U/R)(1 - q^N) (closed form of the RL model); the second
    # half is measured from its own start current cur[3N] (what half 1's resistive
    # residual left), not from i_d0, which would add a first-order bias of
    # (U/R)(1 - q^N)^2 q^{2N} towards "flip" (see the unbiased-peaks test below).
    d_pos = U / R * (1.0 - q**N)
    assert pt.d_i_pos == pytest.approx(d_pos, rel=1e-9)
    assert pt.d_i_neg == pytest.approx(cur[3 * N] - min(cur[3 * N :]), rel=1e-12)
    assert abs(cur[3 * N]) > 0.01 * d_pos  # the residual is there: the reference matters


@pytest.mark.parametrize("pre", [WEN, XUE], ids=["wen", "xue"])
def test_rl_symmetric_machine_gives_unbiased_peaks(pre: Preset) -> None:
    """A linear (unsaturated) d axis has no polarity: the decision quantity
    ``dI_+ - dI_-`` should stay within the second-order resistive residual
    ``3 i_peak (R N T / L)^2`` of the sequence (what remains when each half's peak is
    taken from that half's own start value), not carry a first-order bias."""
    L, R, T = pre.motor.L_d, pre.motor.R_s, pre.T_s
    pt = PolarityTest(L, T, 0.5 * pre.motor.i_max)
    pt.start(U_DC, 0.0)
    _run_rl(pt, L, R, 0.0)
    i_peak = pt.N * pt.U * T / L
    x = R * pt.N * T / L
    assert abs(pt.d_i_pos - pt.d_i_neg) <= 3.0 * i_peak * x * x


@pytest.mark.parametrize(
    "dtheta",
    [0.0, 0.4, 1.2, math.pi - 1.2, math.pi - 0.4, math.pi, -0.4, -(math.pi - 0.4)],
)
@pytest.mark.parametrize("pre", [WEN, XUE], ids=["wen", "xue"])
def test_saturation_decides_north_and_flips_when_off_by_pi(pre: Preset, dtheta: float) -> None:
    """L_+ = 0.87 L_d, L_- = 1.13 L_d (the presets' saturation contrast at rated current).

    Peaks (R = 0): ``dI_+ = N U T (cos^2/L_1 + sin^2/L_q)``, ``dI_- = N U T (cos^2/L_2 +
    sin^2/L_q)`` with (L_1, L_2) = (L_+, L_-) when the estimated axis is within pi/2 of
    the north (cos > 0), (L_-, L_+) otherwise. Decision: ``flip`` iff ``|dtheta| > pi/2``.
    Catches an inverted comparison, peaks taken in the wrong halves, and peaks taken
    as |i| (the pi case would then not flip).
    """
    m = pre.motor
    L_pos, L_neg = 0.87 * m.L_d, 1.13 * m.L_d
    pt = PolarityTest(m.L_d, pre.T_s, 0.5 * m.i_max)
    pt.start(U_DC, 0.0)
    _run_saturated(pt, L_pos, L_neg, m.L_q, dtheta)
    c2, s2 = math.cos(dtheta) ** 2, math.sin(dtheta) ** 2
    L_1, L_2 = (L_pos, L_neg) if math.cos(dtheta) > 0.0 else (L_neg, L_pos)
    v = pt.N * pt.U * pt.T_s
    assert pt.d_i_pos == pytest.approx(v * (c2 / L_1 + s2 / m.L_q), rel=1e-9)
    assert pt.d_i_neg == pytest.approx(v * (c2 / L_2 + s2 / m.L_q), rel=1e-9)
    assert pt.done
    assert pt.flip is (abs(dtheta) > 0.5 * math.pi)
