"""The flux map beyond its checked range (plant_flux_cross_ext) and the plant's count of it.

Inside ``|i_d|, |i_q| <= 2 i_max`` the cross-saturated map is the polynomial of
CrossSaturationPars, written out here::

    L_dd = L_dd,sat(i_d) - (c/2) i_q^2
    L_dq = -c (i_d + i_0) i_q
    L_qq = L_q - (c/2) (i_d^2 + 2 i_0 i_d)

Beyond it the co-energy is taken at the currents limited by
``s(u) = sgn(u) a + w tanh((u - sgn(u) a) / w)``: the matrix stays the Hessian of one
co-energy (symmetric, the Jacobian of the flux), continuous across the edge, positive
definite everywhere, and far out it is the d-axis model's ``diag(L_dd,sat(i_d), L_q)``.
"""

from __future__ import annotations

import hashlib
import math
import platform

import pytest

from bench._errors import EXIT_LOCK_LOST, EXIT_MODEL_RANGE, EXIT_PLANT_TRIPPED
from bench.runs._results import outcome
from bench.scenarios._schema import load_scenario
from bench.scenarios._setup import build_plant
from bench.studies._plants import plant_variant
from plant_rt import InverterPars, Plant, flux_dq, preset
from plant_rt._machine import FLUX_FADE, FLUX_RANGE
from tests.plant_reference import ReferencePlant
from tests.plant_reference import flux_dq as ref_flux_dq

NAMES = ["wen2023", "xue2022"]


def l_sat(name: str, i_d: float, sat: bool) -> float:
    m = preset(name).motor
    if not sat:
        return m.L_d
    x = i_d / m.sat.i_sat
    return m.L_d * (1.0 - m.sat.sigma * x / math.sqrt(1.0 + x * x))


def least_eig(L_dd: float, L_dq: float, L_qq: float) -> float:
    return 0.5 * (L_dd + L_qq) - math.hypot(0.5 * (L_dd - L_qq), L_dq)


def polar(r_max: float, n_r: int = 120, n_a: int = 144) -> list[tuple[float, float]]:
    """Radii evenly in log from r_max / 1000 to r_max, by n_a angles."""
    out = []
    for k in range(n_r + 1):
        r = r_max * 1000.0 ** (k / n_r - 1.0)
        for j in range(n_a):
            a = 2.0 * math.pi * (j + 0.5) / n_a
            out.append((r * math.cos(a), r * math.sin(a)))
    return out


@pytest.mark.parametrize("sat", [False, True])
@pytest.mark.parametrize("name", NAMES)
def test_map_positive_definite_to_50_i_max(name: str, sat: bool) -> None:
    """The least eigenvalue of the incremental inductance matrix is positive on a polar
    grid to 50 i_max (the polynomial alone turns singular past 3 i_max (wen2023) and 4 i_max
    (xue2022), as their presets say), and with both currents past 10 i_max the matrix is diag(L_dd,sat, L_q)."""
    m = preset(name).motor
    worst = math.inf
    for i_d, i_q in polar(50.0 * m.i_max):
        _, _, L_dd, L_dq, L_qq = flux_dq(m, i_d, i_q, sat, True)
        assert L_dq == flux_dq(m, i_d, i_q, sat, True)[3]
        worst = min(worst, least_eig(L_dd, L_dq, L_qq) / m.L_d)
        if min(abs(i_d), abs(i_q)) > 10.0 * m.i_max:
            assert L_dd == pytest.approx(l_sat(name, i_d, sat), rel=1e-9)
            assert L_qq == pytest.approx(m.L_q, rel=1e-9)
            assert abs(L_dq) < 1e-9 * m.L_d
    assert worst > 0.1
    # the polynomial itself is not: the continuation is what keeps it positive
    i = 6.0 * m.i_max
    c, i_0 = m.cross.c_dq, m.psi_f / m.L_d
    poly = least_eig(
        l_sat(name, i, sat) - 0.5 * c * i * i,
        -c * (i + i_0) * i,
        m.L_q - 0.5 * c * (i * i + 2 * i_0 * i),
    )
    assert poly < 0.0


@pytest.mark.parametrize("name", NAMES)
def test_same_map_inside_the_range_and_the_oracle_everywhere(name: str) -> None:
    """Inside |i_d|, |i_q| <= 2 i_max the map is the polynomial (the closed form to 1e-13,
    the reference model's operations bit for bit); beyond it the core and the reference
    model's continuation agree bit for bit too."""
    m = preset(name).motor
    a = FLUX_RANGE * m.i_max
    c, i_0 = m.cross.c_dq, m.psi_f / m.L_d
    n = 0
    for i_d, i_q in polar(50.0 * m.i_max, 60, 72):
        got = flux_dq(m, i_d, i_q, True, True)
        assert got == ref_flux_dq(m, i_d, i_q, True, True)
        if max(abs(i_d), abs(i_q)) <= a:
            n += 1
            want = (
                l_sat(name, i_d, True) - 0.5 * c * i_q * i_q,
                -c * (i_d + i_0) * i_q,
                m.L_q - 0.5 * c * (i_d * i_d + 2.0 * i_0 * i_d),
            )
            assert got[2:] == pytest.approx(want, rel=1e-13, abs=1e-13 * m.L_d)
    assert n > 1000


@pytest.mark.parametrize(
    ("u_d", "u_q"), [(1.0, 0.3), (-1.0, 0.5), (0.2, 1.0), (-0.7, -1.0), (1.0, 1.0), (-1.0, -1.0)]
)
@pytest.mark.parametrize("name", NAMES)
def test_continuous_across_the_edge_and_one_co_energy_beyond(
    name: str, u_d: float, u_q: float
) -> None:
    """At the edge (one current at +-a) flux and matrix are continuous (a jump of the
    matrix would show as a difference of order c a^2 over a step of 1e-9 a); beyond the
    edge the matrix is the flux's Jacobian (central differences, 1e-6) and symmetric."""
    m = preset(name).motor
    a = FLUX_RANGE * m.i_max
    at = (u_d * a, u_q * a)
    for axis in (0, 1):
        if abs(at[axis]) != a:
            continue
        eps = 1e-9 * a
        lo = list(at)
        hi = list(at)
        lo[axis] -= math.copysign(eps, at[axis])
        hi[axis] += math.copysign(eps, at[axis])
        f_lo = flux_dq(m, lo[0], lo[1], True, True)
        f_hi = flux_dq(m, hi[0], hi[1], True, True)
        for x, y in zip(f_lo[2:], f_hi[2:], strict=True):
            assert abs(x - y) < 1e-7 * m.L_d
        for x, y in zip(f_lo[:2], f_hi[:2], strict=True):
            assert abs(x - y) < 1e-8 * m.psi_f
    # beyond: the Jacobian of the flux, symmetric (one co-energy)
    for k in (1.13, 1.37, 2.3, 5.3):  # no current exactly at an edge
        i_d, i_q = k * at[0], k * at[1]
        _, _, L_dd, L_dq, L_qq = flux_dq(m, i_d, i_q, True, True)
        h = 1e-4 * a

        def psi(x: float, y: float) -> tuple[float, float]:
            f = flux_dq(m, x, y, True, True)
            return f[0], f[1]

        dd = (psi(i_d + h, i_q)[0] - psi(i_d - h, i_q)[0]) / (2 * h)
        dq = (psi(i_d, i_q + h)[0] - psi(i_d, i_q - h)[0]) / (2 * h)
        qd = (psi(i_d + h, i_q)[1] - psi(i_d - h, i_q)[1]) / (2 * h)
        qq = (psi(i_d, i_q + h)[1] - psi(i_d, i_q - h)[1]) / (2 * h)
        tol = 1e-6 * m.L_q
        assert (dd, dq, qd, qq) == pytest.approx((L_dd, L_dq, L_dq, L_qq), abs=tol)
    assert FLUX_FADE == 0.25


def test_plant_counts_the_periods_outside_the_range_and_stays_finite() -> None:
    """A locked xue2022 rotor (cross-saturated map) under full voltage: the current runs to
    u / R, about 50 times the range, the states stay finite, and the count is the number
    of periods whose end state lies beyond 2 i_max (read from the truth each period),
    on every flux map."""
    pre = preset("xue2022")
    inv = InverterPars(u_dc=pre.inverter.u_dc)
    for cross in (True, False):
        p = Plant(pre.motor, inv, pre.T_s, saturation=True, cross_saturation=cross)
        p.impose_speed(0.0)
        r = FLUX_RANGE * pre.motor.i_max
        want = 0
        peak = 0.0
        for k in range(200):
            p.step(1.0, 0.0, 0.0) if k < 150 else p.step(0.5, 0.5, 0.5)
            tr = p.truth()
            i = math.hypot(tr.i_d, tr.i_q)
            assert math.isfinite(i)
            peak = max(peak, i)
            want += i > r
        assert peak > 40.0 * pre.motor.i_max
        assert p.out_of_range_periods == want
        assert 100 < want < 300  # and the current came back inside


@pytest.mark.parametrize("cross", [False, True])
def test_a_free_rotor_at_tens_of_i_max_stays_finite(cross: bool) -> None:
    """Full voltage on phase b, 120 deg from the rotor's d axis, the rotor free: the
    torque swings the rotor into line while the current runs to u / R (about 95 i_max).
    The electromechanical mode's frequency grows with the current (plant_rk4.h): without
    the step cut by it, RK4 diverged within 50 periods (4,000 A, then NaN); with it the
    current stays below its DC value (2/3) u_dc / R_s and, on the d-axis model, the rotor
    settles on the current's axis."""
    pre = preset("xue2022")
    m = pre.motor
    p = Plant(
        m, InverterPars(u_dc=pre.inverter.u_dc), pre.T_s, saturation=True, cross_saturation=cross
    )
    peak = 0.0
    for _ in range(400):
        p.step(0.0, 1.0, 0.0)
        tr = p.truth()
        peak = max(peak, math.hypot(tr.i_d, tr.i_q))
        assert math.isfinite(peak) and math.isfinite(tr.w_m)
    i_dc = (2.0 / 3.0) * pre.inverter.u_dc / m.R_s
    assert peak < 1.01 * i_dc
    if not cross:  # settled 0.4 s after the step (with cross the rotor still swings)
        assert math.hypot(tr.i_d, tr.i_q) == pytest.approx(i_dc, rel=1e-3)
        assert abs(tr.w_m) < 0.1
    assert p.out_of_range_periods > 300


def test_a_run_beyond_the_range_is_a_result_with_its_own_exit_status() -> None:
    """``plant_out_of_range_s`` above 0: a warning line naming the time and exit status 7;
    a lost angle (its cause) and a trip win over it; 0 or None (no plant report) is 0."""
    ok = {"plant_fault": "none", "lock_lost": False, "plant_out_of_range_s": 0.0}
    assert outcome(ok, 1e-3) == (0, [])
    assert outcome({**ok, "plant_out_of_range_s": None}, 1e-3) == (0, [])
    out = {**ok, "plant_out_of_range_s": 3.21}
    status, lines = outcome(out, 1e-3)
    assert status == EXIT_MODEL_RANGE == 7
    assert len(lines) == 1 and "3.2100 s" in lines[0] and "2 i_max" in lines[0]
    status, lines = outcome({**out, "lock_lost": True, "lock_lost_at_s": 1.0}, 1e-3)
    assert status == EXIT_LOCK_LOST and len(lines) == 2
    tripped = {**out, "plant_fault": "over_current", "plant_fault_step": 5}
    assert outcome(tripped, 1e-3)[0] == EXIT_PLANT_TRIPPED


@pytest.mark.parametrize("cross", [False, True])
def test_the_reference_model_follows_the_core_beyond_the_range(cross: bool) -> None:
    """The reference model (tests/plant_reference.py) continues the map and cuts the RK4
    step as the core does: the free-rotor run above, the same states on both to 1e-9
    relative over 100 periods (the C and Python square roots may differ in the last bit)."""
    pre = preset("xue2022")
    inv = InverterPars(u_dc=pre.inverter.u_dc)
    a = Plant(pre.motor, inv, pre.T_s, saturation=True, cross_saturation=cross)
    b = ReferencePlant(pre.motor, inv, pre.T_s, saturation=True, cross_saturation=cross)
    for _ in range(100):
        a.step(0.0, 1.0, 0.0)
        b.step(0.0, 1.0, 0.0)
        ta, tb = a.truth(), b.truth()
        for x, y in ((ta.i_d, tb.i_d), (ta.i_q, tb.i_q), (ta.w_m, tb.w_m)):
            assert x == pytest.approx(y, rel=1e-9, abs=1e-9)
    assert math.hypot(ta.i_d, ta.i_q) > 40.0 * pre.motor.i_max


def test_the_plant_node_reports_the_count() -> None:
    """The plant node's report (read by the run's metrics) carries the plant's count."""
    from bench.nodes._loops import make_plant_node
    from bench.scenarios._schema import load_scenario
    from bench.wire._codec import Codec

    pn = make_plant_node(load_scenario("xue-fig13"), Codec())
    assert pn.report()["out_of_range_periods"] == 0
    for _ in range(30):
        pn.plant.step(0.0, 1.0, 0.0)
    n = pn.plant.out_of_range_periods
    assert n > 20 and pn.report()["out_of_range_periods"] == n


def _rotating(p: Plant, n: int, w_e: float, amp: float) -> list[tuple[float, float, float]]:
    """Duties of a stator voltage of amplitude ``amp`` (V) turning at ``w_e`` (rad/s) from
    the rotor's angle, 5 % amplitude modulated: a motor fed as its back-EMF, so that its
    currents stay well inside the range."""
    u_dc = p.inverter.u_dc
    th = p.truth().theta_m * p.motor.n_p
    out = []
    for k in range(n):
        t = th + w_e * p.T_s * (k + 0.5)
        a = amp * (1.0 + 0.05 * math.sin(2e-3 * k))
        u_a, u_b = -a * math.sin(t), a * math.cos(t)
        out.append(
            (
                0.5 + u_a / u_dc,
                0.5 + (-0.5 * u_a + 0.866 * u_b) / u_dc,
                0.5 + (-0.5 * u_a - 0.866 * u_b) / u_dc,
            )
        )
    return out


def _trace(name: str, plant: str, beyond: bool, n: int = 100_000) -> tuple[Plant, bytes]:
    """The plant of ``name`` on ``plant`` stepped ``n`` periods (``Plant.step_n``): inside
    the range, half at an imposed speed (30 % of the link's voltage as back-EMF) and half
    from standstill with the rotor free, dragged by a 5 Hz field at i_max / 2; beyond it,
    full voltage on phase b for 300 periods (tens of i_max), then the legs at half duty."""
    p = build_plant(plant_variant(load_scenario(name), plant))
    m = p.motor
    if beyond:
        return p, p.step_n([(0.0, 1.0, 0.0)] * 300 + [(0.5, 0.5, 0.5)] * (n - 300)).tobytes()
    w_e = 0.3 * (p.inverter.u_dc / math.sqrt(3.0)) / m.psi_f
    p.impose_speed(w_e / m.n_p)
    out = p.step_n(_rotating(p, n // 2, w_e, 1.02 * w_e * m.psi_f))
    p.impose_speed(0.0)
    p.impose_speed(None)
    w_2 = 2.0 * math.pi * 5.0 * m.n_p
    out += p.step_n(_rotating(p, n - n // 2, w_2, 0.5 * m.i_max * math.hypot(m.R_s, w_2 * m.L_d)))
    return p, out.tobytes()


# sha256 of the 100,000 periods' outputs (i_d, i_q, w_m, theta_m, u_dc, u_alpha, u_beta as
# doubles) and the periods beyond the range, recorded with the core whose cross map tests
# each RK4 stage's currents against the range (plant_flux_cross) and whose switching model
# sorted its times with qsort: a change made for speed must keep them.
TRACES = {
    ("wen-5.1", "ideal", False): (
        "ce795af8d5420e68bfcd8256ec69e2d59720c89686bdbd071d943bdbf9b8d0c7",
        0,
    ),
    ("wen-5.1", "drive", False): (
        "a3c62847c0a01b90cacba40445d75779d1bd3244cbc83e2ecea7e4865e2130a6",
        0,
    ),
    ("xue-fig13", "ideal", False): (
        "5f0bf0a5d335c9c2f12ae16109423c24b31c79e3ac897b906d053ce54e926024",
        0,
    ),
    ("xue-fig13", "drive", False): (
        "8eef8a7b1a9c831a683c96cea1bf663e2a2ed841d669636d32cbf2663b098d0f",
        0,
    ),
    ("wen-5.1", "drive", True): (
        "4b1657cefac1ccb041778ee0f4103c661fea09ffadb4e5d355ebb8e5177f27e2",
        678,
    ),
    ("xue-fig13", "drive", True): (
        "63cae8e6577e8a50a98ebd1f377dfb5fe0e06fb8eea3a356526bdd2f5fa2f18c",
        423,
    ),
}


@pytest.mark.parametrize(("name", "plant", "beyond"), list(TRACES))
def test_same_bits_as_the_recorded_core(name: str, plant: str, beyond: bool) -> None:
    """100,000 periods give the same outputs, bit for bit, as the core they were recorded
    with (the digests), inside the flux map's range and beyond it, so a change made for
    speed (the stage's range test, the order of the switching times) changes no bit. The
    drive plant is the cross-saturated one; the ideal plant (d-axis map) guards the other
    path. The digests hold for the x86_64 glibc builds they were recorded on (another libm
    may round cos, sin or exp differently); the count of periods beyond the range holds
    everywhere."""
    digest, periods = TRACES[(name, plant, beyond)]
    p, out = _trace(name, plant, beyond)
    assert p.out_of_range_periods == periods
    assert (periods > 0) == beyond
    if platform.system() != "Linux" or platform.machine() != "x86_64":
        pytest.skip("the digests were recorded on x86_64 Linux (glibc's libm)")
    assert hashlib.sha256(out).hexdigest() == digest
