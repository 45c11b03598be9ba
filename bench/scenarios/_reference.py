"""The scenario reference, ``docs/SCENARIOS.md``, generated from the schema.

Every table and key of a scenario file with its unit, default, range and
meaning; and the ``[estimator_options]`` of each estimator.  The keys come
from the schema (:mod:`bench.scenarios._schema`: ``_TOP_KEYS``,
``INVERTER_KEYS``, ... and the dataclasses), the defaults from the code
(the :class:`~bench.scenarios._schema.Scenario`, ``Latency``, ``Noise`` and
``ModelErrors`` defaults, the presets, the plant profiles, the estimators'
parameters), the estimator options' meanings from the estimators'
docstrings.  What the code cannot say (unit, meaning, range in words) is
:data:`KEYS`, one entry per key; ``tests/test_scenarios_doc.py`` requires an
entry for every key the loader accepts and none more, loads each entry's
``bad`` value and requires the loader to refuse it naming the key, and
requires ``docs/SCENARIOS.md`` to equal :func:`render` (``bench schema --doc
docs/SCENARIOS.md`` rewrites it).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

#: No ``bad`` example.
NO_BAD = object()


@dataclass(frozen=True, slots=True)
class Key:
    """What a scenario key means.

    Attributes
    ----------
    unit : str
        Unit (SI), ``-`` for a pure number, empty for text and switches.
    meaning : str
        What it does, one sentence or two.
    range : str
        The values the loader accepts, in words.
    default : str or None
        The default in words; None: the code's default (:func:`defaults`).
    bad : object
        A value the loader refuses (tested), or :data:`NO_BAD`.
    """

    unit: str
    meaning: str
    range: str = ""
    default: str | None = None
    bad: Any = NO_BAD


_TABLE = "table (below)"

#: Per table ("" = top level), per key: unit, meaning, range, default in words.
KEYS: dict[str, dict[str, Key]] = {
    "": {
        "name": Key(
            "",
            "The scenario's name in reports and the default run folder `runs/<name>-<estimator>`.",
            "text",
            "the file's stem",
            3,
        ),
        "description": Key("", "One line on what the scenario does (bench list).", "text", "", 3),
        "paper": Key(
            "",
            "The source it reproduces; a `Fig. N` in it names the paper's figure "
            "that run.png is to be compared with.",
            "text",
            "",
            3,
        ),
        "preset": Key(
            "",
            "The motor and inverter preset (plant_rt/_presets.py).",
            "wen2023, xue2022",
            "*required*",
            "no-such-motor",
        ),
        "extends": Key(
            "",
            "Start from a shipped scenario or a path (relative to this file): "
            "this file's keys replace the base's, table by table, key by key.",
            "a scenario name or path",
            "none",
            3,
        ),
        "estimator": Key(
            "",
            "The estimator `bench run` uses without `--estimator`.",
            "bench list (estimators)",
            None,
            "no-such-estimator",
        ),
        "estimators": Key(
            "",
            "The estimators `bench suite paper` runs on this scenario.",
            "a list of estimator names",
            "[estimator]",
            ["no-such-estimator"],
        ),
        "f_sw": Key(
            "Hz",
            "PWM frequency, which is also the control and sample rate.",
            "100 to 100,000",
            "the preset's ({preset_f_sw})",
            50.0,
        ),
        "duration": Key("s", "Simulated length of the run.", ">= 0.001", "*required*", 0.0),
        "seed": Key(
            "-", "Seeds the sensor noise and the link's jitter and drops.", "integer >= 0", None, -1
        ),
        "saturation": Key(
            "",
            "d-axis saturation in the plant (the polarity test needs it).",
            "true, false",
            None,
            "yes",
        ),
        "theta_e0_deg": Key("deg", "Initial electrical rotor angle.", "any number", None, "north"),
        "known_initial_angle": Key(
            "",
            "true: the controller starts with the true angle; "
            "false: it finds it (HF estimate, then the magnet polarity "
            "with d-axis pulses) before the speed loop starts.",
            "true, false",
            None,
            1,
        ),
        "speed_rpm": Key(
            "rpm (s)",
            "Speed reference: [t, value] breakpoints, linear between, "
            "held after the last; a step is two points at one time.",
            "times >= 0 and not decreasing; values within BenchCommand.speed_ref",
            "[[0, 0]]",
            [[0.0, 1.0e6]],
        ),
        "load_nm": Key(
            "N m (s)",
            "Load torque, breakpoints as speed_rpm.",
            "values within BenchCommand.load_torque",
            "[[0, 0]]",
            [[0.0, 1.0e6]],
        ),
        "reference_rate_hz": Key(
            "Hz", "How often the bench re-sends a changing reference.", ">= 1", None, 0.5
        ),
        "score_from_s": Key(
            "s",
            "Metrics ignore the start-up before this time.",
            ">= 0 and below duration",
            "0.5, or half of a shorter duration",
            -1.0,
        ),
        "thd_window_s": Key(
            "s",
            "[start, end] of the window of the phase-A current's THD (thd_phase_a_pct).",
            "start < end",
            "none (no THD)",
            [2.0, 1.0],
        ),
        "plant_profile": Key(
            "",
            "The plant as built: `ideal` (the papers': average inverter, "
            "exact sensors, d-axis saturation) or `drive` (switching inverter, "
            "dead time, drops, ADC, offsets, cross-saturation; "
            "plant_rt/_profiles.py). [inverter], [sensors] and [magnetics] "
            "change single values of it.",
            "ideal, drive",
            None,
            "real",
        ),
        "estimator_options": Key(
            "", "Options of the estimator (below, per estimator).", _TABLE, "none"
        ),
        "noise": Key("", "Older form of [sensors] (kept; [sensors] wins).", _TABLE, "none"),
        "latency": Key(
            "", "Latency, jitter and loss injected between plant and controller.", _TABLE, "none"
        ),
        "controller_model": Key("", "The controller's parameter errors.", _TABLE, "none"),
        "motor": Key(
            "", "Motor parameters replacing the preset's, for plant and controller.", _TABLE, "none"
        ),
        "paper_result": Key(
            "",
            "The paper's numbers, by metrics.json key; for reports only.",
            "table of numbers",
            "none",
        ),
        "inverter": Key("", "Single values of the profile's inverter.", _TABLE, "none"),
        "sensors": Key("", "Single values of the profile's current sensing.", _TABLE, "none"),
        "magnetics": Key("", "Single values of the plant's magnetics.", _TABLE, "none"),
        "controller": Key(
            "",
            "What a real drive does against the plant (each on where the plant has what it "
            "counters).",
            _TABLE,
            "none",
        ),
        "faults": Key(
            "",
            "A timeline of faults (`[[faults]]` entries, below; `bench faults`).",
            "an array of tables",
            "none",
            3,
        ),
    },
    "noise": {
        "current_std_a": Key("A rms", "White noise on each phase current.", ">= 0", None, -1.0),
        "adc_bits": Key(
            "bit", "Current ADC resolution; 0: no quantization.", "integer >= 0", None, -1
        ),
        "adc_full_scale_a": Key(
            "A", "ADC full scale, +-; > 0 when adc_bits is set.", ">= 0", None, -1.0
        ),
    },
    "latency": {
        "duty_delay_steps": Key(
            "PWM periods",
            "Lockstep: delay of the duty direction (controller to plant).",
            "integer >= 0; both directions together at most {max_delay}",
            None,
            300,
        ),
        "sample_delay_steps": Key(
            "PWM periods",
            "Lockstep: delay of the sample direction (plant to controller).",
            "as duty_delay_steps",
            None,
            -1,
        ),
        "duty_delay_us": Key(
            "us",
            "Real time: delay of the duty direction.",
            ">= 0, at most {max_delay} periods",
            None,
            -1.0,
        ),
        "sample_delay_us": Key(
            "us",
            "Real time: delay of the sample direction.",
            ">= 0, at most {max_delay} periods",
            None,
            -1.0,
        ),
        "jitter_us": Key(
            "us",
            "Real time: jitter of both directions, standard deviation "
            "(normal) or half-width (uniform).",
            ">= 0",
            None,
            -1.0,
        ),
        "duty_jitter_us": Key(
            "us", "Jitter of the duty direction; wins over jitter_us.", ">= 0", "jitter_us", -1.0
        ),
        "sample_jitter_us": Key(
            "us", "Jitter of the sample direction; wins over jitter_us.", ">= 0", "jitter_us", -1.0
        ),
        "jitter_dist": Key(
            "", "Distribution of the jitter, both directions.", "normal, uniform", None, "gauss"
        ),
        "drop_prob": Key(
            "-", "Probability that a frame is dropped, both directions.", "0 to 1", None, 1.5
        ),
        "duty_drop_prob": Key(
            "-",
            "Drop probability of the duty direction; wins over drop_prob.",
            "0 to 1",
            "drop_prob",
            2.0,
        ),
        "sample_drop_prob": Key(
            "-",
            "Drop probability of the sample direction; wins over "
            "drop_prob (each direction draws from a random stream of its "
            "own).",
            "0 to 1",
            "drop_prob",
            2.0,
        ),
    },
    "controller_model": {
        k: Key(
            "factor",
            f"The controller's {what} over the plant's (1.0 exact, 1.2: it "
            "believes 20 % more); the plant keeps the preset's.",
            "> 0",
            None,
            0.0,
        )
        for k, what in (
            ("R_s", "stator resistance"),
            ("L_d", "d inductance"),
            ("L_q", "q inductance"),
            ("psi_f", "magnet flux"),
            ("J", "inertia"),
        )
    },
    "motor": {
        "n_p": Key("-", "Pole pairs.", "integer >= 1", None, 0),
        "R_s": Key("Ohm", "Stator resistance.", "> 0", None, 0.0),
        "L_d": Key(
            "H", "d-axis inductance (unsaturated).", "> 0; HF estimators need L_q > L_d", None, 0.0
        ),
        "L_q": Key("H", "q-axis inductance.", "> 0; HF estimators need L_q > L_d", None, 0.0),
        "psi_f": Key("Wb", "Magnet flux linkage.", ">= 0", None, -0.1),
        "J": Key("kg m^2", "Inertia of rotor and load.", "> 0", None, 0.0),
        "b": Key("N m s", "Viscous friction.", ">= 0", None, -1.0),
        "i_rated": Key("A", "Rated current, peak.", "> 0", None, 0.0),
        "i_max": Key(
            "A",
            "Current limit, peak (the over-current trip and the controller's limit).",
            "> 0",
            None,
            0.0,
        ),
        "tau_rated": Key("N m", "Rated torque.", "> 0", None, 0.0),
        "w_m_rated": Key("rad/s", "Rated mechanical speed.", "> 0", None, 0.0),
    },
    "inverter": {
        "model": Key(
            "",
            "Average (duty times voltage) or switching (centre-aligned carrier, "
            "sub-stepped) inverter.",
            "average, switching",
            None,
            "ideal",
        ),
        "t_dead": Key("s", "Dead time per transition.", "0 to half a PWM period", None, 1.0),
        "v_ce": Key("V", "Transistor on-state drop.", ">= 0", None, -1.0),
        "v_f": Key("V", "Diode forward drop.", ">= 0", None, -1.0),
        "u_dc": Key("V", "DC-link source voltage.", "> 0", None, 0.0),
        "r_dc": Key("Ohm", "DC source resistance.", ">= 0", None, -1.0),
        "c_dc": Key("F", "DC-link capacitance; 0: none.", ">= 0", None, -1.0),
        "sample_at": Key("", "ADC instant on the carrier.", "peak, valley", None, "middle"),
    },
    "sensors": {
        "current_offset_a": Key(
            "A", "Offset of each phase current.", "a number, or [a, b, c]", None, [1.0, 2.0]
        ),
        "current_gain_error": Key(
            "-",
            "Relative gain error per phase (gain 1 + e).",
            "a number, or [a, b, c]",
            None,
            [1.0, 2.0],
        ),
        "adc_bits": Key("bit", "Current ADC resolution; 0: no quantization.", "0 to 24", None, 25),
        "current_full_scale_a": Key("A", "ADC full scale, +-.", "> 0", None, 0.0),
        "current_noise_a": Key("A rms", "White noise on each phase current.", ">= 0", None, -1.0),
        "sample_delay_s": Key(
            "s", "Delay of the sensor chain.", "0 to below one PWM period", None, 1.0
        ),
        "encoder_counts": Key(
            "count/rev",
            "Position sensor of a sensored controller (PositionSensor frame): counts per "
            "mechanical revolution; 0: none, and under --controller external 65536 (a "
            "controller under test always gets a sensor).",
            "0 to 65536",
            None,
            70000,
        ),
        "encoder_rate_hz": Key(
            "Hz",
            "Position readings per second (rounded to whole PWM periods, at most one per "
            "period); 0: one per PWM period.",
            ">= 0",
            None,
            -1.0,
        ),
        "encoder_delay_s": Key(
            "s", "Age of a position reading (the shaft's angle that long ago).", ">= 0", None, -1.0
        ),
    },
    "magnetics": {
        "saturation": Key(
            "", "d-axis saturation (the polarity test needs it).", "true, false", None, 1
        ),
        "cross_saturation": Key(
            "", "The cross-saturation flux map (c_dq).", "true, false", None, 1
        ),
        "sigma": Key(
            "-", "Depth of the d-axis saturation (plant_rt.SaturationPars).", "0 to 0.99", None, 1.0
        ),
        "i_sat": Key("A", "d-axis saturation current.", "> 0", None, 0.0),
        "c_dq": Key(
            "H/A",
            "Cross-saturation coefficient (plant_rt.CrossSaturationPars).",
            ">= 0",
            None,
            -1.0,
        ),
    },
    "controller": {
        "dead_time_compensation": Key(
            "",
            "Feed-forward of the dead time and device drops.",
            "true, false",
            "true where the controller's t_dead, v_ce or v_f is above 0 "
            "(drive profile: true; ideal: false)",
            1,
        ),
        "t_dead": Key(
            "s",
            "The controller's dead-time setting for the compensation.",
            "0 to half a PWM period",
            "the plant's inverter",
            1.0,
        ),
        "v_ce": Key(
            "V",
            "The controller's transistor drop for the compensation.",
            ">= 0",
            "the plant's inverter",
            -1.0,
        ),
        "v_f": Key(
            "V",
            "The controller's diode drop for the compensation.",
            ">= 0",
            "the plant's inverter",
            -1.0,
        ),
        "cross_saturation_compensation": Key(
            "",
            "Correct the HF estimators' cross-saturation angle.",
            "true, false",
            "true where the plant has cross-saturation with a c_dq other than 0, or k_dq "
            "is given and not 0 (drive profile: true; ideal: false)",
            1,
        ),
        "k_dq": Key(
            "H/A",
            "L_dq = k_dq i_q for the correction.",
            "any number",
            "the plant's flux map at i_d = 0",
            "x",
        ),
        "offset_calibration": Key(
            "",
            "Measure the current offsets at standstill before the start.",
            "true, false",
            "true where the current sensors have an offset (drive profile: true; ideal: false)",
            1,
        ),
        "offset_periods": Key(
            "PWM periods",
            "Length of the offset calibration.",
            "integer >= 1",
            "derived from the sensors' noise and LSB",
            0,
        ),
        "current_feedback": Key(
            "",
            "`filtered`: the current PIs see the fundamental; `raw`: "
            "they see the HF current too, as Wen Sec. 3.3 assumes.",
            "filtered, raw",
            "filtered",
            "hf",
        ),
        "supervision": Key(
            "",
            "Detect current-sensor, open-phase and DC-link faults from the samples and stop "
            "switching, each reported as a CtrlTelemetry.mode (docs/PROTECTION.md).",
            "true, false",
            "true where the scenario has a [[faults]] timeline, else false",
            1,
        ),
    },
}


def option_range(key: str) -> tuple[str, Any]:
    """An ``[estimator_options]`` key's range in words and a value the loader refuses, from
    its declaration (:func:`bench.scenarios._schema.shipped_options`) with the scenario's bound
    (:attr:`controller.Option.limit`)."""
    from bench.scenarios import _schema as sc

    opt = sc.shipped_options()[key]
    kind = opt.value_kind
    if opt.limit == "inverter_linear":
        return f"{opt.range_text()} and <= u_dc / sqrt(3) of the preset", 1000.0
    if opt.limit == "below_nyquist":
        return f"{opt.range_text()} and below half the PWM rate", 6000.0
    bad: Any = {"bool": 1, "str": "no-such-choice", "filter": [[1.0]], "int": 0}.get(kind)
    if bad is None:
        bad = -1.0 if opt.minimum is not None else 0.0
    return opt.range_text(), bad


def defaults() -> dict[str, dict[str, Any]]:
    """The code's default of every key whose :class:`Key` gives none, per table."""
    from bench.scenarios._schema import Latency, ModelErrors, Noise, Scenario

    out: dict[str, dict[str, Any]] = {}
    sc = {f.name: f for f in dataclasses.fields(Scenario)}
    out[""] = {
        k: _field_default(sc[k]) for k, v in KEYS[""].items() if v.default is None and k in sc
    }
    for table, cls in (("latency", Latency), ("noise", Noise), ("controller_model", ModelErrors)):
        fs = {f.name: f for f in dataclasses.fields(cls)}
        out[table] = {k: _field_default(fs[k]) for k, v in KEYS[table].items() if v.default is None}
    return out


def _field_default(f: dataclasses.Field[Any]) -> Any:
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return None


def _profile_defaults() -> dict[str, dict[str, str]]:
    """[inverter], [sensors], [magnetics] defaults: each profile's, on each preset."""
    from plant_rt import PRESETS
    from plant_rt._profiles import plant_profile

    inv: dict[str, list[str]] = {}
    sen: dict[str, list[str]] = {}
    mag: dict[str, list[str]] = {}
    for prof in ("ideal", "drive"):
        for pname, preset in PRESETS.items():
            pr = plant_profile(prof, preset)
            tag = f"{prof}/{pname}"
            for k in KEYS["inverter"]:
                inv.setdefault(k, []).append(f"{tag} {_show(getattr(pr.inverter, k))}")
            s = pr.sensors
            gain = tuple(round(g - 1.0, 6) for g in s.gain_abc)
            vals = {
                "current_offset_a": s.offset_abc,
                "current_gain_error": gain,
                "adc_bits": s.bits or 0,
                "current_full_scale_a": s.i_fs,
                "current_noise_a": s.noise_i,
                "sample_delay_s": s.t_delay,
                "encoder_counts": s.encoder_counts,
                "encoder_rate_hz": s.encoder_rate_hz,
                "encoder_delay_s": s.encoder_delay_s,
            }
            for k, v in vals.items():
                sen.setdefault(k, []).append(f"{tag} {_show(v)}")
            m = preset.motor
            mvals = {
                "saturation": pr.saturation,
                "cross_saturation": pr.cross_saturation,
                "sigma": m.sat.sigma,
                "i_sat": m.sat.i_sat,
                "c_dq": m.cross.c_dq,
            }
            for k, v in mvals.items():
                mag.setdefault(k, []).append(f"{tag} {_show(v)}")
    return {
        t: {k: _squeeze(v) for k, v in d.items()}
        for t, d in (("inverter", inv), ("sensors", sen), ("magnetics", mag))
    }


def _squeeze(items: list[str]) -> str:
    """``ideal/wen2023 0; ideal/xue2022 0; ...`` with equal values merged."""
    vals = [i.split(" ", 1) for i in items]
    if len({v for _, v in vals}) == 1:
        return vals[0][1]
    by: dict[str, list[str]] = {}
    for tag, v in vals:
        by.setdefault(v, []).append(tag)
    return "; ".join(f"{', '.join(tags)}: {v}" for v, tags in by.items())


def _show(v: Any) -> str:
    if v is None:
        return "none"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return f"{v:g}"
    if isinstance(v, tuple | list):
        if len(set(v)) == 1:
            return _show(v[0])
        return "[" + ", ".join(_show(x) for x in v) + "]"
    if isinstance(v, str):
        return f'"{v}"'
    if isinstance(v, dict) and not v:
        return "none"
    return str(v)


def estimator_options() -> dict[str, dict[str, tuple[str, str, str, str]]]:
    """Per estimator: option -> (unit, default, range, meaning), from the registry's entries
    (:data:`controller._registry.SPECS`, each one's options dataclass)."""
    from controller._registry import SPECS

    out: dict[str, dict[str, tuple[str, str, str, str]]] = {}
    for name, spec in SPECS.items():
        rows: dict[str, tuple[str, str, str, str]] = {}
        for k, opt in (spec.declared() or {}).items():
            shown = opt.default_doc or (
                "derived (meta.json: controller_gains)"
                if opt.default is None
                else _show(opt.default)
            )
            rows[k] = (opt.unit, shown, option_range(k)[0], opt.doc)
        out[name] = rows
    return out


def option_groups() -> list[
    tuple[tuple[str, ...], list[tuple[tuple[str, ...], tuple[str, str, str, str]]]]
]:
    """The options of :func:`estimator_options` said once: grouped by the estimators that share
    a row, and within a group the keys with one row merged (``bpf``, ``hpf``, ``lpf``).

    Returns ``[(estimators, [(keys, (unit, default, range, meaning)), ...]), ...]`` in the
    order of the estimators and their options.
    """
    Row = tuple[str, str, str, str]
    per = estimator_options()
    owners: dict[tuple[str, Row], list[str]] = {}
    for name, rows in per.items():
        for k, row in rows.items():
            owners.setdefault((k, row), []).append(name)
    groups: dict[tuple[str, ...], list[tuple[str, Row]]] = {}
    for (k, row), names in owners.items():
        groups.setdefault(tuple(names), []).append((k, row))
    out: list[tuple[tuple[str, ...], list[tuple[tuple[str, ...], Row]]]] = []
    for group, members in groups.items():
        merged: dict[Row, list[str]] = {}
        for k, row in members:
            merged.setdefault(row, []).append(k)
        out.append((group, [(tuple(ks), row) for row, ks in merged.items()]))
    return out


def render() -> str:
    """``docs/SCENARIOS.md``."""
    from bench.scenarios._schema import SHIPPED, _wire_limits
    from plant_rt import PRESETS

    code = defaults()
    prof = _profile_defaults()
    fill = {
        "max_delay": str(_wire_limits().max_delay_steps),
        "preset_f_sw": "; ".join(f"{n} {p.f_sw:g}" for n, p in PRESETS.items()),
    }
    lines = [
        "# Scenario files",
        "",
        "<!-- written by `bench schema --doc docs/SCENARIOS.md` from the schema "
        "(bench/scenarios/_schema.py, _reference.py); do not edit -->",
        "",
        "A scenario is a TOML file: a shipped name (`bench list`: "
        + ", ".join(f"`{s}`" for s in SHIPPED)
        + ") or a path works wherever a scenario is asked for. Every key is optional "
        "except `preset` and `duration`; a mistake gives one line naming the file, the "
        "key and the reason. `bench show NAME` prints a scenario as loaded, with its motor. "
        "Units are SI unless the unit column says otherwise.",
        "",
        "```toml",
        'extends = "wen-5.1"        # start from a shipped scenario',
        "duration = 3.0",
        "speed_rpm = [[0.0, 0.0], [0.5, 100.0]]",
        "[estimator_options]",
        "V_h = 40.0",
        "```",
        "",
    ]
    titles = {
        "": "Top level",
        "noise": "[noise]",
        "latency": "[latency]",
        "controller_model": "[controller_model]",
        "motor": "[motor]",
        "inverter": "[inverter]",
        "sensors": "[sensors]",
        "magnetics": "[magnetics]",
        "controller": "[controller]",
    }
    for table, keys in KEYS.items():
        lines += [f"## {titles[table]}", ""]
        if table == "motor":
            lines += [
                "Default: the preset's value ("
                + "; ".join(
                    f"{p}: " + ", ".join(f"{k} {_show(getattr(PRESETS[p].motor, k))}" for k in keys)
                    for p in PRESETS
                )
                + ").",
                "",
            ]
        lines += ["| key | unit | default | range | meaning |", "|---|---|---|---|---|"]
        for k, key in keys.items():
            if key.default is not None:
                d = key.default
            elif table in prof:
                d = prof[table][k]
            elif table == "motor":
                d = "the preset's"
            else:
                d = _show(code[table][k])
            rng, d = key.range.format(**fill), d.format(**fill)
            lines.append(f"| `{k}` | {key.unit} | {d} | {rng} | {key.meaning} |")
        lines.append("")
    from bench.scenarios._faults import reference_md

    lines += reference_md()
    lines += [
        "## [estimator_options]",
        "",
        "One scenario serves every estimator: each estimator takes the options it declares "
        "(below) and leaves out the others, which a run names in a note (one line on stderr, "
        "and `estimator_options_left_out` in `meta.json`). A key no estimator declares is an "
        "error naming the file and the key; a plug-in's own options are accepted in a file "
        "that names the plug-in in `estimator` or `estimators`, or in a run of it with "
        "`--estimator` (docs/ESTIMATORS.md). Each "
        "value is checked by its key. `meta.json` (`controller_gains`) records the values a "
        "run used, derived ones included.",
        "",
    ]
    for group, members in option_groups():
        lines += [f"### {', '.join(group)}", ""]
        lines += ["| key | unit | default | range | meaning |", "|---|---|---|---|---|"]
        for opt_keys, (unit, d, rng, meaning) in members:
            shown = ", ".join(f"`{k}`" for k in opt_keys)
            lines.append(f"| {shown} | {unit} | {d} | {rng} | {meaning} |")
        lines.append("")
    bare = [n for n, rows in estimator_options().items() if not rows]
    if bare:
        lines += [f"{', '.join(f'`{n}`' for n in bare)}: no options.", ""]
    return "\n".join(lines).rstrip("\n") + "\n"
