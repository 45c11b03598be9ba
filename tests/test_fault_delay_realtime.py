"""A real-time ``delay`` below a period: the plant holds each duty frame ``us`` from its
arrival (its receive timestamp) and a period applies the newest duty released by its
start.  Driven on a fake clock (the node's ``clock`` and the frames' timestamps), so the
assertions are period counts, which a busy machine cannot move."""

from __future__ import annotations

from pathlib import Path

import can
import pytest

from bench.nodes._loops import command_frames, make_plant_node
from bench.scenarios._schema import load_scenario
from bench.wire._codec import Codec

CODEC = Codec()
T_S = 1e-3  # xue-fig13: 1 kHz
K0, K1 = 300, 340  # the fault's periods [K0, K1)


class FakeClock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def _run(tmp_path: Path, us: float | None, answer_s: float) -> tuple[list[int], int]:
    """Periods 0..399 of a real-time plant node whose controller answers sample ``k``
    (sent at ``k T``) ``answer_s`` later with duty ``k + 1``, which the node takes at the
    next period's start, as its loop does; a ``delay`` of ``us`` (None: no fault) on
    ``[K0, K1)``.  Returns each period's duty age and the late duties counted."""
    lines = ['extends = "xue-fig13"', "duration = 1.2"]
    if us is not None:
        lines += [
            "[[faults]]",
            f"at_s = {K0 * T_S!r}",
            f"duration_s = {(K1 - K0) * T_S!r}",
            'kind = "delay"',
            'message = "PwmDuty"',
            f"us = {us!r}",
        ]
    src = tmp_path / f"d-{us}.toml"
    src.write_text("\n".join(lines) + "\n")
    scn = load_scenario(str(src))
    node = make_plant_node(scn, CODEC)
    node.realtime = True
    clock = FakeClock()
    node.clock = clock
    for _, m in command_frames(scn, CODEC):
        node.on_message(m)
    node.apply_commands()
    ages = []
    pending: list[can.Message] = []
    for k in range(400):
        clock.t = 1000.0 + k * T_S  # the period's start
        for m in pending:  # arrived during the period before
            node.on_message(m)
        pending = []
        node.advance_realtime()  # runs period k
        ages.append(node.duty_age)
        duty = CODEC.encode(
            "PwmDuty",
            {"duty_a": 0.5, "duty_b": 0.5, "duty_c": 0.5, "enable": 1, "step": (k + 1) % 1024},
        )
        duty.timestamp = clock.t + answer_s  # the answer to sample k
        pending.append(duty)
    return ages, node.counters.late_duties


@pytest.mark.parametrize("answer_s", [0.5e-3, 0.8e-3])
def test_a_delay_below_a_period_costs_a_period_only_when_it_crosses_the_period_start(
    tmp_path: Path, answer_s: float
) -> None:
    """The duty of period k arrives ``answer_s`` after period k - 1 starts. Held 300 us
    it is released before period k starts when ``answer_s`` + 300 us < T (0.5 ms: no
    period lost), after it otherwise (0.8 ms: every period of the window applies the
    duty before, one period old); a delay of whole periods (the old rounding) would
    cost a period in both cases."""
    base, late0 = _run(tmp_path, None, answer_s)
    ages, late = _run(tmp_path, 300.0, answer_s)
    assert ages[:K0] == base[:K0] and set(base[K0 - 50 :]) == {0}
    window = ages[K0:K1]
    if answer_s + 300e-6 < T_S:
        assert set(window) == {0} and late == late0
    else:
        # the duties taken in the window's periods are held past their own period's start
        assert set(window) == {1} and late - late0 == K1 - K0
    assert set(ages[K1:]) == {0}  # a duty taken after the window is not held


def test_a_hold_longer_than_a_period_moves_the_duty_by_whole_periods_in_order(
    tmp_path: Path,
) -> None:
    """2.5 periods held, answered 0.2 ms after the sample: duty k is released at
    ``(k + 1) T + 0.7 ms``, so period k applies duty k - 2 (age 2) once the window is
    full; from the window's end the duties are fresh again and the older ones still
    held are passed, never applied after a newer one (no age above 0 after it)."""
    ages, _ = _run(tmp_path, 2500.0, 0.2e-3)
    assert ages[K0 : K0 + 2] == [1, 2]
    assert set(ages[K0 + 2 : K1]) == {2}
    assert set(ages[K1:]) == {0}
