"""Bus-load report: frame lengths against ISO 11898-1 counts and the DESIGN.md budget."""

from __future__ import annotations

import pytest

from bench.wire._busload import (
    BUSES,
    PRACTICAL_LOAD,
    Bus,
    busload_table,
    classic_frame_bits,
    fd_frame_bits,
    format_busload,
    frame_time_us,
)
from bench.wire._codec import Codec


@pytest.fixture(scope="module")
def table():
    return busload_table(Codec(), rates=[1e3, 4e3, 10e3])


def _row(table, layout, bus):
    (row,) = [r for r in table if r["layout"] == layout and r["bus"] == bus]
    return row


def _worst_stuffing_bruteforce(n_stuffed_bits: int) -> int:
    """Most stuff bits any pattern of ``n`` stuffed bits can produce (dynamic programming).

    State: length of the run of equal bits last sent (stuff bits included). A stuff bit
    of the opposite value follows every run of 5 and starts a run of its own.
    """
    best = {1: 0}  # run length -> most stuff bits so far (after the first bit)
    for _ in range(n_stuffed_bits - 1):
        nxt: dict[int, int] = {}
        for run, count in best.items():
            for r, c in ((run + 1, count), (1, count)):  # same bit / opposite bit
                if r == 5:
                    r, c = 1, c + 1
                nxt[r] = max(nxt.get(r, -1), c)
        best = nxt
    return max(best.values())


def test_classic_8_bytes_is_111_to_135_bits():
    assert classic_frame_bits(8) == (111, 135)
    assert frame_time_us(8, fd=False, bitrate=1e6) == pytest.approx(135.0)
    assert frame_time_us(8, fd=False, bitrate=1e6, worst=False) == pytest.approx(111.0)


@pytest.mark.parametrize("n", range(9))
def test_classic_general_formula(n):
    base, worst = classic_frame_bits(n)
    assert base == 47 + 8 * n
    assert worst - base == _worst_stuffing_bruteforce(34 + 8 * n)
    ext_base, ext_worst = classic_frame_bits(n, extended=True)
    assert ext_base == base + 20 and ext_worst - ext_base == (54 + 8 * n - 1) // 4


def test_classic_zero_bytes_published():
    # 0-byte standard frame: 47 bits, at most 8 stuff bits (Davis et al. 2007, Table 1).
    assert classic_frame_bits(0) == (47, 55)


def test_fd_frame_phases():
    (arb, data), (arb_w, data_w) = fd_frame_bits(16)
    assert arb == 29  # SOF..BRS 17 + ACK, delimiter, EOF, IFS 12
    # ESI 1, DLC 4, 128 data, stuff count 4, CRC-17, 6 fixed stuff bits, CRC delimiter 1
    assert data == 1 + 4 + 128 + 4 + 17 + 6 + 1
    assert arb_w - arb == 4 and (arb_w - arb) + (data_w - data) == (22 + 128 - 1) // 4
    (_, data24), _ = fd_frame_bits(24)
    assert data24 == 1 + 4 + 192 + 4 + 21 + 7 + 1  # CRC-21 above 16 bytes
    with pytest.raises(ValueError):
        fd_frame_bits(10)


def test_fd_16_bytes_at_5_mbit_about_60_to_70_us():
    best = frame_time_us(16, fd=True, bitrate=1e6, data_bitrate=5e6, worst=False)
    worst = frame_time_us(16, fd=True, bitrate=1e6, data_bitrate=5e6)
    assert best == pytest.approx(29 + 161 / 5)
    assert 58 < best < 65 and 65 < worst < 75
    # Without bit-rate switching the whole frame runs at 1 Mbit/s.
    assert frame_time_us(16, fd=True, bitrate=1e6) == pytest.approx(33 + 194)


def test_design_budget_classic_1M(table):
    row = _row(table, "control", "classic 1M")
    assert row["period_us_min"] == pytest.approx(222.0)
    assert row["period_us_max"] == pytest.approx(270.0)
    # DESIGN.md: about 3.7-4.5 kHz at 100 % load (less the small PlantStatus background).
    assert row["max_rate_hz"] == pytest.approx(1e6 / 270, rel=5e-3)
    assert row["max_rate_hz_min"] == pytest.approx(1e6 / 222, rel=5e-3)
    assert 3.6e3 < row["max_rate_hz"] < 3.71e3 and 4.4e3 < row["max_rate_hz_min"] < 4.51e3
    assert row["max_rate_hz_practical"] == pytest.approx(
        (PRACTICAL_LOAD - row["background_load"]) * 1e6 / 270
    )
    # Half that at 500 kbit/s.
    half = _row(table, "control", "classic 500k")
    assert half["max_rate_hz"] == pytest.approx(row["max_rate_hz"] / 2, rel=5e-3)


def test_loads_scale_with_rate(table):
    row = _row(table, "control", "classic 1M")
    assert row["load"][1e3] == pytest.approx(row["background_load"] + 0.270)
    assert row["load"][4e3] > 1.0 > row["load"][1e3]
    assert row["load_min"][4e3] == pytest.approx(row["background_load"] + 0.888)


def test_recorder_frames_cost_and_fd_helps(table):
    classic = _row(table, "control+recorder", "classic 1M")
    # On a classic bus each FD frame is split into 8-byte frames plus the rest:
    # PlantTruth and CtrlTelemetry (16 bytes each since DBC 2.1) = 8 + 8.
    truth = 2 * classic_frame_bits(8)[1]
    tele = 2 * classic_frame_bits(8)[1]
    assert classic["period_us_max"] == pytest.approx(270 + truth + tele)
    fd = _row(table, "control+recorder", "FD 1M/5M")
    assert fd["period_us_max"] < classic["period_us_max"]
    # The DBC's classic frames stay classic on an FD bus: same control time as classic 1M.
    assert _row(table, "control", "FD 1M/5M")["period_us_max"] == pytest.approx(270.0)
    all_fd = _row(table, "control", "FD 1M/5M all-FD")
    assert 8e3 < all_fd["max_rate_hz"] < 1e4  # DESIGN.md: about 8 kHz with FD at 5 Mbit/s


def test_rows_cover_layouts_and_buses(table):
    assert len(table) == 3 * len(BUSES)
    assert {r["bus"] for r in table} == {b.name for b in BUSES}
    custom = busload_table(Codec(), [1e3], layouts={"duty": ("PwmDuty",)}, buses=[Bus("x", 1e6)])
    assert len(custom) == 1 and custom[0]["period_us_max"] == pytest.approx(135.0)


def test_a_sensored_loop_adds_one_classic_frame(table):
    """PositionSensor every period: three 8-byte classic frames of 111-135 bits, so
    405 us per period at 1 Mbit/s and at most (1 - background) / 405 us = 2.47 kHz."""
    row = _row(table, "control+sensor", "classic 1M")
    assert row["frames"] == ["PwmDuty", "PhaseSamples", "PositionSensor"]
    assert (row["period_us_min"], row["period_us_max"]) == (
        pytest.approx(333.0),
        pytest.approx(405.0),
    )
    assert row["max_rate_hz"] == pytest.approx((1.0 - row["background_load"]) / 405e-6)
    assert 2.4e3 < row["max_rate_hz"] < 2.5e3


def test_protocol_md_states_the_sensored_loops_rates(table):
    """docs/PROTOCOL.md's figures for the sensored loop are bench busload's."""
    from pathlib import Path

    doc = " ".join((Path(__file__).parents[1] / "docs" / "PROTOCOL.md").read_text().split())
    c1, c500 = (
        _row(table, "control+sensor", "classic 1M"),
        _row(table, "control+sensor", "classic 500k"),
    )
    alone = _row(table, "control", "classic 1M")
    half = (1.0 - c1["background_load"]) / ((alone["period_us_max"] + 135.0 / 2) * 1e-6)
    for x in (
        c1["max_rate_hz"],
        c1["max_rate_hz_practical"],
        c500["max_rate_hz"],
        alone["max_rate_hz"],
        half,
    ):
        assert f"{x / 1e3:.2f} kHz" in doc, x
    assert f"{c1['period_us_min']:.0f}-{c1['period_us_max']:.0f} us per period" in doc


def test_format(table):
    text = format_busload(table)
    assert "classic 1M" in text and "FD 1M/5M" in text
    line = next(ln for ln in text.splitlines() if ln.startswith("control ") and "classic 1M" in ln)
    assert "222-270" in line and "3.70 (4.50)" in line
    assert "!" in line  # 4 kHz does not fit
