"""``bench link``: the latency link between two buses (delay, jitter, loss)."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from bench._errors import BenchError
from bench.cli._common import (
    MODES,
    NONNEG_FLOAT,
    NONNEG_INT,
    STOP,
    add_bus,
    bus_spec,
    ready,
    same_bus,
    stop_on_signals,
)


def _own(own: float | None, shared: float) -> float:
    """A direction's own option, or the option of both directions."""
    return shared if own is None else own


def cmd_link(args: argparse.Namespace) -> int:
    from bench.nodes._link import link_logic
    from bench.nodes._plan import LinkPlan
    from bench.wire._bus import BusSpec
    from bench.wire._codec import Codec

    codec = Codec()
    if args.plan:
        return _serve(*_planned(args, codec))
    if args.to is None:
        raise BenchError("bench link: give --to INTERFACE:CHANNEL (or --plan FILE)")
    a = bus_spec(args, announce=False)
    iface, _, chan = args.to.partition(":")
    if not iface or not chan:
        raise BenchError(f"--to: expected INTERFACE:CHANNEL, got {args.to!r}")
    b = BusSpec(iface, chan, args.to_port)
    for opt in ("drop_prob", "duty_drop_prob", "sample_drop_prob"):
        v = getattr(args, opt)
        if v is not None and not 0.0 <= v <= 1.0:
            raise BenchError(f"--{opt.replace('_', '-')}: a probability in [0, 1], got {v}")
    if same_bus(a, b):
        raise BenchError(
            f"--to {b.describe()}: the same bus as the link's input ({a.describe()}); "
            "a link forwards between two buses"
        )
    lp = LinkPlan(
        seed=args.seed or 0,
        duty_delay_steps=args.delay_steps or 0,
        sample_delay_steps=args.sample_delay_steps or 0,
        duty_delay_us=args.duty_delay_us,
        sample_delay_us=args.sample_delay_us,
        duty_jitter_us=_own(args.duty_jitter_us, args.jitter_us),
        sample_jitter_us=_own(args.sample_jitter_us, args.jitter_us),
        jitter_dist=args.jitter_dist,
        duty_drop_prob=_own(args.duty_drop_prob, args.drop_prob),
        sample_drop_prob=_own(args.sample_drop_prob, args.drop_prob),
    )
    logic = link_logic(lp, args.mode, codec)
    return _serve(a, b, logic, args.idle_s)


def _planned(args: argparse.Namespace, codec: Any) -> tuple[Any, Any, Any, float]:
    """The buses and the link of a run's plan (``--plan``): plant side, controller side."""
    from bench.nodes._link import link_logic
    from bench.nodes._plan import read_plan

    plan = read_plan(args.plan)
    lp = plan.link
    if lp is None:
        raise BenchError(f"--plan {args.plan}: the plan injects no latency (no link)")
    logic = link_logic(lp, plan.mode, codec)
    return plan.bus("plant"), plan.bus("controller"), logic, args.idle_s


def _serve(a: Any, b: Any, logic: Any, idle_s: float) -> int:
    """Forward between the buses ``a`` and ``b`` through ``logic`` until stopped or idle."""
    from bench.nodes._link import link_loop

    bus_a = a.open()
    try:
        bus_b = b.open()
    except BaseException:
        bus_a.shutdown()
        raise
    stop_on_signals()
    sent: dict[str, int] = {}
    why = "stopped"
    try:
        why = link_loop(
            bus_a, bus_b, logic, on_ready=ready, idle_s=idle_s, stop=STOP.is_set, sent=sent
        )
    finally:
        bus_a.shutdown()
        bus_b.shutdown()
        if why == "idle":
            print(f"link: no traffic for {idle_s:g} s: stopping", file=sys.stderr)
        print(
            f"link: forwarded {sent.get('a_to_b', 0)} frames {a.describe()} -> {b.describe()}, "
            f"{sent.get('b_to_a', 0)} back; dropped {logic.dropped_samples} samples/truth and "
            f"{logic.dropped_duties} duties on purpose"
            + (
                f"; {sent['send_errors']} sends refused by a bus, "
                f"{sent.get('frames_lost_on_send', 0)} frames lost after retries"
                if sent.get("send_errors")
                else ""
            ),
            file=sys.stderr,
        )
    return 0


def register(sub: Any) -> None:
    p = sub.add_parser("link", help="latency link between two buses (delay, jitter, drop)")
    add_bus(p)
    p.add_argument(
        "--plan",
        metavar="FILE",
        help="forward as a run's plan says (its plan.json: buses, mode, latency); "
        "the other options then do not apply",
    )
    p.add_argument("--to", help="the other bus, INTERFACE:CHANNEL (e.g. socketcan:vcan1)")
    p.add_argument("--to-port", type=int, help="UDP port of the other bus (udp_multicast)")
    p.add_argument("--mode", choices=MODES, default="lockstep")
    p.add_argument(
        "--delay-steps", type=NONNEG_INT, default=0, help="lockstep: duty direction, periods"
    )
    p.add_argument(
        "--sample-delay-steps",
        type=NONNEG_INT,
        default=0,
        help="lockstep: sample direction, periods",
    )
    p.add_argument(
        "--duty-delay-us", type=NONNEG_FLOAT, default=0.0, help="real time: duty direction"
    )
    p.add_argument(
        "--sample-delay-us", type=NONNEG_FLOAT, default=0.0, help="real time: sample direction"
    )
    p.add_argument(
        "--jitter-us",
        type=NONNEG_FLOAT,
        default=0.0,
        help="real time, both directions: standard deviation (normal) or half-width (uniform)",
    )
    for way in ("duty", "sample"):
        p.add_argument(
            f"--{way}-jitter-us",
            type=NONNEG_FLOAT,
            help=f"real time: jitter of the {way} direction (default: --jitter-us)",
        )
    p.add_argument("--jitter-dist", choices=("normal", "uniform"), default="normal")
    p.add_argument(
        "--drop-prob", type=float, default=0.0, help="per frame, both directions, in [0, 1]"
    )
    for way in ("duty", "sample"):
        p.add_argument(
            f"--{way}-drop-prob",
            type=float,
            help=f"drop probability of the {way} direction (default: --drop-prob)",
        )
    p.add_argument(
        "--seed",
        type=NONNEG_INT,
        default=0,
        help="seed of the drops and jitter (a stream per direction)",
    )
    p.add_argument("--duration", type=float, help="ignored (accepted for symmetry with the nodes)")
    p.add_argument(
        "--idle-s",
        type=float,
        default=30.0,
        help="exit after this long without traffic, once traffic has begun (s)",
    )
    p.set_defaults(func=cmd_link)
