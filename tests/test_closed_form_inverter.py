"""Dead time (plant_rt._inverter.dead_time_error) and its use in Plant.step, against the
textbook dead-time voltage error.

Textbook (e.g. Holtz; Mohan, Undeland, Robbins): over one PWM period a leg whose
current ``i_x`` flows into the machine loses ``t_d / T_s`` of its on-time, so its
mean pole voltage is off by ``dv_x = -sign(i_x) V``, ``V = u_dc t_d / T_s``. The
floating star point removes the common mode: the phase voltages are off by
``du_x = dv_x - (dv_a + dv_b + dv_c) / 3`` and the space vector by
``du_ab = (2/3) sum_x dv_x e^{j phi_x}`` (magnitude ``4V/3`` when no current is
zero, opposite to the centre of the current's 60-degree sector).

The plant is held at standstill (:meth:`Plant.impose_speed`), saturation off, so
the d and q axes are two decoupled RL circuits and a voltage difference ``du_dq``
constant over a period changes the current by exactly
``du/R (1 - exp(-R T_s / L))`` per axis (superposition against a plant without
dead time, same state and duties).
"""

from __future__ import annotations

import cmath
import math

import pytest

from plant_rt import InverterPars, Plant, preset
from plant_rt._inverter import dead_time_error

PRE = preset("wen2023")
M = PRE.motor
T_S = PRE.T_s
U_DC = 540.0
T_DEAD = 2e-6
V_DT = U_DC * T_DEAD / T_S  # 10.8 V
PHI = (0.0, 2.0 * math.pi / 3.0, -2.0 * math.pi / 3.0)  # phase axes a, b, c
THETA_E = 1.2  # rotor angle (rad, electrical) for the sign-pattern tests


def _plant(t_dead: float, theta_e: float, meter: bool = False) -> Plant:
    p = Plant(
        M,
        InverterPars(u_dc=U_DC, t_dead=t_dead),
        T_S,
        theta_m0=theta_e / M.n_p,
        meter=meter,
    )
    p.impose_speed(0.0)
    return p


def _duties(u_ab: complex) -> tuple[float, float, float]:
    """Sinusoidal modulation: d_x = 1/2 + Re(u_ab e^{-j phi_x}) / u_dc."""
    d_a, d_b, d_c = (0.5 + (u_ab * cmath.exp(-1j * ph)).real / U_DC for ph in PHI)
    return d_a, d_b, d_c


def _prepare(p: Plant, phi_i: float) -> None:
    """One period of a voltage that moves the current (from zero) along angle phi_i."""
    th = THETA_E
    di_dq = cmath.exp(1j * (phi_i - th))
    u_dq = complex(M.L_d * di_dq.real, M.L_q * di_dq.imag) * (50.0 / M.L_q)
    p.step(*_duties(u_dq * cmath.exp(1j * th)))


def _sign(x: float) -> int:
    return (x > 0.0) - (x < 0.0)


def _textbook_du_ab(signs: tuple[int, int, int], V: float) -> complex:
    return (2.0 / 3.0) * sum(-s * V * cmath.exp(1j * ph) for s, ph in zip(signs, PHI, strict=True))


@pytest.mark.parametrize(
    ("phi_deg", "signs"),
    [
        (0.0, (1, -1, -1)),
        (60.0, (1, 1, -1)),
        (120.0, (-1, 1, -1)),
        (180.0, (-1, 1, 1)),
        (240.0, (-1, -1, 1)),
        (300.0, (1, -1, 1)),
        (95.0, (-1, 1, -1)),
        (-40.0, (1, -1, 1)),
    ],
    ids=lambda v: (
        "".join("+" if s > 0 else "-" for s in v) if isinstance(v, tuple) else f"{v:g}deg"
    ),
)
@pytest.mark.parametrize("meter", [False, True], ids=["fast", "meter"])
def test_dead_time_phase_voltage_error_matches_textbook(
    phi_deg: float, signs: tuple[int, int, int], meter: bool
) -> None:
    """Per sign pattern: phase-voltage errors ``-V (s_x - mean(s))``, ``|du_ab| = 4V/3``
    against the current, and the current response of the RL axes to that error.

    Catches: an error with the current's sign (wrong direction), a missing factor u_dc
    or T_s, an error applied to the line instead of the pole voltage (common mode not
    removed: wrong per-phase values), and a plant that stores u_s_ab but integrates
    the ideal voltage (current check)."""
    ref = _plant(0.0, THETA_E, meter)
    dut = _plant(T_DEAD, THETA_E, meter)
    for p in (ref, dut):
        _prepare(p, math.radians(phi_deg))
    assert tuple(_sign(i) for i in dut.currents_abc()) == signs  # the pattern under test
    assert ref.currents_abc() == dut.currents_abc()  # zero current in the first period
    duties = (0.43, 0.61, 0.52)
    ref.step(*duties)
    dut.step(*duties)
    du_ab = complex(*dut.u_s_ab) - complex(*ref.u_s_ab)
    mean_s = sum(signs) / 3.0
    for s, ph in zip(signs, PHI, strict=True):
        du_x = (du_ab * cmath.exp(-1j * ph)).real  # amplitude-invariant inverse Clarke
        assert du_x == pytest.approx(-V_DT * (s - mean_s), abs=1e-9)
    assert du_ab == pytest.approx(_textbook_du_ab(signs, V_DT), abs=1e-9)
    assert abs(du_ab) == pytest.approx(4.0 * V_DT / 3.0, rel=1e-12)
    # The current the plant integrates: exact RL response per rotor axis at standstill.
    du_dq = du_ab * cmath.exp(-1j * THETA_E)
    i_ref = ref.truth()
    i_dut = dut.truth()
    for du, L, di in (
        (du_dq.real, M.L_d, i_dut.i_d - i_ref.i_d),
        (du_dq.imag, M.L_q, i_dut.i_q - i_ref.i_q),
    ):
        want = du / M.R_s * (1.0 - math.exp(-M.R_s * T_S / L))
        # RK4 with 2 substeps on tau = L/R >= 200 T_s: relative error ~ (T_s/2tau)^5/120.
        assert di == pytest.approx(want, rel=1e-9, abs=1e-13)


def test_zero_current_no_dead_time_error() -> None:
    """Documented: i_x = 0 gives no error in that leg (dead_time_error returns 0).

    At rest (all currents exactly zero) the plant with dead time applies exactly the
    ideal voltage. Then a beta-axis voltage at theta_e = 0 leaves i_a exactly zero and
    i_b = -i_c != 0: only legs b and c err, du_ab = -(2/3) V (e^{j 2pi/3} - e^{-j 2pi/3})
    = -j (2/sqrt(3)) V. An implementation treating i = 0 as positive (or negative)
    adds -(2/3) V (or +(2/3) V) along alpha and fails."""
    assert dead_time_error(0.0, U_DC, T_DEAD, T_S) == 0.0
    assert dead_time_error(1e-12, U_DC, T_DEAD, T_S) == pytest.approx(-V_DT, rel=1e-15)
    assert dead_time_error(-1e-12, U_DC, T_DEAD, T_S) == pytest.approx(V_DT, rel=1e-15)
    ref = _plant(0.0, 0.0)
    dut = _plant(T_DEAD, 0.0)
    d_beta = (0.5, 0.75, 0.25)  # u_alpha = 0 exactly, u_beta = 311.8 V
    ref.step(*d_beta)
    dut.step(*d_beta)
    assert dut.u_s_ab == ref.u_s_ab  # all currents were zero: no error at all
    i_a, i_b, i_c = dut.currents_abc()
    assert i_a == 0.0 and i_b > 0.0 > i_c
    ref.step(0.5, 0.5, 0.5)
    dut.step(0.5, 0.5, 0.5)
    du_ab = complex(*dut.u_s_ab) - complex(*ref.u_s_ab)
    assert du_ab == pytest.approx(_textbook_du_ab((0, 1, -1), V_DT), abs=1e-9)
    assert du_ab == pytest.approx(-1j * 2.0 / math.sqrt(3.0) * V_DT, abs=1e-9)


@pytest.mark.parametrize(
    ("d_a", "phi_deg"),
    [(0.0, 0.0), (0.0, 180.0), (1.0, 0.0), (1.0, 180.0)],
    ids=["d0-i_pos", "d0-i_neg", "d1-i_pos", "d1-i_neg"],
)
def test_leg_at_rail_has_no_dead_time_error(d_a: float, phi_deg: float) -> None:
    """Duty at a rail: no edges in that leg, so no dead-time error there.

    With currents (+,-,-) or (-,+,+), leg a at 0 or 1 and legs b, c switching at
    1/2, the expected error is ``du_ab = (2/3) sum_{x=b,c} -s_x V e^{j phi_x}`` (leg a
    contributes nothing): -/+ 7.2 V along alpha. The model also makes leg a err, so
    du_ab is off by ``-(2/3) s_a V``, giving -/+ 14.4 V."""
    ref = _plant(0.0, THETA_E)
    dut = _plant(T_DEAD, THETA_E)
    for p in (ref, dut):
        _prepare(p, math.radians(phi_deg))
    signs = tuple(_sign(i) for i in dut.currents_abc())
    assert signs in ((1, -1, -1), (-1, 1, 1))
    ref.step(d_a, 0.5, 0.5)
    dut.step(d_a, 0.5, 0.5)
    du_ab = complex(*dut.u_s_ab) - complex(*ref.u_s_ab)
    want = _textbook_du_ab((0, signs[1], signs[2]), V_DT)
    assert du_ab == pytest.approx(want, abs=1e-9)
