"""The shipped estimators' per-period methods, in Python: the oracle the core's kinds are
checked against (``controller/core/cc_<estimator>.c``, tolerance 0,
:data:`tests.oracle.TOLERANCE`).

Each class subclasses its design in ``controller/`` (gains, filters, observer, the
``__init__`` that computes them, ``reset``) and adds the period's ``update``,
``injection`` and ``hf_current_next`` the core runs in C; built by the design's own
constructor, it turns every block it holds into the block's oracle
(:func:`tests.oracle.blocks.oracle`). :func:`oracle_estimator` does the same to an
estimator already built (by the registry, by :class:`controller.Controller`).
"""

from __future__ import annotations

import math
from typing import Any

from controller._api import Estimator, EstimatorInput
from controller._epf import EPFEstimator
from controller._filters import bandpass_coefficients
from controller._hybrid import HybridEstimator
from controller._params import MotorModel
from controller._pll import PositionObserver
from controller._registry import make_estimator
from controller._rotating import RotatingHFEstimator
from controller._self_demod import SelfDemodEstimator
from controller._sensored import SensoredEstimator
from controller._sfhf import SFHFEstimator
from controller._square_wave import SquareWaveEstimator
from controller._tt_ab import TTABEstimator
from controller._tt_dq import TTDQEstimator
from tests.oracle.blocks import (
    ORACLES,
    OracleBiquad2,
    OracleFirstOrder,
    OracleFirstOrder2,
    OracleLuenbergerObserver,
    oracle,
    oracle_of,
)

_TWO_PI = 2.0 * math.pi


class _Oracle:
    """Built by the design's constructor, then every block it holds made an oracle."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        oracle(self)


class _OracleRotating(RotatingHFEstimator):
    """The rotating-injection estimators' common per-period part
    (``controller/core/cc_rotating.c``)."""

    pll: PositionObserver | OracleLuenbergerObserver

    def update(self, x: EstimatorInput) -> None:  # pragma: no cover - each demodulator's
        """Take sample ``k`` and advance the estimate."""
        raise NotImplementedError

    def _publish(
        self, th: float, f: float, err: float, i_af: float, i_bf: float, torque: float
    ) -> None:
        """End of every demodulator's update: outputs of sample ``k``, then the observer step
        (``torque``: the controller's torque, N m, the mechanical observer's feed-forward)."""
        self.i_alpha_f = i_af
        self.i_beta_f = i_bf
        self.theta_hat = th
        self.f = f
        self.err = err
        pll = self.pll
        if isinstance(pll, PositionObserver):
            pll.update(err, self.accel)
            self.w_hat = pll.w_hat
        else:
            # the rate this step gives the angle, as the PLL's ``w_hat``: the
            # speed state before the step plus the proportional correction
            w = pll.w_hat
            pll.step(err, torque)
            self.w_hat = w + self._l3 * err

    def hf_current_next(self) -> tuple[float, float]:
        """Model HF current (alpha, beta) (A) at the mid-point of period ``k + 1``.

        Eq. (4)/(7) in alpha-beta at ``t = (k + 1.5) T_s`` with the model
        amplitudes and ``theta_hat``: what the dead-time compensation needs to
        know the sign of each phase current in the period its duties act in
        (:mod:`controller._compensation`).
        """
        ph = (self._k + 1.5) * self.wT
        ng = 2.0 * self.pll.theta_hat - ph
        # I_p e^{j(ph - pi/2)} + I_n e^{j(ng + pi/2)}
        return (
            self.I_p * math.sin(ph) - self.I_n * math.sin(ng),
            -self.I_p * math.cos(ph) + self.I_n * math.cos(ng),
        )

    def injection(self) -> tuple[float, float]:
        """HF voltage (V) for period ``k + 1``: eq. (3) at ``t = (k + 1.5) T_s``."""
        ph = (self._k + 1.5) * self.wT
        return self.V_h * math.cos(ph), self.V_h * math.sin(ph)


@oracle_of(TTDQEstimator)
class OracleTTDQEstimator(_Oracle, TTDQEstimator, _OracleRotating):
    """:class:`controller._tt_dq.TTDQEstimator`'s period (Wen eqs. 31-34; ``controller/core/cc_tt_dq.c``)."""

    _bpf: OracleBiquad2
    _lpf: OracleFirstOrder
    _lpf2: OracleFirstOrder2

    def update(self, x: EstimatorInput) -> None:
        """Demodulate sample ``k`` (eqs. 31-34) and advance the observer."""
        self._k = x.k
        th = self.pll.theta_hat
        c = math.cos(th)
        s = math.sin(th)
        i_a = x.i_alpha
        i_b = x.i_beta
        i_d = c * i_a + s * i_b
        i_q = c * i_b - s * i_a
        bpf = self._bpf
        if self.bpf_tracking:
            pll = self.pll
            w_t = pll.w_i if isinstance(pll, PositionObserver) else pll.w_hat
            w_0 = self.w_h - w_t
            if w_0 < 0.0:
                w_0 = -w_0
            if w_0 < self._w0_min:
                w_0 = self._w0_min
            b0, bpf.a1, bpf.a2 = bandpass_coefficients(w_0, self.bpf_B, self.T_s)
            bpf.b0 = b0
            bpf.b2 = -b0
        i_dh, i_qh = bpf.update(i_d, i_q)
        if self.measured:
            # quadrature: LPF((i_dh^2 - i_qh^2)/2) = I_p I_n cos(2 dtheta)
            f, g = self._lpf2.update(i_dh * i_qh, 0.5 * (i_dh * i_dh - i_qh * i_qh))
            err = f / (2.0 * max(math.hypot(f, g), self._floor))
        else:
            f = self._lpf.update(i_dh * i_qh)
            err = f * self._inv_norm
        i_df = i_d - i_dh
        i_qf = i_q - i_qh
        if self.accel_ff:
            self.accel = x.accel_ref
        self._publish(th, f, err, c * i_df - s * i_qf, s * i_df + c * i_qf, x.torque)


@oracle_of(TTABEstimator)
class OracleTTABEstimator(_Oracle, TTABEstimator, _OracleRotating):
    """:class:`controller._tt_ab.TTABEstimator`'s period (Wen eqs. 23-28; ``controller/core/cc_tt_ab.c``)."""

    _bpf: OracleBiquad2
    _lpf: OracleFirstOrder2

    def update(self, x: EstimatorInput) -> None:
        """Demodulate sample ``k`` (eqs. 25-28) and advance the observer."""
        self._k = x.k
        th = self.pll.theta_hat
        i_a = x.i_alpha
        i_b = x.i_beta
        i_ah, i_bh = self._bpf.update(i_a, i_b)
        s_2, c_2 = self._lpf.update(i_ah * i_bh, 0.5 * (i_ah * i_ah - i_bh * i_bh))
        f = s_2 * math.cos(2.0 * th) - c_2 * math.sin(2.0 * th)
        if self.measured:
            err = f / (2.0 * max(math.hypot(s_2, c_2), self._floor))
        else:
            err = f * self._inv_norm
        self._publish(th, f, err, i_a - i_ah, i_b - i_bh, x.torque)


@oracle_of(SFHFEstimator)
class OracleSFHFEstimator(_Oracle, SFHFEstimator, _OracleRotating):
    """:class:`controller._sfhf.SFHFEstimator`'s period (Wen Fig. 3, eq. 9; ``controller/core/cc_sfhf.c``)."""

    _bpf: OracleBiquad2
    _hpf: OracleFirstOrder2
    _lpf: OracleFirstOrder
    _lpf2: OracleFirstOrder2

    def update(self, x: EstimatorInput) -> None:
        """Demodulate sample ``k`` (Fig. 3, eq. 9) and advance the observer."""
        self._k = x.k
        th = self.pll.theta_hat
        ph = (x.k * self.wT) % (2.0 * math.pi)
        c_h = math.cos(ph)
        s_h = math.sin(ph)
        i_a = x.i_alpha
        i_b = x.i_beta
        i_ah, i_bh = self._bpf.update(i_a, i_b)
        x_p, y_p = self._hpf.update(c_h * i_ah + s_h * i_bh, c_h * i_bh - s_h * i_ah)
        i_an = c_h * x_p - s_h * y_p
        i_bn = s_h * x_p + c_h * y_p
        ref = 2.0 * th - ph
        c_r = math.cos(ref)
        s_r = math.sin(ref)
        if self.measured:
            # quadrature: Re{...} = i_bn cos(ref) - i_an sin(ref) = I_n cos(2 dtheta)
            f, g = self._lpf2.update(-(i_an * c_r + i_bn * s_r), i_bn * c_r - i_an * s_r)
            err = f / (2.0 * max(math.hypot(f, g), self._floor))
        else:
            f = self._lpf.update(-(i_an * c_r + i_bn * s_r))
            err = f * self._inv_norm
        self._publish(th, f, err, i_a - i_ah, i_b - i_bh, x.torque)


@oracle_of(SelfDemodEstimator)
class OracleSelfDemodEstimator(_Oracle, SelfDemodEstimator, _OracleRotating):
    """:class:`controller._self_demod.SelfDemodEstimator`'s period ([27], reconstructed; ``controller/core/cc_self_demod.c``)."""

    _bpf: OracleBiquad2
    _quad: OracleBiquad2
    _lpf: OracleFirstOrder
    _lpf2: OracleFirstOrder2

    def update(self, x: EstimatorInput) -> None:
        """Separate, self-demodulate and heterodyne sample ``k``; advance the observer."""
        self._k = x.k
        th = self.pll.theta_hat
        i_a = x.i_alpha
        i_b = x.i_beta
        d_a, d_b = self._bpf.update(i_a, i_b)
        q_a, q_b = self._quad.update(i_a, i_b)
        # 2 i_p = d - j q = (d_a + q_b) + j (d_b - q_a), 2 i_n = d + j q
        p_r = d_a + q_b
        p_i = d_b - q_a
        n_r = d_a - q_b
        n_i = d_b + q_a
        # i_p i_n = I_p I_n exp(j(2 theta_e + phi_p + phi_n))
        m_r = 0.25 * (p_r * n_r - p_i * n_i)
        m_i = 0.25 * (p_r * n_i + p_i * n_r)
        c_2 = math.cos(2.0 * th)
        s_2 = math.sin(2.0 * th)
        if self.measured:
            # quadrature: Re{i_p i_n exp(-j 2 theta_hat)} = I_p I_n cos(2 dtheta + ...)
            f, g = self._lpf2.update(m_i * c_2 - m_r * s_2, m_r * c_2 + m_i * s_2)
            err = f / (2.0 * max(math.hypot(f, g), self._floor))
        else:
            f = self._lpf.update(m_i * c_2 - m_r * s_2)
            err = f * self._inv_norm
        self._publish(th, f, err, i_a - d_a, i_b - d_b, x.torque)


@oracle_of(EPFEstimator)
class OracleEPFEstimator(_Oracle, EPFEstimator, _OracleRotating):
    """:class:`controller._epf.EPFEstimator`'s period ([25], reconstructed; ``controller/core/cc_epf.c``)."""

    _bpf: OracleBiquad2
    _lpf_p: OracleFirstOrder2
    _lpf_n: OracleFirstOrder2
    _lpf_m: OracleFirstOrder2

    def update(self, x: EstimatorInput) -> None:
        """Demodulate sample ``k`` with the two demodulation signals; advance the observer."""
        self._k = x.k
        th = self.pll.theta_hat
        c = math.cos(th)
        s = math.sin(th)
        i_a = x.i_alpha
        i_b = x.i_beta
        i_d = c * i_a + s * i_b
        i_q = c * i_b - s * i_a
        i_dh, i_qh = self._bpf.update(i_d, i_q)
        psi = (x.k * self.wT) % _TWO_PI - th
        c_p = math.cos(psi)
        s_p = math.sin(psi)
        dc = i_dh * c_p
        qs = i_qh * s_p
        qc = i_qh * c_p
        ds = i_dh * s_p
        # i_dqh exp(-j psi) -> positive sequence, i_dqh exp(+j psi) -> negative sequence
        p_r, p_i = self._lpf_p.update(dc + qs, qc - ds)
        n_r, n_i = self._lpf_n.update(dc - qs, qc + ds)
        # P_p P_n = I_p I_n exp(j 2 dtheta)
        f = p_r * n_i + p_i * n_r
        if self.measured:
            # the amplitude I_p I_n from the product and its quadrature, low-passed once
            # more: each LPF leaves a tenth of the other sequence at 2 w_h, which would
            # make the instantaneous hypot ripple; f itself stays as the loop is designed
            a_f, a_g = self._lpf_m.update(f, p_r * n_r - p_i * n_i)
            err = f / (2.0 * max(math.hypot(a_f, a_g), self._floor))
        else:
            err = f * self._inv_norm
        i_df = i_d - i_dh
        i_qf = i_q - i_qh
        self._publish(th, f, err, c * i_df - s * i_qf, s * i_df + c * i_qf, x.torque)


@oracle_of(SquareWaveEstimator)
class OracleSquareWaveEstimator(_Oracle, SquareWaveEstimator):
    """:class:`controller._square_wave.SquareWaveEstimator`'s period (Xue eqs. 3-12;
    ``controller/core/cc_square_wave.c``)."""

    observer: OracleLuenbergerObserver
    _interp: Any  # list[OracleCicInterpolator]

    def injection(self) -> tuple[float, float]:
        """HF voltage (alpha, beta) (V) for period ``k + 1``, along ``theta(k + 1.5)``."""
        return self._u_next

    def update(self, x: EstimatorInput) -> None:
        """Take sample ``k``: extract the envelope, interpolate, correct the observer."""
        i_a = x.i_alpha
        i_b = x.i_beta
        n = self._n
        fresh = False
        E_a = E_b = u_c = u_s = 0.0
        if n >= 1:
            # eq. (7): response to the voltage of period k-1
            h_a = 0.5 * (i_a - self._ia1)
            h_b = 0.5 * (i_b - self._ib1)
            if n >= 3 and self._sg1 < 0.0:
                # rate conversion R = 0.5: periods k-2 (+U_h) and k-1 (-U_h) give one
                # envelope sample, mid-point k-1; the fundamental's linear drift cancels
                E_a = 0.5 * (self._ha1 - h_a)
                E_b = 0.5 * (self._hb1 - h_b)
                u_c = 0.5 * (self._c1 + self._c2)
                u_s = 0.5 * (self._s1 + self._s2)
                fresh = True
            self._ha1 = h_a
            self._hb1 = h_b

        err = 0.0
        if fresh and self._env_n == 0:
            for f, v in zip(self._interp, (E_a, E_b, u_c, u_s), strict=True):
                f.prime(v)
        if fresh:
            self._env_n += 1
        if self._env_n:
            if self.cic:
                ip = self._interp
                if fresh:
                    e_a = ip[0].step(E_a)
                    e_b = ip[1].step(E_b)
                    v_c = ip[2].step(u_c)
                    v_s = ip[3].step(u_s)
                else:
                    e_a = ip[0].step(None)
                    e_b = ip[1].step(None)
                    v_c = ip[2].step(None)
                    v_s = ip[3].step(None)
            else:
                if fresh:
                    self._held = (E_a, E_b, u_c, u_s)
                e_a, e_b, v_c, v_s = self._held
            self.e_alpha = e_a
            self.e_beta = e_b
            # normalisation and quadrature PLL error against the injection direction
            den = math.sqrt((e_a * e_a + e_b * e_b) * (v_c * v_c + v_s * v_s))
            if den > 0.0:
                err = (e_b * v_c - e_a * v_s) / den * self._k_err
        self.err = err

        obs = self.observer
        obs.step(err, x.torque)
        th = obs.theta_hat
        w = obs.w_hat
        self.theta_hat = th
        self.w_hat = w

        # injection for period k+1 (eq. 3) along the angle of its mid-point k + 1.5
        sgn = -self._sg0 if self._sg0 != 0.0 else 1.0
        phi = th + self._t_comp * w
        c = math.cos(phi)
        s = math.sin(phi)
        uh = sgn * self.U_h
        self._u_next = (uh * c, uh * s)
        self._sg2 = self._sg1
        self._c2 = self._c1
        self._s2 = self._s1
        self._sg1 = self._sg0
        self._c1 = self._c0
        self._s1 = self._s0
        self._sg0 = sgn
        self._c0 = c
        self._s0 = s

        # fundamental current at k with the square-wave response removed, in the
        # estimated rotor frame (where the response alternates along a fixed axis)
        ct = math.cos(th)
        st = math.sin(th)
        i_d = ct * i_a + st * i_b
        i_q = ct * i_b - st * i_a
        if self._n_tot >= 2:
            i_df = 0.25 * (3.0 * i_d + 2.0 * self._id1 - self._id2)
            i_qf = 0.25 * (3.0 * i_q + 2.0 * self._iq1 - self._iq2)
        else:
            i_df = i_d
            i_qf = i_q
        self.i_alpha_f = ct * i_df - st * i_qf
        self.i_beta_f = st * i_df + ct * i_qf
        self._id2 = self._id1
        self._iq2 = self._iq1
        self._id1 = i_d
        self._iq1 = i_q
        self._ia1 = i_a
        self._ib1 = i_b
        self._n = n + 1
        self._n_tot += 1


@oracle_of(SensoredEstimator)
class OracleSensoredEstimator(_Oracle, SensoredEstimator):
    """:class:`controller._sensored.SensoredEstimator`'s period (``controller/core/cc_sensored.h``)."""

    def update(self, x: EstimatorInput) -> None:
        """Take sample ``k`` (angle and speed at ``k T_s``)."""
        if x.theta_e is None or x.w_e is None:
            raise ValueError("the sensored estimator needs Measurement.theta_e and w_e")
        self.theta_hat = x.theta_e
        self.w_hat = x.w_e
        self.i_alpha_f = x.i_alpha
        self.i_beta_f = x.i_beta

    def injection(self) -> tuple[float, float]:
        """No HF injection."""
        return 0.0, 0.0


@oracle_of(HybridEstimator)
class OracleHybridEstimator(_Oracle, HybridEstimator):
    """:class:`controller._hybrid.HybridEstimator`'s period (``controller/core/cc_hybrid.c``);
    its injection estimator is an oracle too (built by :func:`oracle`)."""

    def hf_current_next(self) -> tuple[float, float]:
        """The injection estimator's predicted HF current, scaled by the injection's fade."""
        predict = getattr(self.hf, "hf_current_next", None)
        if predict is None:
            return 0.0, 0.0
        h_a, h_b = predict()
        return self.gain * h_a, self.gain * h_b

    def injection(self) -> tuple[float, float]:
        """The injection estimator's HF voltage times ``g``; exactly zero above the band."""
        g = self.gain
        if g == 0.0:
            return 0.0, 0.0
        u_a, u_b = self.hf.injection()
        if g == 1.0:
            return u_a, u_b
        return g * u_a, g * u_b

    def update(self, x: EstimatorInput) -> None:
        """Both estimators take sample ``k``; blend; schedule the next period."""
        hf = self.hf
        obs = self.observer
        tr = self.tracker
        hf.update(x)
        lam = self.weight
        off = self.saliency_offset
        if lam == 0.0:
            w_s = tr.w_smooth
            th = (hf.theta_hat - off) % _TWO_PI if off else hf.theta_hat
            obs.update_slaved(x.i_alpha, x.i_beta, x.u_alpha, x.u_beta, th, w_s)
            w = hf.w_hat
            err = hf.err
        else:
            obs.update(x.i_alpha, x.i_beta, x.u_alpha, x.u_beta)
            w_o = obs.w_hat
            if lam == 1.0:
                th = obs.theta_hat
                w = w_o
                w_s = w_o
                err = obs.eps
                tr.sync(th + off, w_o, obs.accel, x.torque)
            else:
                th_h = hf.theta_hat - off
                d = (obs.theta_hat - th_h + math.pi) % _TWO_PI - math.pi
                th = (th_h + lam * d) % _TWO_PI
                w_h = hf.w_hat
                w = w_h + lam * (w_o - w_h)
                w_t = tr.w_smooth
                w_s = w_t + lam * (w_o - w_t)
                e_h = hf.err
                err = e_h + lam * (obs.eps - e_h)
        self.theta_hat = th
        self.w_hat = w
        self.err = err
        g = self.gain
        if g == 1.0:
            self.i_alpha_f = hf.i_alpha_f
            self.i_beta_f = hf.i_beta_f
        elif g == 0.0:
            self.i_alpha_f = x.i_alpha
            self.i_beta_f = x.i_beta
        else:
            self.i_alpha_f = x.i_alpha + g * (hf.i_alpha_f - x.i_alpha)
            self.i_beta_f = x.i_beta + g * (hf.i_beta_f - x.i_beta)
        # schedule: play operator on |w|, then the weight and the injection factor;
        # held below the band during the start-up at standstill (not running),
        # where the injection estimator's convergence transients are not a speed
        band = self.band
        y = band.play(self.y, w_s) if x.running else 0.0
        self.y = y
        self.weight, self.gain = band.weights(y)


def oracle_estimator(est: Any) -> Any:
    """``est``, a shipped estimator as built (by the registry, by a controller), turned into
    its oracle in place, with every block it holds (:func:`tests.oracle.blocks.oracle`)."""
    return oracle(est)


__all__ = [
    "ORACLES",
    "OracleEPFEstimator",
    "OracleHybridEstimator",
    "OracleSFHFEstimator",
    "OracleSelfDemodEstimator",
    "OracleSensoredEstimator",
    "OracleSquareWaveEstimator",
    "OracleTTABEstimator",
    "OracleTTDQEstimator",
    "make_oracle_estimator",
    "oracle_estimator",
]


def make_oracle_estimator(name: str, motor: MotorModel, T_s: float, **options: Any) -> Estimator:
    """:func:`controller.make_estimator`'s estimator, as its oracle (:func:`oracle_estimator`)."""
    est: Estimator = oracle(make_estimator(name, motor, T_s, **options))
    return est
