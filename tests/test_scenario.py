"""Scenario files: the shipped ones load, mistakes give one clear line."""

from pathlib import Path

import pytest

from bench._errors import ScenarioError
from bench.scenarios._schema import PAPER, SHIPPED, Profile, load_scenario


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_scenarios_load(name: str) -> None:
    s = load_scenario(name)
    assert s.name == name
    assert s.duration > s.score_from_s
    assert s.estimator in s.estimators
    # the papers' scenarios carry the papers' numbers; the full speed range is beyond them
    assert bool(s.paper_result) == (name in PAPER)


def test_wen_5_2_speed_steps_follow_the_paper_with_1s_lead_in() -> None:
    s = load_scenario("wen-5.2")
    for t_paper, rpm in [(1.0, 50), (2.5, 100), (5.5, 200), (8.5, 300), (11.5, 400)]:
        assert s.speed_rpm(t_paper + 1.0) == rpm


def test_profile_steps_and_ramps() -> None:
    p = Profile(((0.0, 0.0), (1.0, 0.0), (1.0, 10.0), (3.0, -10.0)))
    assert p(0.5) == 0.0
    assert p(1.0) == 10.0
    assert p(2.0) == pytest.approx(0.0)
    assert p(10.0) == -10.0


def _write(tmp_path: Path, text: str) -> str:
    f = tmp_path / "s.toml"
    f.write_text(text)
    return str(f)


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ('preset = "wen2023"\n', "'duration': required"),
        ('preset = "nope"\nduration = 1.0\n', "'preset': unknown preset 'nope'"),
        ('preset = "wen2023"\nduration = 1.0\nestimator = "kalman"\n', "'estimator': unknown"),
        ('preset = "wen2023"\nduration = "long"\n', "'duration': expected a number"),
        (
            'preset = "wen2023"\nduration = 1.0\nspeed_rpm = [[1.0, 0.0], [0.5, 1.0]]\n',
            "must not decrease",
        ),
        (
            'preset = "wen2023"\nduration = 1.0\n[latency]\ndrop_prob = 2.0\n',
            "'latency.drop_prob': must be <= 1.0",
        ),
        (
            'preset = "wen2023"\nduration = 1.0\n[latency]\nbogus = 1\n',
            "'latency.bogus': unknown key",
        ),
        ('preset = "wen2023"\nduration = 1.0\ncolour = 1\n', "'colour': unknown key"),
        ("preset = \n", "not valid TOML"),
        (
            'preset = "wen2023"\nduration = 1.0\nscore_from_s = 1.0\n',
            "'score_from_s': 1.0 s is not before the end of the run",
        ),
    ],
)
def test_bad_scenarios_name_file_field_and_reason(tmp_path: Path, text: str, needle: str) -> None:
    path = _write(tmp_path, text)
    with pytest.raises(ScenarioError) as e:
        load_scenario(path)
    msg = str(e.value)
    assert path in msg
    assert needle in msg
    assert "\n" not in msg


def test_unknown_scenario_name_lists_the_shipped_ones() -> None:
    with pytest.raises(ScenarioError, match=r"wen-5\.1"):
        load_scenario("wen-9.9")


def test_duration_shorter_than_the_scoring_start_scores_the_second_half() -> None:
    s = load_scenario("xue-fig13")
    assert s.score_from_s == 1.0
    assert s.with_overrides(duration=0.3).score_from_s == pytest.approx(0.15)
    assert s.with_overrides(duration=3.0).score_from_s == 1.0  # long enough: unchanged
    assert s.with_overrides(duration=0.3, score_from_s=0.1).score_from_s == 0.1


def test_a_short_file_scenario_without_scoring_start_scores_its_second_half(tmp_path: Path) -> None:
    assert (
        load_scenario(_write(tmp_path, 'preset = "wen2023"\nduration = 0.4\n')).score_from_s == 0.2
    )
    assert (
        load_scenario(_write(tmp_path, 'preset = "wen2023"\nduration = 2.0\n')).score_from_s == 0.5
    )


def test_every_scenario_file_is_shipped_by_name() -> None:
    from pathlib import Path

    import bench.scenarios

    on_disk = sorted(p.stem for p in Path(bench.scenarios.__file__).parent.glob("*.toml"))
    assert sorted(SHIPPED) == on_disk


def test_the_hybrids_own_options_are_scenario_keys(tmp_path: Path) -> None:
    from bench.scenarios._setup import build_controller

    f = tmp_path / "fast.toml"
    f.write_text('extends = "wide-speed-wen"\n[estimator_options]\nalpha_o = 300.0\nu_err = 2.0\n')
    s = load_scenario(str(f))
    assert s.estimator_options["alpha_o"] == 300.0
    build_controller(s, "hybrid-tt-dq")
    bad = tmp_path / "bad.toml"
    bad.write_text('extends = "wide-speed-wen"\n[estimator_options]\nu_err = -1.0\n')
    with pytest.raises(ScenarioError, match="u_err"):
        load_scenario(str(bad))
