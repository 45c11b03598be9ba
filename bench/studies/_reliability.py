"""Reliability of whole runs: kills, signals, parallel runs and determinism under load.

What :mod:`bench.studies._soak` checks frame by frame on the nodes, this
checks on ``bench run`` and its processes, as a user meets them:

- **determinism under load**: lockstep runs through the latency link (and
  without it) with busy processes beside them on every CPU; each trace is
  compared with the in-process one, bit for bit;
- **kills**: ``kill -9`` of the controller in lockstep (the run ends at once,
  naming the signal) and in real time (the plant's watchdog puts it in the
  safe state; the run reports the node);
- **signals**: SIGINT and SIGTERM to ``bench run`` mid-run: exit 130, every
  node gone, the files written;
- **parallel runs**: two runs started together, each on a bus of its own
  (both give the in-process trace), then two on one bus (each gives that
  trace or refuses with one line; none gives a wrong result).

:func:`run_process_checks` returns the figures as a dict (``bench soak
--processes`` puts them in its JSON), and :func:`render_reliability` writes
``docs/RELIABILITY.md`` from that JSON alone.
"""

from __future__ import annotations

import json
import os
import random
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import can
import numpy as np

#: The multicast group of the study's udp_multicast buses (each run a port of its own).
GROUP = "239.74.163.2"
#: The columns of a trace compared bit for bit (to 1e-9, as the transport tests do).
TRACE_COLUMNS = ("theta_err_deg", "theta_hat", "w_m_rpm", "i_a", "d_a")


def free_port(span: int = 2) -> int:
    """A UDP port ``p`` with ``p .. p + span - 1`` unused on this host (a link uses ``p + 1``)."""
    rng = random.SystemRandom()
    for _ in range(200):
        p = rng.randrange(46000, 60000, 2)
        ok = True
        for q in range(p, p + span):
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
                try:
                    s.bind(("", q))
                except OSError:
                    ok = False
                    break
        if ok:
            return p
    raise RuntimeError("no free UDP port pair")


@contextmanager
def busy_processes(n: int | None = None) -> Iterator[None]:
    """``n`` (default: one per CPU, and one more) processes spinning on the CPUs while the
    block runs."""
    count = n if n is not None else (os.cpu_count() or 1) + 1
    procs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(count)]
    try:
        yield
    finally:
        for p in procs:
            p.kill()
            p.wait()


def _loadavg() -> float:
    try:
        return os.getloadavg()[0]
    except OSError:
        return float("nan")


def run_trace(frames: Sequence[can.Message], scn: Any) -> dict[str, np.ndarray]:
    """The per-step table of a run's frames (the preset's pole pairs)."""
    from bench.runs._analysis import analyze_frames
    from bench.scenarios._setup import get_preset, sample_period
    from bench.wire._codec import default_codec

    n_p = get_preset(scn).motor.n_p
    return analyze_frames(frames, default_codec(), T_s=sample_period(scn), n_p=n_p).table


def first_divergence(ref: dict[str, np.ndarray], got: dict[str, np.ndarray]) -> str | None:
    """Where ``got`` leaves the reference trace (None: the same trace)."""
    if len(ref["step"]) != len(got["step"]) or not np.array_equal(ref["step"], got["step"]):
        return f"steps differ ({len(got['step'])} rows, reference {len(ref['step'])})"
    for col in TRACE_COLUMNS:
        same = np.isclose(ref[col], got[col], rtol=0.0, atol=1e-9, equal_nan=True)
        if not same.all():
            return f"{col} at step {int(ref['step'][int(np.argmin(same))])}"
    return None


def short_scenario(name: str, duration: float, **latency: Any) -> Any:
    """``name`` shortened to ``duration`` (s), its speed reference ramping to 100 rpm in
    50 ms, scored from half way, with ``latency`` fields replaced."""
    from dataclasses import replace

    from bench.scenarios._schema import Profile, load_scenario

    s = load_scenario(name).with_overrides(
        duration=duration,
        score_from_s=duration / 2,
        speed_rpm=Profile(((0.0, 0.0), (0.05, 100.0))),
    )
    return replace(s, latency=replace(s.latency, **latency)) if latency else s


def determinism_under_load(runs: int, say: Callable[[str], None]) -> dict[str, Any]:
    """Lockstep runs with busy processes beside them, each trace against the in-process one."""
    from bench.nodes._loops import run_inprocess
    from bench.runs._run import run_scenario
    from bench.wire._bus import BusSpec
    from bench.wire._codec import default_codec

    busy = (os.cpu_count() or 1) + 1
    cases: tuple[tuple[str, dict[str, int]], ...] = (
        ("through the latency link (duty 2, sample 1 periods)", {"duty_delay_steps": 2,
                                                                  "sample_delay_steps": 1}),
        ("plant and controller on one bus", {}),
    )  # fmt: skip
    out: dict[str, Any] = {"busy_processes": busy, "cases": []}
    with tempfile.TemporaryDirectory() as tmp, busy_processes(busy):
        time.sleep(1.0)  # the load is on before the first run
        for label, lat in cases:
            scn = short_scenario("wen-5.1", 0.06, **lat)
            ref = run_trace(run_inprocess(scn, "sensored", default_codec()), scn)
            case: dict[str, Any] = {"case": label, "runs": runs, "identical": 0, "diverged": []}
            load = []
            for i in range(runs):
                say(f"determinism under load: {label}, run {i + 1}/{runs}")
                spec = BusSpec("udp_multicast", GROUP, free_port())
                d = Path(tmp) / f"{len(out['cases'])}-{i}"
                res = run_scenario(scn, "sensored", spec=spec, out_dir=d, progress=False)
                load.append(_loadavg())
                why = first_divergence(ref, run_trace(list(can.LogReader(str(res.capture))), scn))
                if why is None:
                    case["identical"] += 1
                else:
                    case["diverged"].append(why)
            case["loadavg_1min"] = max(load)
            out["cases"].append(case)
    return out


def _run_cmd(out: Path, port: int, *extra: str, scenario: str = "wen-5.1") -> list[str]:
    return [sys.executable, "-m", "bench", "run", scenario, "-e", "sensored", "-i",
            "udp_multicast", "--channel", GROUP, "--port", str(port), "--out", str(out),
            *extra]  # fmt: skip


def _children(out: Path) -> dict[str, int]:
    """Node processes of the run writing into ``out`` (found by their ``--report`` path)."""
    found: dict[str, int] = {}
    for pid in os.listdir("/proc"):
        if not pid.isdigit():
            continue
        try:
            args = Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace").split("\0")
        except OSError:
            continue
        for role in ("plant", "controller"):
            if role in args and str(out / f"{role}.json") in args:
                found[role] = int(pid)
    return found


def _alive(pid: int) -> bool:
    st = Path(f"/proc/{pid}/stat")
    try:
        return st.read_text().split()[2] != "Z"
    except (OSError, IndexError):
        return False


def _started(out: Path, proc: subprocess.Popen[str], settle_s: float) -> dict[str, int]:
    """Wait until both nodes run and the plant has stepped for ``settle_s``; their pids."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < 120.0:
        kids = _children(out)
        if len(kids) == 2 and (out / "plant.log").exists() and proc.poll() is None:
            time.sleep(settle_s)
            return kids
        if proc.poll() is not None:
            break
        time.sleep(0.1)
    raise RuntimeError(f"the run in {out} did not start")


def _finish(proc: subprocess.Popen[str], t0: float) -> tuple[int, float, str]:
    _, err = proc.communicate(timeout=120)
    return proc.returncode, time.monotonic() - t0, err.strip().splitlines()[-1] if err else ""


def kill_checks(say: Callable[[str], None]) -> list[dict[str, Any]]:
    """``kill -9`` of a node during a run: how the run ends."""
    out: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as tmp:
        for mode, role in (("lockstep", "controller"), ("lockstep", "plant"),
                           ("realtime", "controller")):  # fmt: skip
            say(f"kill -9 of the {role} ({mode})")
            d = Path(tmp) / f"{mode}-{role}"
            extra = ["--mode", mode, "--duration", "30", "-q"]
            scenario = "wen-5.1"
            if mode == "realtime":
                # Xue's motor held at standstill: a held duty on a turning rotor would
                # trip over-current before the watchdog
                f = Path(tmp) / "standstill.toml"
                f.write_text('extends = "xue-fig13"\nspeed_rpm = [[0.0, 0.0]]\n')
                scenario, extra = str(f), ["--mode", mode, "--duration", "3", "-q",
                                           "--watchdog-ms", "200"]  # fmt: skip
            proc = subprocess.Popen(
                _run_cmd(d, free_port(), *extra, scenario=scenario),
                stdout=subprocess.DEVNULL,
                stderr=subprocess.PIPE,
                text=True,
            )
            kids = _started(d, proc, 1.5)
            t0 = time.monotonic()
            os.kill(kids[role], signal.SIGKILL)
            rc, took, last = _finish(proc, t0)
            plant = {}
            if (d / "plant.json").exists():
                plant = json.loads((d / "plant.json").read_text())
            metrics = json.loads((d / "metrics.json").read_text())
            out.append(
                {
                    "mode": mode,
                    "killed": role,
                    "exit_code": rc,
                    "s_to_exit": round(took, 2),
                    "names_signal": "SIGKILL" in last,
                    "message": last.split("; files in ")[0],
                    "steps_scored": int(metrics.get("steps", 0)),
                    "plant_fault": plant.get("fault"),
                    "nodes_left": sum(_alive(p) for p in kids.values()),
                }
            )
    return out


def signal_checks(say: Callable[[str], None]) -> list[dict[str, Any]]:
    """SIGINT and SIGTERM to ``bench run`` mid-run (lockstep)."""
    out: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as tmp:
        for sig in (signal.SIGINT, signal.SIGTERM):
            say(f"{sig.name} to bench run")
            d = Path(tmp) / sig.name
            proc = subprocess.Popen(
                _run_cmd(d, free_port(), "--duration", "30", "-q"),
                stdout=subprocess.DEVNULL,
                stderr=subprocess.PIPE,
                text=True,
            )
            kids = _started(d, proc, 1.5)
            t0 = time.monotonic()
            proc.send_signal(sig)
            rc, took, _ = _finish(proc, t0)
            meta = json.loads((d / "meta.json").read_text())
            metrics = json.loads((d / "metrics.json").read_text())
            files = all((d / f).is_file() for f in ("capture.blf", "signals.csv", "meta.json"))
            out.append(
                {
                    "signal": sig.name,
                    "exit_code": rc,
                    "s_to_exit": round(took, 2),
                    "interrupted_in_meta": bool(meta.get("interrupted")),
                    "files_written": files,
                    "steps_scored": int(metrics.get("steps", 0)),
                    "nodes_left": sum(_alive(p) for p in kids.values()),
                }
            )
    return out


def _two_runs(
    tmp: Path, f: Path, ref: dict[str, np.ndarray], scn: Any, ports: list[int], tag: str
) -> list[dict[str, Any]]:
    """Two runs started together on ``ports``: each one's outcome against ``ref``."""
    procs = []
    for i, port in enumerate(ports):
        d = tmp / f"{tag}{i}"
        cmd = _run_cmd(d, port, "-q", scenario=str(f))
        procs.append((d, subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)))
    out = []
    for d, p in procs:
        _, err = p.communicate(timeout=300)
        lines = err.decode(errors="replace").strip().splitlines()
        last = lines[-1] if lines else ""
        if p.returncode == 0:
            why = first_divergence(ref, run_trace(list(can.LogReader(str(d / "capture.blf"))), scn))
            out.append({"outcome": "identical" if why is None else "wrong", "detail": why or ""})
        elif p.returncode == 2 and last.startswith("bench: error: another run"):
            said = last.removeprefix("bench: error: ").split("; files in ")[0]
            out.append({"outcome": "refused", "detail": said})
        else:
            out.append({"outcome": "wrong", "detail": f"exit {p.returncode}: {last}"})
    return out


def parallel_check(say: Callable[[str], None]) -> dict[str, Any]:
    """Two lockstep runs started together, on a port each, then on one port."""
    from bench.nodes._loops import run_inprocess
    from bench.scenarios._schema import write_effective
    from bench.wire._codec import default_codec

    say("two runs in parallel, a bus each; then two on one bus")
    scn = short_scenario("wen-5.1", 0.1)
    ref = run_trace(run_inprocess(scn, "sensored", default_codec()), scn)
    with tempfile.TemporaryDirectory() as tmp:
        f = write_effective(scn, Path(tmp) / "scenario.json")
        own = _two_runs(Path(tmp), f, ref, scn, [free_port(), free_port()], "own")
        port = free_port()
        shared = _two_runs(Path(tmp), f, ref, scn, [port, port], "shared")
    return {
        "runs": 2,
        "own_bus_identical": sum(r["outcome"] == "identical" for r in own),
        "diverged": [r["detail"] for r in own if r["outcome"] != "identical"],
        "shared_bus_runs": shared,
    }


#: What :func:`pour_fuzz` sends besides random FD frames with the DBC's identifiers
#: (:data:`RANDOM_FD_SHARE` of them): the kinds of
#: :class:`bench.studies._soak.FrameFuzzer`.  ``garbage``: frames no E2E check
#: passes (corrupted copies, wrong lengths, unknown identifiers; the random FD
#: frames of the classic messages have lengths above 8, those of the FD recorder
#: frames pass the 8-bit CRC once in 256 and then differ in their run_id) and
#: copies of the run's own frames (duplicates, replays, reordered bursts);
#: ``forged`` adds frames that a receiver cannot tell from genuine ones: valid
#: frames with random values, and random payloads of the right length (which
#: pass the CRC once in 256).
FLOOD_WEIGHTS: dict[str, dict[str, float]] = {
    "garbage": {"valid": 0.0, "random_payload": 0.0, "duplicate": 2.0, "replay": 2.0},
    "forged": {"valid": 1.0, "random_payload": 3.0, "duplicate": 2.0, "replay": 2.0},
}
#: The share of random CAN FD frames with the DBC's identifiers in a flood.
RANDOM_FD_SHARE = 0.4


#: Age limit (s) of the run's frames the flood replays, by their receive time stamp.
#: A receiver places a frame by its step counter only while it is less than half the
#: counter's range (2**9 = 512 periods for the 10-bit steps, dbc/bench.dbc) old; a
#: replay older than that carries the step of a current period and cannot be told from
#: it, by the protocol's own contract. A lockstep native pair runs up to about 20,000
#: periods/s (the bench perf target), 512 periods in 25.6 ms: 10 ms keeps every replay
#: inside the contract with a margin of 2.5. The flood's reader falls behind a fast run
#: (python-can's receive costs about 90 us a frame) and would otherwise replay frames
#: seconds old: runs that diverged at steps past 1024.
REPLAY_FRESH_S = 0.010


def pour_fuzz(
    bus: can.BusABC,
    stop: Callable[[], bool],
    *,
    seed: int,
    kinds: str = "garbage",
    old_commands: int = 0,
    rate_hz: float = 1000.0,
) -> dict[str, int]:
    """Pour fuzzed CAN FD and classic frames at ``bus`` until ``stop()``; the frames sent, by kind.

    Random FD frames with the DBC's identifiers (:data:`RANDOM_FD_SHARE`), and
    :class:`bench.studies._soak.FrameFuzzer`'s kinds (weights
    :data:`FLOOD_WEIGHTS` ``[kinds]``), its replays and duplicates drawn from the
    frames seen on the bus (the run's own, a moment old) and the flood's own.  ``old_commands``:
    first that many valid ``BenchCommand`` frames of a longer run (steps that
    unwrap to before this run's start), one every few milliseconds, the replay
    that once kept a plant from ever starting.  At most ``rate_hz`` frames a
    second (on average): a flood that takes every CPU measures the host, not
    the run.
    """
    from bench.studies._soak import FrameFuzzer
    from bench.wire._codec import default_codec

    codec = default_codec()
    fz = FrameFuzzer(codec, seed, weights=FLOOD_WEIGHTS[kinds])
    rng = random.Random(seed)
    sent: dict[str, int] = {}
    n = 0
    t0 = time.monotonic()
    #: The flood's own frames, which multicast loops back to its socket with a fresh
    #: time stamp: not the run's, and a replayed old frame must not come back as new.
    echo: dict[tuple[int, bytes], int] = {}
    while not stop():
        while (seen := bus.recv(0.0)) is not None:
            key = (seen.arbitration_id, bytes(seen.data))
            if echo.get(key, 0) > 0:
                echo[key] -= 1
                continue
            fz.history.append(seen)
        now = time.time()
        if any(0.0 < m.timestamp < now - REPLAY_FRESH_S for m in fz.history):
            # the flood's own frames have no time stamp (0); copies keep the original's
            fz.history = deque(
                (m for m in fz.history if not 0.0 < m.timestamp < now - REPLAY_FRESH_S),
                maxlen=fz.history.maxlen,
            )
        if n < old_commands:
            sig = {"cmd": 0, "speed_ref": 0.0, "load_torque": 0.0, "seq": rng.randrange(16),
                   "step": rng.randrange(1 << 15, 1 << 16)}  # fmt: skip
            msg, kind = codec.encode("BenchCommand", sig), "old_command"
            time.sleep(0.005)
        elif rng.random() < RANDOM_FD_SHARE:
            name = rng.choice(codec.names)
            size = codec.length(name)
            if size <= 8 or rng.random() < 0.5:
                size = rng.choice([x for x in (12, 16, 20, 24, 32, 48, 64) if x != size])
            msg = can.Message(arbitration_id=codec.frame_id(name), data=rng.randbytes(size),
                              is_fd=True, is_extended_id=False)  # fmt: skip
            kind = "random_fd"
            fz.history.append(msg)
        else:
            msg, kind = fz.one()
            if 0.0 < msg.timestamp < time.time() - REPLAY_FRESH_S:
                # a copy chosen before a stall of this thread (a burst's later frames
                # wait in the fuzzer across iterations): 0.41 s and 992 periods old on a
                # loaded host, it took the place of a current sample; not sent
                continue
        try:
            bus.send(msg)
            key = (msg.arbitration_id, bytes(msg.data))
            echo[key] = echo.get(key, 0) + 1
        except (can.CanError, OSError):
            kind = "send_failed"
        sent[kind] = sent.get(kind, 0) + 1
        n += 1
        ahead = t0 + n / rate_hz - time.monotonic()
        if ahead > 0:
            time.sleep(ahead)
    return sent


def flood_check(
    say: Callable[[str], None],
    *,
    seed: int = 0,
    kinds: str = "garbage",
    keep: Path | None = None,
) -> dict[str, Any]:
    """A 0.3 s lockstep run of wen-5.1 (sensored) beside a flood of fuzzed frames.

    The flood starts as the run's nodes start (after the run's listening
    window: a bus that carries valid plant or bench frames then is rightly
    refused) with replays of another run's commands, then the frames of
    ``kinds`` (:data:`FLOOD_WEIGHTS`) until the run ends.  ``keep``: the run's
    folder (default: a temporary one).  The run must end within its timeouts
    with the in-process trace and the rejections counted, or with a named
    stop (exit 2, 3 or 4 and its line); a run that hangs is killed after
    :data:`FLOOD_LIMIT_S` and recorded as ``stalled``.
    """
    import threading

    from bench.nodes._loops import run_inprocess
    from bench.runs._run import build_native_libraries
    from bench.scenarios._schema import write_effective
    from bench.wire._codec import default_codec

    scn = short_scenario("wen-5.1", 0.3)
    ref = run_trace(run_inprocess(scn, "sensored", default_codec()), scn)
    # the run's own first build of the native library (minutes on a loaded host) is
    # done here, not inside FLOOD_LIMIT_S, which is the run's
    build_native_libraries()
    with tempfile.TemporaryDirectory() as tmp:
        scn_file = Path(tmp) / "flood.json"
        write_effective(scn, scn_file)
        out = keep or Path(tmp) / "run"
        port = free_port()
        t0 = time.monotonic()
        proc = subprocess.Popen(_run_cmd(out, port, "-q", scenario=str(scn_file)),
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
        bus = can.Bus(interface="udp_multicast", channel=GROUP, port=port, fd=True)
        done = threading.Event()
        sent: dict[str, int] = {}

        def flood() -> None:
            while not (out / "plant.log").exists() and not done.is_set():
                time.sleep(0.01)
            sent.update(pour_fuzz(bus, done.is_set, seed=seed, kinds=kinds, old_commands=50))

        th = threading.Thread(target=flood, daemon=True)
        th.start()
        try:
            _, err = proc.communicate(timeout=FLOOD_LIMIT_S)
            stalled = False
        except subprocess.TimeoutExpired:
            proc.send_signal(signal.SIGINT)
            _, err = proc.communicate(timeout=60)
            stalled = True
        finally:
            done.set()
            th.join()
            bus.shutdown()
        wall = time.monotonic() - t0
        last = err.strip().splitlines()[-1] if err.strip() else ""
        code = proc.returncode
        m = (
            json.loads((out / "metrics.json").read_text())
            if (out / "metrics.json").exists()
            else {}
        )
        if stalled:
            outcome = "stalled"
        elif code == 0:
            div = first_divergence(
                ref, run_trace(list(can.LogReader(str(out / "capture.blf"))), scn)
            )
            outcome = "identical" if div is None else f"diverged: {div}"
        elif code in (2, 3, 4) and last.startswith(("bench: error:", "warning:")):
            outcome = "named stop"
        else:
            outcome = f"exit {code} without a line"
    say(f"flood beside a lockstep run: {outcome} ({sum(sent.values()):,} frames, {wall:.0f} s)")
    return {
        "outcome": outcome,
        "exit_code": code,
        "last_line": last,
        "seconds": round(wall, 1),
        "frames_poured": sent,
        "steps": m.get("steps"),
        "frames_rejected": m.get("frames_rejected"),
        "frames_rejected_by_reason": m.get("frames_rejected_by_reason"),
        "frames_repeated_ignored": m.get("frames_repeated_ignored"),
    }


#: A flooded 0.3 s run that has not ended after this long is stalled (s): the
#: run's own timeouts (the plant's start 20 s, no progress 40 s) and a loaded
#: host's start-up of the node processes, twice over.
FLOOD_LIMIT_S = 150.0


def run_process_checks(
    *, loaded_runs: int = 3, progress: Callable[[str], None] | None = None
) -> dict[str, Any]:
    """Every process-level check; the figures as a JSON-ready dict."""
    say = progress or (lambda s: None)
    t0 = time.perf_counter()
    out: dict[str, Any] = {
        "cpus": os.cpu_count(),
        "loadavg_1min_start": _loadavg(),
        "determinism_under_load": determinism_under_load(loaded_runs, say),
        "kills": kill_checks(say),
        "signals": signal_checks(say),
        "parallel": parallel_check(say),
        "flood": flood_check(say),
    }
    out["wall_s"] = round(time.perf_counter() - t0, 1)
    return out


def process_checks_ok(p: dict[str, Any]) -> bool:
    """Every process-level check as it must be."""
    det = all(c["identical"] == c["runs"] for c in p["determinism_under_load"]["cases"])
    kills = all(
        k["exit_code"] == 2 and k["names_signal"] and k["nodes_left"] == 0 for k in p["kills"]
    )
    sigs = all(
        s["exit_code"] == 130 and s["files_written"] and s["nodes_left"] == 0 for s in p["signals"]
    )
    par = p["parallel"]["own_bus_identical"] == p["parallel"]["runs"] and all(
        r["outcome"] != "wrong" for r in p["parallel"].get("shared_bus_runs", [])
    )
    # a flood leaves the run's trace as it was, or stops it with a line (never a stall)
    flood = p.get("flood", {}).get("outcome", "identical") in ("identical", "named stop")
    return det and kills and sigs and par and flood


# -- docs/RELIABILITY.md ---------------------------------------------------------------------

#: Text of docs/RELIABILITY.md that is not a figure of the run (mechanisms and tests).
_DOC_HEAD = """\
# Reliability: what fails safe, and what is tested

<!-- Written by `bench soak --processes --doc` from docs/reliability/soak.json: do not edit;
     rerun `make reliability`.  tests/test_reliability_doc.py checks that this page is the
     rendering of that file. -->

A bench that drives real hardware must fail safe and lose nothing. This page
lists the mechanisms, the tests that check them, and the figures of the last
soak run, produced by

```sh
make reliability   # = .venv/bin/bench soak --processes --out docs/reliability/soak.json --doc docs/RELIABILITY.md
```

which fuzzes both nodes, runs a closed loop with injected faults, then kills,
signals, loads, doubles and floods real `bench run` processes, writes
[`docs/reliability/soak.json`](reliability/soak.json) and renders this page from it
(`bench soak --from-json docs/reliability/soak.json --doc docs/RELIABILITY.md`
renders it again without measuring).

## Mechanisms

**End-to-end protection.** Every control frame (`PwmDuty`, `PhaseSamples`,
`BenchCommand`, `PlantStatus`) carries a CRC-8 SAE J1850 over its E2E data ID
and payload, and an alive counter (the `step` counters; `BenchCommand.seq`).
A node puts every frame it receives into exactly one counter:

| counter | meaning |
|---|---|
| accepted | passed every check, used |
| rejected, `bad_crc` | CRC mismatch |
| rejected, `bad_length` | DLC differs from the DBC |
| rejected, `decode_error` | remote/error frame, or cantools could not unpack it |
| rejected, `out_of_range` | a value outside its `[min|max]` (e.g. an undefined `cmd` enum), or a duty outside [0, 1] |
| rejected, `stale_counter` | counter older than the receiver accepts (replayed or very late frame) |
| rejected, `future_counter` | counter ahead of anything the sender can have produced (a duty for a period whose sample was not sent yet; in lockstep, a sample more than the latency + 1 steps ahead of the controller's next step, docs/PROTOCOL.md) |
| rejected, `queue_full` | more than 4096 pending bench commands (a flood) |
| repeated, `repeated_counter` | exact repeat of an accepted counter |
| ignored / unknown | a DBC message the node does not consume / an ID not in the DBC |

`repeated_counter` is counted (node reports; in `metrics.json` as
`frames_repeated_ignored`, apart from `frames_rejected` and its per-reason
counts, which add up): the bench produces repeats itself (every bench
command is sent twice; in lockstep the plant retransmits after a lost frame
and the controller answers from its cache), and recovery depends on them.
The DBC has no multiplexed messages; the codec refuses a DBC with any, so an
unknown multiplexer value cannot reach a node. Only an accepted duty frame
with every duty in [0, 1] is ever applied.  The recorder frames (`PlantTruth`,
`CtrlTelemetry`) carry a CRC too (DBC 2.1): the analysis drops a frame that
fails it before placing any step and counts it (`frames_rejected_recorded`,
a warning line), so a crafted or corrupted frame cannot move the step
unwrapping (`tests/test_run_isolation.py`: one crafted `PlantTruth` leaves
`steps_missing` unchanged; random FD frames with the DBC's identifiers
poured at a running bench leave its scored rows unchanged).

**Watchdogs.** The plant trips to its safe state (all switches open,
`enable=False`: the currents freewheel through the diodes and die out, the
motor coasts, the bridge rectifies if the back-EMF exceeds the DC link) and
sends `PlantStatus` with `state = fault`, `fault_code = watchdog` when

- real time: no valid duty frame has arrived for `watchdog_periods` PWM
  periods of its clock (default 10 periods but at least 20 ms; `bench plant
  --watchdog-ms`, `bench run --watchdog-ms`); armed by the first valid duty;
- lockstep: `watchdog_rounds` retransmission rounds (50 ms each) in a row
  brought no duty (default 100 = 5 s; `bench plant --watchdog-rounds`); also
  armed by the first valid duty.  A lockstep plant's periods do not pass
  while it waits, so these rounds are wall-clock time of the bench's own
  processes: armed from the start command, the wait for the first duty (the
  command burst through the link, the controller's first step) passed them on
  a loaded host, and the run went on in the safe state with a trace that left
  the in-process one.  A controller that never answers is reported by the
  plant's stall error (20 s) instead.

`PlantTruth.duty_age` reads 255 in every period the safe state applies no duty.
The controller disables its PWM (duties with `enable = 0`) when no valid
sample has come for `--sample-timeout-ms` (default 50 ms, real time).

**Protection** (`plant_rt.Protection`, a pure class; `ProtectionPars.from_preset`):
over-current `|i_x| > 1.5 i_max`, DC-link over-voltage `u_dc > 1.2 u_dc,nom`,
over-speed `|w_m| > 1.5 w_m,rated`, checked every period on the plant's true
values; NaN trips. Fault codes are the DBC's `PlantStatus.fault_code` table.

Every fault is latched: the plant stays in the safe state until a
`BenchCommand` `reset` or `enable`; if the condition persists, the next
period trips again. `PhaseSamples.status` reads `fault` meanwhile. The plant's
last frame at the end of a run is `PlantStatus` with `state = idle` (and the
latched fault code).

**Send errors.** A refused send (`can.CanError`, `OSError`: buffer full,
bus-off) is counted (`send_errors`), retried 5 times with a short back-off,
then counted as lost (`frames_lost_on_send`); never fatal (lockstep recovers
the frame by retransmission).

**Signals and dead nodes.** SIGINT/SIGTERM to `bench run`, also while the
nodes are still starting, sends SIGTERM to every node at once (the nodes end
their loops and write their reports), says that it is scoring what was
recorded (unless `-q`), closes the capture and writes `signals.csv`,
`metrics.json` and `meta.json` with `"interrupted": true`; exit status 130.
A run cut short is scored by the rule `bench analyze` applies to its capture:
one that ended before `score_from_s` over the second half of the steps it
recorded, so the run and a later analysis give the same numbers.  A node
that dies in lockstep (the plant cannot take another period without it)
ends the run at once: one line naming the node and how it ended (`killed by
SIGKILL`), exit status 2, the files written without the plot.  In real time
a dead controller is left to the plant's watchdog, as in a drive, and the
run reports it at its end: every period the plant ran is a row of
`signals.csv` (the estimate empty after the death, `steps_without_telemetry`),
so the safe state and the coasting rotor are in the speed tracking error;
exit status 3.

**No silent stall.** A plant that sends no sample 20 s after its start
command went out (the plant's own lockstep stall time; it cannot say so
itself), or whose step the recorder has not seen move for 40 s, ends the run
with one line naming it and what the plant rejected (`bench: error: the
plant sent no sample 20 s after its start command ...; the plant's frames:
675 rejected (repeated_counter)`), exit status 2, the files and `error.txt`
kept.  A bench command whose step unwraps to before 0 (a replay of a longer
run's) is rejected as `stale_counter`, and a late command comes due at the
next period the node handles, also for a plant that waits for its start
(one that arrived before the start once moved the start to a step the
waiting plant never reached).

**User mistakes** are one line and exit status 2: an `--out` that cannot be
written (`bench run`, `bench analyze`), a scenario whose motor fails the
physics checks (a value off by 1000 names its field and the unit it looks
like), injection settings without a `[motor]` table, an option of the other
injection family.  A text capture's unparsable lines are skipped and counted
(`capture_lines_skipped`), never the rest of the file.

**Run isolation** (DBC 2.1, docs/PROTOCOL.md "Runs on one bus"): every run
has a 16-bit nonce, `run_id`, that its plant echoes in `PlantTruth` and its
controller in `CtrlTelemetry`.  The recorder frames carry an E2E CRC; the
analysis drops a frame that fails it before the step unwrapping and counts it
(`frames_rejected_recorded`, a warning line), and counts the recorder frames
of another run (`frames_foreign`), never scored.  Two runs on one bus cannot
both be right (the 8-byte control frames have no room for the nonce, and
their layout is what the reference results were recorded with), so the
second refuses: `bench run` listens 0.3 s before starting its nodes and
refuses a bus that carries at least 8 distinct plant or bench frames that
pass their E2E check (garbage with those identifiers is no run), with one
line and exit 2; runs
started within that window of each other see each other's `PlantTruth` and
stop with one line (exit 2) after 8 frames of distinct steps of one other
`run_id` (copies of one frame count once), their files kept and marked as no
result.  A
`bench plant` that sees another plant's truth says so once, naming its run.
`bench run` without `--interface` on a host without vcan0 takes a
udp_multicast port of its own per process; where vcan0 exists it is the
default bus, shared by every run, so parallel runs must name a bus each.

**What E2E and `run_id` protect against, and what they do not.** They
protect a run against errors (corrupted, lost, repeated, late or reordered
frames: E2E) and against another run on the same bus (`run_id`, the refusal
above).  They do not protect against a hostile host on the same link: the
CRC is not a secret (its data IDs are in the DBC), so a valid frame with a
fresh counter is accepted from anyone who can send on the bus, and
udp_multicast has neither authentication nor encryption.  The bus is a
trusted link, as a CAN bus in a drive is.  udp_multicast sends with hop
limit 0, the Python nodes' buses and the native ones alike (`UDP_HOP_LIMIT`
of `bench/wire/_bus.py`; `tests/test_dask_tls.py` and
`tests/test_native_transport.py` check them), so its frames do not leave
the host; run it on a host that only trusted users share.  A Dask
cluster for sweeps is another matter: its scheduler runs the code it is
sent, so a remote one is started with TLS (docs/SCALING.md).

## Tests

| file | what |
|---|---|
| `tests/test_fuzz_nodes.py` | random frames at `PlantNode.on_message` (real time and lockstep) and `ControllerNode.on_message`: valid frames with random values under the bench's own IDs, corrupted copies, wrong lengths, unknown IDs, random payloads, duplicates, replays, reordered bursts; no exception, every frame in exactly one counter, `bad_crc`/`bad_length` counts equal to an independent oracle, no applied duty outside [0, 1] or not from a valid frame; a hypothesis test of the same |
| `tests/test_soak_cli.py` | `bench soak` end to end: every fuzzed frame accounted for, rejections by reason, every injected fault tripped and recovered, no period lost |
| `tests/test_protection.py` | each comparator trips with its code, latch and reset, NaN; over-current and over-speed trips in the plant node |
| `tests/test_reliability_watchdog.py` | real time: trip in exactly the configured period after the last duty; lockstep: armed by the first duty, trip after exactly the configured rounds; the controller disables its PWM when samples stop |
| `tests/test_lockstep_under_load.py` | the link logic under random schedules with retransmissions and a start longer than the watchdog gives the in-process trace, and so it does when samples, truth and duties are lost before and after the link (a truth frame lost before the link once stalled a run for good; a link that answered every repeated sample with every duty fell behind its input on a loaded host); lockstep through `bench link` with busy processes beside it, over udp_multicast and on vcan |
| `tests/test_signals_process.py` | real processes: kill -9 of the controller in real time (watchdog fault frame, capture complete); SIGINT, SIGTERM mid-run and during start-up |
| `tests/test_reliability_errors.py` | unwritable `--out`, unparsable capture lines, the scoring of a run cut short and the line that announces it, kill -9 of the controller in lockstep (named, prompt), the transport line from python-can's configuration, `duty_age` in the safe state |
| `tests/test_scenario_plausible.py` | the physics checks of a scenario's motor, injection settings without `[motor]`, `sensored` from any scenario |
| `tests/test_run_isolation.py` | a crafted `PlantTruth` (bad CRC) in a clean capture: rejected, counted, `steps_missing` unchanged; one of another `run_id`: counted foreign, not scored; a plant seeing another plant says so once; two runs started together on one udp_multicast port: each gives its solo rows or refuses with one line; a run refuses a bus that already carries another run; random FD frames with the DBC's identifiers poured at a running bench leave its scored rows unchanged |
| `tests/test_fuzz_flood.py` | a flood of random FD frames with the DBC's identifiers, corrupted copies, wrong lengths, unknown identifiers, duplicates, replays and bursts beside a lockstep `bench run`, after replays of a longer run's commands: the in-process trace, the rejections counted; a command forged with the start's step and counter: the run stops after the start timeout with one line; the command queue of a plant waiting for its start |
| `tests/test_external_controller.py` | a controller under test from docs/PROTOCOL.md: each mistake named with its status; no valid duty within `--dut-timeout` (bad CRC, or none) in both modes: one line, exit 2, `error.txt`; kill -9 in real time before the scoring start: exit 3, the plant's rows go on without telemetry |
| `tests/test_reliability_doc.py` | this page is the rendering of `docs/reliability/soak.json` |
"""


def _n(x: Any) -> str:
    return f"{int(x):,}"


def _shared_text(par: dict[str, Any]) -> str:
    runs = par.get("shared_bus_runs")
    if runs is None:  # a JSON from before run isolation
        return f"Runs sharing one bus: {par.get('shared_bus', 'not measured')}."
    n = {k: sum(r["outcome"] == k for r in runs) for k in ("identical", "refused", "wrong")}
    said = "; ".join(sorted({f"`{r['detail']}`" for r in runs if r["outcome"] == "refused"}))
    return (
        f"Then {len(runs)} runs started together on one udp_multicast port: "
        f"{n['identical']} gave the in-process trace, {n['refused']} refused with one line, "
        f"{n['wrong']} gave a wrong result" + (f" (the refusals: {said})" if said else "") + "."
    )


def render_reliability(rep: dict[str, Any]) -> str:
    """``docs/RELIABILITY.md`` from the JSON of ``bench soak --processes``."""
    rej = {k: v for k, v in rep["rejected"].items() if k != "repeated_counter"}
    fd = rep.get("frames_fd", {})
    plant, ctrl, loop = (
        rep["frames_fuzzed_plant"],
        rep["frames_fuzzed_controller"],
        rep["frames_fuzzed_loop"],
    )
    by_reason = ", ".join(
        f"`{k}` {_n(v)}" for k, v in sorted(rej.items(), key=lambda x: (-x[1], x[0]))
    )
    faults = rep["faults_injected"]
    trips = ", ".join(f"{k} {_n(v)}" for k, v in sorted(rep["trips"].items()))
    lines = [
        _DOC_HEAD,
        "## Last soak run",
        "",
        f"`bench soak{' --processes' if 'processes' in rep else ''} --frames "
        f"{_n(rep['frames_per_node'])} --loop-periods "
        f"{_n(rep['loop_periods'])} --seed {rep['seed']}` ({rep['scenario']} nodes); "
        f"{'every check passed' if rep['ok'] else 'NOT every check passed'}.",
        "",
        "### Frames fuzzed",
        "",
        "| part | frames | of them CAN FD | classic |",
        "|---|---|---|---|",
    ]
    for label, key, n in (
        ("plant node (half real time, half lockstep)", "plant", plant),
        ("controller node", "controller", ctrl),
        ("closed loop (both nodes, 1 to 6 a period)", "loop", loop),
    ):
        lines.append(f"| {label} | {_n(n)} | {_n(fd.get(key, 0))} | {_n(n - fd.get(key, 0))} |")
    lines += [
        f"| all | {_n(rep['frames_fuzzed'])} | {_n(sum(fd.values()))} | "
        f"{_n(rep['frames_fuzzed'] - sum(fd.values()))} |",
        "",
        "| figure | value |",
        "|---|---|",
        f"| rejected, by reason | {_n(sum(rej.values()))}: {by_reason} |",
        f"| repeated (not rejections) | {_n(rep['rejected'].get('repeated_counter', 0))} |",
        f"| crashes (exceptions escaped) | {_n(rep['exceptions'])} |",
        f"| applied bad duties / uncounted frames | {_n(rep['violations'])} / "
        f"{_n(rep['unchecked_rejections'])} |",
        f"| faults injected in the closed loop | {_n(sum(faults.values()))} ("
        + ", ".join(f"{k} {_n(v)}" for k, v in sorted(faults.items()))
        + ") |",
        f"| recoveries (reset, then duties applied again) | {_n(rep['recoveries'])} |",
        f"| trips in total | {trips} (the fuzzed plant node accepts valid forged commands "
        "with large load torques; the closed loop re-trips when reset too early) |",
        f"| data lost | {_n(rep['data_lost_periods'])} of {_n(rep['loop_periods'])} "
        "closed-loop periods |",
        f"| wall time of the fuzzing | {rep['wall_s']:.1f} s |",
        "",
        "A valid frame with a correct CRC and a fresh counter is indistinguishable",
        "from a genuine one: E2E protection detects corruption, loss, repetition and",
        "delay, not forgery. The fuzzers' valid frames are accepted by design, and",
        "what they do (over-speed trips, commands) is still bounded by the",
        "protection and checked by the oracle.",
        "",
    ]
    p = rep.get("processes")
    if p is None:
        lines += ["(No process-level checks in this run: `bench soak` without `--processes`.)"]
        return "\n".join(lines).rstrip() + "\n"
    det = p["determinism_under_load"]
    lines += [
        "### Determinism under load",
        "",
        f"Lockstep `bench run` of wen-5.1 (0.06 s, sensored) with {det['busy_processes']} "
        f"busy processes beside it on {p['cpus']} CPUs; each trace compared with the "
        "in-process one (angle, estimate, speed, current, duty to 1e-9).",
        "",
        "| case | runs | identical | highest 1-min load average | diverged |",
        "|---|---|---|---|---|",
    ]
    for c in det["cases"]:
        lines.append(
            f"| {c['case']} | {c['runs']} | {c['identical']} | {c['loadavg_1min']:.1f} | "
            f"{'; '.join(c['diverged']) or 'none'} |"
        )
    lines += [
        "",
        "### Kills and signals",
        "",
        "| what | mode | exit status | seconds to exit | signal named | nodes left | "
        "steps scored | plant fault |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for k in p["kills"]:
        lines.append(
            f"| kill -9 of the {k['killed']} | {k['mode']} | {k['exit_code']} | "
            f"{k['s_to_exit']:.1f} | {'yes' if k['names_signal'] else 'no'} | "
            f"{k['nodes_left']} | {_n(k['steps_scored'])} | {k['plant_fault'] or '-'} |"
        )
    for s in p["signals"]:
        lines.append(
            f"| {s['signal']} to bench run | lockstep | {s['exit_code']} | "
            f"{s['s_to_exit']:.1f} | - | {s['nodes_left']} | {_n(s['steps_scored'])} | - |"
        )
    lines += [
        "",
        "In lockstep the run ends as soon as a node is gone; in real time the plant's "
        "watchdog puts it in the safe state and the run goes on to its end (3 s here) "
        "before it reports the node.  The last line of each kill: "
        + "; ".join(f"{k['mode']} {k['killed']}: `{k['message']}`" for k in p["kills"])
        + ".",
        "",
        "### Parallel runs",
        "",
        f"{p['parallel']['runs']} lockstep runs started together, each on a udp_multicast "
        f"port of its own: {p['parallel']['own_bus_identical']} of them gave the in-process "
        "trace"
        + (
            f" (diverged: {'; '.join(p['parallel']['diverged'])})"
            if p["parallel"]["diverged"]
            else ""
        )
        + ".  "
        + _shared_text(p["parallel"]),
        "",
        *_flood_text(p.get("flood")),
        f"The process-level checks took {p['wall_s']:.0f} s; the one-minute load average was "
        f"{p['loadavg_1min_start']:.1f} at their start.",
    ]
    return "\n".join(lines).rstrip() + "\n"


def _flood_text(fl: dict[str, Any] | None) -> list[str]:
    """The flood check's section (none for a soak JSON written before it existed)."""
    if not fl:
        return []
    poured = ", ".join(f"{k} {_n(v)}" for k, v in sorted(fl["frames_poured"].items()))
    by = ", ".join(
        f"`{k}` {_n(v)}" for k, v in sorted((fl["frames_rejected_by_reason"] or {}).items())
    )
    return [
        "### A flood beside a run",
        "",
        f"A 0.3 s lockstep `bench run` of wen-5.1 (sensored) with {_n(sum(fl['frames_poured'].values()))} "
        f"fuzzed frames poured at its bus ({poured}): {fl['outcome']}, exit status "
        f"{fl['exit_code']} after {fl['seconds']:.0f} s; {_n(fl['frames_rejected'] or 0)} frames "
        f"rejected ({by or 'none'}), {_n(fl['frames_repeated_ignored'] or 0)} repeats ignored.",
        "",
    ]
