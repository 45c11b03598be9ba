"""``bench show``: the effective scenario, its motor, PWM rate, commands and transport."""

from __future__ import annotations

import argparse
import json
from typing import Any

from bench.cli._common import add_bus, add_plant_profile, add_scenario_overrides


def cmd_show(args: argparse.Namespace) -> int:
    from bench.cli._common import bus_spec, scenario_from_args
    from bench.scenarios._describe import describe, schedule_lines
    from bench.scenarios._setup import position_sensor

    scn = scenario_from_args(args)
    d = describe(scn)
    from bench.wire._bus import UDP_DEFAULT_PORT
    from bench.wire._codec import default_codec

    spec = bus_spec(args, announce=False)
    default_port = spec.interface == "udp_multicast" and args.port is None
    port = UDP_DEFAULT_PORT if default_port else spec.port
    d["transport"] = {
        "interface": spec.interface,
        "channel": spec.channel,
        "port": port,
        "note": (
            "the port of bench run --controller external and bench plant without --port "
            "(python-can's default); bench run with its own controller picks one per run"
            if default_port
            else ""
        ),
    }
    d["dbc_version"] = default_codec().version
    # what a controller under test reads for its angle (docs/PROTOCOL.md)
    d["position_sensor"] = position_sensor(scn)
    if args.json:
        print(json.dumps(d, indent=2))
        return 0
    m, pwm = d["motor"], d["pwm"]
    print(f"scenario {scn.name}: {scn.description} ({scn.paper or 'no paper'})")
    print(f"DBC version {d['dbc_version']} (docs/PROTOCOL.md)")
    print(f"PWM {pwm['f_sw_hz']:g} Hz (T_s {pwm['T_s']:g} s), {pwm['periods']} periods")
    keys = ("n_p", "R_s", "L_d", "L_q", "psi_f", "J", "b", "i_rated", "i_max", "tau_rated")
    units = ("", "Ohm", "H", "H", "Wb", "kg m^2", "N m s", "A", "A", "N m")
    print(
        f"motor {m['preset']}"
        + (f" ([motor] sets {', '.join(m['replaced'])})" if m["replaced"] else "")
    )
    for k, u in zip(keys, units, strict=True):
        print(f"  {k:10s} {m[k]:g} {u}".rstrip())
    print(f"  {'w_m_rated':10s} {m['w_m_rated']:g} rad/s (mechanical)")
    pl = d["plant"]
    inv = pl["inverter"]
    print(
        f"plant {pl['profile']}: {inv['model']} inverter, u_dc {inv['u_dc']:g} V, "
        f"t_dead {inv['t_dead']:g} s, drops {inv['v_ce']:g}/{inv['v_f']:g} V"
    )
    tr = d["transport"]
    print(
        f"transport {tr['interface']} {tr['channel']}"
        + (f" port {tr['port']}" if tr["port"] is not None else "")
        + (f" ({tr['note']})" if tr["note"] else "")
    )
    ps = d["position_sensor"]
    print(
        f"position sensor (PositionSensor, --controller external): {ps['counts']} counts/rev, "
        f"every {ps['every']} period(s) ({ps['rate_hz']:g} Hz), {ps['delay_s']:g} s old"
        + (" (no [sensors] encoder_counts: the 16-bit default)" if ps["default"] else "")
    )
    st = d["start"]
    print(
        f"start: rotor at {st['theta_e0_deg']:g} deg electrical (theta_e0_deg), "
        + (
            "known to the controller (known_initial_angle = true)"
            if st["known_initial_angle"]
            else "found by the controller's start-up (known_initial_angle = false)"
        )
    )
    print(f"scoring from {st['score_from_s']:g} s (score_from_s)")
    sc = d["schedule"]
    print(
        f"schedule ({sc['frames']} BenchCommand frames: start at step {sc['start_step']}, "
        f"stop at step {sc['stop_step']}; a ramp is sent as steps at "
        f"{sc['reference_rate_hz']:g} Hz; --commands lists every frame; in lockstep "
        f"{sc['frames_lockstep']} with the keep-alives, docs/PROTOCOL.md):"
    )
    for line in schedule_lines(sc):
        print(f"  {line}")
    if args.commands:
        print(
            f"commands ({len(d['commands'])} BenchCommand frames; step = the period they apply in):"
        )
        print(f"  {'step':>8} {'cmd':>6} {'speed_ref rpm':>14} {'load N m':>9}")
        for c in d["commands"]:
            print(
                f"  {c['step']:>8} {c['cmd_name']:>6} {c['speed_ref_rpm']:>14.1f} "
                f"{c['load_nm']:>9.3f}"
            )
    return 0


def register(sub: Any) -> None:
    p = sub.add_parser(
        "show",
        help="the effective scenario: motor parameters, PWM rate, plant, start-up and scoring, "
        "the command schedule (segments; --commands: every BenchCommand frame) and the transport",
    )
    p.add_argument("scenario", help="shipped scenario name or a .toml path")
    add_scenario_overrides(p)
    add_plant_profile(p)
    add_bus(p)
    p.add_argument(
        "--commands",
        action="store_true",
        help="also list every BenchCommand frame (a ramp is one frame per reference period)",
    )
    p.add_argument(
        "--json",
        action="store_true",
        help="everything as JSON: the compact schedule (schedule) and every frame (commands)",
    )
    p.set_defaults(func=cmd_show)
