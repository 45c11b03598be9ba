"""Lockstep through the latency link gives the in-process trace whatever the load.

The race this guards against: the lockstep plant's watchdog counts
retransmission rounds, which are wall-clock time of the bench's processes,
not periods of the plant.  It was armed from the start command, and the
wait for the first duty is the longest of a run (the link forwards the
command burst, the controller takes its first step): on a loaded host that
wait passed the 100 rounds, the plant ran every later period in the safe
state, and the trace left the in-process one at step 43 (where the speed
ramp makes the missing torque visible).  The watchdog is now armed by the
first valid duty (:meth:`bench.nodes._plant_node.PlantNode.on_duty_timeout`).

- In-process, the same node and link objects are driven by a random
  scheduler that delivers frames in any interleaving the buses allow (FIFO
  per path) and lets the plant retransmit whenever it waits and hears
  nothing; every schedule must give the reference trace.  The first test
  makes the start-up wait longer than the watchdog, the exact failure.
- As processes, the run goes through ``bench link`` over udp_multicast and
  on vcan (inside User-Mode Linux under ``tools/vcan-tests``) with busy
  processes beside it on every CPU.
"""

from __future__ import annotations

import random
from collections import deque
from pathlib import Path

import can
import numpy as np
import pytest

from bench.nodes._link import LockstepLink
from bench.nodes._loops import (
    WATCHDOG_ROUNDS,
    command_frames,
    lockstep_delay,
    make_controller_node,
    make_plant_node,
    run_inprocess,
)
from bench.runs._run import PACE_EVERY, run_scenario
from bench.scenarios._schema import Scenario
from bench.studies._reliability import busy_processes
from bench.wire._bus import BusSpec
from tests.conftest import require_vcan
from tests.ports import free_port
from tests.trace_helpers import CODEC, assert_same_trace, short, trace


def link_scenario(duty: int = 2, sample: int = 1) -> Scenario:
    return short("wen-5.1", 0.06, duty_delay_steps=duty, sample_delay_steps=sample)


def scheduled_run(
    scn: Scenario,
    seed: int,
    *,
    retransmit_p: float,
    startup_rounds: int = 0,
    lose_p: float = 0.0,
) -> tuple[list[can.Message], dict[str, int]]:
    """The lockstep loop through the link logic under a random schedule.

    Four FIFO paths (plant to link, link to controller, controller to link,
    link to plant); each step delivers the head of a random non-empty path,
    or lets the plant run its period (when its duty and pacing allow), or,
    when the plant waits and nothing is on its way to it, a retransmission
    round (:meth:`PlantNode.on_duty_timeout` and :meth:`PlantNode.retransmit`,
    as the plant loop does after each quiet ``RETRANSMIT_S``).  A round
    comes only while the link has at most one round's frames from the plant
    still to read: ``RETRANSMIT_S`` is 50 ms, in which a link that keeps up
    with its input reads hundreds of frames (a link that cannot keep up falls
    behind whatever the rules; :class:`LockstepLink` sends nothing twice for
    one repeat so that it does not make its own backlog).
    ``startup_rounds`` rounds pass before the link sees anything: a slow start.
    ``lose_p``: each frame other than a bench command is lost on its way with this
    probability, on any of the four paths (a full socket queue of a loaded host;
    the bench sends every command twice, which a test of losses must not count on).
    Returns every frame the nodes sent (the recorder's view) and the plant's trips.
    """
    rng = random.Random(seed)
    pn = make_plant_node(scn, CODEC)
    pn.pace_every = PACE_EVERY
    cn = make_controller_node(scn, "sensored", CODEC)
    lt = scn.latency
    link = LockstepLink(CODEC, sample_delay=lt.sample_delay_steps, duty_delay=lt.duty_delay_steps)
    to_link_a: deque[can.Message] = deque()
    to_link_b: deque[can.Message] = deque()
    to_ctrl: deque[can.Message] = deque()
    to_plant: deque[can.Message] = deque()
    rec: list[can.Message] = []
    for _, m in command_frames(scn, CODEC, pace_every=PACE_EVERY):
        for _ in range(2):  # bench run sends each command twice
            rec.append(m)
            pn.on_message(m)
            to_link_a.append(m)
    pn.apply_commands()
    out = pn.frames_now()
    rec += out
    to_link_a.extend(out)
    for _ in range(startup_rounds):
        out = pn.on_duty_timeout() + pn.retransmit()
        rec += out
        to_link_a.extend(out)

    def deliver(q: deque[can.Message]) -> None:
        m = q.popleft()
        if lose_p and m.arbitration_id != CODEC.frame_id("BenchCommand") and rng.random() < lose_p:
            return
        if q is to_link_a or q is to_link_b:
            tb, ta = link.from_a(m) if q is to_link_a else link.from_b(m)
            to_ctrl.extend(tb)
            to_plant.extend(ta)
        elif q is to_ctrl:
            r = cn.on_message(m)
            rec.extend(r)
            to_link_b.extend(r)
        else:
            pn.on_message(m)

    paths = (to_link_a, to_link_b, to_ctrl, to_plant)
    for _ in range(2_000_000):
        if pn.done:
            break
        busy = [q for q in paths if q]
        if pn.ready() and pn.paced() and (not busy or rng.random() < 0.3):
            out = pn.advance_lockstep()
        elif not busy or (
            not pn.ready()
            and not to_plant
            and len(to_link_a) <= 3 * (lockstep_delay(scn) + 3)  # one round's frames
            and rng.random() < retransmit_p
        ):
            out = pn.on_duty_timeout() + pn.retransmit()
        else:
            deliver(rng.choice(busy))
            continue
        rec += out
        to_link_a.extend(out)
    assert pn.done
    # the frames still on their way, none lost: no period waits for the answer to
    # the last sample, so nothing would resend it (a loss there is a last row
    # without the controller's answer, a different matter from recovery)
    lose_p = 0.0
    while any(paths):
        deliver(next(q for q in paths if q))
    return rec, dict(pn.trips)


def test_a_start_longer_than_the_watchdog_leaves_the_trace_unchanged() -> None:
    scn = link_scenario()
    ref = trace(run_inprocess(scn, "sensored", CODEC), scn)
    rec, trips = scheduled_run(scn, 0, retransmit_p=0.0, startup_rounds=WATCHDOG_ROUNDS + 20)
    assert trips == {}
    assert_same_trace(ref, trace(rec, scn))


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_any_schedule_with_retransmissions_gives_the_in_process_trace(seed: int) -> None:
    scn = link_scenario()
    ref = trace(run_inprocess(scn, "sensored", CODEC), scn)
    rec, trips = scheduled_run(scn, seed, retransmit_p=0.3, startup_rounds=seed * 40)
    assert trips == {}
    assert_same_trace(ref, trace(rec, scn))
    # the schedule did what it is for: frames repeated, answered from the caches
    n_samples = sum(m.arbitration_id == CODEC.frame_id("PhaseSamples") for m in rec)
    assert n_samples > len(ref["step"]) + 100


@pytest.mark.parametrize(("seed", "duty", "sample"), [(4, 2, 1), (5, 2, 1), (6, 2, 1), (7, 9, 4)])
def test_frames_lost_on_any_path_are_recovered_with_the_in_process_trace(
    seed: int, duty: int, sample: int
) -> None:
    """Frames lost before and after the link, both ways, samples, truth and duties:
    the plant's retransmission through the link's rules recovers every one.

    A truth frame lost before the link once stalled the run for good on vcan: its
    repeat came after its sample had been released, was queued behind the newest
    sample (held until the next one, which the waiting plant never sends), and the
    sensored controller waited for it for ever."""
    scn = link_scenario(duty, sample)
    ref = trace(run_inprocess(scn, "sensored", CODEC), scn)
    rec, trips = scheduled_run(scn, seed, retransmit_p=0.3, lose_p=0.05)
    assert trips == {}
    assert_same_trace(ref, trace(rec, scn))


def test_a_silent_controller_still_trips_the_armed_watchdog() -> None:
    """Armed by the first duty, the lockstep watchdog still catches a controller gone mid-run."""
    scn = link_scenario()
    pn = make_plant_node(scn, CODEC, watchdog_rounds=3)
    cn = make_controller_node(scn, "sensored", CODEC)
    for _, m in command_frames(scn, CODEC)[:1]:
        pn.on_message(m)
        cn.on_message(m)
    pn.apply_commands()
    out = pn.frames_now()
    for _ in range(10):  # before any duty: rounds do not count
        pn.on_duty_timeout()
    assert pn.trips == {}
    for _ in range(20):  # no link here: the duty of sample k is applied in period k + 1
        for m in [r for f in out for r in cn.on_message(f)]:
            pn.on_message(m)
        out = pn.advance_lockstep()
    for _ in range(3):  # the controller goes silent
        pn.on_duty_timeout()
    assert pn.trips == {"watchdog": 1} and pn.fault_step == 20


def loaded_link_run(spec: BusSpec, out: Path) -> None:
    scn = link_scenario()
    ref = trace(run_inprocess(scn, "sensored", CODEC), scn)
    with busy_processes():
        res = run_scenario(scn, "sensored", spec=spec, out_dir=out, progress=False)
    frames = list(can.LogReader(str(res.capture)))
    assert_same_trace(ref, trace(frames, scn))
    assert res.metrics.get("plant_fault", "none") in ("none", None)
    assert res.metrics["loop_latency_steps"]["median"] == 3
    # and the trace compared is the link's: without latency it differs
    assert not np.allclose(ref["duty_age"][5:], 0.0)


def test_lockstep_through_link_under_load_over_udp_multicast(tmp_path: Path) -> None:
    loaded_link_run(BusSpec("udp_multicast", "239.74.163.2", free_port()), tmp_path / "run")


@pytest.mark.socketcan
def test_lockstep_through_link_under_load_on_vcan(tmp_path: Path) -> None:
    require_vcan("vcan0", "vcan1")
    loaded_link_run(BusSpec("socketcan", "vcan0"), tmp_path / "run")
