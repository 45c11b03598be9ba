"""The real-time link per direction, on a fake clock (no wall-clock timing).

Frames arrive on a 10 kHz pattern (samples and truth from the plant's bus A
at ``k T``, the duty from the controller's bus B 30 us later).  The fake
clock jumps from event to event: to each arrival, and to each release time
the link announces with ``next_time()``, so every frame's realised delay is
read exactly.  The statistical bounds come from the sample size: with
``n`` draws, the sample mean has standard error ``sigma / sqrt(n)`` and the
sample standard deviation ``sigma * sqrt((kurtosis - 1) / (4 n))``
(kurtosis 3 for the normal law, 9/5 for the uniform one); the tests allow
5 standard errors, which a correct link exceeds with probability below
6e-7, while a wrong width, a swapped direction or the wrong law is tens of
standard errors away.
"""

from __future__ import annotations

import math
import statistics
from typing import Any

import can
import pytest

from bench.nodes._link import RealtimeLink
from bench.wire._codec import Codec

CODEC = Codec()
ID_SAMPLES = CODEC.frame_id("PhaseSamples")
ID_TRUTH = CODEC.frame_id("PlantTruth")
ID_DUTY = CODEC.frame_id("PwmDuty")
ID_CMD = CODEC.frame_id("BenchCommand")
T = 100e-6  # 10 kHz PWM
N = 20000  # periods


class FakeClock:
    """A clock the test sets by hand (seconds)."""

    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def _link(clock: FakeClock, **kw: Any) -> RealtimeLink:
    return RealtimeLink(CODEC, clock=clock, **kw)


def _events(
    n: int, *, with_truth: bool = True, extra_duties: int = 0
) -> list[tuple[float, str, int]]:
    """(time s, side, frame ID) of ``n`` periods, in time order."""
    out: list[tuple[float, str, int]] = []
    for k in range(n):
        out.append((k * T, "a", ID_SAMPLES))
        if with_truth:
            out.append((k * T, "a", ID_TRUTH))
        out += [(k * T + 30e-6 + 1e-6 * i, "b", ID_DUTY) for i in range(1 + extra_duties)]
    return out


def _run(
    link: RealtimeLink, clock: FakeClock, events: list[tuple[float, str, int]]
) -> dict[int, list[float]]:
    """Feed the events; return the realised delays in us per frame ID, in release order."""
    arrival: dict[int, float] = {}
    delays: dict[int, list[float]] = {ID_SAMPLES: [], ID_TRUTH: [], ID_DUTY: [], ID_CMD: []}
    sides: dict[int, str] = {}

    def drain(until: float) -> None:
        while (nt := link.next_time()) is not None and nt <= until:
            assert nt >= clock.t  # never released before it arrived
            clock.t = nt
            for side, m in link.due():
                delays[m.arbitration_id].append((clock.t - arrival[id(m)]) * 1e6)
                sides[m.arbitration_id] = side

    msgs = []
    for t, side, fid in events:
        drain(t)
        clock.t = t
        msg = can.Message(arbitration_id=fid, data=bytes(8), is_extended_id=False)
        msgs.append(msg)  # keep it alive: its id() names it until the end
        arrival[id(msg)] = t
        if side == "a":
            link.from_a(msg)
        else:
            link.from_b(msg)
    drain(math.inf)
    assert link.next_time() is None
    # samples and truth go to the controller's bus, duties to the plant's
    assert all(sides.get(f, "b") == "b" for f in (ID_SAMPLES, ID_TRUTH, ID_CMD))
    assert sides.get(ID_DUTY, "a") == "a"
    return delays


def _se_mean(sigma: float, n: int) -> float:
    return sigma / math.sqrt(n)


def _se_std(sigma: float, n: int, kurtosis: float) -> float:
    return sigma * math.sqrt((kurtosis - 1.0) / (4.0 * n))


@pytest.mark.parametrize("dist", ["normal", "uniform"])
def test_realised_delays_match_each_direction(dist: str) -> None:
    clock = FakeClock()
    # shared jitter 60 us (the duties keep it), the samples give their own 20 us
    link = _link(
        clock,
        sample_delay_us=300.0,
        duty_delay_us=700.0,
        jitter_us=60.0,
        sample_jitter_us=20.0,
        jitter_dist=dist,
        seed=4,
    )
    d = _run(link, clock, _events(N))
    kurt = 3.0 if dist == "normal" else 9.0 / 5.0
    for fids, delay, jit in (((ID_SAMPLES, ID_TRUTH), 300.0, 20.0), ((ID_DUTY,), 700.0, 60.0)):
        x = [v for f in fids for v in d[f]]
        n = len(x)
        assert n == N * len(fids)  # nothing dropped
        sigma = jit if dist == "normal" else jit / math.sqrt(3.0)
        assert abs(statistics.fmean(x) - delay) <= 5 * _se_mean(sigma, n), fids
        assert abs(statistics.pstdev(x) - sigma) <= 5 * _se_std(sigma, n, kurt), fids
        if dist == "uniform":
            # bounded by the half-width, and reaching close to both ends
            assert delay - jit <= min(x) < delay - 0.99 * jit
            assert delay + 0.99 * jit < max(x) <= delay + jit


def test_without_jitter_the_delay_is_exact_per_direction() -> None:
    clock = FakeClock()
    link = _link(clock, sample_delay_us=250.0, duty_delay_us=40.0, duty_jitter_us=15.0)
    d = _run(link, clock, _events(2000))
    for f in (ID_SAMPLES, ID_TRUTH):
        assert d[f] == pytest.approx([250.0] * 2000, abs=1e-6)
    assert statistics.pstdev(d[ID_DUTY]) > 10.0


@pytest.mark.parametrize("dist", ["normal", "uniform"])
def test_delay_is_never_negative(dist: str) -> None:
    clock = FakeClock()
    # jitter far wider than the delay: a large share of the draws are negative
    link = _link(clock, sample_delay_us=10.0, duty_delay_us=0.0, jitter_us=50.0, jitter_dist=dist)
    d = _run(link, clock, _events(N))
    x = d[ID_SAMPLES] + d[ID_TRUTH]
    assert min(x) >= 0.0 and min(d[ID_DUTY]) >= 0.0
    # the negative draws are held for no time at all, at the rate the law gives
    p0 = (
        0.5 * math.erfc(10.0 / 50.0 / math.sqrt(2.0))
        if dist == "normal"
        else (50.0 - 10.0) / (2 * 50.0)
    )
    n0 = sum(v <= 1e-6 for v in x)
    assert abs(n0 - len(x) * p0) <= 5 * math.sqrt(len(x) * p0 * (1 - p0))
    assert abs(sum(v <= 1e-6 for v in d[ID_DUTY]) - N * 0.5) <= 5 * math.sqrt(N * 0.25)


def test_commands_pass_at_once() -> None:
    clock = FakeClock()
    link = _link(clock, sample_delay_us=500.0, duty_delay_us=500.0, jitter_us=100.0, drop_prob=1.0)
    events = [(k * 1e-3, "a", ID_CMD) for k in range(50)] + _events(10)
    d = _run(link, clock, sorted(events, key=lambda e: e[0]))
    assert d[ID_CMD] == [0.0] * 50
    assert link.dropped == 30 and d[ID_SAMPLES] == d[ID_DUTY] == []


def _delays(seed: int, extra_duties: int = 0, **kw: Any) -> dict[int, list[float]]:
    clock = FakeClock()
    args = {"sample_delay_us": 200.0, "duty_delay_us": 400.0, "jitter_us": 30.0}
    link = _link(clock, seed=seed, **(args | kw))
    return _run(link, clock, _events(3000, extra_duties=extra_duties))


def test_same_seed_same_delays_other_seed_other_delays() -> None:
    a = _delays(9, drop_prob=0.1)
    assert a == _delays(9, drop_prob=0.1)
    b = _delays(10, drop_prob=0.1)
    assert a[ID_SAMPLES] != b[ID_SAMPLES] and a[ID_DUTY] != b[ID_DUTY]


def test_each_direction_has_its_own_random_stream() -> None:
    base = _delays(9, sample_drop_prob=0.1, duty_drop_prob=0.1)
    # other duty settings and twice the duty traffic: the samples' draws do not move
    duty_changed = _delays(
        9, sample_drop_prob=0.1, duty_drop_prob=0.4, duty_jitter_us=90.0, extra_duties=1
    )
    for f in (ID_SAMPLES, ID_TRUTH):
        assert duty_changed[f] == base[f]
    assert duty_changed[ID_DUTY] != base[ID_DUTY]
    # and the other way round
    sample_changed = _delays(
        9, sample_drop_prob=0.0, duty_drop_prob=0.1, sample_jitter_us=5.0, jitter_dist="normal"
    )
    assert sample_changed[ID_DUTY] == base[ID_DUTY]
    assert sample_changed[ID_SAMPLES] != base[ID_SAMPLES]


def test_directions_draw_uncorrelated_jitter() -> None:
    # the same settings both ways: the two directions' jitter must still be unrelated draws
    clock = FakeClock()
    link = _link(clock, sample_delay_us=500.0, duty_delay_us=500.0, jitter_us=40.0, seed=3)
    d = _run(link, clock, _events(N, with_truth=False))
    x, y = d[ID_SAMPLES], d[ID_DUTY]
    assert len(x) == len(y) == N
    # Pearson r of independent draws: standard error 1 / sqrt(n)
    assert abs(statistics.correlation(x, y)) <= 5 / math.sqrt(N)


def test_drop_rates_per_direction() -> None:
    clock = FakeClock()
    p_s, p_d = 0.2, 0.05
    link = _link(
        clock,
        sample_delay_us=100.0,
        duty_delay_us=100.0,
        jitter_us=10.0,
        drop_prob=0.5,  # overridden in both directions
        sample_drop_prob=p_s,
        duty_drop_prob=p_d,
        seed=1,
    )
    d = _run(link, clock, _events(N))
    lost_s = 2 * N - len(d[ID_SAMPLES]) - len(d[ID_TRUTH])
    lost_d = N - len(d[ID_DUTY])
    assert (lost_s, lost_d) == (link.dropped_samples, link.dropped_duties)
    assert abs(lost_s - 2 * N * p_s) <= 5 * math.sqrt(2 * N * p_s * (1 - p_s))
    assert abs(lost_d - N * p_d) <= 5 * math.sqrt(N * p_d * (1 - p_d))
    for f in (ID_SAMPLES, ID_TRUTH):
        assert abs(N - len(d[f]) - N * p_s) <= 5 * math.sqrt(N * p_s * (1 - p_s))


def test_shared_drop_prob_applies_to_both_directions() -> None:
    clock = FakeClock()
    link = _link(clock, sample_delay_us=0.0, duty_delay_us=0.0, drop_prob=0.3, seed=2)
    d = _run(link, clock, _events(N))
    bound = 5 * math.sqrt(N * 0.3 * 0.7)
    for f in (ID_SAMPLES, ID_TRUTH, ID_DUTY):
        assert abs(N - len(d[f]) - 0.3 * N) <= bound
