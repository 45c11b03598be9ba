"""Drive supervision: the faults a production drive detects from its own samples.

A pure, per-period check of what the controller sees (the two phase-current
samples ``i_a``, ``i_b`` of :class:`controller.Measurement`, ``i_c = -i_a -
i_b`` as the DBC computes it, the DC-link sample ``u_dc``) against what it
commanded (the duties of its :class:`controller.ControlOutput`). It never
reads plant truth. Each detection is a controller mode (``CtrlTelemetry.mode``,
dbc/bench.dbc) and stops the switching; docs/PROTECTION.md is its prose.
Python designs the thresholds (:meth:`SupervisionPars.design`); the per-period
check is C, ``controller/core/cc_supervision.c`` (:meth:`Supervisor.args` hands
it the thresholds): the controller's core runs it after each step, and
:class:`Supervisor` is its binding (:meth:`Supervisor.check`), which
:meth:`Supervisor.wrap` puts after a step as the core does.

Checks, each with its threshold derived in :meth:`SupervisionPars.design`:

- **current-sensor plausibility** (:data:`MODE_CURRENT_SENSOR`): with two
  sensors the Kirchhoff sum ``i_a + i_b + i_c = 0`` holds by construction and
  checks nothing, so the check is what a single sensor can betray:

  - *out of range*: a reading at the converter's rail (``|i| >= i_rail``)
    for :attr:`SupervisionPars.n_range` samples in a row. The plant's
    over-current protection trips below the rail, so a healthy sensor never
    reads it;
  - *stuck*: a reading that does not move by more than ``i_res`` over
    :attr:`SupervisionPars.n_stuck` periods while the phase's commanded
    voltage swung by enough (``du_stuck``) to move a healthy current by many
    resolution steps, and while the other sensor's reading moved by more than
    ``i_res``. The last condition is what keeps a voltage swing that the
    back-EMF takes up out of it: at no load a drive without injection
    commands the rotating back-EMF (a swing of twice its amplitude within one
    window) and its currents hold still, every one of them; with a current
    flowing or an injection the other phase moves, and so would this one
    (``i_c = -i_a - i_b`` moves with it). A stuck sensor on a drive whose
    currents all hold is not seen: a healthy one reads the same. A reading
    held within ``i_res`` of zero is the pattern of a phase that carries
    nothing, and is reported as :data:`MODE_OPEN_PHASE` (below): a sensor
    that sticks at its last value is seldom there, an open phase and a
    sensor that reads zero always are. This is what detects an open phase
    at any speed, within ``n_stuck`` periods, where the block check below
    needs a whole electrical period and a speed.

- **open phase** (:data:`MODE_OPEN_PHASE`): over a block of one electrical
  period of the estimated speed, the mean square of one phase's current
  about its block mean is below ``rho_open^2`` times the mean of the other
  two, which carry current (``i_min``). About the mean: a current-sensor
  offset is a constant on one reading (and, through ``i_c``, on another),
  which a phase that carries nothing would otherwise show as current; over
  a whole period a healthy phase's current has no mean. Only over a whole period does a healthy drive give every
  phase the same RMS: a pulsating injection (square wave, along the
  estimated d axis) or a standing current leaves the phase at right angles
  to it without current. So the check runs only where a period is at most
  :data:`T_OPEN_MAX` (above 60 rpm with 4 pole pairs), and an open phase at
  lower speed is not detected. A lost sensor that reads zero gives the same
  pattern, and is reported the same way: from two samples the controller
  cannot tell them apart.
- **DC-link under- and over-voltage** (:data:`MODE_DC_UNDERVOLTAGE`,
  :data:`MODE_DC_OVERVOLTAGE`): the mean of ``u_dc`` over
  :attr:`SupervisionPars.n_dc` samples outside ``[u_uv, u_ov]``.

Reaction: every detection stops the switching (``enable = 0``, the
controller disabled) and latches its mode. A new enable command (the bench
enables the controller again) clears the latch only when the condition is
gone: for the DC link, once ``u_dc`` is back inside the band narrowed by the
hysteresis ``u_hyst``; else the drive stays stopped in its fault mode.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, fields

from controller._api import MODE_DISABLED, ControlOutput, Measurement
from controller._built import _cctl

#: A current sensor's reading is implausible (out of range, or stuck).
MODE_CURRENT_SENSOR = 5
#: One phase carries no current while the others do (open phase, or a sensor reading zero).
MODE_OPEN_PHASE = 6
#: The DC link is under its lower limit.
MODE_DC_UNDERVOLTAGE = 7
#: The DC link is over its upper limit.
MODE_DC_OVERVOLTAGE = 8

#: Every mode a detection reports, with its name in the DBC's ``CtrlTelemetry.mode`` table.
DETECTION_MODES: dict[int, str] = {
    MODE_CURRENT_SENSOR: "current_sensor",
    MODE_OPEN_PHASE: "open_phase",
    MODE_DC_UNDERVOLTAGE: "dc_undervoltage",
    MODE_DC_OVERVOLTAGE: "dc_overvoltage",
}

#: The DC-link tolerance of the supply that must never alarm: rectified
#: three-phase mains of EN 50160, nominal +-10 %.
SUPPLY_TOLERANCE = 0.10
#: Detection-time target of the DC-link checks (s): a sag or surge is seen
#: within 1 ms, well inside the DC-link's r_dc c_dc time constants and before
#: the plant's own over-voltage protection acts on a surge that keeps rising.
T_DC_DETECT = 1e-3
#: Detection-time target of the stuck-sensor check (s).
T_STUCK_DETECT = 10e-3
#: Shortest and longest open-phase block (s): at least 20 ms (ten periods of
#: a 500 Hz injection: a block is never shorter than ten ripples of the
#: current), at most 0.25 s, the detection-time target at low speed (one
#: electrical period at 60 rpm for 4 pole pairs); below that speed the check
#: does not run (module docstring).
T_OPEN_MIN = 20e-3
T_OPEN_MAX = 0.25
#: How many standard deviations of the floor a threshold sits above it
#: (false-alarm probability of a Gaussian reading below 1e-9 per test).
K_SIGMA = 6.0


@dataclass(frozen=True, slots=True)
class SupervisionPars:
    """Thresholds of the supervision (derived by :meth:`design`; module docstring).

    Attributes
    ----------
    T_s : float
        Control period (s).
    i_rail : float
        A current reading at or beyond this magnitude is out of range (A).
    n_range : int
        Samples in a row at the rail that detect it.
    i_res : float
        Resolution of a current reading (A): a stuck sensor moves by less.
    du_stuck : float
        Swing of a phase's commanded voltage within the stuck window that
        must move a healthy current by much more than ``i_res`` (V).
    n_stuck : int
        Stuck window (periods).
    i_min : float
        RMS the other two phases must carry for the open-phase test (A).
    rho_open : float
        RMS ratio under which a phase is open.
    n_open_min, n_open_max : int
        Bounds of the open-phase block (periods).
    u_uv, u_ov : float
        DC-link under- and over-voltage thresholds (V).
    u_hyst : float
        Hysteresis of the DC-link thresholds on release (V).
    n_dc : int
        Samples averaged by the DC-link check.
    """

    T_s: float
    i_rail: float
    n_range: int
    i_res: float
    du_stuck: float
    n_stuck: int
    i_min: float
    rho_open: float
    n_open_min: int
    n_open_max: int
    u_uv: float
    u_ov: float
    u_hyst: float
    n_dc: int

    @classmethod
    def design(
        cls,
        *,
        T_s: float,
        L_q: float,
        u_dc: float,
        u_dc_trip: float,
        i_max: float,
        i_fs: float,
        i_lsb: float,
        i_noise: float,
        i_offset: float,
        u_lsb: float,
        u_noise: float,
    ) -> SupervisionPars:
        """The thresholds from the drive's ratings and its sensors.

        Parameters
        ----------
        T_s : float
            Control period (s).
        L_q : float
            The controller's larger inductance (H).
        u_dc : float
            Nominal DC-link voltage (V), the inverter's rating.
        u_dc_trip : float
            The power stage's own over-voltage trip (V).
        i_max : float
            The drive's current limit, peak (A).
        i_fs : float
            Current converter's full scale (A): it saturates at ``+-i_fs``
            (the wire's range where the plant has no converter).
        i_lsb : float
            Current resolution (A): the converter's or the wire's LSB, the larger.
        i_noise : float
            Standard deviation of a current reading (A).
        i_offset : float
            Largest current-sensor offset (A).
        u_lsb, u_noise : float
            DC-link reading resolution and noise (V).

        Derivations
        -----------
        - ``i_rail = i_fs - i_lsb``: the last code below the rail. The
          plant's over-current trip (1.5 ``i_max``) sits below the rail
          (``2 i_max`` on the drive profile), so a healthy reading never
          reaches it; ``n_range = 2``: one corrupted sample is not a fault,
          two are (detection time ``2 T_s``).
        - ``i_res = i_lsb + 2 K_SIGMA i_noise``: the largest move of a healthy
          but constant current's reading (one code, plus the noise's
          peak-to-peak at ``K_SIGMA``); a stuck sensor moves by 0.
          ``du_stuck``: a phase voltage that changes by ``du`` across a period
          moves its current by at least ``du T_s / L_q`` (the resistance and
          the back-EMF are the same before and after); ``du_stuck`` makes that
          ``4 i_res``, four times what a stuck reading may move.
          ``n_stuck = T_STUCK_DETECT / T_s``.
        - ``i_min = K_SIGMA (i_noise + i_lsb / sqrt(12)) + i_offset``: below
          it, a phase's RMS is noise and offset (both its own and, through
          ``i_c``, the others'), so a ratio means nothing. ``rho_open =
          0.3``: over a whole electrical period a balanced three-phase set
          gives every phase the same RMS; a block of one period of the
          *estimated* speed off by 20 % leaves a ratio of at least 0.8; an
          open phase carries only the floor, ``i_min / K_SIGMA`` against at
          least ``i_min``, a ratio of at most ``1 / K_SIGMA`` = 0.17. 0.3
          sits between them with a factor of about 1.7 to the fault and 2.7
          to the healthy side.
        - ``u_uv = (1 - 2 SUPPLY_TOLERANCE) u_dc`` and ``u_ov`` half way
          from ``(1 + SUPPLY_TOLERANCE) u_dc`` to the power stage's own trip:
          the supply's tolerance never alarms, and a surge stops the
          switching before the hardware trips. ``u_hyst =
          SUPPLY_TOLERANCE u_dc / 2``. ``n_dc = T_DC_DETECT / T_s``; the
          mean of ``n_dc`` readings has a noise of ``u_noise / sqrt(n_dc)``;
          ``K_SIGMA`` of it plus one LSB must stay under a tenth of the
          margin between the tolerance band and a threshold (checked here).
        """
        if not (T_s > 0 and L_q > 0 and u_dc > 0 and u_dc_trip > u_dc and i_fs > 0):
            raise ValueError("SupervisionPars.design: ratings must be positive")
        i_res = i_lsb + 2.0 * K_SIGMA * i_noise
        i_min = K_SIGMA * (i_noise + i_lsb / math.sqrt(12.0)) + i_offset
        n_dc = max(1, round(T_DC_DETECT / T_s))
        u_top = (1.0 + SUPPLY_TOLERANCE) * u_dc
        u_ov = 0.5 * (u_top + u_dc_trip)
        u_uv = (1.0 - 2.0 * SUPPLY_TOLERANCE) * u_dc
        margin = min(u_ov - u_top, SUPPLY_TOLERANCE * u_dc)
        if K_SIGMA * u_noise / math.sqrt(n_dc) + u_lsb > 0.1 * margin:
            raise ValueError(
                f"SupervisionPars.design: a DC-link reading's noise ({u_noise:g} V) and LSB "
                f"({u_lsb:g} V) leave no margin to the thresholds"
            )
        return cls(
            T_s=T_s,
            i_rail=i_fs - i_lsb,
            n_range=2,
            i_res=i_res,
            du_stuck=4.0 * i_res * L_q / T_s,
            n_stuck=max(2, round(T_STUCK_DETECT / T_s)),
            i_min=max(i_min, 1e-3 * i_max),
            rho_open=0.3,
            n_open_min=max(1, round(T_OPEN_MIN / T_s)),
            n_open_max=max(1, round(T_OPEN_MAX / T_s)),
            u_uv=u_uv,
            u_ov=u_ov,
            u_hyst=0.5 * SUPPLY_TOLERANCE * u_dc,
            n_dc=n_dc,
        )


class Supervisor(_cctl.Sup):
    """The supervision's state; :meth:`check` checks one period (module docstring).

    A public block a user may call per period (a plug-in's estimator composes
    it): a binding of the core's ``controller/core/cc_supervision.c``, the one
    implementation the controller's engine runs too (:meth:`check`,
    :meth:`release_ok` and the windows' reset). Its readable Python is the
    tests' oracle (``tests/oracle/blocks.py``, tolerance 0).

    Parameters
    ----------
    pars : SupervisionPars

    Notes
    -----
    Its members, the core struct's fields (writable):

    latched : int
        The latched detection mode (0: none).
    detected_k : int
        The period of the latest detection (-1: none).
    """

    def __init__(self, pars: SupervisionPars) -> None:
        self.pars = pars
        super().__init__(*self.args())

    def check(self, i_a: float, i_b: float, u_dc: float, out: ControlOutput) -> int:
        """The detection of this period (a mode of :data:`DETECTION_MODES`, or 0).

        ``i_a``, ``i_b`` and ``u_dc`` are the period's samples, ``out`` what
        the controller answered to them. The current checks run while it
        switches in ``MODE_RUN``; the DC-link check always.
        """
        hit: int = self._check(
            i_a, i_b, u_dc, out.d_a, out.d_b, out.d_c, out.enable, out.mode, out.w_hat
        )
        return hit

    def args(self) -> tuple[float | int, ...]:
        """The thresholds in the order of ``cc_sup_init`` (controller/core/cc_supervision.h)."""
        p = self.pars
        return (
            p.T_s,
            p.i_rail,
            p.n_range,
            p.i_res,
            p.du_stuck,
            p.n_stuck,
            p.i_min,
            p.rho_open,
            p.n_open_min,
            p.n_open_max,
            p.u_uv,
            p.u_ov,
            p.u_hyst,
            p.n_dc,
        )

    def gains(self) -> dict[str, float]:
        """Every threshold (for the controller's ``gains``, ``meta.json``)."""
        p = self.pars
        return {f.name: float(getattr(p, f.name)) for f in fields(p) if f.name != "T_s"}

    # release_ok(u_dc) and _reset_windows(): the core's (_cctl.Sup)

    def wrap(
        self,
        step: Callable[[Measurement], ControlOutput],
        disable: Callable[[], None],
    ) -> Callable[[Measurement], ControlOutput]:
        """The controller's step with the supervision after it.

        ``step`` is the controller's own step, ``disable`` its
        ``set_enable(False)``. A period without a detection returns the
        controller's output unchanged (the same object); on a detection, and
        while one is latched, the output keeps the controller's estimate and
        carries ``enable = 0``, duties 0.5 and the detection's mode.
        """

        def supervised(meas: Measurement) -> ControlOutput:
            out = step(meas)
            if self.latched:
                if out.mode != MODE_DISABLED and self.release_ok(meas.u_dc):
                    self.latched = 0  # enabled again, the condition gone
                    self._reset_windows()
                else:
                    if out.mode != MODE_DISABLED:
                        disable()
                    return self._stopped(out)
            hit = self.check(meas.i_a, meas.i_b, meas.u_dc, out)
            if not hit:
                return out
            self.latched = hit
            self.detected_k = meas.k
            disable()
            return self._stopped(out)

        return supervised

    def _stopped(self, out: ControlOutput) -> ControlOutput:
        return ControlOutput(
            out.k,
            0.5,
            0.5,
            0.5,
            False,
            out.theta_hat,
            out.w_hat,
            out.err,
            self.latched,
            out.i_d,
            out.i_q,
        )
