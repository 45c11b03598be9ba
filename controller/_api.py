"""The controller's seam: what it receives each PWM period and what it returns.

Only plain values cross this seam, and every one of them is also carried by a
frame of the DBC (``dbc/bench.dbc``), so a controller node on a CAN bus and an
in-process loop see exactly the same numbers.

Timing convention (see DESIGN.md, "Timing model"): step ``k`` is the PWM
period that starts at ``t = k T_s``.  The plant samples the phase currents at
that instant (carrier peak of symmetric PWM) and sends :class:`Measurement`
``k``.  The controller answers with the duties that take effect in period
``k + 1`` (one-period computation delay).  Every angle a controller reports
(:attr:`ControlOutput.theta_hat`) is its estimate of the electrical rotor angle
*at the sample instant* ``k T_s``, so the bench can score it against the
plant's truth at the same instant.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Protocol


@dataclass(frozen=True, slots=True)
class Measurement:
    """Samples of one PWM period, taken at ``t = k T_s``.

    Parameters
    ----------
    k : int
        Step counter (PWM periods since the start of the run).
    i_a, i_b, i_c : float
        Phase currents (A).
    u_dc : float
        DC-link voltage (V).
    theta_e : float or None
        True electrical rotor angle (rad). Only the ``sensored`` baseline may
        receive it; every sensorless estimator gets ``None``.
    w_e : float or None
        True electrical speed (rad/s), same rule as ``theta_e``.
    """

    k: int
    i_a: float
    i_b: float
    i_c: float
    u_dc: float
    theta_e: float | None = None
    w_e: float | None = None


@dataclass(frozen=True, slots=True)
class ControlOutput:
    """What the controller returns for sample ``k``.

    Parameters
    ----------
    k : int
        The sample this answers; the duties apply in period ``k + 1``.
    d_a, d_b, d_c : float
        Phase duty cycles in [0, 1] for period ``k + 1``.
    enable : bool
        False keeps the inverter's switches open (PWM disabled).
    theta_hat : float
        Estimated electrical angle at ``t = k T_s`` (rad, wrapped to [0, 2 pi)).
    w_hat : float
        Estimated electrical speed (rad/s).
    err : float
        The estimator's normalised error signal (rad; about the angle error
        for small errors once the observer is locked).
    mode : int
        Controller state, one of the ``MODE_*`` constants.
    i_d, i_q : float
        Fundamental currents in the estimated d-q frame (A), HF removed.
    """

    k: int
    d_a: float
    d_b: float
    d_c: float
    enable: bool
    theta_hat: float
    w_hat: float
    err: float
    mode: int
    i_d: float = 0.0
    i_q: float = 0.0


#: Controller mode (``ControlOutput.mode``, the DBC's ``mode`` values): disabled.
MODE_DISABLED = 0
#: Controller mode: standstill, HF estimator converging, speed loop held.
MODE_ALIGN = 1
#: Controller mode: magnet polarity test (d-axis current pulses).
MODE_POLARITY = 2
#: Controller mode: speed loop released.
MODE_RUN = 3
#: Controller mode: fault (the DBC's value table of the telemetry's ``mode``).
MODE_FAULT = 4


@dataclass(frozen=True, slots=True)
class EstimatorInput:
    """What an estimator sees of sample ``k``.

    Parameters
    ----------
    k : int
        Step counter.
    i_alpha, i_beta : float
        Measured stator current in the stationary frame (A), HF included.
    torque : float
        Electromagnetic torque the controller believes it produces (N m),
        from its own motor model and current reference; used for the
        torque feed-forward of the Luenberger observer (Xue eq. 9).
    theta_e : float or None
        Truth, for the ``sensored`` estimator only.
    w_e : float or None
        Truth, for the ``sensored`` estimator only.
    u_alpha, u_beta : float
        Stator voltage the controller commanded for the period that ended at
        this sample, ``[(k-1) T_s, k T_s]`` (V, stationary frame, HF injection
        included): the command computed from sample ``k - 2``. With the
        average inverter in its linear range this is the voltage that drove
        the current from sample ``k - 1`` to sample ``k``; model-based
        observers integrate it. Zero before the first two commands.
    running : bool
        The speed loop is released (``MODE_RUN``); False during the start-up
        at standstill (alignment), where only the injection can see the
        angle and its estimator's transients are not a speed.
    accel_ref : float
        The electrical angular acceleration (rad/s^2) the speed loop is
        designed to give the rotor from the speed reference alone: the slope
        of its designed response ``alpha_s / (s + alpha_s)`` to ``w_m_ref``,
        times ``n_p`` (:class:`controller._controller.ReferenceModel`). It
        depends on the reference only, never on an estimate; tt-dq's
        ``accel_ff`` option feeds it forward into its PLL. Zero outside the
        speed loop.
    """

    k: int
    i_alpha: float
    i_beta: float
    torque: float
    theta_e: float | None = None
    w_e: float | None = None
    u_alpha: float = 0.0
    u_beta: float = 0.0
    running: bool = True
    accel_ref: float = 0.0


class Estimator(Protocol):
    """A rotor-position estimator plugged into the field-oriented controller.

    Call order in every period ``k``: :meth:`update` with sample ``k``, then
    the controller reads the attributes below, computes the fundamental
    voltage for period ``k + 1`` and adds :meth:`injection` to it (the HF
    voltage is added after the current PI output, so the PI never sees it as
    its own output).

    Attributes
    ----------
    theta_hat : float
        Estimated electrical angle at ``t = k T_s`` (rad).
    w_hat : float
        Estimated electrical speed (rad/s).
    err : float
        Normalised error signal fed to the observer (rad for small errors).
    i_alpha_f, i_beta_f : float
        Sample ``k`` with the HF response removed, for the current loop (A).
    """

    theta_hat: float
    w_hat: float
    err: float
    i_alpha_f: float
    i_beta_f: float

    def update(self, x: EstimatorInput) -> None:
        """Take sample ``k`` and advance the estimate."""
        ...

    def injection(self) -> tuple[float, float]:
        """HF voltage (alpha, beta) (V) to add to the command for period ``k + 1``."""
        ...

    def reset(self, theta0: float) -> None:
        """Restart from angle ``theta0`` (rad) at zero speed (e.g. after a polarity flip)."""
        ...

    def gains(self) -> dict[str, float]:
        """Every gain, bandwidth, filter corner and delay of the estimator, by name.

        Recorded in ``meta.json`` through :meth:`controller.Controller.gains`
        (which records none for an estimator without this method).
        """
        ...


#: The kinds of value an :class:`Option` holds.
OPTION_KINDS = ("float", "int", "bool", "str", "filter")

#: The bounds of an option that depend on the scenario (:attr:`Option.limit`):
#: ``inverter_linear``, an injection amplitude (V) at most the inverter's linear limit
#: ``u_dc / sqrt(3)`` of space-vector modulation; ``below_nyquist``, a frequency (Hz)
#: below half the sample rate.
OPTION_LIMITS = ("inverter_linear", "below_nyquist")


@dataclass(frozen=True, slots=True)
class Option:
    """One option an estimator declares: a key of a scenario's ``[estimator_options]``.

    Every estimator declares its options as a dataclass whose fields are the
    options (:attr:`controller.EstimatorSpec.options`): their defaults and
    types from the fields, units and meanings from the class's numpydoc
    ``Parameters`` section, and the checks by :func:`option_field` (which sets
    any attribute below).  A plug-in may still give a mapping of names to
    :class:`Option` instead.  :func:`controller._registry.declared_options`
    reads either; docs/ESTIMATORS.md.

    Parameters
    ----------
    default : object
        The factory's value when the scenario leaves the key out; None: derived
        by the estimator (meta.json: ``controller_gains``).
    unit : str
        Unit (SI), ``-`` for a pure number, empty for text and switches.
    doc : str
        What the option does, a sentence or two.
    kind : str
        One of :data:`OPTION_KINDS`; empty: from ``choices`` and the default's type
        (``float`` for None).
    minimum, maximum : float or None
        Inclusive bounds of a number.
    positive : bool
        A number must be > 0.
    choices : tuple of str
        The strings a text option may be.
    limit : str
        A bound the scenario sets (one of :data:`OPTION_LIMITS`), empty for none.
    default_doc : str
        How the docs state the default when its value says too little (a
        filter's source); empty: the value.
    """

    default: Any = None
    unit: str = ""
    doc: str = ""
    kind: str = ""
    minimum: float | None = None
    maximum: float | None = None
    positive: bool = False
    choices: tuple[str, ...] = ()
    limit: str = ""
    default_doc: str = ""

    @property
    def value_kind(self) -> str:
        """The kind in force: :attr:`kind`, else from ``choices`` and the default."""
        if self.kind:
            return self.kind
        d = self.default
        if self.choices or isinstance(d, str):
            return "str"
        if isinstance(d, bool):
            return "bool"
        if isinstance(d, int):
            return "int"
        if isinstance(d, tuple | list):
            return "filter"
        return "float"

    def range_text(self) -> str:
        """The values it takes, in words (docs)."""
        k = self.value_kind
        if k == "bool":
            return "true, false"
        if k == "str":
            return ", ".join(self.choices) if self.choices else "text"
        if k == "filter":
            return "[[b_0, ...], [a_0, ...]], a_0 != 0"
        parts = ["integer"] if k == "int" else []
        if self.positive:
            parts.append("> 0")
        if self.minimum is not None:
            parts.append(f">= {self.minimum:g}")
        if self.maximum is not None:
            parts.append(f"<= {self.maximum:g}")
        return " ".join(parts) or "any number"

    def check(self, value: Any) -> tuple[Any, str | None]:
        """``(value, None)`` with the value in its type, or ``(None, why)`` when it is refused."""
        k = self.value_kind
        if k == "bool":
            return (
                (value, None)
                if isinstance(value, bool)
                else (None, f"expected true or false, got {value!r}")
            )
        if k == "str":
            if not isinstance(value, str):
                return None, f"expected a string, got {value!r}"
            if self.choices and value not in self.choices:
                return None, f"expected {' or '.join(map(repr, self.choices))}, got {value!r}"
            return value, None
        if k == "filter":
            ok = (
                isinstance(value, list | tuple)
                and len(value) == 2
                and all(
                    isinstance(c, list | tuple) and c and all(_finite_number(x) for x in c)
                    for c in value
                )
                and value[1][0] != 0
            )
            if not ok:
                return None, (
                    "expected [[b_0, b_1, ...], [a_0, a_1, ...]], the numerator and denominator "
                    f"of a continuous prototype (finite numbers, a_0 != 0), got {value!r}"
                )
            return tuple(tuple(float(x) for x in c) for c in value), None
        if k == "int":
            if isinstance(value, bool) or not isinstance(value, int):
                return None, f"expected an integer, got {value!r}"
        elif isinstance(value, bool) or not isinstance(value, int | float):
            return None, f"expected a number, got {type(value).__name__} {value!r}"
        elif not math.isfinite(value):
            return None, "must be finite"
        v = value if k == "int" else float(value)
        if self.positive and not v > 0:
            return None, f"must be > 0, got {v}"
        if self.minimum is not None and v < self.minimum:
            return None, f"must be >= {self.minimum}, got {v}"
        if self.maximum is not None and v > self.maximum:
            return None, f"must be <= {self.maximum}, got {v}"
        return v, None


def option_field(default: Any = None, **checks: Any) -> Any:
    """A field of an options dataclass: ``default`` and the :class:`Option` attributes
    ``checks`` (``positive=True``, ``minimum=0.0``, ``choices=(...)``, ``unit="V"``...).

    The unit and meaning otherwise come from the class's numpydoc ``Parameters``.
    An unknown attribute is an error when the options are declared.
    """
    return field(default=default, metadata=checks)


def _finite_number(x: Any) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x)
