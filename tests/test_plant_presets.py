"""Presets: paper values, chosen values consistent, lookup errors."""

from __future__ import annotations

import dataclasses
import math

import pytest

from plant_rt import PRESETS, Preset, UnknownPresetError, preset

RPM = 2 * math.pi / 60


def test_paper_values() -> None:
    w = preset("wen2023")
    assert isinstance(w, Preset)
    assert (w.motor.n_p, w.motor.R_s, w.motor.L_d, w.motor.L_q) == (4, 2.8, 57e-3, 82e-3)
    assert (w.motor.tau_rated, w.motor.J) == (7.5, 0.003)
    assert w.motor.w_m_rated == pytest.approx(1500 * RPM)
    assert w.f_sw == 10e3
    x = preset("xue2022")
    assert (x.motor.n_p, x.motor.R_s, x.motor.L_d, x.motor.L_q) == (4, 0.19, 3.53e-3, 7.48e-3)
    assert x.inverter.u_dc == 540.0
    assert x.motor.w_m_rated == pytest.approx(1200 * RPM)
    assert x.f_sw == 1e3
    assert x.motor.tau_rated * x.motor.w_m_rated == pytest.approx(3000.0)


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_rated_point_reachable(name: str) -> None:
    """MTPA at rated torque needs at most i_rated, and the stator voltage at
    rated speed stays inside the sine-triangle limit u_dc / 2; the input power
    is within 10 % above the rated output (1.2 kW or 3 kW)."""
    p = preset(name)
    m = p.motor

    def max_torque(i_abs: float) -> tuple[float, float, float]:
        """MTPA: the largest torque for current magnitude i_abs and its (i_d, i_q)."""
        best = (-math.inf, 0.0, 0.0)
        for j in range(0, 1801):
            beta = math.radians(j / 20.0)  # current angle from the q axis towards -d
            i_d, i_q = -i_abs * math.sin(beta), i_abs * math.cos(beta)
            tau = 1.5 * m.n_p * (m.psi_f * i_q + (m.L_d - m.L_q) * i_d * i_q)
            if tau > best[0]:
                best = (tau, i_d, i_q)
        return best

    lo, hi = 0.0, m.i_max
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if max_torque(mid)[0] < m.tau_rated else (lo, mid)
    i_abs = hi
    _, i_d, i_q = max_torque(i_abs)
    assert 0.9 * m.i_rated < i_abs <= m.i_rated
    w_e = m.n_p * m.w_m_rated
    u_d = m.R_s * i_d - w_e * m.L_q * i_q
    u_q = m.R_s * i_q + w_e * (m.L_d * i_d + m.psi_f)
    assert math.hypot(u_d, u_q) < 0.5 * p.inverter.u_dc
    p_in = 1.5 * (u_d * i_d + u_q * i_q)
    assert m.tau_rated * m.w_m_rated < p_in < 1.1 * m.tau_rated * m.w_m_rated
    assert m.i_max >= 2 * m.i_rated
    assert m.L_d * (1 + m.sat.sigma) < m.L_q  # saliency kept under saturation
    assert p.doc and "psi_f" in p.doc


def test_unknown_preset_message() -> None:
    with pytest.raises(UnknownPresetError) as exc:
        preset("wen2024")
    assert isinstance(exc.value, KeyError)
    msg = str(exc.value)
    assert "wen2024" in msg and "wen2023" in msg and "xue2022" in msg
    assert "\n" not in msg


def test_presets_are_frozen() -> None:
    with pytest.raises(dataclasses.FrozenInstanceError):
        preset("wen2023").motor.R_s = 1.0  # type: ignore[misc]
