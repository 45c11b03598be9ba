"""Latency per direction: the ``[latency]`` schema, ``bench link`` and the lockstep link.

Duties go to the plant (B to A), samples and truth to the controller (A to
B).  Each direction has its own jitter and drop probability; the shared
``jitter_us`` and ``drop_prob`` are the value of a direction that does not
give its own.  The lockstep link's drops are counted by frame ID on frames
fed by a scripted plant and controller (no bus), then once through real
processes, where the plant's retransmission recovers every dropped duty.
"""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import can
import pytest

from bench._errors import ScenarioError
from bench.cli import main
from bench.nodes._link import LockstepLink, RealtimeLink
from bench.nodes._loops import run_inprocess
from bench.runs._run import run_scenario
from bench.scenarios._schema import (
    Direction,
    Latency,
    load_scenario,
    scenario_from_dict,
    write_effective,
)
from bench.wire._bus import BusSpec
from bench.wire._codec import Codec
from tests.ports import free_port
from tests.trace_helpers import assert_same_trace, short, trace

CODEC = Codec()
ID_SAMPLES = CODEC.frame_id("PhaseSamples")
ID_TRUTH = CODEC.frame_id("PlantTruth")
ID_DUTY = CODEC.frame_id("PwmDuty")

#: The keys ``[latency]`` had before the per-direction ones (old meta.json files).
OLD_KEYS = {
    "duty_delay_steps",
    "sample_delay_steps",
    "duty_delay_us",
    "sample_delay_us",
    "jitter_us",
    "jitter_dist",
    "drop_prob",
}


def _scenario_file(tmp_path: Path, latency: str) -> str:
    f = tmp_path / "s.toml"
    f.write_text(f'preset = "wen2023"\nduration = 1.0\nseed = 7\n[latency]\n{latency}')
    return str(f)


# --- schema ---------------------------------------------------------------------------


def test_per_direction_keys_are_read(tmp_path: Path) -> None:
    lt = load_scenario(
        _scenario_file(
            tmp_path,
            "duty_jitter_us = 30.0\nsample_jitter_us = 5.0\n"
            "duty_drop_prob = 0.25\nsample_drop_prob = 0.0\n",
        )
    ).latency
    assert lt.duty == Direction(delay_steps=0, delay_us=0.0, jitter_us=30.0, drop_prob=0.25)
    assert lt.sample == Direction(delay_steps=0, delay_us=0.0, jitter_us=5.0, drop_prob=0.0)
    assert lt.any


def test_shared_keys_apply_to_both_directions(tmp_path: Path) -> None:
    # an old scenario file: only the shared keys
    lt = load_scenario(
        _scenario_file(
            tmp_path,
            "duty_delay_us = 100.0\nsample_delay_us = 50.0\njitter_us = 12.0\ndrop_prob = 0.1\n",
        )
    ).latency
    assert lt.duty == Direction(delay_steps=0, delay_us=100.0, jitter_us=12.0, drop_prob=0.1)
    assert lt.sample == Direction(delay_steps=0, delay_us=50.0, jitter_us=12.0, drop_prob=0.1)


def test_per_direction_key_wins_over_the_shared_one(tmp_path: Path) -> None:
    lt = load_scenario(
        _scenario_file(
            tmp_path,
            "jitter_us = 12.0\nsample_jitter_us = 0.0\ndrop_prob = 0.1\nduty_drop_prob = 0.4\n",
        )
    ).latency
    # the sample direction's explicit zero jitter is kept, not replaced by the shared 12 us
    assert (lt.sample.jitter_us, lt.duty.jitter_us) == (0.0, 12.0)
    assert (lt.sample.drop_prob, lt.duty.drop_prob) == (0.1, 0.4)


def test_only_one_direction_lossy_counts_as_latency() -> None:
    assert not Latency().any
    assert Latency(sample_drop_prob=0.01).any
    assert Latency(duty_jitter_us=1.0).any
    # an explicit zero for one direction does not hide the shared value of the other
    assert Latency(drop_prob=0.2, duty_drop_prob=0.0).any
    assert not Latency(drop_prob=0.2, duty_drop_prob=0.0, sample_drop_prob=0.0).any


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("duty_drop_prob = 1.5\n", "'latency.duty_drop_prob': must be <= 1.0"),
        ("sample_drop_prob = -0.1\n", "'latency.sample_drop_prob': must be >= 0.0"),
        ("duty_jitter_us = -1.0\n", "'latency.duty_jitter_us': must be >= 0.0"),
        ('sample_jitter_us = "lots"\n', "'latency.sample_jitter_us': expected a number"),
        ("sample_drop_prob = nan\n", "'latency.sample_drop_prob': must be finite"),
        ("duty_jitter = 1.0\n", "'latency.duty_jitter': unknown key"),
    ],
)
def test_bad_per_direction_values_name_file_and_field(
    tmp_path: Path, text: str, needle: str
) -> None:
    path = _scenario_file(tmp_path, text)
    with pytest.raises(ScenarioError) as e:
        load_scenario(path)
    msg = str(e.value)
    assert path in msg and needle in msg and "\n" not in msg


def test_round_trip_keeps_per_direction_and_shared_values(tmp_path: Path) -> None:
    scn = load_scenario("wen-5.1")
    lat = Latency(
        duty_delay_us=80.0,
        jitter_us=10.0,
        jitter_dist="uniform",
        drop_prob=0.05,
        sample_jitter_us=3.0,
        duty_drop_prob=0.0,
    )
    scn = replace(scn, latency=lat)
    d = scn.to_dict()
    assert d["latency"]["sample_jitter_us"] == 3.0 and d["latency"]["duty_drop_prob"] == 0.0
    assert "duty_jitter_us" not in d["latency"] and "sample_drop_prob" not in d["latency"]
    back = scenario_from_dict(json.loads(json.dumps(d)), scn.source)
    assert back == scn
    assert back.latency.duty.jitter_us == 10.0 and back.latency.sample.drop_prob == 0.05
    # and through the effective-scenario file the node processes read
    eff = load_scenario(str(write_effective(scn, tmp_path / "eff.json")))
    assert eff.latency == lat


def test_old_meta_json_still_loads(tmp_path: Path) -> None:
    scn = load_scenario("wen-5.1")
    d: dict[str, Any] = scn.to_dict()
    # a scenario without per-direction values writes exactly the old keys
    assert set(d["latency"]) == OLD_KEYS
    d["latency"].update(jitter_us=7.0, drop_prob=0.3)
    meta = tmp_path / "meta.json"
    meta.write_text(json.dumps(d))
    lt = load_scenario(str(meta)).latency
    assert lt.duty.jitter_us == lt.sample.jitter_us == 7.0
    assert lt.duty.drop_prob == lt.sample.drop_prob == 0.3


# --- bench link options ---------------------------------------------------------------


LINK_ARGV = ["link", "-i", "udp_multicast", "--port", "47100", "--to", "udp_multicast:239.74.163.2"]


@pytest.mark.parametrize(
    ("extra", "word"),
    [
        (["--duty-drop-prob", "1.5"], "--duty-drop-prob"),
        (["--sample-drop-prob", "-0.5"], "--sample-drop-prob"),
        (["--sample-drop-prob", "nan"], "--sample-drop-prob"),
        (["--duty-jitter-us", "-1"], "--duty-jitter-us"),
        (["--sample-jitter-us", "inf"], "--sample-jitter-us"),
    ],
)
def test_link_per_direction_options_are_checked(
    extra: list[str], word: str, capsys: pytest.CaptureFixture[str]
) -> None:
    rc = main([*LINK_ARGV, "--to-port", "47101", *extra])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2
    assert len(err) == 1 and "error" in err[0] and word in err[0], err


@pytest.mark.parametrize("mode", ["lockstep", "realtime"])
def test_link_options_reach_the_link(
    mode: str, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import bench.cli.link
    import bench.nodes._link

    got: list[LockstepLink | RealtimeLink] = []
    opened: list[can.BusABC] = []

    def fake_open(spec: BusSpec) -> can.BusABC:
        opened.append(can.Bus(interface="virtual", channel=f"link-{len(opened)}"))
        return opened[-1]

    monkeypatch.setattr(BusSpec, "open", fake_open)
    monkeypatch.setattr(bench.cli.link, "stop_on_signals", lambda: None)
    monkeypatch.setattr(bench.nodes._link, "link_loop", lambda a, b, logic, **kw: got.append(logic))
    argv = [*LINK_ARGV, "--to-port", "47101", "--mode", mode, "--seed", "3"]
    extra = ["--drop-prob", "0.2", "--duty-drop-prob", "0.6", "--jitter-us", "9"]
    assert main([*argv, *extra, "--sample-jitter-us", "4"]) == 0
    assert "dropped 0 samples/truth and 0 duties" in capsys.readouterr().err
    (logic,) = got
    if isinstance(logic, LockstepLink):
        assert (logic.p_s, logic.p_d) == (0.2, 0.6)
    else:
        assert (logic.samples.drop_prob, logic.duties.drop_prob) == (0.2, 0.6)
        assert logic.samples.jit == pytest.approx(4e-6) and logic.duties.jit == pytest.approx(9e-6)


# --- lockstep link, scripted plant and controller --------------------------------------


def _samples(k: int) -> can.Message:
    return CODEC.encode(
        "PhaseSamples", {"i_a": 0.0, "i_b": 0.0, "u_dc": 300.0, "status": 0, "step": k}
    )


def _truth(k: int) -> can.Message:
    sig = {"theta_e": 0.0, "w_m": 0.0, "tau_e": 0.0, "tau_L": 0.0, "step": k, "duty_age": 0}
    return CODEC.encode("PlantTruth", sig)


def _duty(t: int) -> can.Message:
    sig = {"duty_a": 0.5, "duty_b": 0.5, "duty_c": 0.5, "enable": 1, "step": t}
    return CODEC.encode("PwmDuty", sig)


def _step(m: can.Message) -> int:
    d = CODEC.decode(m)
    assert d is not None
    return int(d.signals["step"])


def _drive(link: LockstepLink, n: int) -> tuple[list[can.Message], list[can.Message]]:
    """Periods 0..n-1: the plant sends samples and truth of k, the controller duty k+1.

    The controller answers every period whether its sample arrived or not, so
    the duties offered to the link do not depend on the sample direction's
    drops.  Returns every frame the link forwarded to B and to A.
    """
    to_b: list[can.Message] = []
    to_a: list[can.Message] = []
    for k in range(n):
        for out in (link.from_a(_samples(k)), link.from_a(_truth(k)), link.from_b(_duty(k + 1))):
            to_b += out[0]
            to_a += out[1]
    return to_b, to_a


def _binomial_ok(k: int, n: int, p: float) -> bool:
    """``k`` within 5 standard deviations of Binomial(n, p)'s mean.

    A correct link fails this with probability below 6e-7 (normal tail,
    n p (1 - p) >= 36 here); a link dropping at half or twice the rate, or
    at the other direction's rate, is far outside it.
    """
    return abs(k - n * p) <= 5.0 * math.sqrt(n * p * (1.0 - p))


N = 4000
N_S, N_D = 2, 1
SAMPLE_STEPS = [k % 1024 for k in range(N - N_S)]


def test_lockstep_without_drops_forwards_every_frame_once() -> None:
    link = LockstepLink(CODEC, sample_delay=N_S, duty_delay=N_D)
    to_b, to_a = _drive(link, N)
    # PhaseSamples and PwmDuty count periods modulo 1024, PlantTruth does not wrap
    assert [_step(m) for m in to_b if m.arbitration_id == ID_SAMPLES] == SAMPLE_STEPS
    assert [_step(m) for m in to_b if m.arbitration_id == ID_TRUTH] == list(range(N - N_S))
    # duty t is released with sample t - 1 + N_s + N_d
    assert [_step(m) % 1024 for m in to_a] == [(t + 1) % 1024 for t in range(N - N_S - N_D)]
    assert link.dropped == 0


def test_lockstep_drops_only_the_duty_direction() -> None:
    p = 0.1
    link = LockstepLink(CODEC, sample_delay=N_S, duty_delay=N_D, duty_drop_prob=p, seed=11)
    to_b, to_a = _drive(link, N)
    # every sample and truth frame reaches the controller, each once
    assert [_step(m) for m in to_b if m.arbitration_id == ID_SAMPLES] == SAMPLE_STEPS
    assert [_step(m) for m in to_b if m.arbitration_id == ID_TRUTH] == list(range(N - N_S))
    assert {m.arbitration_id for m in to_a} == {ID_DUTY}
    offered = N - N_S - N_D
    lost = offered - len(to_a)
    assert lost == link.dropped_duties and link.dropped_samples == 0
    assert _binomial_ok(lost, offered, p), lost


def test_lockstep_drops_only_the_sample_direction() -> None:
    p = 0.05
    link = LockstepLink(CODEC, sample_delay=N_S, duty_delay=N_D, sample_drop_prob=p, seed=11)
    to_b, to_a = _drive(link, N)
    # every duty reaches the plant
    assert len(to_a) == N - N_S - N_D and link.dropped_duties == 0
    offered = 2 * (N - N_S)  # PhaseSamples and PlantTruth of each released period
    lost = offered - len(to_b)
    assert lost == link.dropped_samples
    assert _binomial_ok(lost, offered, p), lost
    # both frame IDs of the direction are dropped, each at the same rate
    for fid in (ID_SAMPLES, ID_TRUTH):
        lost_id = (N - N_S) - sum(m.arbitration_id == fid for m in to_b)
        assert _binomial_ok(lost_id, N - N_S, p), (fid, lost_id)


def _dropped_duty_steps(link: LockstepLink) -> set[int]:
    _, to_a = _drive(link, 1000)
    return set(range(1, 1000 - N_S - N_D + 1)) - {_step(m) for m in to_a}


def test_lockstep_drops_are_deterministic_for_a_seed() -> None:
    def run(seed: int, p_s: float = 0.0) -> set[int]:
        link = LockstepLink(
            CODEC,
            sample_delay=N_S,
            duty_delay=N_D,
            seed=seed,
            duty_drop_prob=0.2,
            sample_drop_prob=p_s,
        )
        return _dropped_duty_steps(link)

    first = run(5)
    assert first == run(5)
    assert first != run(6)
    # the sample direction's loss draws from its own stream: same duties dropped
    assert run(5, p_s=0.3) == first


def test_shared_drop_prob_drops_both_directions() -> None:
    p = 0.1
    link = LockstepLink(CODEC, sample_delay=0, duty_delay=0, drop_prob=p, seed=2)
    to_b, to_a = _drive(link, N)
    assert _binomial_ok(N - len(to_a), N, p)
    assert _binomial_ok(2 * N - len(to_b), 2 * N, p)
    # a per-direction zero overrides the shared value
    link = LockstepLink(CODEC, sample_delay=0, duty_delay=0, drop_prob=p, duty_drop_prob=0.0)
    to_b, to_a = _drive(link, N)
    assert len(to_a) == N and _binomial_ok(2 * N - len(to_b), 2 * N, p)


def test_repeated_sample_recovers_a_dropped_duty() -> None:
    # every duty dropped on first release; the plant's repeat of its last sample gets it
    link = LockstepLink(CODEC, sample_delay=0, duty_delay=0, duty_drop_prob=1.0)
    assert link.from_a(_samples(0))[0]
    link.from_a(_truth(0))
    assert link.from_b(_duty(1)) == ([], [])
    again_b, again_a = link.from_a(_samples(0))
    # the repeat also gets the period's samples and truth again (a lost sample's recovery)
    assert [m.arbitration_id for m in again_b] == [ID_SAMPLES, ID_TRUTH]
    assert [_step(m) for m in again_a] == [1]
    assert link.dropped_duties == 1 and link.dropped_samples == 0


def test_a_sample_whose_first_copy_the_link_lost_is_forwarded_when_repeated() -> None:
    """The link never saw sample 1 (lost on its way in, as a busy receive buffer loses
    it) and saw sample 2: the plant's repeat of sample 1 is a new sample to the link,
    released in its place, not a repeat of something released (before, it was taken
    for one and never reached the controller: the run stalled).  Repeats of released
    samples are sent again, as before."""
    link = LockstepLink(CODEC, sample_delay=0, duty_delay=0)
    link.from_a(_samples(0))
    to_b, _ = link.from_a(_samples(2))  # sample 1 never reached the link
    assert [_step(m) for m in to_b] == [2]
    to_b, _ = link.from_a(_samples(1))  # the plant repeats its recent samples
    assert [_step(m) for m in to_b] == [1]
    to_b, _ = link.from_a(_samples(1))  # now a repeat of a released sample
    assert [_step(m) for m in to_b] == [1] and 1 in link.released_b  # sent again
    with_delay = LockstepLink(CODEC, sample_delay=2, duty_delay=0)
    for k in (0, 1, 3, 4):  # sample 2 lost; 0 and 1 released by 2 periods of delay
        with_delay.from_a(_samples(k))
    to_b, _ = with_delay.from_a(_samples(2))
    assert [_step(m) for m in to_b] == [2]  # held in its place, released at once (4 - 2)


# --- through the processes -------------------------------------------------------------


def test_lockstep_duty_loss_only_is_recovered_end_to_end(tmp_path: Path) -> None:
    scn = short("wen-5.1", 0.05, duty_drop_prob=0.03, sample_delay_steps=1)
    ref = trace(run_inprocess(scn, "sensored", CODEC), scn)
    spec = BusSpec("udp_multicast", "239.74.163.2", free_port())
    res = run_scenario(scn, "sensored", spec=spec, out_dir=tmp_path / "run", progress=False)
    got = trace(list(can.LogReader(str(res.capture))), scn)
    assert_same_trace(ref, got)
    # the plant repeated itself for the lost duties, and only duties were lost
    assert res.metrics["retransmits"] > 0
    log = (tmp_path / "run" / "link.log").read_text()
    assert "dropped 0 samples/truth and " in log
    n_duties = int(log.split("samples/truth and ")[1].split()[0])
    assert n_duties > 0
