"""Scenario files: a documented, validated TOML schema.

A scenario fixes everything a run needs besides the transport: the motor
preset, the PWM rate, the estimator, the duration, the speed-reference and
load-torque profiles, the injected latency, the sensing noise and the seed.
The ten scenarios of the papers ship in ``bench/scenarios/``; a user's own file
path works wherever a name does.

Units are SI unless a key's name carries its own (``_rpm``, ``_deg``, ``_us``,
``_hz``, ``_s``, ``_a``, ``_nm``): currents are **peak** phase values in A
(the amplitude-invariant Park transform, as on the wire; an rms rating is
multiplied by sqrt(2)), flux linkages peak per phase in Wb, inductances in H
(not mH), the ``[motor]`` speeds mechanical rad/s (not rpm), speed
references in rpm, angles electrical degrees, voltages V, times s.  A motor
is checked against physics on load (``bench/scenarios/_plausible.py``): a
value off by a factor of 1000 (or an inertia in kg cm^2) is an error that
names the field and the unit it looks like.

Schema (all keys optional unless marked *required*; every key with its unit,
default, range and meaning: docs/SCENARIOS.md, written by ``bench schema`` from
this module and :mod:`bench.scenarios._reference`)::

    name = "wen-5.1"                 # defaults to the file's stem
    description = "..."
    paper = "Wen et al. 2023, Sec. 5.1, Table 5"
    preset = "wen2023"               # *required*: plant preset (plant_rt.PRESETS)
    estimator = "tt-dq"              # default estimator for `bench run`
    estimators = ["sfhf", "tt-ab", "tt-dq", "sensored"]   # the ones `bench suite` runs
    f_sw = 10000.0                   # PWM (= control) frequency, Hz; default: the preset's
    duration = 3.0                   # simulated seconds, *required*
    seed = 1                         # seeds the sensor noise and the latency jitter
    saturation = true                # d-axis saturation in the plant (needed by the polarity test)
    theta_e0_deg = 0.0               # initial electrical rotor angle, electrical degrees
    known_initial_angle = true       # false: the controller runs its start-up (HF + polarity)
    speed_rpm = [[0.0, 100.0]]       # (t s, rpm) breakpoints, linear between, held after the last;
                                     # a step is two points at the same time; values within the
                                     # range of BenchCommand.speed_ref (dbc/bench.dbc)
    load_nm = [[0.0, 0.0]]           # (t s, N m) breakpoints, same rules (BenchCommand.load_torque)
    reference_rate_hz = 1000.0       # how often the bench re-sends a changing reference
    score_from_s = 0.5               # metrics ignore the start-up transient before this time
    thd_window_s = [3.0, 11.0]       # window for the THD of phase-A current (optional)

    [estimator_options]              # passed to the estimator, checked on load by key name
    V_h = 50.0                       # rotating (sfhf, tt-ab, tt-dq): injection amplitude, V peak,
    f_h = 500.0                      # frequency, Hz; also w_o (PLL bandwidth, rad/s), normalise,
                                     # bpf, hpf, lpf (continuous prototypes, s-domain, rad/s)
    U_h = 20.0                       # square-wave: injection amplitude, V peak; also a (observer
                                     # pole, rad/s), M (CIC delay, periods), delay_comp (periods)
                                     # (amplitudes <= u_dc/sqrt(3) of the preset, f_h below
                                     # Nyquist; the keys of every estimator load, since the
                                     # estimator may be chosen on the command line; a run
                                     # leaves out the keys of the others with a note, and a
                                     # key no estimator declares is an error).  Needs [motor]
                                     # in a file that does not extend a scenario (the settings
                                     # are for a motor; an empty [motor] keeps the preset's)
    extends = "wen-5.1"              # start from a shipped scenario (or a path): this file's
                                     # keys replace the base's, table by table, key by key
    plant_profile = "ideal"          # "ideal" (the papers' plant) | "drive" (switching inverter,
                                     # dead time, drops, ADC, offsets, cross-saturation;
                                     # plant_rt/_profiles.py); the tables below change single
                                     # values of the profile
    [inverter]
    model = "average"                # "average" | "switching"
    t_dead = 0.0                     # dead time per transition, s
    v_ce = 0.0                       # transistor on-state drop, V
    v_f = 0.0                        # diode forward drop, V
    u_dc = 540.0                     # DC-link source voltage, V (default: the preset's)
    r_dc = 0.0                       # DC source resistance, Ohm
    c_dc = 0.0                       # DC-link capacitance, F (0: none)
    sample_at = "peak"               # ADC instant: carrier "peak" | "valley"
    [sensors]
    current_offset_a = 0.0           # per phase, A (one number, or [a, b, c])
    current_gain_error = 0.0         # relative, per phase (gain 1 + e; one number, or [a, b, c])
    adc_bits = 0                     # 0: no quantization
    current_full_scale_a = 50.0      # +- A
    current_noise_a = 0.0            # white noise, A rms
    sample_delay_s = 0.0             # sensor chain delay, s (below one period)
    [magnetics]
    saturation = true                # d-axis saturation (the polarity test needs it)
    cross_saturation = false         # cross-saturation flux map (the preset's c_dq)
    sigma = 0.15                     # d-axis saturation depth, - (plant_rt.SaturationPars)
    i_sat = 2.0                      # d-axis saturation current, A
    c_dq = 0.0                       # cross-saturation coefficient (plant_rt.CrossSaturationPars)
    [controller]                     # what a real drive does against the plant (each on by
    dead_time_compensation = false   # default where the plant has what it counters):
    t_dead = 2e-6                    # dead-time and device-drop feed-forward, with the
    v_ce = 1.5                       # controller's own setting (s, V; default: the plant's
    v_f = 1.5                        # inverter, as a drive is configured for its own bridge)
    cross_saturation_compensation = false   # correct the HF estimators' cross-saturation angle
    k_dq = -1e-4                     # L_dq = k_dq i_q (H/A; default: the plant's flux map at i_d = 0)
    offset_calibration = false       # measure the current offsets at standstill before the start
    offset_periods = 200             # its length (default: derived from the sensors' noise and LSB)
    current_feedback = "filtered"    # "filtered" | "raw" (the current PI sees the HF current,
                                     # as Wen Sec. 3.3 assumes)
    supervision = false              # detect current-sensor, open-phase and DC-link faults
                                     # and stop switching (docs/PROTECTION.md; default: on
                                     # where the scenario has a [[faults]] timeline)
    [noise]                          # older form of [sensors] (kept; [sensors] wins)
    current_std_a = 0.0              # white noise on each phase current, A rms
    adc_bits = 0                     # 0: no quantization
    adc_full_scale_a = 0.0
    [latency]
    duty_delay_steps = 0             # lockstep: whole PWM periods per direction; together at
    sample_delay_steps = 0           # most a quarter of the step counters' range (256 periods)
    duty_delay_us = 0.0              # real-time mode: microseconds per direction
    sample_delay_us = 0.0
    jitter_us = 0.0                  # real-time: standard deviation (normal) or half-width
                                     # (uniform), both directions
    duty_jitter_us = 0.0             # per direction; default jitter_us, wins over it when both given
    sample_jitter_us = 0.0
    jitter_dist = "normal"           # "normal" | "uniform", both directions
    drop_prob = 0.0                  # per frame, both directions
    duty_drop_prob = 0.0             # per direction; default drop_prob, wins over it when both given
    sample_drop_prob = 0.0           # (the seed gives each direction a random stream of its own:
                                     # one direction's settings never change the other's draws)
    [motor]                          # explicit motor parameters (SI) replacing the preset's,
                                     # for plant and controller alike; any of these keys:
    n_p = 4                          # pole pairs
    R_s = 2.8                        # stator resistance, Ohm
    L_d = 0.057                      # d-axis inductance at zero current, H (not mH)
    L_q = 0.082                      # q-axis inductance at zero current, H
    psi_f = 0.3                      # permanent-magnet flux linkage, peak per phase, Wb
    J = 0.003                        # inertia of rotor and load, kg m^2
    b = 0.00048                      # viscous friction, N m s/rad
    i_rated = 4.0                    # rated current, peak phase, A (rms times sqrt(2))
    i_max = 8.0                      # current limit, peak phase, A
    tau_rated = 7.5                  # rated torque, N m
    w_m_rated = 157.08               # rated speed, mechanical rad/s (rpm times pi/30)
    [controller_model]               # the controller's parameter errors: factors on the
    R_s = 1.0                        # plant's values (1.0 exact, 1.2 = believes 20 % more);
    L_d = 1.0                        # the plant keeps the preset's values
    L_q = 1.0
    psi_f = 1.0
    J = 1.0
    [paper_result]                   # the paper's numbers, for reports only
    theta_err_max_deg = 4.0
    [[faults]]                       # a fault timeline (bench/scenarios/_faults.py, bench faults)
    at_s = 2.0                       # *required*: plant time at which it starts, s
    duration_s = 0.5                 # absent: to the end of the run
    kind = "resistance_drift"        # *required*, with the kind's parameters
    R_s_factor = 1.5
    expect = "ride_through"          # "trip" | "detect" | "ride_through"
"""

from __future__ import annotations

import functools
import itertools
import json
import math
import tomllib
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path
from typing import Any

from bench._errors import ScenarioError
from bench.scenarios._faults import Fault, parse_faults

#: The papers' scenarios (what ``bench suite paper`` runs).
PAPER = (
    "wen-5.1",
    "wen-5.2",
    "wen-5.3",
    "wen-5.4",
    "xue-fig13",
    "xue-fig14",
    "xue-fig15",
    "xue-fig16",
    "xue-fig17",
    "xue-fig18",
)
#: Every scenario shipped in ``bench/scenarios/``: the papers', and the full
#: speed range (HF injection handed over to a flux observer) for both motors.
SHIPPED = (*PAPER, "wide-speed-wen", "wide-speed-xue")


@dataclass(frozen=True, slots=True)
class Profile:
    """Piecewise-linear function of time, held constant after the last breakpoint."""

    points: tuple[tuple[float, float], ...]

    def __call__(self, t: float) -> float:
        pts = self.points
        if t <= pts[0][0]:
            return pts[0][1]
        for (t0, v0), (t1, v1) in itertools.pairwise(pts):
            if t < t1:
                if t1 == t0:
                    return v1
                return v0 + (v1 - v0) * (t - t0) / (t1 - t0)
        return pts[-1][1]

    def is_constant_between(self, t0: float, t1: float) -> bool:
        """True when the profile does not change on [t0, t1]."""
        return self(t0) == self(t1) and all(
            v == self(t0) for (t, v) in self.points if t0 <= t <= t1
        )


@dataclass(frozen=True, slots=True)
class Direction:
    """The latency of one direction of the link, shared values resolved.

    Attributes
    ----------
    delay_steps : int
        Lockstep: fixed delay, whole PWM periods.
    delay_us : float
        Real time: fixed delay, us.
    jitter_us : float
        Real time: standard deviation (normal) or half-width (uniform) of the
        jitter added to ``delay_us``, us.
    drop_prob : float
        Probability that a frame of this direction is dropped.
    """

    delay_steps: int
    delay_us: float
    jitter_us: float
    drop_prob: float


@dataclass(frozen=True, slots=True)
class Latency:
    """Latency injected on the link, per direction.

    The duty direction carries ``PwmDuty`` to the plant, the sample direction
    ``PhaseSamples`` and ``PlantTruth`` to the controller.  ``jitter_us`` and
    ``drop_prob`` apply to both directions; ``duty_jitter_us``,
    ``sample_jitter_us``, ``duty_drop_prob`` and ``sample_drop_prob`` (``None``:
    not given) override them for one direction, and win when a file gives
    both.  Use :attr:`duty` and :attr:`sample` for the values in force.  One
    ``jitter_dist`` and the scenario's one ``seed`` serve both directions;
    the link derives a separate random stream per direction from the seed.
    """

    duty_delay_steps: int = 0
    sample_delay_steps: int = 0
    duty_delay_us: float = 0.0
    sample_delay_us: float = 0.0
    jitter_us: float = 0.0
    jitter_dist: str = "normal"
    drop_prob: float = 0.0
    duty_jitter_us: float | None = None
    sample_jitter_us: float | None = None
    duty_drop_prob: float | None = None
    sample_drop_prob: float | None = None

    @property
    def duty(self) -> Direction:
        """Duties to the plant (B to A), shared values resolved."""
        return Direction(
            delay_steps=self.duty_delay_steps,
            delay_us=self.duty_delay_us,
            jitter_us=self.jitter_us if self.duty_jitter_us is None else self.duty_jitter_us,
            drop_prob=self.drop_prob if self.duty_drop_prob is None else self.duty_drop_prob,
        )

    @property
    def sample(self) -> Direction:
        """Samples (and truth) to the controller (A to B), shared values resolved."""
        return Direction(
            delay_steps=self.sample_delay_steps,
            delay_us=self.sample_delay_us,
            jitter_us=self.jitter_us if self.sample_jitter_us is None else self.sample_jitter_us,
            drop_prob=self.drop_prob if self.sample_drop_prob is None else self.sample_drop_prob,
        )

    @property
    def any(self) -> bool:
        d, s = self.duty, self.sample
        return bool(
            d.delay_steps
            or s.delay_steps
            or d.delay_us
            or s.delay_us
            or d.jitter_us
            or s.jitter_us
            or d.drop_prob
            or s.drop_prob
        )

    def to_dict(self) -> dict[str, Any]:
        """Plain representation; per-direction keys only when given (exact round trip)."""
        out: dict[str, Any] = {
            "duty_delay_steps": self.duty_delay_steps,
            "sample_delay_steps": self.sample_delay_steps,
            "duty_delay_us": self.duty_delay_us,
            "sample_delay_us": self.sample_delay_us,
            "jitter_us": self.jitter_us,
            "jitter_dist": self.jitter_dist,
            "drop_prob": self.drop_prob,
        }
        for k in _LATENCY_DIRECTION_KEYS:
            v = getattr(self, k)
            if v is not None:
                out[k] = v
        return out


#: Per-direction keys of ``[latency]`` that override a shared one when given.
_LATENCY_DIRECTION_KEYS = (
    "duty_jitter_us",
    "sample_jitter_us",
    "duty_drop_prob",
    "sample_drop_prob",
)


@dataclass(frozen=True, slots=True)
class Noise:
    current_std_a: float = 0.0
    adc_bits: int = 0
    adc_full_scale_a: float = 0.0


@dataclass(frozen=True, slots=True)
class ModelErrors:
    """Relative errors of the controller's motor model against the plant's parameters.

    Each field is a factor on the plant's value (1.0 = exact, 1.2 = the
    controller believes 20 % more); the plant always keeps the preset's
    values. Used for robustness studies: the current-loop gains and the
    decoupling use ``R_s``, ``L_d``, ``L_q`` and ``psi_f``; the torque
    constant ``1.5 n_p psi_f``; the speed-loop gains ``J``; the HF
    estimators their normalisation by the model's ``L_d``, ``L_q``.
    """

    R_s: float = 1.0
    L_d: float = 1.0
    L_q: float = 1.0
    psi_f: float = 1.0
    J: float = 1.0


#: Keys of the ``[controller_model]`` table, in schema order.
MODEL_ERROR_KEYS = ("R_s", "L_d", "L_q", "psi_f", "J")


@dataclass(frozen=True, slots=True)
class Scenario:
    """One validated scenario. Build with :func:`load_scenario`."""

    name: str
    source: str
    preset: str
    duration: float
    description: str = ""
    paper: str = ""
    estimator: str = "tt-dq"
    estimators: tuple[str, ...] = ()
    f_sw: float | None = None
    seed: int = 1
    saturation: bool = True
    theta_e0_deg: float = 0.0
    known_initial_angle: bool = True
    speed_rpm: Profile = field(default_factory=lambda: Profile(((0.0, 0.0),)))
    load_nm: Profile = field(default_factory=lambda: Profile(((0.0, 0.0),)))
    reference_rate_hz: float = 1000.0
    score_from_s: float = 0.5
    thd_window_s: tuple[float, float] | None = None
    estimator_options: dict[str, Any] = field(default_factory=dict)
    noise: Noise = field(default_factory=Noise)
    latency: Latency = field(default_factory=Latency)
    controller_model: ModelErrors = field(default_factory=ModelErrors)
    paper_result: dict[str, Any] = field(default_factory=dict)
    #: Explicit motor parameters (SI units) replacing the preset's (``[motor]``).
    motor: dict[str, float] = field(default_factory=dict)
    #: The plant profile (``ideal`` or ``drive``, :mod:`plant_rt._profiles`).
    plant_profile: str = "ideal"
    #: ``[inverter]``, ``[sensors]``, ``[magnetics]``: values replacing the profile's.
    inverter: dict[str, Any] = field(default_factory=dict)
    sensors: dict[str, Any] = field(default_factory=dict)
    magnetics: dict[str, Any] = field(default_factory=dict)
    #: ``[controller]``: the drive's countermeasures and options.
    controller: dict[str, Any] = field(default_factory=dict)
    #: ``[[faults]]``: the fault timeline (:mod:`bench.scenarios._faults`).
    faults: tuple[Fault, ...] = ()

    def with_overrides(self, **kw: Any) -> Scenario:
        """A copy with some fields replaced (command-line options).

        A ``duration`` shorter than the scoring start would leave nothing to
        score: such a shortened run is scored over its second half
        (``score_from_s = duration / 2``), which ``metrics.json`` states.
        """
        clean = {k: v for k, v in kw.items() if v is not None}
        out = replace(self, **clean)
        if "latency" in clean or "f_sw" in clean:  # e.g. --delay-steps, --duty-delay-us
            from plant_rt import PRESETS

            _check_delay_steps(out.source, out.latency)
            _check_delay_us(out.source, out.latency, out.f_sw or PRESETS[out.preset].f_sw)
        if "score_from_s" not in clean and out.score_from_s >= out.duration:
            out = replace(out, score_from_s=out.duration / 2)
        return out

    def to_dict(self) -> dict[str, Any]:
        """Plain representation for the run metadata."""
        return {
            "name": self.name,
            "source": self.source,
            "preset": self.preset,
            "duration": self.duration,
            "description": self.description,
            "paper": self.paper,
            "estimator": self.estimator,
            "estimators": list(self.estimators),
            "f_sw": self.f_sw,
            "seed": self.seed,
            "saturation": self.saturation,
            "theta_e0_deg": self.theta_e0_deg,
            "known_initial_angle": self.known_initial_angle,
            "speed_rpm": [list(p) for p in self.speed_rpm.points],
            "load_nm": [list(p) for p in self.load_nm.points],
            "reference_rate_hz": self.reference_rate_hz,
            "score_from_s": self.score_from_s,
            "thd_window_s": list(self.thd_window_s) if self.thd_window_s else None,
            "estimator_options": dict(self.estimator_options),
            "noise": {
                "current_std_a": self.noise.current_std_a,
                "adc_bits": self.noise.adc_bits,
                "adc_full_scale_a": self.noise.adc_full_scale_a,
            },
            "latency": self.latency.to_dict(),
            "controller_model": {k: getattr(self.controller_model, k) for k in MODEL_ERROR_KEYS},
            "motor": dict(self.motor),
            "paper_result": dict(self.paper_result),
            "plant_profile": self.plant_profile,
            "inverter": dict(self.inverter),
            "sensors": dict(self.sensors),
            "magnetics": dict(self.magnetics),
            "controller": dict(self.controller),
            "faults": [f.to_dict() for f in self.faults],
        }


_TOP_KEYS = {
    "name",
    "description",
    "paper",
    "preset",
    "estimator",
    "estimators",
    "f_sw",
    "duration",
    "seed",
    "saturation",
    "theta_e0_deg",
    "known_initial_angle",
    "speed_rpm",
    "load_nm",
    "reference_rate_hz",
    "score_from_s",
    "thd_window_s",
    "estimator_options",
    "noise",
    "latency",
    "controller_model",
    "motor",
    "paper_result",
    "plant_profile",
    "inverter",
    "sensors",
    "magnetics",
    "extends",
    "controller",
    "faults",
}

#: ``[inverter]`` keys: fields of :class:`plant_rt.InverterPars`, with their checks.
INVERTER_KEYS = ("model", "t_dead", "v_ce", "v_f", "u_dc", "r_dc", "c_dc", "sample_at")
#: ``[sensors]`` keys: the keywords of :meth:`plant_rt.SensorPars.from_keys`.
SENSOR_KEYS = (
    "current_offset_a",
    "current_gain_error",
    "adc_bits",
    "current_full_scale_a",
    "current_noise_a",
    "sample_delay_s",
    "encoder_counts",
    "encoder_rate_hz",
    "encoder_delay_s",
)
#: ``[magnetics]`` keys.
MAGNETICS_KEYS = ("saturation", "cross_saturation", "sigma", "i_sat", "c_dq")
#: ``[controller]`` keys.
CONTROLLER_KEYS = (
    "dead_time_compensation",
    "t_dead",
    "v_ce",
    "v_f",
    "cross_saturation_compensation",
    "k_dq",
    "offset_calibration",
    "offset_periods",
    "current_feedback",
    "supervision",
)

#: Keys of the ``[motor]`` table: the fields of :class:`plant_rt.MotorPars`.
MOTOR_KEYS = (
    "n_p", "R_s", "L_d", "L_q", "psi_f", "J", "b", "i_rated", "i_max", "tau_rated", "w_m_rated",
)  # fmt: skip


@functools.cache
def shipped_options() -> dict[str, Any]:
    """Every built-in estimator's ``[estimator_options]`` key with its declaration
    (:class:`controller.Option`; the first estimator's where several declare one key)."""
    from controller._registry import SPECS

    out: dict[str, Any] = {}
    for spec in SPECS.values():
        for k, opt in (spec.declared() or {}).items():
            out.setdefault(k, opt)
    return out


@functools.cache
def estimator_option_keys() -> dict[str, Any]:
    """Every ``[estimator_options]`` key of the built-in estimators with its default.

    The estimators' declarations: the fields of each registry entry's options
    dataclass (:attr:`controller.EstimatorSpec.options`).
    """
    return {k: opt.default for k, opt in shipped_options().items()}


def estimator_keys(estimator: str) -> frozenset[str]:
    """The ``[estimator_options]`` keys one estimator declares (a plug-in without a
    declaration: the keywords its factory names, none for ``**options``)."""
    from controller._registry import declared_options, plugin

    decl = declared_options(estimator)
    if decl is not None:
        return frozenset(decl)
    p = plugin(estimator)
    return frozenset(p.keywords or ()) if p is not None else frozenset()


def split_options(options: dict[str, Any], estimator: str) -> tuple[dict[str, Any], list[str]]:
    """A scenario's estimator options: (those ``estimator`` receives, the keys it does not)
    (:func:`controller._registry.hand_over`)."""
    from controller._registry import hand_over

    return hand_over(estimator, options)


def option_owners(key: str, also: tuple[str, ...] = ()) -> list[str]:
    """The estimators that declare ``[estimator_options]`` key ``key``: the built-in ones and
    the plug-ins ``also``."""
    from controller._registry import ESTIMATOR_NAMES

    return [e for e in dict.fromkeys((*ESTIMATOR_NAMES, *also)) if key in estimator_keys(e)]


def _signal_range(message: Any, signal: str) -> tuple[float, float]:
    """``[min|max]`` of a DBC signal (its raw range when the DBC gives none), as encoded."""
    s = message.get_signal_by_name(signal)
    raw_lo = -(1 << (s.length - 1)) if s.is_signed else 0
    raw_hi = (1 << (s.length - 1)) - 1 if s.is_signed else (1 << s.length) - 1
    lo = raw_lo * s.scale + s.offset if s.minimum is None else s.minimum
    hi = raw_hi * s.scale + s.offset if s.maximum is None else s.maximum
    return float(lo), float(hi)


@dataclass(frozen=True, slots=True)
class _WireLimits:
    """What the DBC (``dbc/bench.dbc``) lets a scenario ask for."""

    speed_rpm: tuple[float, float]  # BenchCommand.speed_ref
    load_nm: tuple[float, float]  # BenchCommand.load_torque
    step_bits: int  # width of the narrowest step counter
    step_messages: tuple[str, ...]  # the messages that carry it

    @property
    def max_delay_steps(self) -> int:
        """Largest injected lockstep delay, periods, both directions together.

        Receivers unwrap a step counter of modulus ``2**bits`` within half of
        it; a quarter leaves the other quarter to the retransmission window.
        """
        return (1 << self.step_bits) // 4


@functools.cache
def _wire_limits() -> _WireLimits:
    from bench.wire._codec import default_codec

    codec = default_codec()
    cmd = codec.message("BenchCommand")
    widths = {n: codec.step_bits(n) for n in codec.names if codec.step_bits(n)}
    bits = min(widths.values())
    return _WireLimits(
        speed_rpm=_signal_range(cmd, "speed_ref"),
        load_nm=_signal_range(cmd, "load_torque"),
        step_bits=bits,
        step_messages=tuple(n for n, b in widths.items() if b == bits),
    )


def _check_delay_steps(src: str, lat: Latency) -> None:
    """Injected lockstep delays the step counters of the wire can carry."""
    w = _wire_limits()
    bound = w.max_delay_steps
    why = (
        f"a quarter of the {1 << w.step_bits} periods after which the {w.step_bits}-bit "
        f"step counters of {'/'.join(w.step_messages)} wrap (receivers place a frame "
        "only within half of that; the rest is the retransmission margin)"
    )
    for key in ("duty_delay_steps", "sample_delay_steps"):
        v = getattr(lat, key)
        if v > bound:
            raise ScenarioError(
                f"{src}: field 'latency.{key}': {v} periods is more than {bound}, {why}"
            )
    total = lat.duty_delay_steps + lat.sample_delay_steps
    if total > bound:
        raise ScenarioError(
            f"{src}: field 'latency': duty_delay_steps + sample_delay_steps = {total} periods "
            f"is more than {bound}, {why}"
        )


def _check_delay_us(src: str, lat: Latency, f_sw: float) -> None:
    """Injected real-time delays the step counters can carry, at the PWM rate ``f_sw``.

    A frame held longer than the lockstep bound (in periods of ``f_sw``)
    would reach a receiver that can no longer place its step counter.
    """
    bound = _wire_limits().max_delay_steps
    for key in ("duty_delay_us", "sample_delay_us"):
        v = getattr(lat, key)
        if v * 1e-6 * f_sw > bound:
            raise ScenarioError(
                f"{src}: field 'latency.{key}': {v:g} us is more than {bound} PWM periods at "
                f"{f_sw:g} Hz ({bound / f_sw * 1e6:g} us), the most the step counters carry "
                "(see latency.duty_delay_steps)"
            )


def saliency_error(
    src: str, preset: str, motor: dict[str, float], estimators: tuple[str, ...] | list[str]
) -> ScenarioError | None:
    """The error of a motor without saliency asked to run HF-injection estimators, if any.

    ``motor``: the scenario's ``[motor]`` overrides of the preset.  Checked on
    load for the scenario's estimators and again when an estimator chosen on
    the command line is built.
    """
    from controller._registry import SPECS, injection_family
    from plant_rt import PRESETS

    base = PRESETS[preset].motor
    L_d, L_q = motor.get("L_d", base.L_d), motor.get("L_q", base.L_q)
    hf = [e for e in dict.fromkeys(estimators) if injection_family(e) != "none"]
    if not hf or L_q > L_d:
        return None
    key = "L_q" if "L_q" in motor or "L_d" not in motor else "L_d"
    plain = [n for n, s in SPECS.items() if s.family == "none"]
    return ScenarioError(
        f"{src}: field 'motor.{key}': the motor is not salient (L_q {L_q:.4g} H <= L_d "
        f"{L_d:.4g} H), and the HF-injection estimators asked for ({', '.join(hf)}) need "
        f"L_q > L_d; only {', '.join(map(repr, plain))} runs without saliency "
        f'(estimator = "{plain[0]}", estimators = ["{plain[0]}"])'
    )


def _check_plausible(
    src: str, preset: str, motor: dict[str, float], inverter: dict[str, Any]
) -> None:
    """The scenario's motor against physics (:mod:`bench.scenarios._plausible`).

    Only a motor the scenario changes is checked (the presets' are the papers'
    and checked by the tests); a unit mistake names its field and unit.
    """
    if not motor and "u_dc" not in inverter:
        return
    from bench.scenarios._plausible import motor_plausibility_error
    from plant_rt import PRESETS

    p = PRESETS[preset]
    keys = ("n_p", "R_s", "L_d", "L_q", "psi_f", "i_rated", "i_max", "tau_rated", "w_m_rated", "J")
    values = {k: float(motor.get(k, getattr(p.motor, k))) for k in keys}
    values["u_dc"] = float(inverter.get("u_dc", p.inverter.u_dc))
    given = {k: f"motor.{k}" for k in motor}
    if "u_dc" in inverter:
        given["u_dc"] = "inverter.u_dc"
    if err := motor_plausibility_error(values, given):
        raise ScenarioError(f"{src}: field '{err[0]}': {err[1]}")


def scenario_path(name_or_path: str) -> Path:
    """Resolve a shipped scenario name or a user's file path."""
    p = Path(name_or_path)
    if p.suffix in (".toml", ".json") or p.exists():
        if not p.is_file():
            raise ScenarioError(f"{name_or_path}: no such scenario file")
        return p
    shipped = resources.files("bench.scenarios").joinpath(f"{name_or_path}.toml")
    if not shipped.is_file():
        raise ScenarioError(
            f"{name_or_path}: unknown scenario (shipped: {', '.join(SHIPPED)}; "
            "or give a path to a .toml file)"
        )
    return Path(str(shipped))


class _Reader:
    """Typed access to one TOML table with errors that name file and field."""

    def __init__(self, src: str, table: dict[str, Any], prefix: str = "") -> None:
        self.src = src
        self.t = table
        self.prefix = prefix

    def fail(self, key: str, reason: str) -> ScenarioError:
        return ScenarioError(f"{self.src}: field '{self.prefix}{key}': {reason}")

    def num(
        self,
        key: str,
        default: float | None = None,
        *,
        lo: float | None = None,
        hi: float | None = None,
    ) -> float:
        if key not in self.t:
            if default is None:
                raise self.fail(key, "required")
            return default
        v = self.t[key]
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise self.fail(key, f"expected a number, got {type(v).__name__} {v!r}")
        v = float(v)
        if not math.isfinite(v):
            raise self.fail(key, "must be finite")
        if lo is not None and v < lo:
            raise self.fail(key, f"must be >= {lo}, got {v}")
        if hi is not None and v > hi:
            raise self.fail(key, f"must be <= {hi}, got {v}")
        return v

    def integer(self, key: str, default: int, *, lo: int | None = None) -> int:
        v = self.t.get(key, default)
        if isinstance(v, bool) or not isinstance(v, int):
            raise self.fail(key, f"expected an integer, got {v!r}")
        if lo is not None and v < lo:
            raise self.fail(key, f"must be >= {lo}, got {v}")
        return v

    def string(self, key: str, default: str | None = None) -> str:
        if key not in self.t:
            if default is None:
                raise self.fail(key, "required")
            return default
        v = self.t[key]
        if not isinstance(v, str):
            raise self.fail(key, f"expected a string, got {v!r}")
        return v

    def boolean(self, key: str, default: bool) -> bool:
        v = self.t.get(key, default)
        if not isinstance(v, bool):
            raise self.fail(key, f"expected true or false, got {v!r}")
        return v

    def table(self, key: str, allowed: set[str] | None = None) -> _Reader:
        v = self.t.get(key, {})
        if not isinstance(v, dict):
            raise self.fail(key, "expected a table")
        if allowed is not None:
            for k in v:
                if k not in allowed:
                    raise ScenarioError(
                        f"{self.src}: field '{key}.{k}': unknown key (known: {', '.join(sorted(allowed))})"
                    )
        return _Reader(self.src, v, f"{self.prefix}{key}.")

    def profile(
        self, key: str, carried: tuple[float, float] | None = None, unit: str = ""
    ) -> Profile:
        """Breakpoints ``[[t, value], ...]``; values within ``carried`` (the
        BenchCommand signal's range) when given."""
        v = self.t.get(key, [[0.0, 0.0]])
        if not isinstance(v, list) or not v:
            raise self.fail(key, "expected a non-empty list of [time_s, value] pairs")
        pts: list[tuple[float, float]] = []
        for i, p in enumerate(v):
            if (
                not isinstance(p, list)
                or len(p) != 2
                or not all(isinstance(x, int | float) and not isinstance(x, bool) for x in p)
            ):
                raise self.fail(key, f"entry {i}: expected [time_s, value], got {p!r}")
            t, val = float(p[0]), float(p[1])
            if pts and t < pts[-1][0]:
                raise self.fail(key, f"entry {i}: times must not decrease ({t} < {pts[-1][0]})")
            if not (math.isfinite(t) and math.isfinite(val)) or t < 0:
                raise self.fail(key, f"entry {i}: time must be >= 0 and values finite")
            if carried is not None and not carried[0] <= val <= carried[1]:
                raise self.fail(
                    key,
                    f"entry {i}: {val:.10g} {unit} outside the range the BenchCommand frame "
                    f"carries ({carried[0]:g} to {carried[1]:g} {unit})",
                )
            pts.append((t, val))
        return Profile(tuple(pts))


def _parse_latency(r: _Reader) -> Latency:
    """The ``[latency]`` table; a per-direction key wins over the shared one."""
    lt = r.table(
        "latency",
        {
            "duty_delay_steps",
            "sample_delay_steps",
            "duty_delay_us",
            "sample_delay_us",
            "jitter_us",
            "jitter_dist",
            "drop_prob",
            *_LATENCY_DIRECTION_KEYS,
        },
    )
    dist = lt.string("jitter_dist", "normal")
    if dist not in ("normal", "uniform"):
        raise lt.fail("jitter_dist", f"expected 'normal' or 'uniform', got {dist!r}")

    def opt(key: str, hi: float | None) -> float | None:
        return lt.num(key, 0.0, lo=0.0, hi=hi) if key in lt.t else None

    out = Latency(
        duty_delay_steps=lt.integer("duty_delay_steps", 0, lo=0),
        sample_delay_steps=lt.integer("sample_delay_steps", 0, lo=0),
        duty_delay_us=lt.num("duty_delay_us", 0.0, lo=0.0),
        sample_delay_us=lt.num("sample_delay_us", 0.0, lo=0.0),
        jitter_us=lt.num("jitter_us", 0.0, lo=0.0),
        jitter_dist=dist,
        drop_prob=lt.num("drop_prob", 0.0, lo=0.0, hi=1.0),
        duty_jitter_us=opt("duty_jitter_us", None),
        sample_jitter_us=opt("sample_jitter_us", None),
        duty_drop_prob=opt("duty_drop_prob", 1.0),
        sample_drop_prob=opt("sample_drop_prob", 1.0),
    )
    _check_delay_steps(r.src, out)
    return out


def _parse_estimator_options(
    r: _Reader, preset: str, f_s: float, named: tuple[str, ...] = ()
) -> dict[str, Any]:
    """The ``[estimator_options]`` table, each value checked by its key's name.

    The keys of every built-in estimator are accepted (the estimator may be
    chosen on the command line; a run leaves out, with a note, the keys of the
    others), and those of the plug-ins the file names (``named``: its
    ``estimator`` and ``estimators``), checked as they declare them; a key no
    estimator declares is an error.  Amplitudes must be > 0 and within the
    inverter's linear range ``u_dc / sqrt(3)`` (space-vector modulation) of the
    preset; frequencies > 0 and below the Nyquist frequency of the sample rate
    ``f_s``.
    """
    from controller._registry import declared_options, is_plugin_name, plugin
    from plant_rt import PRESETS

    keys = estimator_option_keys()
    plugin_opts: dict[str, Any] = {}  # key -> (plug-in, Option) of the named plug-ins
    takes_any = []  # named plug-ins without a declaration that take **options
    for name in dict.fromkeys(named):
        if name in _shipped_names():
            continue
        decl = declared_options(name)
        if decl is None:
            p = plugin(name)
            if p is not None and p.keywords is None:
                takes_any.append(name)
            for k in (p.keywords or ()) if p is not None else ():
                plugin_opts.setdefault(k, (name, None))
            continue
        for k, opt in decl.items():
            plugin_opts.setdefault(k, (name, opt))
    table = r.t.get("estimator_options", {})
    if isinstance(table, dict) and not takes_any:
        for k in table:
            if k not in keys and k not in plugin_opts:
                hint = (
                    ""
                    if any(is_plugin_name(n) for n in named)
                    else "; a plug-in's options are accepted in a file that names the plug-in in "
                    "estimator or estimators, or in a run of it with --estimator"
                )
                raise ScenarioError(
                    f"{r.src}: field 'estimator_options.{k}': unknown key (known: "
                    f"{', '.join(sorted({*keys, *plugin_opts}))}): no estimator declares it{hint}"
                )
    eo = r.table("estimator_options")
    u_dc = PRESETS[preset].inverter.u_dc
    out: dict[str, Any] = {}
    for k in eo.t:
        if k not in keys:
            owner, opt = plugin_opts.get(k, (None, None))
            if opt is None:  # a plug-in without a declaration: its factory's own check
                out[k] = eo.t[k]
                continue
            of = f" (an option of {owner})"
        else:
            opt, of = shipped_options()[k], ""
        v, why = opt.check(eo.t[k])
        if why is None and v is not None:
            why = _limit_error(opt.limit, v, preset, u_dc, f_s)
        if why is not None:
            raise eo.fail(k, why + of)
        out[k] = v
    return out


def _limit_error(limit: str, v: float, preset: str, u_dc: float, f_s: float) -> str | None:
    """Why the value ``v`` of an option with the scenario bound ``limit``
    (:data:`controller._api.OPTION_LIMITS`) is out of it, or None."""
    u_lin = u_dc / math.sqrt(3.0)
    if limit == "inverter_linear" and v > u_lin:
        return (
            f"injection amplitude {v:g} V is above the inverter's linear limit "
            f"u_dc/sqrt(3) = {u_lin:.4g} V (preset {preset}, u_dc = {u_dc:g} V)"
        )
    if limit == "below_nyquist" and v >= f_s / 2.0:
        return (
            f"injection frequency {v:g} Hz is not below the Nyquist frequency "
            f"{f_s / 2.0:g} Hz of the {f_s:g} Hz sample rate"
        )
    return None


def _shipped_names() -> tuple[str, ...]:
    from controller._registry import ESTIMATOR_NAMES

    return ESTIMATOR_NAMES


def _estimator_error(name: str) -> str | None:
    """Why ``name`` is no estimator (built in or plug-in), or None."""
    from controller._registry import UnknownEstimatorError, check_estimator

    try:
        check_estimator(name)
    except UnknownEstimatorError as e:
        return str(e)
    return None


def parse_scenario(data: dict[str, Any], src: str, also: tuple[str, ...] = ()) -> Scenario:
    """Validate a scenario table (already parsed from TOML).

    ``also``: the estimators a command runs on it besides the file's
    (``--estimator``).  A plug-in among them that takes options is taken as
    named in ``estimators``: the options it declares are accepted and checked
    as the file's own, and the effective scenario of a run names it for the
    node processes.
    """
    also = tuple(e for e in dict.fromkeys(also) if _takes_options(e))
    from plant_rt import PRESETS

    for k in data:
        if k not in _TOP_KEYS:
            raise ScenarioError(
                f"{src}: field '{k}': unknown key (known: {', '.join(sorted(_TOP_KEYS))})"
            )
    r = _Reader(src, data)
    preset = r.string("preset")
    if preset not in PRESETS:
        raise r.fail("preset", f"unknown preset {preset!r} (known: {', '.join(PRESETS)})")
    estimator = r.string("estimator", "tt-dq")
    if why := _estimator_error(estimator):
        raise r.fail("estimator", why)
    ests = data.get("estimators", [estimator])
    if not isinstance(ests, list) or not all(isinstance(e, str) for e in ests):
        raise r.fail("estimators", "expected a list of estimator names")
    for e in ests:
        if why := _estimator_error(e):
            raise r.fail("estimators", why)
    f_sw = r.num("f_sw", -1.0)
    if f_sw != -1.0 and not 100.0 <= f_sw <= 100e3:
        raise r.fail("f_sw", f"must be between 100 Hz and 100 kHz, got {f_sw}")
    thd = data.get("thd_window_s")
    thd_window: tuple[float, float] | None = None
    if thd is not None:
        if (
            not isinstance(thd, list)
            or len(thd) != 2
            or not all(isinstance(x, int | float) for x in thd)
            or not thd[0] < thd[1]
        ):
            raise r.fail("thd_window_s", "expected [start_s, end_s] with start < end")
        thd_window = (float(thd[0]), float(thd[1]))
    nz = r.table("noise", {"current_std_a", "adc_bits", "adc_full_scale_a"})
    noise = Noise(
        current_std_a=nz.num("current_std_a", 0.0, lo=0.0),
        adc_bits=nz.integer("adc_bits", 0, lo=0),
        adc_full_scale_a=nz.num("adc_full_scale_a", 0.0, lo=0.0),
    )
    if noise.adc_bits and noise.adc_full_scale_a <= 0:
        raise nz.fail("adc_full_scale_a", "must be > 0 when adc_bits is set")
    latency = _parse_latency(r)
    cm = r.table("controller_model", set(MODEL_ERROR_KEYS))
    factors: dict[str, float] = {}
    for k in MODEL_ERROR_KEYS:
        v = cm.num(k, 1.0)
        if not v > 0.0:
            raise cm.fail(k, f"must be a positive factor (1.0 = exact), got {v}")
        factors[k] = v
    controller_model = ModelErrors(**factors)
    mt = r.table("motor", set(MOTOR_KEYS))
    motor: dict[str, float] = {}
    for k in MOTOR_KEYS:
        if k in mt.t:
            if k == "n_p":
                motor[k] = mt.integer(k, 0, lo=1)
            elif k in ("psi_f", "b"):
                motor[k] = mt.num(k, lo=0.0)
            else:
                v = mt.num(k)
                if not v > 0.0:
                    raise mt.fail(k, f"must be > 0, got {v}")
                motor[k] = v
    # only estimators the file names: without any, the scenario may be for an
    # external controller (bench run --controller external), and tt-dq is a default
    named = (*ests, estimator) if "estimator" in data or "estimators" in data else ()
    if err := saliency_error(r.src, preset, motor, named):
        raise err
    f_eff = PRESETS[preset].f_sw if f_sw == -1.0 else f_sw
    profile, inverter, sensors, magnetics = _parse_plant(r, 1.0 / f_eff)
    _check_plausible(r.src, preset, motor, inverter)
    controller = _parse_controller(r, 1.0 / f_eff)
    _check_delay_us(r.src, latency, f_eff)
    opts = _parse_estimator_options(r, preset, f_eff, (estimator, *ests, *also))
    paper = r.table("paper_result").t
    duration = r.num("duration", lo=1e-3)
    # default: past the start-up transient (0.5 s), or the second half of a shorter run
    score_from_s = r.num("score_from_s", min(0.5, duration / 2), lo=0.0)
    if score_from_s >= duration:
        raise r.fail(
            "score_from_s",
            f"{score_from_s} s is not before the end of the run (duration {duration} s): "
            "nothing would be scored",
        )
    return Scenario(
        name=r.string("name", Path(src[:-5]).name if src.endswith(".toml") else src),
        source=src,
        preset=preset,
        duration=duration,
        description=r.string("description", ""),
        paper=r.string("paper", ""),
        estimator=estimator,
        estimators=tuple(dict.fromkeys((*ests, *also))),
        f_sw=None if f_sw == -1.0 else f_sw,
        seed=r.integer("seed", 1, lo=0),
        saturation=r.boolean("saturation", True),
        theta_e0_deg=r.num("theta_e0_deg", 0.0),
        known_initial_angle=r.boolean("known_initial_angle", True),
        speed_rpm=r.profile("speed_rpm", _wire_limits().speed_rpm, "rpm"),
        load_nm=r.profile("load_nm", _wire_limits().load_nm, "N m"),
        reference_rate_hz=r.num("reference_rate_hz", 1000.0, lo=1.0),
        score_from_s=score_from_s,
        thd_window_s=thd_window,
        estimator_options=dict(opts),
        noise=noise,
        latency=latency,
        controller_model=controller_model,
        paper_result=dict(paper),
        motor=motor,
        plant_profile=profile,
        inverter=inverter,
        sensors=sensors,
        magnetics=magnetics,
        controller=controller,
        faults=parse_faults(
            data.get("faults"),
            src,
            duration=duration,
            f_sw=f_eff,
            max_delay_steps=_wire_limits().max_delay_steps,
        ),
    )


def _three(r: _Reader, key: str) -> float | tuple[float, float, float]:
    """One number, or [a, b, c] (a value per phase)."""
    v = r.t[key]
    if isinstance(v, list):
        if len(v) != 3 or not all(
            isinstance(x, int | float) and not isinstance(x, bool) for x in v
        ):
            raise r.fail(key, f"expected a number or [a, b, c], got {v!r}")
        if not all(math.isfinite(x) for x in v):
            raise r.fail(key, "must be finite")
        return (float(v[0]), float(v[1]), float(v[2]))
    return r.num(key)


def _parse_plant(
    r: _Reader, T_s: float
) -> tuple[str, dict[str, Any], dict[str, Any], dict[str, Any]]:
    """``plant_profile`` and the ``[inverter]``, ``[sensors]``, ``[magnetics]`` tables.

    Each table holds only the values it changes in the profile; every value is
    checked here, so a plant that cannot be built is one line at load time.
    """
    from plant_rt import PROFILE_NAMES

    profile = r.string("plant_profile", "ideal")
    if profile not in PROFILE_NAMES:
        raise r.fail(
            "plant_profile", f"unknown profile {profile!r} (known: {', '.join(PROFILE_NAMES)})"
        )
    it = r.table("inverter", set(INVERTER_KEYS))
    inverter: dict[str, Any] = {}
    for k in INVERTER_KEYS:
        if k not in it.t:
            continue
        if k == "model":
            inverter[k] = it.string(k)
            if inverter[k] not in ("average", "switching"):
                raise it.fail(k, f'expected "average" or "switching", got {inverter[k]!r}')
        elif k == "sample_at":
            inverter[k] = it.string(k)
            if inverter[k] not in ("peak", "valley"):
                raise it.fail(k, f'expected "peak" or "valley", got {inverter[k]!r}')
        elif k == "u_dc":
            inverter[k] = it.num(k)
            if not inverter[k] > 0.0:
                raise it.fail(k, f"must be > 0 V, got {inverter[k]}")
        elif k == "t_dead":
            inverter[k] = it.num(k, lo=0.0, hi=0.5 * T_s)
        else:
            inverter[k] = it.num(k, lo=0.0)
    st = r.table("sensors", set(SENSOR_KEYS))
    sensors: dict[str, Any] = {}
    for k in SENSOR_KEYS:
        if k not in st.t:
            continue
        if k in ("current_offset_a", "current_gain_error"):
            sensors[k] = _three(st, k)
        elif k == "adc_bits":
            sensors[k] = st.integer(k, 0, lo=0)
            if sensors[k] > 24:
                raise st.fail(k, f"must be at most 24 bits, got {sensors[k]}")
        elif k == "current_full_scale_a":
            sensors[k] = st.num(k)
            if not sensors[k] > 0.0:
                raise st.fail(k, f"must be > 0 A, got {sensors[k]}")
        elif k == "sample_delay_s":
            sensors[k] = st.num(k, lo=0.0)
            if not sensors[k] < T_s:
                raise st.fail(k, f"must be below one PWM period ({T_s:g} s), got {sensors[k]}")
        elif k == "encoder_counts":
            sensors[k] = st.integer(k, 0, lo=0)
            if sensors[k] > 1 << 16:
                raise st.fail(k, f"must be at most 65536 (16 bits on the wire), got {sensors[k]}")

        else:
            sensors[k] = st.num(k, lo=0.0)
    mg = r.table("magnetics", set(MAGNETICS_KEYS))
    magnetics: dict[str, Any] = {}
    for k in MAGNETICS_KEYS:
        if k not in mg.t:
            continue
        if k in ("saturation", "cross_saturation"):
            magnetics[k] = mg.boolean(k, False)
        elif k == "sigma":
            magnetics[k] = mg.num(k, lo=0.0, hi=0.99)
        elif k == "i_sat":
            magnetics[k] = mg.num(k)
            if not magnetics[k] > 0.0:
                raise mg.fail(k, f"must be > 0 A, got {magnetics[k]}")
        else:
            magnetics[k] = mg.num(k, lo=0.0)
    return profile, inverter, sensors, magnetics


def _parse_controller(r: _Reader, T_s: float) -> dict[str, Any]:
    """The ``[controller]`` table: the values it sets, each checked."""
    ct = r.table("controller", set(CONTROLLER_KEYS))
    out: dict[str, Any] = {}
    for k in CONTROLLER_KEYS:
        if k not in ct.t:
            continue
        if k in (
            "dead_time_compensation",
            "cross_saturation_compensation",
            "offset_calibration",
            "supervision",
        ):
            out[k] = ct.boolean(k, False)
        elif k == "t_dead":
            out[k] = ct.num(k, lo=0.0, hi=0.5 * T_s)
        elif k == "k_dq":
            out[k] = ct.num(k)
        elif k == "offset_periods":
            out[k] = ct.integer(k, 1, lo=1)
        elif k == "current_feedback":
            out[k] = ct.string(k)
            if out[k] not in ("filtered", "raw"):
                raise ct.fail(k, f'expected "filtered" or "raw", got {out[k]!r}')
        else:
            out[k] = ct.num(k, lo=0.0)
    return out


def scenario_from_dict(d: dict[str, Any], src: str) -> Scenario:
    """A scenario from :meth:`Scenario.to_dict` (run metadata, effective scenarios)."""
    data = {k: v for k, v in d.items() if v is not None and k != "source"}
    return parse_scenario(data, src)


def write_effective(scn: Scenario, path: Path) -> Path:
    """Write the exact scenario of a run (overrides included) for its node processes."""
    path.write_text(json.dumps(scn.to_dict(), indent=2) + "\n", encoding="utf-8")
    return path


def load_scenario(name_or_path: str, run_with: tuple[str, ...] = ()) -> Scenario:
    """Load a shipped scenario by name, or a user's TOML file by path.

    A ``.json`` file written by :func:`write_effective` (the effective
    scenario of a run, which ``bench run`` hands to its node processes) is
    read too.  ``run_with``: the estimators a command runs on it
    (``--estimator``), as :func:`parse_scenario`'s ``also``.
    """
    return _load_scenario(name_or_path, run_with)


def _takes_options(estimator: str) -> bool:
    """A plug-in (not a shipped estimator) that declares or names options; False for a name
    that does not resolve (the command checks its estimator and says why in one line)."""
    from controller._registry import SPECS, UnknownEstimatorError, plugin

    if estimator in SPECS:
        return False
    try:
        p = plugin(estimator)
    except UnknownEstimatorError:
        return False  # said where the estimator is checked
    return p is not None and (p.options is None or bool(p.options))


def _load_scenario(name_or_path: str, also: tuple[str, ...]) -> Scenario:
    path = scenario_path(name_or_path)
    if path.suffix == ".json":
        try:
            d = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError) as e:
            raise ScenarioError(f"{path}: not a scenario file: {e}") from None
        if not isinstance(d, dict):
            raise ScenarioError(f"{path}: not a scenario file")
        return scenario_from_dict(d, str(d.get("source", path)))
    src = name_or_path if not Path(name_or_path).exists() else str(path)
    scn = parse_scenario(_resolved_toml(path, src, ()), src, also)
    own = _read_toml(path)
    if "extends" not in own:  # every value checked first: a wrong one is named before this
        _check_options_have_a_motor(src, own)
    return scn


def _read_toml(path: Path) -> dict[str, Any]:
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as e:
        raise ScenarioError(f"{path}: not valid TOML: {e}") from None
    except OSError as e:
        raise ScenarioError(f"{path}: cannot read: {e.strerror}") from None


def _check_options_have_a_motor(src: str, data: dict[str, Any]) -> None:
    """Injection settings belong to a motor: a file that sets them names it in ``[motor]``.

    A file of its own (not ``extends``: a shipped scenario is a motor and its
    settings together) whose ``[estimator_options]`` came without ``[motor]``
    would run the preset's motor with settings tuned for another: amplitude,
    frequency and filters are designed from ``L_d``, ``L_q`` and the rate.
    An empty ``[motor]`` table says that the preset's motor is meant.
    """
    opts = data.get("estimator_options")
    if isinstance(opts, dict) and opts and "motor" not in data:
        preset = data.get("preset", "?")
        raise ScenarioError(
            f"{src}: field 'estimator_options': injection settings "
            f"({', '.join(sorted(opts))}) without a [motor] table would run preset "
            f"{preset}'s motor with them; give the motor they are for in [motor] "
            "(an empty [motor] table keeps the preset's)"
        )


def _resolved_toml(path: Path, src: str, seen: tuple[Path, ...]) -> dict[str, Any]:
    """The TOML table of ``path`` with its ``extends`` chain merged in, base first.

    ``extends`` names a shipped scenario or a path (relative to the file that
    names it); the file's keys replace the base's, tables merged key by key
    (a profile such as ``speed_rpm`` is one value, replaced whole).  The
    base's ``name`` is not inherited: a file is named after itself.
    """
    data = _read_toml(path)
    base_name = data.pop("extends", None)
    if base_name is None:
        return data
    if not isinstance(base_name, str):
        raise ScenarioError(f"{src}: field 'extends': expected a scenario name or path")
    rel = path.parent / base_name
    base_path = scenario_path(str(rel) if rel.suffix == ".toml" and rel.exists() else base_name)
    key = base_path.resolve()
    if key in seen or key == path.resolve():
        raise ScenarioError(f"{src}: field 'extends': {base_name} extends itself (a cycle)")
    if base_path.suffix != ".toml":
        raise ScenarioError(f"{src}: field 'extends': {base_name} is not a TOML scenario")
    base = _resolved_toml(base_path, base_name, (*seen, path.resolve()))
    base.pop("name", None)
    merged = dict(base)
    for k, v in data.items():
        if isinstance(v, dict) and isinstance(merged.get(k), dict):
            merged[k] = {**merged[k], **v}
        else:
            merged[k] = v
    return merged
