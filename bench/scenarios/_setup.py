"""From a scenario to the objects of a run: plant, controller, command schedule.

Every node (plant process, controller process, in-process loop) builds its
objects here, so they agree on the motor, the rate and the references.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

from bench._errors import ScenarioError
from bench.scenarios._schema import ModelErrors, Scenario, saliency_error
from bench.wire._protocol import CMD_START, CMD_STOP, RPM_PER_RAD_S
from controller import Controller, ControllerPars, MotorModel
from controller._registry import ESTIMATOR_NAMES, injection_family
from plant_rt import ConstantLoad, Plant, Preset, SensorPars, preset


@dataclass(frozen=True, slots=True)
class PlannedCommand:
    """A bench command and the step it applies at."""

    apply_step: int
    cmd: int
    speed_ref_rpm: float
    load_nm: float


def get_preset(scn: Scenario) -> Preset:
    """The scenario's preset, with its ``[motor]`` parameters in place of the preset's."""
    try:
        p = preset(scn.preset)
    except KeyError as e:
        raise ScenarioError(f"{scn.source}: field 'preset': {e.args[0] if e.args else e}") from None
    if not scn.motor:
        return p
    over: dict[str, Any] = dict(scn.motor)  # n_p an int, the rest floats (checked on load)
    try:
        motor = replace(p.motor, **over)
    except (ValueError, TypeError) as e:
        raise ScenarioError(f"{scn.source}: field 'motor': {e}") from None
    given = ", ".join(f"{k} = {v:g}" for k, v in scn.motor.items())
    return replace(
        p, motor=motor, doc=f"{p.doc}\n\nReplaced by the scenario's [motor] table: {given}."
    )


def sample_period(scn: Scenario) -> float:
    """PWM (= control) period of the scenario (s)."""
    return 1.0 / (scn.f_sw or get_preset(scn).f_sw)


def n_steps(scn: Scenario) -> int:
    return int(round(scn.duration / sample_period(scn)))


def lockstep_delay(scn: Scenario) -> int:
    return scn.latency.duty_delay_steps + scn.latency.sample_delay_steps


def build_plant(scn: Scenario, engine: str = "auto") -> Plant:
    """The scenario's plant; ``engine`` as :class:`plant_rt.Plant`'s (``--engine``)."""
    p = get_preset(scn)
    nz = scn.noise
    sensors = SensorPars(
        bits=nz.adc_bits or None,
        i_fs=nz.adc_full_scale_a or 50.0,
        noise_i=nz.current_std_a,
        seed=scn.seed,
    )
    theta_m0 = math.radians(scn.theta_e0_deg) / p.motor.n_p
    return Plant(
        p.motor,
        p.inverter,
        sample_period(scn),
        sensors=sensors,
        load=ConstantLoad(scn.load_nm(0.0)),
        saturation=scn.saturation,
        theta_m0=theta_m0,
        engine=engine,
    )


def motor_model(p: Preset, errors: ModelErrors | None = None) -> MotorModel:
    """The controller's copy of the motor parameters.

    Parameters
    ----------
    p : Preset
        The plant's preset; its parameters are read, never changed.
    errors : ModelErrors, optional
        Factors on ``R_s``, ``L_d``, ``L_q``, ``psi_f`` and ``J`` (the
        scenario's ``[controller_model]`` table); ``None``: the nominal values.
    """
    m = p.motor
    e = errors or ModelErrors()
    return MotorModel(
        n_p=m.n_p,
        R_s=m.R_s * e.R_s,
        L_d=m.L_d * e.L_d,
        L_q=m.L_q * e.L_q,
        psi_f=m.psi_f * e.psi_f,
        J=m.J * e.J,
        b=m.b,
        i_max=m.i_max,
        tau_max=1.5 * m.tau_rated,
    )


def build_controller(scn: Scenario, estimator: str) -> Controller:
    if estimator not in ESTIMATOR_NAMES:
        raise ScenarioError(
            f"unknown estimator {estimator!r} (known: {', '.join(ESTIMATOR_NAMES)})"
        )
    p = get_preset(scn)
    kw: dict[str, Any] = {}
    if estimator == "sensored":
        kw["startup"] = False
    elif scn.known_initial_angle:
        kw["startup"] = False
        kw["theta0"] = math.radians(scn.theta_e0_deg)
    model = motor_model(p, scn.controller_model)
    if err := saliency_error(scn.source, scn.preset, scn.motor, [estimator]):
        raise err
    if injection_family(estimator) != "none" and not model.L_q > model.L_d:
        raise ScenarioError(
            f"{scn.source}: field 'controller_model': the factors L_d = {scn.controller_model.L_d} "
            f"and L_q = {scn.controller_model.L_q} leave the controller's model without "
            f"saliency (L_q {model.L_q:.4g} H <= L_d {model.L_d:.4g} H), which {estimator} needs"
        )
    try:
        pars = ControllerPars(
            motor=model,
            T_s=sample_period(scn),
            estimator=estimator,
            estimator_options=dict(scn.estimator_options),
            **kw,
        )
        return Controller(pars)
    except TypeError as e:
        raise ScenarioError(f"{scn.source}: field 'estimator_options': {e}") from None


def command_schedule(scn: Scenario) -> list[PlannedCommand]:
    """The bench commands of a run, one per reference change.

    References are evaluated every ``1 / reference_rate_hz`` (a ramp becomes
    a staircase at that rate, as a drive receiving set-points at 1 kHz sees
    it) and at every breakpoint of the profiles, so steps happen at the
    exact period the scenario names.  The first command starts the run at
    step 0; the last stops it after ``duration``.
    """
    T_s = sample_period(scn)
    n = n_steps(scn)
    every = max(1, int(round(1.0 / (scn.reference_rate_hz * T_s))))
    ticks = set(range(0, n, every))
    for t, _ in (*scn.speed_rpm.points, *scn.load_nm.points):
        k = int(round(t / T_s))
        if 0 <= k < n:
            ticks.add(k)
    out = [PlannedCommand(0, CMD_START, scn.speed_rpm(0.0), scn.load_nm(0.0))]
    last = (out[0].speed_ref_rpm, out[0].load_nm)
    for k in sorted(ticks - {0}):
        t = k * T_s
        val = (scn.speed_rpm(t), scn.load_nm(t))
        if val != last:
            out.append(PlannedCommand(k, 0, val[0], val[1]))
            last = val
    out.append(PlannedCommand(n, CMD_STOP, last[0], last[1]))
    return out


def rad_s(rpm: float) -> float:
    return rpm / RPM_PER_RAD_S


def check_estimator_fits(scn: Scenario, est: str) -> None:
    """Build the controller once, so a misfit is one line before any process starts."""
    try:
        build_controller(scn, est)
    except (ValueError, TypeError) as e:
        raise ScenarioError(
            f"--estimator {est}: cannot run scenario {scn.name} ({e}); "
            f"the scenario's estimators: {', '.join(scn.estimators)}"
        ) from None
