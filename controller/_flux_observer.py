"""Reduced-order flux observer for medium and high speed (Hinkkanen et al. 2018).

The observer of Hinkkanen, Saarakkala, Awan, Mölsä and Tuovinen, "Observers
for sensorless synchronous motor drives: framework for design and analysis",
IEEE Trans. Ind. Appl. 54(6), 2018 (doi:10.1109/TIA.2018.2858753), in the form
motulator implements (``motulator.drive.control.sm.Observer``), written here
for one PWM period at a time.

Model (estimated rotor coordinates, complex ``x = x_d + j x_q``)::

    psi_m(i)  = psi_f + L_d i_d + j L_q i_q              current model
    e         = psi_m(i) - psi_hat                       flux error signal
    psi_a     = psi_f + (L_d - L_q) conj(i)              auxiliary (active) flux
    d psi_hat / dt = u - R_s i - j w_s psi_hat + k_1 e + k_2 conj(e)
    eps       = -Im(e / psi_a)                           angle error signal
    w_s       = w_i + k_p eps,  d w_i / dt = k_i eps,  d theta_hat / dt = w_s

Why ``eps`` is the angle error. With ``theta~ = theta - theta_hat`` and the
true flux ``psi`` seen in the estimated frame,
``psi_m(i) - psi = -j theta~ psi_a`` to first order, so
``e = -j theta~ psi_a + psi~`` (``psi~ = psi - psi_hat``) and
``eps = theta~ - Im(psi~ / psi_a)``.

Gains. ``k_2 = k_1 psi_a / conj(psi_a)`` (the decoupling choice of the paper)
makes the correction ``2 k_1 psi_a Re(e / psi_a)``, which does not contain
``theta~``: the flux error obeys on its own::

    d psi~ / dt = -j w psi~ - 2 k_1 psi_a Re(psi~ / psi_a)

With ``psi~ = psi_a (x + j y)`` this is ``x' = w y - 2 k_1 x``,
``y' = -w x``: characteristic polynomial ``s^2 + 2 k_1 s + w^2``. The angle
loop is the phase-locked loop ``s^2 + k_p s + k_i`` driven by ``y``. Both
blocks are placed from stated targets:

- ``k_1 = zeta_f max(|w_hat|, w_min)``: the flux-error poles have the
  damping ``zeta_f`` at every speed above ``w_min`` (Hinkkanen et al. and
  motulator keep a term ``~ 0.2 |w|`` for the same reason), and below it
  the error decays at the rate ``zeta_f w_min``. The damping is what the
  closed loop needs: the flux-error poles sit at ``+/- j w`` in the
  estimated frame (the electrical frequency), and the synchronous-frame
  current loop at a low pulse ratio is itself poorly damped (xue2022 at
  1 kHz and 1200 rpm, 12.5 samples per electrical period, rings for more
  than 0.1 s after a 10-degree angle kick even with the true angle). With
  a constant ``k_1`` of 6 or 20 rad/s (damping ``k_1 / |w|`` of 0.01 to
  0.04 there) the closed loop at rated load fell into a voltage-saturated
  limit cycle with an angle ripple of up to 10 degrees at the electrical
  frequency; with ``zeta_f = 0.2`` it does not (``wide-speed-xue``). The
  price of ``zeta_f`` is the steady angle error per unit flux-model error,
  ``2 zeta_f`` (closed form below).
  The hybrid estimators (:mod:`controller._hybrid`) set ``zeta_f = 0.2``
  and ``w_min`` to the lower edge of their band.
- ``k_p``, ``k_i``: exact discrete pole placement of a double pole at
  ``z = p = exp(-alpha_o T_s)`` (below; :mod:`controller._hybrid` derives
  ``alpha_o`` from the largest acceleration), so an angle error decays as
  ``(1 - k (1 - p)/p) p^k``, i.e. ``(1 - alpha_o t) exp(-alpha_o t)`` at
  fast sampling.

Discretisation (one PWM period, exact where it matters at 1 kHz, where the
rotor turns up to 0.6 rad a period):

- the flux estimate is kept in *stationary* coordinates, where the
  inverter's voltage is constant over a period: the voltage model
  ``psi_hat(k) = psi_hat+(k-1) + T_s u(k-1) - R_s T_s (i(k-1) + i(k))/2`` is
  exact for the average inverter (trapezoid on the resistive drop), and the
  term ``-j w_s psi_hat`` of the rotating form disappears;
- ``u(k-1)`` is the command that acted over ``[(k-1) T_s, k T_s]``
  (:attr:`EstimatorInput.u_alpha`), so the one-period computation delay of
  the controller is bookkept, not approximated, and no delay enters this
  loop: ``theta_hat(k)`` and sample ``k`` give ``eps(k)`` at once;
- the correction is forward Euler, ``psi_hat+(k) = psi_hat(k) + T_s
  e^{j theta_hat} (k_1 e + k_2 conj e)``. In the estimated frame the flux
  error then obeys ``z(k+1) = e^{-j w T_s} (z(k) - 2 k_1 T_s Re z(k))``
  (``z = psi~/psi_a``), with characteristic polynomial
  ``lambda^2 - 2 (1 - k_1 T_s) cos(w T_s) lambda + (1 - 2 k_1 T_s)``:
  stable at every speed except zero for ``0 < k_1 T_s < 1`` (``k_1 T_s``
  is capped at 0.5);
- the PLL (as :class:`controller.PositionObserver`): ``w_i += T_s k_i eps``,
  ``w_s = w_i + k_p eps``, ``theta_hat += T_s w_s``. Its error recursion has
  the characteristic polynomial ``z^2 - (2 - T_s k_p - T_s^2 k_i) z +
  (1 - T_s k_p)``; a double root at ``p`` needs::

      k_p = (1 - p^2) / T_s,   k_i = (1 - p)^2 / T_s^2

  (``2 alpha_o`` and ``alpha_o^2`` for ``alpha_o T_s -> 0``).

Steady angle error against model errors (the closed forms the tests check).
At constant speed ``w`` and current, a flux-model error ``dpsi =
psi_true(i) - psi_m(i)`` (e.g. ``dpsi_f``, or ``j dL_q i_q``), written
``b = b_r + j b_i = dpsi / psi_a``, leaves in the steady state of the
discrete recursion::

    theta~ = -b_i - b_r k_1 T_s cot(w T_s / 2) / (1 - k_1 T_s)
           -> -b_i - (2 k_1 / w) b_r          (T_s -> 0)

and a voltage the observer misses, ``v = (u - R_s i)_true - (u - R_s
i)_model`` (e.g. ``v = -dR_s i`` for a resistance error), leaves (continuous
form, ``n = v / psi_a``)::

    theta~ = -Re(n) / w + (2 k_1 / w^2) Im(n),
    |theta~| <= |v| sqrt(1 + (2 k_1 / w)^2) / (|w| |psi_a|)

with ``|psi_a| >= psi_f`` whenever ``i_d <= 0``; the exact discrete steady
state (in ``tests/test_closed_form_flux_observer.py``) differs from this
limit by a few per cent at ``w T_s = 0.1`` and by half at ``0.5``. Both vanish for an exact
model; the voltage term falls as ``1 / w``, which is why the observer serves
only above a band (:mod:`controller._hybrid`).

Slaved (sensored) mode: :meth:`FluxObserver.update_slaved` takes the angle
from elsewhere (the HF estimator below the band) and corrects the flux with
``k_1 e`` only (``k_2 = 0``, motulator's sensored mode), so the flux error
decays at the rate ``k_1`` at every speed, standstill included, and the
observer is converged when it is released.
"""

from __future__ import annotations

import math

from controller._built import _cctl
from controller._params import MotorModel


def pll_gains(alpha_o: float, T_s: float) -> tuple[float, float]:
    """``(k_p, k_i)`` placing the discrete PLL's double pole at ``exp(-alpha_o T_s)``."""
    if not (alpha_o > 0.0 and T_s > 0.0):
        raise ValueError(f"need alpha_o, T_s > 0; got alpha_o={alpha_o}, T_s={T_s}")
    p = math.exp(-alpha_o * T_s)
    return (1.0 - p * p) / T_s, (1.0 - p) * (1.0 - p) / (T_s * T_s)


class FluxObserver(_cctl.Flux):
    """Reduced-order flux observer with a PLL (Hinkkanen et al. 2018), per PWM period.

    A public block a user may call per period (a plug-in's estimator composes
    it): a binding of the core's ``controller/core/cc_flux_observer.c``, the one
    implementation the controller's engine runs too: :meth:`update`,
    :meth:`update_slaved`, :meth:`reset` and :meth:`set_state`. Its readable
    Python is the tests' oracle (``tests/oracle/blocks.py``, tolerance 0).

    Parameters
    ----------
    motor : MotorModel
        The controller's motor model (``R_s``, ``L_d``, ``L_q``, ``psi_f``).
    T_s : float
        Sampling period (s).
    alpha_o : float
        PLL bandwidth (rad/s): double pole at ``exp(-alpha_o T_s)``.
    zeta_f : float
        Damping of the flux-error poles (-): ``k_1 = zeta_f max(|w|, w_min)``.
    w_min : float
        Speed below which ``k_1`` stays at ``zeta_f w_min`` (rad/s, electrical).

    Notes
    -----
    Its members, the core struct's fields (design values read-only, states
    writable):

    R_s, L_d, L_q, psi_f, T_s, alpha_o, zeta_f, w_min, k_p, k_i : float
        The design values (the motor model's, the arguments', the PLL's gains), read-only.
    theta_hat : float
        Angle estimate at the last sample (rad, [0, 2 pi)).
    w_hat : float
        Speed estimate (rad/s, electrical): the PLL's integral state.
    eps : float
        Angle error signal of the last sample (rad).
    accel : float
        Acceleration estimate (rad/s^2): the PLL integrator's input ``k_i eps``,
        which equals the acceleration at a steady one (zero when slaved).
    psi_alpha, psi_beta : float
        Stator flux estimate after the last correction (Wb, stationary).
    """

    __slots__ = ()

    def __init__(
        self, motor: MotorModel, T_s: float, alpha_o: float, zeta_f: float, w_min: float
    ) -> None:
        if not (zeta_f > 0.0 and w_min > 0.0):
            raise ValueError(f"need zeta_f, w_min > 0; got zeta_f={zeta_f}, w_min={w_min}")
        k_p, k_i = pll_gains(alpha_o, T_s)
        super().__init__(
            motor.R_s, motor.L_d, motor.L_q, motor.psi_f, T_s, zeta_f, w_min, k_p, k_i, alpha_o
        )

    # update(i_alpha, i_beta, u_alpha, u_beta), update_slaved(..., theta, w),
    # reset(theta0, w0=0.0), set_state(psi_alpha, psi_beta, i_alpha, i_beta): the core's
    # (_cctl.Flux)
