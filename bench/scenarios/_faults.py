"""The ``[[faults]]`` timeline of a scenario: its schema, its checks and its reference.

A fault starts at plant time ``at_s`` (the first PWM period that starts at or
after it) and lasts ``duration_s`` (absent: to the end of the run)::

    [[faults]]
    at_s = 2.0              # plant time at which it starts, s
    duration_s = 0.5        # optional; absent: to the end of the run
    kind = "resistance_drift"
    R_s_factor = 1.5        # the kind's parameters (bench faults lists them)
    expect = "ride_through" # optional: what the drive should do

Each kind's parameters, units, ranges and behaviour per mode are
:data:`KINDS` (one home: ``bench faults``, docs/SCENARIOS.md and the checks
below read it).  A mistake is one line naming the file, the field
(``faults[2].phase``) and the reason.  The plant side applies them in
:mod:`plant_rt._faults` (pure), the bus side in the plant node
(:mod:`bench.nodes._fault_bus`); the scoring is in :mod:`bench.runs._metrics`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from bench._errors import ScenarioError

#: What a scenario may expect of the drive during a fault (``expect``).
#:
#: - ``trip``: a plant protection trips while the fault lasts;
#: - ``detect``: the fault is detected while it lasts, by a plant protection or
#:   by a controller mode that reports it;
#: - ``ride_through``: no protection trips and the estimator keeps the rotor
#:   angle while the fault lasts.
EXPECTATIONS = ("trip", "detect", "ride_through")

#: The messages a bus fault acts on: the control loop's frames (``PlantTruth``
#: is the recorder's instrument and ``BenchCommand`` the bench's own, never faulted).
BUS_MESSAGES = ("PwmDuty", "PhaseSamples", "PositionSensor")

PHASES = ("a", "b", "c")


@dataclass(frozen=True, slots=True)
class Param:
    """One parameter of a fault kind."""

    name: str
    unit: str
    range: str
    meaning: str
    required: bool = True


@dataclass(frozen=True, slots=True)
class Kind:
    """A fault kind: its group, parameters and behaviour per mode."""

    name: str
    group: str  # "power stage and machine" | "sensor" | "bus"
    params: tuple[Param, ...]
    meaning: str
    lockstep: str
    realtime: str
    #: None: implemented; else why the loader refuses it (one line).
    refused: str | None = None


_PHASE = Param("phase", "", "a, b, c", "the phase")

#: Every fault kind, in the order ``bench faults`` lists them.
KINDS: dict[str, Kind] = {
    k.name: k
    for k in (
        Kind(
            "open_phase",
            "power stage and machine",
            (_PHASE,),
            "The phase's connection opens: the leg's switches turn off, the current that "
            "was flowing freewheels through the leg's diodes to zero (within about "
            "L i / u_dc), and the phase's current is then held at zero; the other two "
            "phases carry i and -i (plant_rt/core/plant_leg.h). Closing it (duration_s) "
            "gives the leg back to the PWM.",
            "from the first period at or after at_s",
            "the same",
        ),
        Kind(
            "open_switch",
            "power stage and machine",
            (_PHASE, Param("device", "", "upper, lower", "the switch that stays open")),
            "One switch of the leg stays open: when the gate calls for it the leg conducts "
            "through a diode only, its voltage following the current's sign, so an open "
            "upper switch lets the phase carry no positive current (an open lower one no "
            "negative) (plant_rt/core/plant_leg.h).",
            "from the first period at or after at_s",
            "the same",
        ),
        Kind(
            "dc_link_step",
            "power stage and machine",
            (Param("u_dc_v", "V", "> 0", "the DC-link source voltage while it lasts"),),
            "A sag or a surge of the DC-link source: the inverter's voltage and the "
            "measured u_dc follow it (through r_dc and c_dc where the link has them); "
            "a surge above the over-voltage threshold trips the plant.",
            "from the first period at or after at_s",
            "the same",
        ),
        Kind(
            "demagnetisation",
            "power stage and machine",
            (Param("psi_f_factor", "-", "(0, 1]", "factor on the magnet's flux linkage"),),
            "The magnets lose flux (heat, over-current): back-EMF and torque constant fall.",
            "from the first period at or after at_s",
            "the same",
        ),
        Kind(
            "resistance_drift",
            "power stage and machine",
            (
                Param(
                    "R_s_factor",
                    "-",
                    "> 0",
                    "factor on the stator resistance (copper: "
                    "1 + 0.00393/K times the temperature rise)",
                ),
            ),
            "The stator resistance changes, as from heating.",
            "from the first period at or after at_s",
            "the same",
        ),
        Kind(
            "current_offset",
            "sensor",
            (_PHASE, Param("a", "A", "finite", "offset added to the phase's measured current")),
            "The phase's current sensor reads a offset.",
            "every sample at or after at_s",
            "the same",
        ),
        Kind(
            "current_gain",
            "sensor",
            (_PHASE, Param("factor", "-", "finite", "factor on the phase's measured current")),
            "The phase's current sensor's gain changes.",
            "every sample at or after at_s",
            "the same",
        ),
        Kind(
            "current_stuck",
            "sensor",
            (_PHASE,),
            "The phase's current sensor holds the value of the last sample before the fault.",
            "every sample at or after at_s",
            "the same",
        ),
        Kind(
            "current_lost",
            "sensor",
            (_PHASE,),
            "The phase's current sensor reads zero.",
            "every sample at or after at_s",
            "the same",
        ),
        Kind(
            "dc_voltage_offset",
            "sensor",
            (Param("v", "V", "finite", "offset added to the measured DC-link voltage"),),
            "The DC-link voltage sensor reads v offset (the true voltage is unchanged).",
            "every sample at or after at_s",
            "the same",
        ),
        Kind(
            "position_sensor_lost",
            "sensor",
            (),
            "The PositionSensor frame (a sensored controller's angle) is not sent. "
            "The bench's own sensored baseline reads its angle from PlantTruth, which "
            "stays (the recorder's): for it the fault is not seen.",
            "no PositionSensor frame at or after at_s",
            "the same",
        ),
        Kind(
            "drop",
            "bus",
            (
                Param("message", "", ", ".join(BUS_MESSAGES), "the message lost"),
                Param("prob", "-", "[0, 1]", "probability that one period's frame is lost"),
            ),
            "Frames of one message are lost, each period's with probability prob "
            "(a seeded stream per fault and period, so a run is reproducible).",
            "PwmDuty: a lost duty stays lost when the controller sends it again: the "
            "plant runs that period with the last duty it applied (never a later one "
            "already received, so a run in-process and one as processes agree), counts "
            "it late (with a controller under test, once the lost duty has arrived: the "
            "plant keeps its pace), and "
            "its watchdog counts periods as in real time (prob 1.0 for longer than the "
            "watchdog trips it). PhaseSamples: the retransmission rules keep the "
            "controller's samples in order: a lost sample is sent again before the next "
            "sample that gets through, and its answer, come late, is lost; the plant "
            "runs that period as for a lost duty (prob 1.0 for longer than the watchdog "
            "trips it). PositionSensor: not sent, nor sent again (as position_sensor_lost)",
            "the frame is discarded: a duty on arrival at the plant, a sample or a "
            "position frame instead of being sent",
        ),
        Kind(
            "delay",
            "bus",
            (
                Param("message", "", "PwmDuty", "the message delayed"),
                Param(
                    "steps",
                    "periods",
                    "1 to the step counters' bound",
                    "extra delay in lockstep",
                    required=False,
                ),
                Param("us", "us", "> 0", "extra delay in real time", required=False),
            ),
            "Duties take effect later (one of steps and us is required; the other "
            "mode takes the same time rounded up to whole periods).",
            "the period k applies the duty of period k - steps (the last one applied "
            "when that one is gone; us alone: rounded up to whole periods)",
            "the plant holds each duty frame us microseconds from its arrival (its receive "
            "timestamp); a period applies at its start the newest duty released by then, so "
            "a delay below a period costs a period only to a duty that arrives less than us "
            "before the period starts (steps alone: steps periods of its clock)",
        ),
        Kind(
            "corrupt",
            "bus",
            (Param("message", "", "PwmDuty", "the message whose E2E CRC is broken"),),
            "Every frame of the message arrives with a bad E2E CRC and is rejected "
            "(counted as bad_crc).",
            "as drop with prob 1.0, counted as bad_crc",
            "the same",
        ),
        Kind(
            "silence",
            "bus",
            (),
            "No frame either way, as a bus-off: no PhaseSamples or PositionSensor goes "
            "out, no PwmDuty comes in (PlantTruth, the recorder's, and BenchCommand pass).",
            "as drop with prob 1.0 of PwmDuty, PhaseSamples and PositionSensor at once: "
            "the periods run with the last duty applied and the watchdog trips after its "
            "periods; the samples are sent again, in order, once it ends",
            "the plant sends no sample and takes no duty: its watchdog trips after "
            "its periods, the controller's sample timeout disables its PWM",
        ),
        Kind(
            "babble",
            "bus",
            (Param("rate_hz", "Hz", "(0, f_sw]", "foreign frames per second and identifier"),),
            "A foreign node sends frames with the DBC's PwmDuty and PhaseSamples "
            "identifiers and random payloads (seeded) at rate_hz: the plant receives "
            "the duties, the controller the samples; receivers reject them by their "
            "E2E check or counters, and one that passes is a result.",
            "one foreign frame of each every round(f_sw / rate_hz) periods",
            "the same (at the plant's periods)",
        ),
    )
}


@dataclass(frozen=True, slots=True)
class Fault:
    """One validated entry of ``[[faults]]``.

    Attributes
    ----------
    index : int
        Its place in the timeline (``faults[index]`` in messages, the seed of
        its random stream).
    kind : str
    at_s : float
        Plant time at which it starts (s).
    duration_s : float or None
        How long it lasts (s); None: to the end of the run.
    params : dict
        The kind's parameters, as given (numbers as float, ``steps`` as int).
    expect : str or None
        One of :data:`EXPECTATIONS`, or None (nothing expected: ``met`` null).
    """

    index: int
    kind: str
    at_s: float
    duration_s: float | None
    params: dict[str, Any] = field(default_factory=dict)
    expect: str | None = None

    def end_s(self, run_s: float) -> float:
        """When it ends (s): ``at_s + duration_s``, or the end of the run."""
        return run_s if self.duration_s is None else min(run_s, self.at_s + self.duration_s)

    def periods(self, T_s: float) -> tuple[int, int | None]:
        """The PWM periods ``[k0, k1)`` it covers (``k1`` None: to the end).

        ``k0`` is the first period that starts at or after ``at_s``; ``k1``
        the first that starts at or after ``at_s + duration_s``.
        """
        k0 = math.ceil(self.at_s / T_s - 1e-9)
        if self.duration_s is None:
            return k0, None
        return k0, max(k0 + 1, math.ceil((self.at_s + self.duration_s) / T_s - 1e-9))

    def to_dict(self) -> dict[str, Any]:
        """The TOML entry (round trip through :func:`parse_faults`)."""
        out: dict[str, Any] = {"at_s": self.at_s}
        if self.duration_s is not None:
            out["duration_s"] = self.duration_s
        out["kind"] = self.kind
        out.update(self.params)
        if self.expect is not None:
            out["expect"] = self.expect
        return out


_COMMON = ("at_s", "duration_s", "kind", "expect")


def parse_faults(
    value: Any, src: str, *, duration: float, f_sw: float, max_delay_steps: int
) -> tuple[Fault, ...]:
    """The ``[[faults]]`` array of tables, each entry checked against its kind.

    ``duration`` is the run's (a fault must start within it), ``f_sw`` the
    PWM rate (``babble``'s rate at most one frame a period),
    ``max_delay_steps`` the step counters' bound on a lockstep delay
    (:meth:`bench.scenarios._schema._WireLimits.max_delay_steps`).
    """
    if value is None:
        return ()
    if not isinstance(value, list) or not all(isinstance(e, dict) for e in value):
        raise ScenarioError(
            f"{src}: field 'faults': expected an array of tables ([[faults]] entries)"
        )
    return tuple(
        _parse_one(i, e, src, duration, f_sw, max_delay_steps) for i, e in enumerate(value)
    )


def _num(src: str, where: str, v: Any) -> float:
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise ScenarioError(f"{src}: field '{where}': expected a number, got {v!r}")
    if not math.isfinite(v):
        raise ScenarioError(f"{src}: field '{where}': must be finite")
    return float(v)


def _parse_one(
    i: int, e: dict[str, Any], src: str, duration: float, f_sw: float, max_delay_steps: int
) -> Fault:
    pre = f"faults[{i}]"

    def fail(key: str, why: str) -> ScenarioError:
        return ScenarioError(f"{src}: field '{pre}.{key}': {why}")

    if "kind" not in e:
        raise fail("kind", f"required (one of: {', '.join(KINDS)}; bench faults lists them)")
    kind = e["kind"]
    if kind not in KINDS:
        raise fail("kind", f"unknown kind {kind!r} (known: {', '.join(KINDS)})")
    spec = KINDS[kind]
    known = {*_COMMON, *(p.name for p in spec.params)}
    for k in e:
        if k not in known:
            raise fail(k, f"unknown key for kind {kind!r} (known: {', '.join(sorted(known))})")
    if "at_s" not in e:
        raise fail("at_s", "required (plant time at which the fault starts, s)")
    at_s = _num(src, f"{pre}.at_s", e["at_s"])
    if not 0.0 <= at_s < duration:
        raise fail(
            "at_s", f"must be within the run, 0 <= at_s < duration {duration:g} s, got {at_s:g}"
        )
    dur: float | None = None
    if "duration_s" in e:
        dur = _num(src, f"{pre}.duration_s", e["duration_s"])
        if not dur > 0.0:
            raise fail("duration_s", f"must be > 0 s (absent: to the end of the run), got {dur:g}")
    expect = e.get("expect")
    if expect is not None and expect not in EXPECTATIONS:
        raise fail("expect", f"expected one of {', '.join(EXPECTATIONS)}, got {expect!r}")
    params: dict[str, Any] = {}
    for p in spec.params:
        if p.name not in e:
            if p.required:
                raise fail(p.name, f"required for kind {kind!r} ({p.meaning}; {p.range})")
            continue
        v = e[p.name]
        where = f"{pre}.{p.name}"
        if p.name == "phase":
            if v not in PHASES:
                raise fail(p.name, f'expected "a", "b" or "c", got {v!r}')
            params[p.name] = v
        elif p.name == "device":
            if v not in ("upper", "lower"):
                raise fail(p.name, f'expected "upper" or "lower", got {v!r}')
            params[p.name] = v
        elif p.name == "message":
            allowed = p.range.split(", ")
            if v not in allowed:
                raise fail(p.name, f"expected one of {', '.join(allowed)}, got {v!r}")
            params[p.name] = v
        elif p.name == "steps":
            if isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= max_delay_steps:
                raise fail(
                    p.name,
                    f"expected an integer from 1 to {max_delay_steps} periods (the step "
                    f"counters' bound, as latency.duty_delay_steps), got {v!r}",
                )
            params[p.name] = v
        else:
            x = _num(src, where, v)
            why = _range_error(p.name, x, f_sw)
            if why:
                raise fail(p.name, why)
            params[p.name] = x
    if kind == "delay" and "steps" not in params and "us" not in params:
        raise fail("steps", "kind 'delay' needs steps (lockstep) or us (real time), or both")
    if spec.refused:
        raise fail("kind", f"kind {kind!r}: {spec.refused}")
    return Fault(i, kind, at_s, dur, params, expect)


def _range_error(name: str, x: float, f_sw: float) -> str | None:
    """Why a numeric parameter is out of its range (:data:`KINDS`), or None."""
    if name in ("u_dc_v", "R_s_factor", "us") and not x > 0.0:
        return f"must be > 0, got {x:g}"
    if name == "psi_f_factor" and not 0.0 < x <= 1.0:
        return f"must be in (0, 1] (demagnetisation lowers the flux), got {x:g}"
    if name == "prob" and not 0.0 <= x <= 1.0:
        return f"must be a probability in [0, 1], got {x:g}"
    if name == "rate_hz" and not 0.0 < x <= f_sw:
        return (
            f"must be in (0, {f_sw:g}] Hz: the plant node sends at most one foreign "
            f"frame of each identifier a period (f_sw {f_sw:g} Hz), got {x:g}"
        )
    return None


def describe_kinds() -> list[str]:
    """``bench faults``: every kind with its parameters and its behaviour per mode."""
    lines = [
        "[[faults]] keys of every kind: at_s (s, required), duration_s (s; absent: to the "
        f"end of the run), kind, expect ({', '.join(EXPECTATIONS)}; optional)",
        "",
    ]
    group = ""
    for k in KINDS.values():
        if k.group != group:
            group = k.group
            lines.append(f"{group}:")
        ps = ", ".join(
            f"{p.name}{'' if p.required else '?'}" + (f" [{p.unit}]" if p.unit else "")
            for p in k.params
        )
        lines.append(f"  {k.name}({ps}){'  -- ' + k.refused if k.refused else ''}")
        lines.append(f"      {k.meaning}")
        for p in k.params:
            lines.append(f"      {p.name}: {p.meaning}; {p.range}")
        if not k.refused:
            lines.append(f"      lockstep: {k.lockstep}")
            lines.append(f"      real time: {k.realtime}")
    return lines


def reference_md() -> list[str]:
    """The ``[[faults]]`` section of docs/SCENARIOS.md (:func:`bench.scenarios._reference.render`)."""
    lines = [
        "## [[faults]]",
        "",
        "A timeline of faults, one `[[faults]]` entry each (`bench faults` lists the kinds). "
        "Keys of every entry: `at_s` (s, required: plant time at which it starts, the first "
        "PWM period at or after it), `duration_s` (s, > 0; absent: to the end of the run), "
        "`kind` (required), its parameters, and `expect`: "
        + ", ".join(f"`{x}`" for x in EXPECTATIONS)
        + " (optional; `trip`: a plant protection trips while it lasts; `detect`: a plant "
        "protection or a controller mode detects it while it lasts; `ride_through`: no trip "
        "and the rotor angle kept while it lasts). `metrics.json` scores each fault "
        "(docs/RUNS.md); a missed expectation is exit status 6.",
        "",
        "```toml",
        "[[faults]]",
        "at_s = 2.0",
        "duration_s = 0.5",
        'kind = "resistance_drift"',
        "R_s_factor = 1.5",
        'expect = "ride_through"',
        "```",
        "",
        "| kind | parameters | what it does | lockstep | real time |",
        "|---|---|---|---|---|",
    ]
    for k in KINDS.values():
        ps = (
            "<br>".join(
                f"`{p.name}`{'' if p.required else ' (optional)'}"
                + (f" ({p.unit})" if p.unit else "")
                + f": {p.meaning}; {p.range}"
                for p in k.params
            )
            or "none"
        )
        if k.refused:
            lines.append(f"| `{k.name}` | {ps} | {k.meaning} | {k.refused} | {k.refused} |")
        else:
            lines.append(f"| `{k.name}` | {ps} | {k.meaning} | {k.lockstep} | {k.realtime} |")
    lines.append("")
    return lines


def lockstep_error(faults: tuple[Fault, ...], src: str) -> ScenarioError | None:
    """The error of a fault a lockstep run cannot apply (:data:`KINDS`' lockstep column).

    None for every kind: each has its lockstep rule (the sample side's under the
    retransmission rules, :mod:`bench.nodes._fault_bus`). Kept as the one check the
    lockstep runs call, for a kind to come that has none.
    """
    del faults, src
    return None
