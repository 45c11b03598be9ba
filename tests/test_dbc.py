"""The DBC file: loadable, complete, and its scalings fit the physics they carry."""

from __future__ import annotations

import math
import subprocess
import sys

import cantools
import pytest

from dbc import DBC_PATH

EXPECTED = {
    "PwmDuty": {"duty_a", "duty_b", "duty_c", "enable", "step", "crc"},
    "PhaseSamples": {"i_a", "i_b", "u_dc", "step", "status", "crc"},
    "PlantTruth": {"theta_e", "w_m", "tau_e", "tau_L", "step", "duty_age", "run_id", "crc"},
    "PlantCurrents": {"i_a", "i_b", "step", "run_id", "crc"},
    "CtrlTelemetry": {
        "theta_hat",
        "w_hat",
        "err",
        "mode",
        "step",
        "run_id",
        "crc",
        "cmd_ack_valid",
        "cmd_ack",
    },
    "BenchCommand": {"cmd", "speed_ref", "load_torque", "seq", "step", "crc"},
    "PositionSensor": {"theta_m", "step", "crc"},
    "PlantStatus": {"state", "fault_code", "overruns", "late_frames", "step", "crc"},
}


@pytest.fixture(scope="module")
def db() -> cantools.database.can.Database:
    database = cantools.database.load_file(str(DBC_PATH))
    assert isinstance(database, cantools.database.can.Database)
    return database


def test_messages_and_signal_names(db):
    got = {m.name: {s.name for s in m.signals} for m in db.messages}
    assert got == EXPECTED
    assert {n.name for n in db.nodes} == {"Plant", "Controller", "Bench"}


def test_cantools_dump_is_clean():
    res = subprocess.run(
        [sys.executable, "-m", "cantools", "dump", str(DBC_PATH)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert res.returncode == 0, res.stderr
    assert "PwmDuty" in res.stdout and "CtrlTelemetry" in res.stdout
    assert "warning" not in (res.stdout + res.stderr).lower()


def test_priorities(db):
    fid = {m.name: m.frame_id for m in db.messages}
    per_period = max(fid["PwmDuty"], fid["PhaseSamples"])
    assert per_period < fid["BenchCommand"]
    assert fid["BenchCommand"] < min(
        fid["PlantStatus"], fid["PlantTruth"], fid["CtrlTelemetry"], fid["PlantCurrents"]
    )
    assert all(not m.is_extended_frame for m in db.messages)


def test_frame_formats(db):
    for m in db.messages:
        if m.name in ("PlantTruth", "CtrlTelemetry", "PlantCurrents"):
            assert m.is_fd and 8 < m.length <= 64
        else:
            assert not m.is_fd and m.length == 8
        # Every bit of each frame is used or the frame is FD-padded to a valid DLC.
        used = sum(s.length for s in m.signals)
        assert used <= 8 * m.length


def test_every_signal_commented(db):
    for m in db.messages:
        assert m.comment, m.name
        for s in m.signals:
            assert s.comment, f"{m.name}.{s.name}"


def test_crc_and_e2e_data_ids(db):
    """Every frame, the recorder's included (2.1, issue 17), carries a crc in byte 0."""
    ids = []
    for m in db.messages:
        crc = [s for s in m.signals if s.name == "crc"]
        assert crc, m.name
        assert crc[0].length == 8 and crc[0].start == 0
        ids.append(m.dbc.attributes["E2EDataId"].value)
    assert len(ids) == 8 and len(set(ids)) == 8
    # a data ID fed in the wrong byte order must fail the check: its two bytes
    # differ, and swapped it is no other message's data ID
    swapped = {(i >> 8) | ((i & 0xFF) << 8) for i in ids}
    assert all(i & 0xFF != i >> 8 for i in ids)
    assert not swapped & set(ids)


def test_protocol_version_attribute(db):
    """The DBC's version is in its VERSION line and its ProtocolVersion attribute, the same."""
    from bench.wire._codec import Codec

    assert db.version == str(db.dbc.attributes["ProtocolVersion"].value) == Codec().version
    assert int(db.version.split(".")[0]) >= 2  # 2.0: duty scale and PwmDuty data ID changed
    assert db.version == "2.4"  # 2.1: crc and run_id in PlantTruth and CtrlTelemetry; 2.2: cmd_ack;
    # 2.3: the supervision's CtrlTelemetry.mode values; 2.4: PlantCurrents


def test_the_dbc_comment_names_its_version_once(db):
    """The DBC's own comment states no version of its own beside VERSION: every version it
    names is a change ("Version 2.4 added ..."), the newest of them the VERSION line's."""
    import re

    text = DBC_PATH.read_text()
    comment = re.search(r'^CM_ "(.*?)";', text, re.M | re.S)
    assert comment is not None
    named = re.findall(r"[Vv]ersion (\d+\.\d+)(\s+\w+)?", comment.group(1))
    assert named, "the DBC comment names no version"
    assert [v for v, verb in named if verb.strip() != "added"] == []
    newest = max(named, key=lambda m: tuple(map(int, m[0].split("."))))[0]
    assert newest == db.version


def test_duty_one_encodes_strictly_and_above_one_is_out_of_range(db):
    """cantools' strict encoding takes duty 1.0 (issue 16); a raw value above it is
    expressible on the wire and outside the range, so the plant can reject it."""
    m = db.get_message_by_name("PwmDuty")
    sig = {"crc": 0, "duty_a": 1.0, "duty_b": 0.0, "duty_c": 0.5, "enable": 1, "step": 1}
    got = m.decode(m.encode(sig, strict=True))
    assert got["duty_a"] == 1.0 and got["duty_b"] == 0.0 and got["duty_c"] == 0.5
    duty = m.get_signal_by_name("duty_a")
    assert (duty.minimum, duty.maximum) == (0.0, 1.0)
    assert (1 << duty.length) - 1 > round(1.0 / duty.scale)  # raw above 1.0 exists


def test_value_tables(db):
    cmd = db.get_message_by_name("BenchCommand").get_signal_by_name("cmd")
    assert {k: str(v) for k, v in cmd.choices.items()} == {
        0: "none",
        1: "start",
        2: "stop",
        3: "reset",
        4: "enable",
        5: "disable",
    }
    fault = db.get_message_by_name("PlantStatus").get_signal_by_name("fault_code")
    assert [str(fault.choices[i]) for i in range(6)] == [
        "none",
        "watchdog",
        "over_current",
        "over_voltage",
        "over_speed",
        "wrong_step",
    ]
    mode = db.get_message_by_name("CtrlTelemetry").get_signal_by_name("mode")
    from controller._api import MODE_ALIGN, MODE_DISABLED, MODE_FAULT, MODE_POLARITY, MODE_RUN

    assert str(mode.choices[MODE_DISABLED]) == "disabled"
    assert str(mode.choices[MODE_ALIGN]) == "align"
    assert str(mode.choices[MODE_POLARITY]) == "polarity"
    assert str(mode.choices[MODE_RUN]) == "run"
    assert str(mode.choices[MODE_FAULT]) == "fault"


def test_step_counters_wide_enough(db):
    for m in db.messages:
        step = m.get_signal_by_name("step") if "step" in {s.name for s in m.signals} else None
        if step is not None:
            assert step.length >= 10 and not step.is_signed and step.scale == 1


def _hf_currents(V_h: float, f_h: float, L_d: float, L_q: float) -> tuple[float, float]:
    """Positive and negative-sequence HF current amplitudes at standstill (Wen (5), and (6)
    with the sign derived from (2): V_h (L_q - L_d) / (2 w_h L_d L_q))."""
    w_h = 2 * math.pi * f_h
    return V_h * (L_d + L_q) / (2 * w_h * L_d * L_q), V_h * (L_q - L_d) / (2 * w_h * L_d * L_q)


def test_current_scale_resolves_wen_hf_response_and_xue_range(db):
    i_a = db.get_message_by_name("PhaseSamples").get_signal_by_name("i_a")
    lsb = i_a.scale
    I_p, I_n = _hf_currents(50.0, 500.0, 57e-3, 82e-3)
    assert I_p == pytest.approx(0.237, abs=2e-3) and I_n == pytest.approx(0.0426, abs=1e-3)
    assert I_n / lsb > 16  # the negative sequence spans many LSB
    # Quantization noise (uniform, LSB/sqrt(12)) as angle noise on the 2-theta vector, per
    # raw sample: far below the degree-level errors the bench scores.
    angle_noise_deg = math.degrees(lsb / math.sqrt(12) / (2 * I_n))
    assert angle_noise_deg < 0.5
    # xue2022: about 30 A peak; the range leaves room for an over-current trip at 1.5 x.
    assert i_a.minimum <= -45 and i_a.maximum >= 45


def test_duty_resolution_does_not_limit_current_loop(db):
    duty = db.get_message_by_name("PwmDuty").get_signal_by_name("duty_a")
    i_lsb = db.get_message_by_name("PhaseSamples").get_signal_by_name("i_a").scale
    v_lsb = duty.scale * 540.0
    # 15 bits for 0..1 with half the raw range above 1 (out of range, detectable):
    # LSB 2^-14, < 40 mV of phase voltage at 540 V (0.007 %)
    assert v_lsb < 0.04
    # Largest current change one duty LSB makes in a period: xue2022 (L_d 3.53 mH,
    # 1 kHz), about 10 mA: below 5 LSB of i_a, and 0.1 % of the injection's HF current
    di = v_lsb * 1e-3 / 3.53e-3
    assert di < 5 * i_lsb
    assert duty.minimum == 0 and duty.maximum == 1.0


def test_u_dc_range_and_resolution(db):
    u_dc = db.get_message_by_name("PhaseSamples").get_signal_by_name("u_dc")
    assert u_dc.maximum >= 540 * 1.5 and u_dc.scale / 540 < 1e-3
