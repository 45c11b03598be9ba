"""What a controller author needs to know about a scenario, as plain data.

``bench show`` prints it; ``bench list`` lists what exists.  The motor is
the preset with the scenario's ``[motor]`` values in place, the plant the
profile as built, and the commands are the frames the bench sends:
``BenchCommand`` with the step it applies at, the command code, the speed
reference (rpm, mechanical) and the load torque (N m).  The same schedule in
compact form (:func:`schedule`) is what a reader wants: the speed and load
profiles as constant, ramp and step segments, and how many frames each
segment takes (a ramp is sent as a staircase at ``reference_rate_hz``).
"""

from __future__ import annotations

import itertools
from dataclasses import asdict
from typing import Any

from bench.scenarios._schema import SHIPPED, Profile, Scenario, load_scenario
from bench.scenarios._setup import (
    PACE_EVERY,
    command_schedule,
    n_steps,
    plant_setup,
    sample_period,
    with_keepalives,
)

#: Kinds of a schedule segment (:func:`profile_segments`).
SEGMENT_KINDS = ("constant", "ramp", "step")


def cmd_names() -> dict[int, str]:
    """``BenchCommand.cmd`` names, from the DBC's value table (``none``: new references only)."""
    from bench.wire._codec import default_codec

    sig = default_codec().message("BenchCommand").get_signal_by_name("cmd")
    return {int(k): str(v) for k, v in (sig.choices or {}).items()}


def profile_segments(prof: Profile, duration: float) -> list[dict[str, Any]]:
    """A profile over ``0 .. duration`` as segments, in time order.

    Each segment is ``{"kind", "t0_s", "t1_s", "v0", "v1"}``: ``constant``
    (``v0 == v1`` from ``t0_s`` to ``t1_s``), ``ramp`` (linear from ``v0`` to
    ``v1``) or ``step`` (``t0_s == t1_s``: the value jumps from ``v0`` to
    ``v1``).  Adjacent constants of one value are one segment; a ramp cut by
    the end of the run ends at the value it reaches there.
    """
    pts = prof.points
    segs: list[dict[str, Any]] = []

    def add(kind: str, t0: float, t1: float, v0: float, v1: float) -> None:
        last = segs[-1] if segs else None
        if (
            kind == "constant"
            and last is not None
            and last["kind"] == "constant"
            and last["v1"] == v0
            and last["t1_s"] == t0
        ):
            last["t1_s"] = t1
            return
        segs.append({"kind": kind, "t0_s": t0, "t1_s": t1, "v0": v0, "v1": v1})

    if pts[0][0] > 0.0:
        add("constant", 0.0, min(pts[0][0], duration), pts[0][1], pts[0][1])
    for (t0, v0), (t1, v1) in itertools.pairwise(pts):
        if t0 >= duration:
            break
        if t1 == t0:
            if v1 != v0:
                add("step", t0, t0, v0, v1)
        elif v1 == v0:
            add("constant", max(t0, 0.0), min(t1, duration), v0, v0)
        else:
            end = min(t1, duration)
            add("ramp", t0, end, v0, prof(end) if end < t1 else v1)
    if pts[-1][0] < duration:
        add("constant", max(pts[-1][0], 0.0), duration, pts[-1][1], pts[-1][1])
    return segs


def schedule(scn: Scenario) -> dict[str, Any]:
    """The command schedule in compact form: what ``bench show`` and ``bench codegen`` print.

    ``speed_rpm`` and ``load_nm``: :func:`profile_segments` of the two
    profiles, each with ``frames``, the number of ``BenchCommand`` frames
    (other than start and stop) that apply within it (``t0_s < t <= t1_s``;
    a step's own frame included); ``frames``: every frame, start and stop
    included; ``frames_lockstep``: the same with the keep-alives ``bench run`` adds in
    lockstep (one wherever :data:`PACE_EVERY` periods pass without a command, each a
    command of its own: its own ``seq``); ``reference_rate_hz``: the staircase rate of a
    ramp; ``start_step``/``stop_step``: the periods the start and the stop apply in.
    """
    T_s = sample_period(scn)
    cmds = command_schedule(scn)
    out: dict[str, Any] = {}
    for j, (key, prof) in enumerate((("speed_rpm", scn.speed_rpm), ("load_nm", scn.load_nm))):
        segs = profile_segments(prof, scn.duration)
        for g in segs:
            g["frames"] = 0
        values = [(c.speed_ref_rpm, c.load_nm)[j] for c in cmds]
        for c, before, now in zip(cmds[1:-1], values, values[1:], strict=False):
            if now != before:
                _segment_at(segs, c.apply_step * T_s, T_s)["frames"] += 1
        out[key] = segs
    out.update(
        frames=len(cmds),
        frames_lockstep=len(with_keepalives(cmds, PACE_EVERY)),
        reference_rate_hz=scn.reference_rate_hz,
        start_step=cmds[0].apply_step,
        stop_step=cmds[-1].apply_step,
    )
    return out


def _segment_at(segs: list[dict[str, Any]], t: float, T_s: float) -> dict[str, Any]:
    """The segment a frame at ``t`` that changes the profile belongs to: a step at ``t``
    (within half a period), else the ramp with ``t0_s < t <= t1_s``, else the last
    segment that starts at or before ``t``."""
    half = 0.5 * T_s
    for g in segs:
        if g["kind"] == "step" and abs(g["t0_s"] - t) < half:
            return g
    for g in segs:
        if g["kind"] == "ramp" and g["t0_s"] + half < t < g["t1_s"] + half:
            return g
    return [g for g in segs if g["t0_s"] <= t + half][-1]


def schedule_lines(sched: dict[str, Any]) -> list[str]:
    """The compact schedule as text lines (no indentation), as ``bench show`` prints it."""
    lines = []
    for key, what, unit in (("speed_rpm", "speed", "rpm"), ("load_nm", "load", "N m")):
        for i, g in enumerate(sched[key]):
            head = f"{what:5s}" if i == 0 else " " * 5
            if g["kind"] == "step":
                span, text = f"at {g['t0_s']:g} s", f"step {g['v0']:g} -> {g['v1']:g} {unit}"
            elif g["kind"] == "ramp":
                span = f"{g['t0_s']:g}-{g['t1_s']:g} s"
                text = f"ramp {g['v0']:g} -> {g['v1']:g} {unit}"
            else:
                span, text = f"{g['t0_s']:g}-{g['t1_s']:g} s", f"constant {g['v0']:g} {unit}"
            n = g["frames"]
            frames = f" ({n} frame{'s' if n != 1 else ''})" if n else ""
            lines.append(f"{head} {span:>14}  {text}{frames}")
    return lines


def describe(scn: Scenario) -> dict[str, Any]:
    """The effective scenario, its motor, PWM rate, plant and command schedule.

    ``commands`` lists every ``BenchCommand`` frame; ``schedule`` is the
    same in compact form (:func:`schedule`).
    """
    p, prof = plant_setup(scn)
    T_s = sample_period(scn)
    names = cmd_names()
    return {
        "scenario": scn.to_dict(),
        "pwm": {"f_sw_hz": 1.0 / T_s, "T_s": T_s, "periods": n_steps(scn)},
        "motor": {"preset": p.name, **asdict(p.motor), "replaced": sorted(scn.motor)},
        "plant": {
            "profile": prof.name,
            "inverter": asdict(prof.inverter),
            "sensors": asdict(prof.sensors),
            "saturation": prof.saturation,
            "cross_saturation": prof.cross_saturation,
        },
        "commands": [
            {
                "step": c.apply_step,
                "cmd": c.cmd,
                "cmd_name": names.get(c.cmd, "?"),
                "speed_ref_rpm": c.speed_ref_rpm,
                "load_nm": c.load_nm,
            }
            for c in command_schedule(scn)
        ],
        "schedule": schedule(scn),
        "start": {
            "theta_e0_deg": scn.theta_e0_deg,
            "known_initial_angle": scn.known_initial_angle,
            "score_from_s": scn.score_from_s,
        },
    }


def catalogue() -> dict[str, Any]:
    """The shipped scenarios, presets, estimators and plant profiles."""
    from controller._registry import (
        SPECS,
        UnknownEstimatorError,
        entry_point_names,
        injection_family,
    )
    from plant_rt import PRESETS, PROFILE_NAMES

    scenarios = {}
    for name in SHIPPED:
        s = load_scenario(name)
        scenarios[name] = {
            "description": s.description,
            "paper": s.paper,
            "preset": s.preset,
            "estimators": list(s.estimators),
            "duration_s": s.duration,
        }
    presets = {
        name: {"f_sw_hz": p.f_sw, "n_p": p.motor.n_p, "u_dc": p.inverter.u_dc}
        for name, p in PRESETS.items()
    }
    plugins: dict[str, str] = {}
    for e in entry_point_names():
        try:
            plugins[e] = injection_family(e)
        except UnknownEstimatorError as err:  # an installed plug-in that does not load
            plugins[e] = f"error: {err}"
    return {
        "scenarios": scenarios,
        "presets": presets,
        "estimators": {name: s.family for name, s in SPECS.items()},
        # the registry's entries (controller.EstimatorSpec), for ``bench list``
        "estimator_specs": {
            name: {
                "family": s.family,
                "summary": s.summary,
                "options": list(s.declared() or {}),
                "needs_truth": s.needs_truth,
                "compiled": s.compiled_kind is not None,
            }
            for name, s in SPECS.items()
        },
        "estimator_plugins": plugins,
        "plant_profiles": list(PROFILE_NAMES),
    }
