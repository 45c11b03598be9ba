"""The designed gains the guides name are the ones the controller builds.

docs/PAPERS.md's "Parameters the papers leave open" states the bandwidths the
design gives (they are derived in the docstrings, not chosen); this test
computes them from the shipped scenarios, so a design change that moves one
fails here until the guide says the new value.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

from bench.scenarios._schema import load_scenario
from bench.scenarios._setup import build_controller

GUIDE = " ".join(
    (Path(__file__).resolve().parent.parent / "docs" / "PAPERS.md").read_text().split()
)


def gains(scn: str, est: str) -> dict[str, float]:
    return build_controller(load_scenario(scn), est).gains()


def rpm(w_e: float, n_p: int = 4) -> int:
    return round(w_e / n_p * 60.0 / (2.0 * math.pi))


def test_the_pll_bandwidths_and_speed_loops_in_the_readme() -> None:
    tt, sf, ab = (gains("wen-5.1", e) for e in ("tt-dq", "sfhf", "tt-ab"))
    text = (
        f"tt-dq {tt['estimator.w_o']:.1f} rad/s (its BPF and LPF are in the loop), "
        f"sfhf {sf['estimator.w_o']:.0f} rad/s, tt-ab {ab['estimator.w_o']:.0f} rad/s"
    )
    assert text in GUIDE
    hz = [g["alpha_s"] / (2.0 * math.pi) for g in (tt, sf, ab)]
    assert f"(tt-dq {hz[0]:.1f} Hz, sfhf {hz[1]:.1f} Hz, tt-ab {hz[2]:.1f} Hz)" in GUIDE


def test_the_square_wave_observer_pole_in_the_readme() -> None:
    a = gains("xue-fig13", "square-wave")["estimator.a"]
    a_zoh = gains("xue-fig13", "square-wave-nocic")["estimator.a"]
    assert f"{a:.1f} rad/s at 1 kHz ({a_zoh:.1f} without the CIC)" in GUIDE


def test_the_hand_over_bands_in_the_readme() -> None:
    w = gains("wide-speed-wen", "hybrid-tt-dq")
    x = gains("wide-speed-xue", "hybrid-square-wave")
    wen = f"{rpm(w['estimator.band.w_lo'])}-{rpm(w['estimator.band.w_hi'])} rpm"
    xue = f"{rpm(x['estimator.band.w_lo'])}-{rpm(x['estimator.band.w_hi'])} rpm"
    assert f"(Wen motor {wen}, Xue motor {xue})" in GUIDE
    assert re.search(r"\d", wen)
