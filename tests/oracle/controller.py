"""The controller's per-period step in Python: the oracle the core is checked against.

:class:`OracleController` is a :class:`controller.Controller` (the same
design: gains, filters, thresholds, the estimator built by the registry) that
runs its periods in Python instead of the core: the step that was the
controller's ``"python"`` engine, operation for operation. The core
(``controller/core/``) repeats these operations in the same order, so the
oracle tests compare at tolerance 0 (:data:`tests.oracle.TOLERANCE`): every
output's bits.
"""

from __future__ import annotations

import math
from typing import Any

from controller import Controller, ControllerPars
from controller._api import (
    MODE_ALIGN,
    MODE_DISABLED,
    MODE_POLARITY,
    MODE_RUN,
    ControlOutput,
    EstimatorInput,
    Measurement,
)
from controller._controller import STATE_NAMES, hybrid_states
from controller._hybrid import HybridEstimator
from controller._square_wave import SquareWaveEstimator
from tests.oracle.blocks import (
    OracleDeadTimeCompensator,
    OracleFirstOrder,
    OracleOffsetCalibration,
    OracleReferenceModel,
    cross_saturation_offset,
    oracle,
    svpwm,
)
from tests.oracle.estimators import oracle_estimator

_TWO_PI = 2.0 * math.pi
_SQRT3_INV = 1.0 / math.sqrt(3.0)


def _plain(name: str) -> property:
    """A state kept in the instance (the controller's read the core's)."""

    def get(self: Controller) -> Any:
        return self.__dict__[name]

    def put(self: Controller, value: Any) -> None:
        self.__dict__[name] = value

    return property(get, put, doc=f"``{name}`` (the oracle's own)")


class OracleController(Controller):
    """A :class:`controller.Controller` whose periods run in Python (module docstring)."""

    engine = "oracle"
    # the design's blocks, made oracles by _attach_engine
    lpf_w: OracleFirstOrder
    dead_time: OracleDeadTimeCompensator | None
    calibration: OracleOffsetCalibration | None

    def __init__(self, pars: ControllerPars) -> None:
        super().__init__(pars)

    def _attach_engine(self) -> Any:
        """No core: the Python step below, with the supervision after it; the design's
        estimator and blocks made oracles (their steps added, :mod:`tests.oracle.blocks`)."""
        oracle_estimator(self.estimator)
        oracle(self.lpf_w)
        oracle((self.pi_d, self.pi_q, self.pi_w, self.polarity, self.supervisor))
        oracle(self.dead_time)
        oracle(self.calibration)
        self.oracle_ref_model = OracleReferenceModel.of(self.ref_model)
        self.mode = MODE_DISABLED
        self.w_m_ref = 0.0
        self.i_d_ref = 0.0
        self.i_q_ref = 0.0
        self.tau_ref = 0.0
        self.w_m_hat = 0.0
        #: Realised fundamental voltage of the last step, estimated frame (V).
        self.u_d = 0.0
        self.u_q = 0.0
        # stator-voltage commands (V, stationary): *_1 computed from the last
        # sample (acting now), *_2 from the one before (acted until this sample)
        self._u_a1 = self._u_b1 = self._u_a2 = self._u_b2 = 0.0
        self._n_mode = 0
        self._settled = False
        self._i_ref: tuple[float, float] | None = None
        self._theta_pol = 0.0
        sup = self.supervisor
        if sup is not None:
            self.__dict__["step"] = sup.wrap(self._step, lambda: self.set_enable(False))
        else:
            self.__dict__["step"] = self._step
        return None

    # -- commands ---------------------------------------------------------------
    def set_speed_ref(self, w_m_ref: float) -> None:
        self.w_m_ref = float(w_m_ref)

    def set_current_ref(self, i_dq_ref: tuple[float, float] | None) -> None:
        self._i_ref = None if i_dq_ref is None else (float(i_dq_ref[0]), float(i_dq_ref[1]))
        self.pi_w.reset()

    def set_enable(self, enable: bool) -> None:
        if enable and self.mode == MODE_DISABLED:
            self._restart()
        elif not enable:
            self.mode = MODE_DISABLED

    def states(self) -> dict[str, float]:
        est = self.estimator
        u_h = self.injection()
        out = {
            "mode": self.mode,
            "w_m_ref": self.w_m_ref,
            "w_m_hat": self.w_m_hat,
            "i_d_ref": self.i_d_ref,
            "i_q_ref": self.i_q_ref,
            "tau_ref": self.tau_ref,
            "u_d": self.u_d,
            "u_q": self.u_q,
            "pi_d_u_i": self.pi_d.u_i,
            "pi_q_u_i": self.pi_q.u_i,
            "pi_w_u_i": self.pi_w.u_i,
            "polarity_flip": int(self.polarity.flip),
            "theta_hat": est.theta_hat,
            "w_hat": est.w_hat,
            "err": est.err,
            "u_h_alpha": u_h[0],
            "u_h_beta": u_h[1],
        }
        assert tuple(out)[: len(STATE_NAMES)] == STATE_NAMES
        if isinstance(est, HybridEstimator):
            out.update(hybrid_states(est))
        return out

    def quadrature(self) -> tuple[float, float]:
        est: Any = self.estimator
        sqw = est.hf if isinstance(est, HybridEstimator) else est
        if not isinstance(sqw, SquareWaveEstimator):
            return 0.0, 0.0
        return float(sqw.e_alpha), float(sqw.e_beta)

    def injection(self) -> tuple[float, float]:
        u_a, u_b = self.estimator.injection()
        return float(u_a), float(u_b)

    def _restart(self) -> None:
        self.pi_d.reset()
        self.pi_q.reset()
        self.pi_w.reset()
        self.lpf_w.reset()
        self.oracle_ref_model.reset()
        self.estimator.reset(self.pars.theta0)
        self.i_d_ref = self.i_q_ref = self.tau_ref = 0.0
        self._u_a1 = self._u_b1 = self._u_a2 = self._u_b2 = 0.0
        self._n_mode = 0
        self._settled = False
        if self.calibration is not None:
            self.calibration.restart()
        if self.family == "none" or not self.pars.startup:
            self.mode = MODE_RUN
        else:
            self.mode = MODE_ALIGN

    # -- one PWM period -----------------------------------------------------------
    def _step(self, meas: Measurement) -> ControlOutput:
        """Compute the duties for period ``k + 1`` from the samples of period ``k``."""
        k = meas.k
        mode = self.mode
        est = self.estimator
        if mode == MODE_DISABLED:
            return ControlOutput(
                k, 0.5, 0.5, 0.5, False, est.theta_hat % _TWO_PI, est.w_hat, 0.0, mode
            )
        # Measure (amplitude-invariant Clarke), offsets removed when calibrated.
        i_a = meas.i_a
        i_b = meas.i_b
        i_c = meas.i_c
        cal = self.calibration
        if cal is not None:
            if not cal.done:
                cal.add(i_a, i_b, i_c)
                return ControlOutput(
                    k, 0.5, 0.5, 0.5, False, est.theta_hat % _TWO_PI, 0.0, 0.0, MODE_ALIGN
                )
            i_a -= cal.o_a
            i_b -= cal.o_b
            i_c -= cal.o_c
        i_alpha = (2.0 * i_a - i_b - i_c) / 3.0
        i_beta = (i_b - i_c) * _SQRT3_INV
        u_dc = meas.u_dc
        m = self.motor
        if mode == MODE_POLARITY:
            return self._polarity_step(k, i_alpha, i_beta, u_dc)
        if self._sal_own:
            # the hybrid corrects its injection estimate only (controller._hybrid)
            est.saliency_offset = cross_saturation_offset(  # type: ignore[attr-defined]
                m.k_dq, self.i_q_ref, m.L_d, m.L_q
            )
        speed_loop = mode == MODE_RUN and self._i_ref is None
        est.update(
            EstimatorInput(
                k,
                i_alpha,
                i_beta,
                self.tau_ref,
                meas.theta_e,
                meas.w_e,
                self._u_a2,
                self._u_b2,
                mode == MODE_RUN,
                self.oracle_ref_model.update(self.w_m_ref) if speed_loop else 0.0,
            )
        )
        th = est.theta_hat
        if self.cross_sat and not self._sal_own:
            th -= cross_saturation_offset(m.k_dq, self.i_q_ref, m.L_d, m.L_q)
        w = est.w_hat
        c = math.cos(th)
        s = math.sin(th)
        i_af = est.i_alpha_f
        i_bf = est.i_beta_f
        i_d = c * i_af + s * i_bf
        i_q = c * i_bf - s * i_af
        if self.raw_feedback:
            i_d_pi = c * i_alpha + s * i_beta
            i_q_pi = c * i_beta - s * i_alpha
        else:
            i_d_pi = i_d
            i_q_pi = i_q
        # Compute output: speed loop.
        w_m = self.lpf_w.update(w / m.n_p)
        self.w_m_hat = w_m
        i_ref = self._i_ref
        if mode == MODE_RUN and i_ref is not None:
            i_d_ref, i_q_ref = i_ref
            tau = self.k_tau * i_q_ref
        elif mode == MODE_RUN:
            tau_u = self.pi_w.output(self.w_m_ref, w_m)
            tau_max = self.tau_max
            tau = tau_max if tau_u > tau_max else (-tau_max if tau_u < -tau_max else tau_u)
            i_d_ref = 0.0
            i_q_ref = tau / self.k_tau
            i_q_max = math.sqrt(max(self.i_max * self.i_max - i_d_ref * i_d_ref, 0.0))
            if i_q_ref > i_q_max:
                i_q_ref = i_q_max
            elif i_q_ref < -i_q_max:
                i_q_ref = -i_q_max
            tau = self.k_tau * i_q_ref
        else:
            i_d_ref = i_q_ref = tau = 0.0
        # Current loop with decoupling (estimated speed, filtered).
        w_e = m.n_p * w_m
        u_d = self.pi_d.output(i_d_ref, i_d_pi, -w_e * m.L_q * i_q)
        u_q = self.pi_q.output(i_q_ref, i_q_pi, w_e * (m.L_d * i_d + m.psi_f))
        u_ah, u_bh = est.injection()
        u_lim = u_dc * _SQRT3_INV - math.sqrt(u_ah * u_ah + u_bh * u_bh)
        mag2 = u_d * u_d + u_q * u_q
        if mag2 > u_lim * u_lim:
            r = u_lim / math.sqrt(mag2)
            u_dl = u_d * r
            u_ql = u_q * r
        else:
            u_dl = u_d
            u_ql = u_q
        # Inverse Park at the mid-point of period k + 1, then the HF voltage.
        th_u = th + self.t_delay * w
        c_u = math.cos(th_u)
        s_u = math.sin(th_u)
        u_a = c_u * u_dl - s_u * u_ql + u_ah
        u_b = s_u * u_dl + c_u * u_ql + u_bh
        d_a, d_b, d_c = svpwm(u_a, u_b, u_dc)
        # the voltage commanded for period k + 1 (the dead-time feed-forward below
        # makes the inverter give it), which a model-based estimator integrates
        self._u_a2 = self._u_a1
        self._u_b2 = self._u_b1
        self._u_a1 = u_a
        self._u_b1 = u_b
        dt = self.dead_time
        if dt is not None:
            # phase currents expected at the mid-point of period k + 1: the reference,
            # plus the injection's HF current where the estimator predicts it
            i_ar = c_u * i_d_ref - s_u * i_q_ref
            i_br = s_u * i_d_ref + c_u * i_q_ref
            if self._predicts_hf:
                h_a, h_b = est.hf_current_next()  # type: ignore[attr-defined]
                i_ar += h_a
                i_br += h_b
            h = 0.5 * math.sqrt(3.0) * i_br
            d_a, d_b, d_c = dt.duties(d_a, d_b, d_c, i_ar, -0.5 * i_ar + h, -0.5 * i_ar - h, u_dc)
        # The speed reported is the filtered estimate the speed loop uses, not
        # the observer's raw output (which carries the demodulation ripple).
        out = ControlOutput(
            k, d_a, d_b, d_c, True, th % _TWO_PI, w_m * m.n_p, est.err, mode, i_d, i_q
        )
        # Update states with the realised outputs.
        self.pi_d.update(u_dl)
        self.pi_q.update(u_ql)
        self.u_d = u_dl
        self.u_q = u_ql
        if mode == MODE_RUN and i_ref is None:
            self.pi_w.update(tau)
        self.i_d_ref = i_d_ref
        self.i_q_ref = i_q_ref
        self.tau_ref = tau
        self._advance_mode(i_alpha, i_beta, u_dc)
        return out

    def _advance_mode(self, i_alpha: float, i_beta: float, u_dc: float) -> None:
        if self.mode != MODE_ALIGN:
            return
        self._n_mode += 1
        if not self._settled and self._n_mode >= self.n_align:
            th = self.estimator.theta_hat
            i_d0 = math.cos(th) * i_alpha + math.sin(th) * i_beta
            self.polarity.start(u_dc, i_d0)
            self._theta_pol = th
            self.mode = MODE_POLARITY
            self._n_mode = 0
        elif self._settled and self._n_mode >= self.n_settle:
            self.pi_w.reset()
            self.mode = MODE_RUN
            self._n_mode = 0

    def _polarity_step(self, k: int, i_alpha: float, i_beta: float, u_dc: float) -> ControlOutput:
        th = self._theta_pol
        c = math.cos(th)
        s = math.sin(th)
        i_d = c * i_alpha + s * i_beta
        i_q = c * i_beta - s * i_alpha
        pt = self.polarity
        u_d = pt.step(i_d)
        if pt.done:
            th_new = (th + math.pi) % _TWO_PI if pt.flip else th
            self.estimator.reset(th_new)
            self.pi_d.reset()
            self.pi_q.reset()
            self.mode = MODE_ALIGN
            self._settled = True
            self._n_mode = 0
        u_a = c * u_d
        u_b = s * u_d
        d_a, d_b, d_c = svpwm(u_a, u_b, u_dc)
        dt = self.dead_time
        if dt is not None:
            # the pulses get the same feed-forward as every other voltage: uncompensated,
            # the bridge's drops oppose the rise and aid the return of each pulse, which
            # leaves a current offset of the order of the saturation asymmetry the test
            # measures; the sign is the present pulse current's, along the pulse axis
            i_a = c * i_d
            h = 0.5 * math.sqrt(3.0) * s * i_d
            d_a, d_b, d_c = dt.duties(d_a, d_b, d_c, i_a, -0.5 * i_a + h, -0.5 * i_a - h, u_dc)
        self._u_a2 = self._u_a1
        self._u_b2 = self._u_b1
        self._u_a1 = u_a
        self._u_b1 = u_b
        return ControlOutput(k, d_a, d_b, d_c, True, th, 0.0, 0.0, MODE_POLARITY, i_d, i_q)


for _name in STATE_NAMES[:8]:
    setattr(OracleController, _name, _plain(_name))
