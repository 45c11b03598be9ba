"""Lockstep pacing: the plant runs no further than the bench commands it has.

``bench run`` sends its commands (with keep-alives every ``PACE_EVERY``
periods) only as far ahead as its recorder has seen, so a paced plant
cannot outrun the recording; the keep-alives change nothing in the run.
"""

from __future__ import annotations

import itertools
import os
import threading
import time

import can

from bench.nodes._loops import (
    command_frames,
    controller_loop,
    make_controller_node,
    make_plant_node,
    plant_loop,
    run_inprocess,
)
from tests.trace_helpers import CODEC, assert_same_trace, short, trace


def test_keep_alives_fill_the_gaps_and_change_no_reference() -> None:
    scn = short("wen-5.1", 0.1)
    plain = command_frames(scn, CODEC)
    paced = command_frames(scn, CODEC, pace_every=50)
    steps = [k for k, _ in paced]
    assert steps == sorted(steps) and len(set(steps)) == len(steps)  # one per step
    assert {k for k, _ in plain} <= set(steps)
    assert max(b - a for a, b in itertools.pairwise(steps)) <= 50
    # every keep-alive repeats the references in force at its step
    active = None
    plain_at = {k: CODEC.decode(m).signals for k, m in plain}  # type: ignore[union-attr]
    for k, m in paced:
        sig = CODEC.decode(m).signals  # type: ignore[union-attr]
        if k in plain_at:
            active = plain_at[k]
        else:
            assert sig["cmd"] == 0 and active is not None
            assert (sig["speed_ref"], sig["load_torque"]) == (
                active["speed_ref"],
                active["load_torque"],
            )


def test_a_paced_plant_waits_for_the_commands_and_the_trace_is_unchanged() -> None:
    scn = short("wen-5.1", 0.05)
    ref = trace(run_inprocess(scn, "sensored", CODEC), scn)
    chan = f"pace{os.getpid()}"
    bus_p, bus_c, bus_r = (can.Bus(interface="virtual", channel=chan) for _ in range(3))
    pn = make_plant_node(scn, CODEC)
    pn.pace_every = 50
    cn = make_controller_node(scn, "sensored", CODEC)
    cmds = command_frames(scn, CODEC, pace_every=50)
    tc = threading.Thread(target=controller_loop, args=(bus_c, cn), kwargs={"realtime": False})
    tp = threading.Thread(target=plant_loop, args=(bus_p, pn), kwargs={"realtime": False})
    tc.start()
    tp.start()
    try:
        first = [m for k, m in cmds if k <= 200]
        for m in first:
            bus_r.send(m)
        # the plant runs the periods before the last command it has (200), then waits:
        # period 200 would end with the commands of step 201, not here yet
        t0 = time.monotonic()
        while pn.plant.k < 200 and time.monotonic() - t0 < 30:
            time.sleep(0.01)
        time.sleep(0.3)  # time to run further, were it not paced
        assert pn.plant.k == 200 and pn.cmd_horizon == 200 and not pn.paced()
        for m in (m for k, m in cmds if k > 200):
            bus_r.send(m)
        tp.join(60)
        tc.join(10)
        assert not tp.is_alive() and not tc.is_alive()
        frames = [*first, *(m for k, m in cmds if k > 200)]
        while (got := bus_r.recv(0.2)) is not None:
            frames.append(got)
    finally:
        for b in (bus_p, bus_c, bus_r):
            b.shutdown()
    assert pn.counters.late_commands == 0
    assert_same_trace(ref, trace(frames, scn))
