"""From a scenario to the objects of a run: plant, controller, command schedule.

Every node (plant process, controller process, in-process loop) builds its
objects here, so they agree on the motor, the rate and the references.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

from bench._errors import ScenarioError
from bench.scenarios._schema import (
    ModelErrors,
    Scenario,
    option_owners,
    saliency_error,
    split_options,
)
from bench.wire._protocol import CMD_NONE, CMD_START, CMD_STOP, RPM_PER_RAD_S
from controller import (
    CompensationPars,
    Controller,
    ControllerPars,
    DesignRecord,
    MotorModel,
    SupervisionPars,
)
from controller._registry import EstimatorSpec, UnknownEstimatorError, check_estimator
from controller._registry import spec as _spec
from plant_rt import (
    ConstantLoad,
    InverterPars,
    MotorPars,
    Plant,
    PlantProfile,
    Preset,
    SensorPars,
    plant_profile,
    preset,
)


@dataclass(frozen=True, slots=True)
class PlannedCommand:
    """A bench command and the step it applies at."""

    apply_step: int
    cmd: int
    speed_ref_rpm: float
    load_nm: float


#: Lockstep pacing: a bench command (a keep-alive when nothing changes) at
#: least every this many periods; see :attr:`bench.nodes._plant_node.PlantNode.pace_every`.
PACE_EVERY = 100


def with_keepalives(plan: Sequence[PlannedCommand], pace_every: int) -> list[PlannedCommand]:
    """``plan`` with a keep-alive (``cmd`` 0, the references already in force, so nothing
    changes) at every multiple of ``pace_every`` before the last command that has no
    command of its own, in step order: the pace tokens of a paced lockstep plant
    (:attr:`bench.nodes._plant_node.PlantNode.pace_every`); each is a command of its
    own (a ``seq`` of its own).  ``pace_every <= 0``: ``plan`` as it is."""
    out = list(plan)
    if pace_every <= 0 or not out:
        return out
    have = {c.apply_step for c in out}
    extra = []
    j = 0
    for k in range(pace_every, out[-1].apply_step, pace_every):
        while j + 1 < len(out) and out[j + 1].apply_step < k:
            j += 1
        if k not in have:
            c = out[j]
            extra.append(PlannedCommand(k, CMD_NONE, c.speed_ref_rpm, c.load_nm))
    return sorted([*out, *extra], key=lambda c: c.apply_step)


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


#: ``[sensors]`` key -> the :class:`plant_rt.SensorPars` fields it sets.
_SENSOR_FIELDS = {
    "adc_bits": ("bits",),
    "current_full_scale_a": ("i_fs",),
    "current_offset_a": ("offset_abc",),
    "current_gain_error": ("gain_abc",),
    "current_noise_a": ("noise_i",),
    "sample_delay_s": ("t_delay",),
    "encoder_counts": ("encoder_counts",),
    "encoder_rate_hz": ("encoder_rate_hz",),
    "encoder_delay_s": ("encoder_delay_s",),
}


#: Counts per revolution of the position sensor a controller under test gets
#: (``bench run --controller external``, ``bench plant --dut-timeout``) when
#: the scenario states none (``[sensors] encoder_counts`` 0): the resolution of
#: the ``PositionSensor.theta_m`` signal itself (16 bits), as a 16-bit
#: resolver-to-digital converter reads it, so the sensor adds no error the
#: frame would not add anyway. A drive under test needs its sensor, and the
#: recorder's ``PlantTruth`` is no sensor (docs/PROTOCOL.md).
EXTERNAL_ENCODER_COUNTS = 1 << 16


def with_position_sensor(scn: Scenario) -> Scenario:
    """The scenario with a position sensor: its own, or :data:`EXTERNAL_ENCODER_COUNTS`.

    The scenario's ``encoder_rate_hz`` and ``encoder_delay_s`` stay (default:
    one reading per PWM period, no delay). The sensor changes no number of the
    plant: it only adds the ``PositionSensor`` frame.
    """
    if plant_setup(scn)[1].sensors.encoder_counts > 0:
        return scn
    return replace(scn, sensors={**scn.sensors, "encoder_counts": EXTERNAL_ENCODER_COUNTS})


def position_sensor(scn: Scenario) -> dict[str, Any]:
    """What a controller under test reads in ``PositionSensor`` (``bench show``).

    ``counts`` per mechanical revolution, one reading every ``every`` PWM
    periods (``rate_hz`` readings per second), each ``delay_s`` old.
    """
    sp = plant_setup(with_position_sensor(scn))[1].sensors
    T_s = sample_period(scn)
    every = sp.encoder_every(T_s)
    return {
        "frame": "PositionSensor",
        "counts": sp.encoder_counts,
        "every": every,
        "rate_hz": 1.0 / (every * T_s),
        "delay_s": sp.encoder_delay_s,
        "default": plant_setup(scn)[1].sensors.encoder_counts == 0,
    }


def plant_setup(scn: Scenario) -> tuple[Preset, PlantProfile]:
    """The plant of a scenario: its motor preset and its effective profile.

    The profile (``plant_profile``, :mod:`plant_rt._profiles`) gives the
    inverter, the sensors and the magnetic effects; the scenario's
    ``[inverter]``, ``[sensors]`` and ``[magnetics]`` tables (and the older
    ``[noise]`` table and top-level ``saturation``) change single values of it.
    ``[magnetics]`` ``sigma``, ``i_sat`` and ``c_dq`` change the motor's.
    """
    p = get_preset(scn)
    mg = scn.magnetics
    sat = p.motor.sat
    if "sigma" in mg or "i_sat" in mg:
        sat = replace(sat, **{k: mg[k] for k in ("sigma", "i_sat") if k in mg})
    cross = replace(p.motor.cross, c_dq=mg["c_dq"]) if "c_dq" in mg else p.motor.cross
    if sat is not p.motor.sat or cross is not p.motor.cross:
        p = replace(p, motor=replace(p.motor, sat=sat, cross=cross))
    try:
        return _plant_setup(scn, p, mg)
    except ValueError as e:  # a combination the plant refuses (each value was checked on load)
        raise ScenarioError(f"{scn.source}: plant ({scn.plant_profile} profile): {e}") from None


def _plant_setup(scn: Scenario, p: Preset, mg: dict[str, Any]) -> tuple[Preset, PlantProfile]:
    prof = plant_profile(scn.plant_profile, p, scn.seed)
    nz = scn.noise
    legacy: dict[str, Any] = {"seed": scn.seed}
    if nz.adc_bits:
        legacy.update(bits=nz.adc_bits, i_fs=nz.adc_full_scale_a or 50.0)
    if nz.current_std_a:
        legacy["noise_i"] = nz.current_std_a
    sensors = replace(prof.sensors, **legacy)
    if scn.sensors:
        given = SensorPars.from_keys(**scn.sensors)
        fields = [f for k in scn.sensors for f in _SENSOR_FIELDS[k]]
        sensors = replace(sensors, **{f: getattr(given, f) for f in fields})
    inverter = replace(prof.inverter, **scn.inverter)
    return p, replace(
        prof,
        inverter=inverter,
        sensors=sensors,
        saturation=bool(mg.get("saturation", scn.saturation)),
        cross_saturation=bool(mg.get("cross_saturation", prof.cross_saturation)),
    )


@dataclass(frozen=True, slots=True)
class PlantBuild:
    """The arguments of a scenario's :class:`plant_rt.Plant`, as built (:func:`plant_build`):
    what a run's plan hands the plant node (:mod:`bench.nodes._plan`)."""

    motor: MotorPars
    inverter: InverterPars
    T_s: float
    sensors: SensorPars
    load_nm0: float
    saturation: bool
    cross_saturation: bool
    theta_m0: float

    def build(self, engine: str = "auto") -> Plant:
        """The plant; ``engine`` as :class:`plant_rt.Plant`'s (``--engine``)."""
        return Plant(
            self.motor,
            self.inverter,
            self.T_s,
            sensors=self.sensors,
            load=ConstantLoad(self.load_nm0),
            saturation=self.saturation,
            cross_saturation=self.cross_saturation,
            theta_m0=self.theta_m0,
            engine=engine,
        )


def plant_build(scn: Scenario) -> PlantBuild:
    """The scenario's plant as built: preset, profile and tables in place."""
    p, prof = plant_setup(scn)
    return PlantBuild(
        p.motor,
        prof.inverter,
        sample_period(scn),
        prof.sensors,
        scn.load_nm(0.0),
        prof.saturation,
        prof.cross_saturation,
        math.radians(scn.theta_e0_deg) / p.motor.n_p,
    )


def build_plant(scn: Scenario, engine: str = "auto") -> Plant:
    """The scenario's plant; ``engine`` as :class:`plant_rt.Plant`'s (``--engine``)."""
    return plant_build(scn).build(engine)


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


#: The environment variable that holds ``--engine`` for the controllers built without an
#: engine: the CLI sets it, and the controller processes a run starts inherit it.
ENGINE_ENV = "CAN_HIL_ENGINE"
#: The engine value of a node whose whole per-period loop runs in C (bench/nodes/native).
NATIVE = "native"


def estimator_spec(estimator: str) -> EstimatorSpec:
    """The registry entry of ``estimator`` (:class:`controller.EstimatorSpec`); an unknown or
    broken one is a :class:`ScenarioError` (one line)."""
    try:
        return _spec(estimator)
    except UnknownEstimatorError as e:
        raise ScenarioError(str(e)) from None


def needs_truth(estimator: str) -> bool:
    """The estimator reads the plant's truth (its spec's ``needs_truth``: the sensored
    baseline); False for a name that no longer resolves (a recorded plug-in)."""
    try:
        return _spec(estimator).needs_truth
    except UnknownEstimatorError:
        return False


def proposed_methods() -> dict[str, str]:
    """Paper (``wen``, ``xue``) -> the estimator it proposes (its spec's ``proposed_in``)."""
    from controller._registry import SPECS

    return {s.proposed_in: name for name, s in SPECS.items() if s.proposed_in}


def build_controller(
    scn: Scenario, estimator: str, engine: str | None = None, *, cached: bool = False
) -> Controller:
    """The scenario's controller for ``estimator`` (:func:`controller_pars`).

    ``engine`` as :class:`controller.Controller`'s (compiled where the
    compiled controller covers the estimator, else Python); None takes
    :data:`ENGINE_ENV` (``--engine``), else ``"auto"``. ``cached``: built from
    the design kept for its settings when there is one, and its design kept
    (:mod:`bench.scenarios._designs`).
    """
    pars = controller_pars(scn, estimator)
    design = None
    if cached:
        from bench.scenarios._designs import load_design

        design = load_design(pars)
    try:
        ctrl = Controller(pars, engine or os.environ.get(ENGINE_ENV) or "auto", design=design)
        if cached:
            from bench.scenarios._designs import store_design

            made = ctrl.design_record()
            if made != design:
                store_design(pars, made)
        return ctrl
    except TypeError as e:
        raise ScenarioError(f"{scn.source}: field 'estimator_options': {e}") from None


def controller_pars(scn: Scenario, estimator: str) -> ControllerPars:
    """The settings of the scenario's controller for ``estimator``, as built: what a
    run's plan hands the controller node (:mod:`bench.nodes._plan`)."""
    try:
        check_estimator(estimator)
    except UnknownEstimatorError as e:
        raise ScenarioError(str(e)) from None
    spec = estimator_spec(estimator)
    p = get_preset(scn)
    kw: dict[str, Any] = {}
    if spec.needs_truth:  # it knows the angle: no start-up
        kw["startup"] = False
    elif scn.known_initial_angle:
        kw["startup"] = False
        kw["theta0"] = math.radians(scn.theta_e0_deg)
    model = motor_model(p, scn.controller_model)
    comp, k_dq = _countermeasures(scn)
    if k_dq is not None:
        model = replace(model, k_dq=k_dq)
    if scn.controller.get("current_feedback"):
        kw["current_feedback"] = scn.controller["current_feedback"]
    if err := saliency_error(scn.source, scn.preset, scn.motor, [estimator]):
        raise err
    if spec.family != "none" and not model.L_q > model.L_d:
        raise ScenarioError(
            f"{scn.source}: field 'controller_model': the factors L_d = {scn.controller_model.L_d} "
            f"and L_q = {scn.controller_model.L_q} leave the controller's model without "
            f"saliency (L_q {model.L_q:.4g} H <= L_d {model.L_d:.4g} H), which {estimator} needs"
        )
    # the options the estimator declares; the others are for the scenario's other
    # estimators (options_note says so)
    options, _ = split_options(scn.estimator_options, estimator)
    try:
        return ControllerPars(
            motor=model,
            T_s=sample_period(scn),
            estimator=estimator,
            estimator_options=options,
            compensation=comp,
            supervision=supervision_pars(scn, model),
            **kw,
        )
    except TypeError as e:
        raise ScenarioError(f"{scn.source}: field 'estimator_options': {e}") from None


def supervision_on(scn: Scenario) -> bool:
    """Whether the scenario's controller runs the supervision (:mod:`controller._supervision`).

    ``[controller] supervision`` when the scenario sets it; else on where
    the scenario has a ``[[faults]]`` timeline. Off otherwise, so the paper
    scenarios keep their traces and speed.
    """
    return bool(scn.controller.get("supervision", bool(scn.faults)))


def supervision_pars(scn: Scenario, model: MotorModel) -> SupervisionPars | None:
    """The supervision's thresholds for the scenario's drive, or None when it is off.

    The ratings and sensors are the plant's as built, as a drive's firmware is
    configured for its own bridge, sensors and supply: the inverter's nominal
    ``u_dc``, the power stage's over-voltage trip
    (:meth:`plant_rt.ProtectionPars.from_preset`), the current converter's full
    scale, LSB, noise and offsets, the DC-link converter's LSB and noise; the
    wire's resolution and range (``PhaseSamples``) where they are coarser.
    """
    if not supervision_on(scn):
        return None
    from bench.wire._codec import default_codec
    from plant_rt import ProtectionPars

    p, prof = plant_setup(scn)
    inv, sens = prof.inverter, prof.sensors
    msg = default_codec().message("PhaseSamples")
    sig_i = msg.get_signal_by_name("i_a")
    sig_u = msg.get_signal_by_name("u_dc")
    i_fs = min(float(sig_i.maximum or 0.0), sens.i_fs) if sens.bits else float(sig_i.maximum or 0.0)
    i_lsb = max(float(sig_i.scale), 2.0 * sens.i_fs / (1 << sens.bits) if sens.bits else 0.0)
    u_lsb = max(float(sig_u.scale), sens.u_fs / (1 << sens.bits) if sens.bits else 0.0)
    prot = ProtectionPars.from_preset(p.motor, inv)
    return SupervisionPars.design(
        T_s=sample_period(scn),
        L_q=model.L_q,
        u_dc=inv.u_dc,
        u_dc_trip=prot.u_dc_trip,
        i_max=model.i_max,
        i_fs=i_fs,
        i_lsb=i_lsb,
        i_noise=float(sens.noise_i),
        i_offset=max(abs(float(o)) for o in sens.offset_abc),
        u_lsb=u_lsb,
        u_noise=float(sens.noise_u),
    )


#: The ``[controller]`` switches of the drive's countermeasures, in the order they are named.
COUNTERMEASURES = ("dead_time_compensation", "cross_saturation_compensation", "offset_calibration")
#: How titles and tables name each countermeasure.
COUNTERMEASURE_LABELS = {
    "dead_time_compensation": "dead-time comp.",
    "cross_saturation_compensation": "cross-saturation comp.",
    "offset_calibration": "offset calibration",
}


def countermeasures(scn: Scenario) -> dict[str, bool]:
    """Which of :data:`COUNTERMEASURES` the scenario's controller runs.

    A ``[controller]`` switch the scenario sets wins. One it leaves open
    follows what the scenario tells the controller about its own hardware,
    as a drive's firmware is configured for the bridge, sensors and motor it
    drives:

    - ``dead_time_compensation``: on when the controller's bridge has a dead
      time or device drops (its ``t_dead``, ``v_ce``, ``v_f``, which default
      to the plant's inverter): the firmware programs the dead time into its
      PWM unit, so it knows it.
    - ``offset_calibration``: on when the current sensors have an offset
      (``[sensors] current_offset_a``, the ``drive`` profile's): a drive
      measures its offsets at standstill before every start, since a
      sensor's zero drifts.
    - ``cross_saturation_compensation``: on when the plant's magnetics have
      cross-saturation (``[magnetics] cross_saturation`` with a ``c_dq`` other
      than 0, the ``drive`` profile's) or the ``[controller]`` table gives a
      ``k_dq`` other than 0: the offset it corrects is a property of the
      motor, identified with its inductances at commissioning (the same
      flux map the plant runs), not something an estimator can observe.

    On the ``ideal`` profile (no dead time, drops, offsets or cross-saturation)
    everything is off, so the papers' plant sees the papers' controller.
    """
    p, prof = plant_setup(scn)
    c = scn.controller
    inv = prof.inverter
    bridge = any(float(c.get(k, getattr(inv, k))) > 0.0 for k in ("t_dead", "v_ce", "v_f"))
    offsets = any(o != 0.0 for o in prof.sensors.offset_abc)
    cross = (prof.cross_saturation and p.motor.cross.c_dq != 0.0) or float(
        c.get("k_dq", 0.0)
    ) != 0.0
    default = {
        "dead_time_compensation": bridge,
        "cross_saturation_compensation": cross,
        "offset_calibration": offsets,
    }
    return {k: bool(c.get(k, default[k])) for k in COUNTERMEASURES}


def countermeasures_text(on: dict[str, bool] | None) -> str:
    """``"dead-time comp., offset calibration"``, ``"none"``, or ``"the controller's own"``
    (``None``: a controller under test, whose firmware the bench does not know)."""
    if on is None:
        return "the controller's own"
    return ", ".join(COUNTERMEASURE_LABELS[k] for k in COUNTERMEASURES if on.get(k)) or "none"


def _countermeasures(scn: Scenario) -> tuple[CompensationPars, float | None]:
    """The countermeasures (:func:`countermeasures`) with the controller's settings, and
    the model's ``k_dq`` (None: kept).

    What the ``[controller]`` table leaves open comes from the plant as built,
    as a drive's designer configures it for the bridge and motor it drives:
    the dead time and device drops of the plant's inverter; the current
    sensors' noise and LSB (2 full scale / 2^bits) for the offset
    calibration's length; and the cross-saturation coefficient from the
    plant's flux map at ``i_d = 0`` (:class:`plant_rt.CrossSaturationPars`:
    ``L_dq = -c_dq (i_d + psi_f / L_d) i_q``, so ``k_dq = -c_dq psi_f / L_d``).
    """
    on = countermeasures(scn)
    c = scn.controller
    if not c and not any(on.values()):
        return CompensationPars(), None
    p, prof = plant_setup(scn)
    inv, sens = prof.inverter, prof.sensors
    lsb = 2.0 * sens.i_fs / (1 << sens.bits) if sens.bits else 0.0
    comp = CompensationPars(
        dead_time=on["dead_time_compensation"],
        t_dead=float(c.get("t_dead", inv.t_dead)),
        v_ce=float(c.get("v_ce", inv.v_ce)),
        v_f=float(c.get("v_f", inv.v_f)),
        cross_saturation=on["cross_saturation_compensation"],
        offset_calibration=on["offset_calibration"],
        offset_periods=c.get("offset_periods"),
        current_noise=float(sens.noise_i),
        adc_lsb=lsb,
    )
    k_dq: float | None = None
    if comp.cross_saturation:
        m = p.motor
        k_dq = float(c.get("k_dq", -m.cross.c_dq * m.psi_f / m.L_d))
    return comp, k_dq


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


def check_estimator_name(est: str, option: str = "--estimator") -> str:
    """The one-line error of an unknown estimator or a broken plug-in; its family otherwise."""
    from bench._errors import BenchError

    try:
        return check_estimator(est)
    except UnknownEstimatorError as e:
        raise BenchError(f"{option}: {e}") from None


def check_estimator_fits(scn: Scenario, est: str) -> str | None:
    """Build the controller once, so a misfit is one line before any run starts.

    Returns the line to tell the user when some of the scenario's estimator
    options are left out (:func:`options_note`: one scenario serves every
    estimator, each takes the options it declares; ``sensored`` takes none).
    """
    check_estimator_name(est)
    build_controller_check(scn, est)
    return options_note(scn, est)


def checked_design(scn: Scenario, est: str) -> tuple[str | None, DesignRecord]:
    """:func:`check_estimator_fits`, and the design of the controller it built
    (:meth:`controller.Controller.design_record`), which ``bench run`` hands its
    controller node in the run's plan so that the design is made once; made
    once for the same settings and code, too (:mod:`bench.scenarios._designs`)."""
    check_estimator_name(est)
    ctrl = build_controller_check(scn, est, cached=True)
    return options_note(scn, est), ctrl.design_record()


def build_controller_check(scn: Scenario, est: str, *, cached: bool = False) -> Controller:
    """Build the controller once; a misfit is a :class:`ScenarioError` of one line
    (:func:`check_estimator_fits` without its note); returns the controller.
    ``cached``: as :func:`build_controller`'s."""
    try:
        return build_controller(scn, est, cached=cached)
    except (ValueError, TypeError) as e:
        raise ScenarioError(
            f"--estimator {est}: cannot run scenario {scn.name} ({e}); "
            f"the scenario's estimators: {', '.join(scn.estimators)}"
        ) from None


def options_note(scn: Scenario, est: str) -> str | None:
    """The line that says which of the scenario's ``[estimator_options]`` ``est`` leaves out
    (a scenario serves every estimator; each takes the options it declares), or None."""
    foreign = left_out_options(scn, est)
    if not foreign:
        return None
    owners = {k: option_owners(k, scn.estimators) for k in foreign}
    of = "; ".join(f"{k}: {', '.join(o) or '?'}" for k, o in owners.items())
    return (
        f"note: {est} leaves out the scenario's estimator options {', '.join(foreign)} "
        f"(options of other estimators: {of})"
    )


def left_out_options(scn: Scenario, est: str) -> list[str]:
    """The keys of the scenario's ``[estimator_options]`` estimator ``est`` does not take."""
    return split_options(scn.estimator_options, est)[1]
