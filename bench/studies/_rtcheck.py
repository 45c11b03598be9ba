"""``bench rtcheck``: what real time this host can keep, measured before a run finds out.

Two measurements, then a verdict per PWM rate:

- Wake-up latency, as ``cyclictest`` measures it: a process sleeps to
  absolute deadlines (:class:`bench.nodes._clock.RealTimeClock`, the plant's own clock)
  at the period of each rate, doing no work, for ``seconds``; the lateness
  of every wake-up is kept (median, p99, p99.9, max), and host stalls
  (wake-ups later than the clock's stall threshold) are counted.  Once with
  normal scheduling and once under ``SCHED_FIFO`` with memory locked
  (``--rt-priority``; refused without root or ``CAP_SYS_NICE``, which the
  result says).  Each runs in a process of its own, as a node would.
- The plant's computation per period: the plant node of ``wen-5.1`` (the
  plant step, its sample and truth frames encoded) run in-process against
  the project's controller, timed per period (median and p99), in the same
  process and under the same scheduling as the wake-ups; plus the cost of
  sending one period's frames (``PhaseSamples`` and ``PlantTruth``) on the
  default transport, medians and p99s added.

Verdict per rate and setting, with ``T`` the period, ``c`` the plant's
computation and ``w`` the wake-up latency: ``yes`` when the p99s fit,
``c_p99 + w_p99 <= 0.8 T`` (20 % left for receiving the duty and the
controller's share of the machine); ``marginal`` when only the medians fit,
``c_med + w_med <= T`` (most periods on time, some late); ``no`` otherwise.
"""

from __future__ import annotations

import math
import multiprocessing as mp
import os
import queue
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from bench._errors import BenchError

#: Share of the period the p99 computation and wake-up latency may use for ``yes``.
MARGIN = 0.8
#: The SCHED_FIFO priority the check asks for (the plant's in ``bench run --rt-priority 80``).
FIFO_PRIORITY = 80


@dataclass(frozen=True, slots=True)
class Latency:
    """Wake-up lateness at one period (us), and the host stalls seen."""

    period_us: float
    n: int
    median: float
    p99: float
    p999: float
    max: float
    stalls: int
    granted: bool
    refused: tuple[str, ...]
    compute_median: float
    compute_p99: float


def _quantile(xs: list[float], q: float) -> float:
    return xs[min(len(xs) - 1, int(q * (len(xs) - 1) + 0.5))]


def _measure_wakeups(T_s: float, seconds: float, fifo: bool, out: Any) -> None:
    """Child process: sleep to absolute deadlines for ``seconds``; the lateness to ``out``."""
    from bench.nodes._clock import RealTimeClock
    from bench.nodes._rt import apply_rt, no_gc

    rt = apply_rt(FIFO_PRIORITY if fifo else None, None, role="rtcheck")
    compute = plant_compute_us()
    send = send_cost_us()
    compute = {k: compute[k] + send[k] for k in ("median", "p99")}
    clock = RealTimeClock(T_s)
    late: list[float] = []
    with no_gc():
        clock.start()
        t_end = time.perf_counter() + seconds
        while time.perf_counter() < t_end:
            late.append(clock.wait())
    late.sort()
    out.put(
        Latency(
            period_us=1e6 * T_s,
            n=len(late),
            median=1e6 * _quantile(late, 0.5),
            p99=1e6 * _quantile(late, 0.99),
            p999=1e6 * _quantile(late, 0.999),
            max=1e6 * late[-1],
            stalls=clock.stalls,
            granted=not (fifo and rt.refused),
            refused=tuple(rt.refused),
            compute_median=compute["median"],
            compute_p99=compute["p99"],
        )
    )


def wakeup_latency(T_s: float, seconds: float, *, fifo: bool) -> Latency:
    """Wake-up latency of a fresh process at period ``T_s`` (normal or ``SCHED_FIFO``)."""
    ctx = mp.get_context("spawn")
    q = ctx.Queue()
    p = ctx.Process(target=_measure_wakeups, args=(T_s, seconds, fifo, q))
    p.start()
    # The child imports the bench and measures the plant's computation before its
    # wake-ups: on a loaded host that took more than a minute, so it is waited for as
    # long as it lives (up to START_LIMIT_S beyond the measurement), never by one timeout.
    deadline = time.monotonic() + seconds + START_LIMIT_S
    try:
        while True:
            try:
                res: Latency = q.get(timeout=1.0)
                return res
            except queue.Empty:
                if not p.is_alive():
                    try:  # its result may have come just before it ended
                        return q.get(timeout=1.0)
                    except queue.Empty:
                        raise BenchError(
                            "rtcheck: the measuring process ended without a result "
                            f"(exit status {p.exitcode})"
                        ) from None
                if time.monotonic() > deadline:
                    p.kill()
                    raise BenchError(
                        f"rtcheck: the measuring process gave no result in "
                        f"{seconds + START_LIMIT_S:g} s (a host this loaded cannot be rated)"
                    ) from None
    finally:
        p.join(timeout=10.0)


#: How long a measuring process may take beyond its measurement (s): its start-up
#: (imports, the plant's computation measured first) on a loaded 2-core host took
#: over 60 s; ten times that is a host that cannot be rated at all.
START_LIMIT_S = 600.0


def plant_compute_us(periods: int = 4000) -> dict[str, float]:
    """The plant node's computation per period (us): median and p99 over ``periods``."""
    from bench.nodes._loops import run_inprocess
    from bench.scenarios._schema import load_scenario
    from bench.scenarios._setup import sample_period
    from bench.wire._codec import Codec

    scn = load_scenario("wen-5.1")
    scn = scn.with_overrides(duration=periods * sample_period(scn))
    times: list[float] = []
    run_inprocess(scn, "tt-dq", Codec(), plant_times=times)
    times = sorted(times[len(times) // 10 :])  # the start-up's first periods left out
    return {
        "periods": float(len(times)),
        "median": 1e6 * _quantile(times, 0.5),
        "p99": 1e6 * _quantile(times, 0.99),
    }


def send_cost_us(periods: int = 2000) -> dict[str, float]:
    """Sending one period's plant frames on the default transport (us): median and p99."""
    import os

    from bench.wire._bus import BusSpec, default_transport, own_udp_port
    from bench.wire._codec import Codec

    iface, chan, _ = default_transport()
    port = own_udp_port(os.getpid()) if iface == "udp_multicast" else None
    codec = Codec()
    frames = [
        codec.encode(
            "PhaseSamples", {"i_a": 1.0, "i_b": -0.5, "u_dc": 540.0, "status": 1, "step": 3}
        ),
        codec.encode(
            "PlantTruth",
            {"theta_e": 1.0, "w_m": 10.0, "tau_e": 1.0, "tau_L": 0.5, "step": 3, "duty_age": 1},
        ),
    ]
    bus = BusSpec(iface, chan, port).open()
    times: list[float] = []
    try:
        for _ in range(periods):
            t0 = time.perf_counter()
            for f in frames:
                bus.send(f)
            times.append(time.perf_counter() - t0)
    finally:
        bus.shutdown()
    times.sort()
    return {"median": 1e6 * _quantile(times, 0.5), "p99": 1e6 * _quantile(times, 0.99)}


def verdict(T_us: float, lat: Latency) -> str:
    """``yes``, ``marginal`` or ``no`` (module doc)."""
    if lat.compute_p99 + lat.p99 <= MARGIN * T_us:
        return "yes"
    if lat.compute_median + lat.median <= T_us:
        return "marginal"
    return "no"


def run_rtcheck(rates_hz: list[float], seconds: float) -> dict[str, Any]:
    """Measure and judge every rate, normal and ``SCHED_FIFO``; the result as JSON data."""
    out: dict[str, Any] = {"seconds": seconds, "rates": {}}
    for rate in rates_hz:
        T_s = 1.0 / rate
        row: dict[str, Any] = {}
        for setting, fifo in (("normal", False), ("sched_fifo", True)):
            lat = wakeup_latency(T_s, seconds, fifo=fifo)
            row[setting] = {
                **asdict(lat),
                "refused": list(lat.refused),
                "verdict": verdict(1e6 * T_s, lat) if lat.granted else "not granted",
            }
        out["rates"][f"{rate:g}"] = row
    return out


def _by_rate(res: dict[str, Any]) -> list[tuple[str, dict[str, Any]]]:
    """The rates in numeric order (a JSON file keeps them sorted as text)."""
    return sorted(res["rates"].items(), key=lambda kv: float(kv[0]))


def format_rtcheck(res: dict[str, Any]) -> str:
    """The measurements as a table, and which rates this host sustains with which setting."""
    lines = [
        f"{'rate':>8} {'setting':<11} {'plant compute median':>21} {'p99':>8} "
        f"{'wake-up median':>15} {'p99':>8} {'p99.9':>8} {'max':>9} {'stalls':>7}  verdict",
    ]
    for rate, row in _by_rate(res):
        for setting, r in row.items():
            lines.append(
                f"{rate + ' Hz':>8} {setting:<11} {r['compute_median']:>18.1f} us "
                f"{r['compute_p99']:>8.1f} {r['median']:>12.1f} us {r['p99']:>8.1f} "
                f"{r['p999']:>8.1f} {r['max'] / 1e3:>6.1f} ms {r['stalls']:>7}  {r['verdict']}"
            )
    ok = [
        f"{rate} Hz ({setting})"
        for rate, row in _by_rate(res)
        for setting, r in row.items()
        if r["verdict"] == "yes"
    ]
    lines += ["", "sustained: " + (", ".join(ok) if ok else "none of the rates checked")]
    refused = {
        w for row in res["rates"].values() for w in row.get("sched_fifo", {}).get("refused", [])
    }
    if refused:
        lines.append("SCHED_FIFO refused: " + "; ".join(sorted(refused)))
    return "\n".join(lines)


#: The markers of the measured block in docs/REALTIME.md.
DOC_BEGIN = "<!-- rtcheck:begin (written by bench rtcheck --doc; do not edit) -->"
DOC_END = "<!-- rtcheck:end -->"


def render_doc_block(res: dict[str, Any]) -> str:
    """The measured block of docs/REALTIME.md, from ``rtcheck.json``."""
    return "\n".join(
        [
            DOC_BEGIN,
            "",
            f"`bench rtcheck --seconds {res['seconds']:g}` on this project's 2-core shared "
            "virtual machine (every figure below is from `docs/realtime/rtcheck.json`):",
            "",
            "```",
            format_rtcheck(res),
            "```",
            "",
            DOC_END,
        ]
    )


def splice_block(doc: str, block: str, begin: str, end: str) -> str:
    """``doc`` with the block from ``begin`` to ``end`` replaced by ``block`` (which holds
    both markers), appended when ``doc`` has none: docs/REALTIME.md's measured blocks."""
    if begin in doc and end in doc:
        head, _, rest = doc.partition(begin)
        _, _, tail = rest.partition(end)
        return head + block + tail
    return doc.rstrip() + "\n\n" + block + "\n"


def update_doc(doc: str, res: dict[str, Any]) -> str:
    """``doc`` with its measured block replaced (appended when it has none)."""
    return splice_block(doc, render_doc_block(res), DOC_BEGIN, DOC_END)


def host_file() -> Path:
    """Where ``bench rtcheck`` keeps this host's last result for ``bench run`` to read:
    ``$XDG_CACHE_HOME/can-hil-bench/rtcheck.json`` (``~/.cache/...`` by default)."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "can-hil-bench" / "rtcheck.json"


def host_warning(f_sw: float, fifo: bool, res: dict[str, Any] | None) -> str | None:
    """The line ``bench run --mode realtime`` prints before it starts, from this host's
    ``bench rtcheck`` result ``res`` (None: never measured); None when the host keeps
    ``f_sw`` (Hz) with that scheduling (verdict ``yes``)."""
    setting = "sched_fifo" if fifo else "normal"
    how = "with --rt-priority" if fifo else "with normal scheduling"
    if res is None:
        return (
            "warning: this host's real-time capacity is not measured; run `bench rtcheck` "
            "first (docs/REALTIME.md: the settings, and a reference machine's figures)"
        )
    r = (res.get("rates") or {}).get(str(int(round(f_sw))), {}).get(setting)
    if r is None:
        return (
            f"warning: bench rtcheck has not measured {f_sw:g} Hz {how} on this host; "
            f"run `bench rtcheck --rate {f_sw / 1e3:g}`"
        )
    if r.get("verdict") == "yes":
        return None
    return (
        f"warning: bench rtcheck rates this host '{r.get('verdict')}' at {f_sw:g} Hz {how} "
        f"(wake-up p99 {float(r.get('p99', math.nan)):.0f} us, plant computation p99 "
        f"{float(r.get('compute_p99', math.nan)):.0f} us, period {1e6 / f_sw:.0f} us): "
        "expect late periods, and an injection estimator may lose its angle or trip"
        + ("" if fifo else "; --rt-priority 80 may help")
    )


def load_host_result() -> dict[str, Any] | None:
    """This host's last ``bench rtcheck`` result, or None."""
    import json

    f = host_file()
    try:
        data = json.loads(f.read_text())
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None
