"""A drive controller written from docs/PROTOCOL.md and the DBC alone, as a user would.

It imports nothing from the bench (``bench``, ``controller``, ``plant_rt``):
python-can for the bus, cantools for the DBC, and the scenario's motor and
PWM rate from ``bench show SCENARIO --json`` (a file given with ``--show``).
It is the controller under test of ``tests/test_external_controller.py``::

    python tests/ext_controller.py --show show.json -i udp_multicast -c GROUP -p PORT

A sensored field-oriented speed controller.  Its rotor angle is the encoder's,
``PositionSensor`` (DBC 2.2; docs/PROTOCOL.md, "Sensored controllers"), with
the sensor's counts, spacing and delay from ``bench show``'s
``position_sensor``; it never reads ``PlantTruth`` (the recorder's frame) and
so sends ``run_id`` 0.  The angle at sample ``k`` is the reading's count plus
half a count (the encoder floors) advanced by the estimated speed over the
reading's age (its delay and the periods since it).  Gains by design
(internal-model control, as a drive's commissioning would set them):

- current PI: bandwidth ``alpha_c``; ``k_p = alpha_c L``, ``k_i = alpha_c R_s``
  cancels the winding's pole, closed loop ``alpha_c / (s + alpha_c)``; a fiftieth
  of the PWM rate (2 pi 200 Hz at 10 kHz), so the loop's delay (1.5 periods:
  computation and PWM) costs 2 pi 1.5 / 50 = 0.19 rad (11 degrees) of phase margin;
- speed PI: bandwidth ``alpha_s``, a twentieth of ``alpha_c``;
  ``k_p = alpha_s J / k_t``, ``k_i = alpha_s k_p / 4`` (integral corner
  two octaves below the crossover: about 76 degrees of phase margin);
- speed from the angle (:class:`SpeedFromAngle`): the difference of two
  readings over their spacing ``T_r``, through a first-order filter of
  bandwidth ``w_f = 10 alpha_s``.  Target: the filter costs the speed loop at
  most 6 degrees of phase at its crossover ``alpha_s`` (``atan(1/10)`` = 5.7
  degrees, plus ``alpha_s T_r / 2`` for the difference's half-reading delay,
  0.2 degrees at 10 kHz).  Its price is the encoder's quantisation noise: a
  reading's error ``e`` (uniform over one count ``q = 2 pi / counts``) reaches
  the estimate through ``(a / T_r) (1 - z^-1) / (1 - (1 - a) z^-1)`` with
  ``a = 1 - exp(-w_f T_r)``, whose squared impulse response sums to
  ``2 / (2 - a)``: rms ``(q / sqrt 12) (a / T_r) sqrt(2 / (2 - a))`` and at
  most ``q a / T_r`` (about ``q w_f``).  At 65536 counts and 10 kHz
  (``w_f`` = 2 pi 100 Hz): 0.017 rad/s rms, at most 0.058 rad/s (0.56 rpm);
  a 4096-count encoder gives sixteen times that.

``--mistake`` makes it commit one of the errors docs/PROTOCOL.md warns
about: ``crc-no-id`` (the E2E CRC without the data ID), ``step-k`` (the duty
of sample k sent with step k, no one-period delay), ``out-of-range`` (duty
1.2 sent without clipping), ``every-other`` (only even samples answered).

Command acknowledgement (DBC 2.2, docs/PROTOCOL.md "Commands"): it reports
in ``CtrlTelemetry.cmd_ack`` the seq of the newest ``BenchCommand`` it holds
with every earlier one (seq counts commands from 0, the start), and sends its
newest telemetry again when that moves.  ``--protocol 2.1`` sends 0 there, as a
controller written to 2.1 does.  ``--drop P`` throws away a share ``P`` of the
``BenchCommand``, ``PhaseSamples`` and ``PositionSensor`` frames it receives, at random
(``--seed``), as an overflowing receive buffer does.

It answers no sample before it holds the start (docs/PROTOCOL.md, "Bench
commands and pacing"): the plant sends sample 0 again every 50 ms and the bench
its commands, so its first answer is computed with the start however late it
joined the bus.  ``--deaf-samples N`` throws away every frame until it has
seen ``N`` ``PhaseSamples``: a controller that opened its bus after the start,
its first copies and the first sample.  ``--protocol 2.1`` answers from the
first sample, as a controller written to 2.1 may.
"""

from __future__ import annotations

import argparse
import json
import math
import random
import sys
from pathlib import Path
from typing import Any

import can
import cantools

DBC = Path(__file__).resolve().parents[1] / "dbc" / "bench.dbc"
MISTAKES = ("crc-no-id", "step-k", "out-of-range", "every-other")


def crc8_j1850(data: bytes, reg: int = 0xFF) -> int:
    """CRC-8 SAE J1850 (poly 0x1D, init 0xFF, xorout 0xFF), bit by bit as the DBC states it."""
    for byte in data:
        reg ^= byte
        for _ in range(8):
            reg = ((reg << 1) ^ 0x1D) & 0xFF if reg & 0x80 else (reg << 1) & 0xFF
    return reg ^ 0xFF


class Wire:
    """The DBC's frames: cantools packs them, the E2E CRC is added as the DBC comment says."""

    def __init__(self, mistake: str | None) -> None:
        self.db: Any = cantools.database.load_file(str(DBC))
        self.mistake = mistake

    def data_id(self, name: str) -> int:
        return int(self.db.get_message_by_name(name).dbc.attributes["E2EDataId"].value)

    def has_crc(self, name: str) -> bool:
        return any(s.name == "crc" for s in self.db.get_message_by_name(name).signals)

    def crc(self, name: str, payload: bytes) -> int:
        did = self.data_id(name)
        head = b"" if self.mistake == "crc-no-id" else bytes((did & 0xFF, did >> 8))
        return crc8_j1850(head + payload[1:])

    def encode(self, name: str, sig: dict[str, float], strict: bool = True) -> can.Message:
        m = self.db.get_message_by_name(name)
        data = bytearray(m.encode({"crc": 0, **sig} if self.has_crc(name) else sig, strict=strict))
        if self.has_crc(name):  # every frame since DBC 2.1: crc in byte 0
            data[0] = self.crc(name, bytes(data))
        return can.Message(
            arbitration_id=m.frame_id, data=bytes(data), is_extended_id=False, is_fd=m.length > 8
        )

    def decode(self, msg: can.Message) -> tuple[str, dict[str, float]] | None:
        """The message's name and signals; None for a frame to ignore (unknown, bad CRC)."""
        try:
            m = self.db.get_message_by_frame_id(msg.arbitration_id)
        except KeyError:
            return None
        data = bytes(msg.data)
        if len(data) != m.length:
            return None
        if any(s.name == "crc" for s in m.signals):
            did = self.data_id(m.name)
            if crc8_j1850(bytes((did & 0xFF, did >> 8)) + data[1:]) != data[0]:
                return None
        return m.name, dict(m.decode(data, decode_choices=False))


def unwrap(raw: int, expected: int, bits: int) -> int:
    mod = 1 << bits
    d = (raw - expected + mod // 2) % mod - mod // 2
    return expected + d


class SpeedFromAngle:
    """Mechanical speed from successive sensor readings (the module docstring's design)."""

    def __init__(self, w_f: float, T_r: float) -> None:
        self.T_r = T_r
        self.a = 1.0 - math.exp(-w_f * T_r)
        self.prev: float | None = None
        self.w = 0.0

    def quantisation_noise(self, counts: int) -> tuple[float, float]:
        """Speed error (rad/s) from an encoder of ``counts``: (rms, largest), the module docstring's."""
        q, a = 2 * math.pi / counts, self.a
        return q / math.sqrt(12) * a / self.T_r * math.sqrt(2 / (2 - a)), q * a / self.T_r

    def update(self, theta_m: float) -> float:
        """Take the next reading (rad, mechanical); returns the speed estimate (rad/s)."""
        if self.prev is not None:
            d = (theta_m - self.prev + math.pi) % (2 * math.pi) - math.pi
            self.w += self.a * (d / self.T_r - self.w)
        self.prev = theta_m
        return self.w


class Foc:
    """Sensored FOC with the gains of the module docstring."""

    def __init__(self, show: dict[str, Any]) -> None:
        mo = show["motor"]
        self.T_s = float(show["pwm"]["T_s"])
        self.n_p = int(mo["n_p"])
        self.R_s, self.L_d, self.L_q = float(mo["R_s"]), float(mo["L_d"]), float(mo["L_q"])
        self.k_t = 1.5 * self.n_p * float(mo["psi_f"])
        self.i_max = float(mo["i_max"])
        a_c = 2 * math.pi / (50.0 * self.T_s)
        a_s = a_c / 20.0
        self.kp_d, self.ki_d = a_c * self.L_d, a_c * self.R_s
        self.kp_q, self.ki_q = a_c * self.L_q, a_c * self.R_s
        self.kp_w = a_s * float(mo["J"]) / self.k_t
        self.ki_w = a_s * self.kp_w / 4.0
        ps = show["position_sensor"]
        self.sensor_every = int(ps["every"])
        self.sensor_delay = float(ps["delay_s"])
        self.half_count = math.pi / int(ps["counts"])  # the encoder floors: add half a count
        self.speed = SpeedFromAngle(10.0 * a_s, self.sensor_every * self.T_s)
        self.reading: tuple[int, float] | None = None  # (step, theta_m) of the newest reading
        self.x_d = self.x_q = self.x_w = 0.0
        self.w_ref = 0.0  # mechanical rad/s
        self.enabled = False

    def read(self, k: int, theta_m: float) -> None:
        """A ``PositionSensor`` reading of sample ``k``."""
        self.speed.update(theta_m)
        self.reading = (k, theta_m)

    def angle(self, k: int) -> tuple[float, float]:
        """Electrical angle at sample ``k`` and mechanical speed, from the newest reading."""
        if self.reading is None:
            return 0.0, 0.0
        k_r, th = self.reading
        w_m = self.speed.w
        th_m = th + self.half_count + w_m * (self.sensor_delay + (k - k_r) * self.T_s)
        return (self.n_p * th_m) % (2 * math.pi), w_m

    def step(
        self, i_a: float, i_b: float, u_dc: float, theta: float, w_m: float
    ) -> tuple[float, float, float]:
        if not self.enabled:
            self.x_d = self.x_q = self.x_w = 0.0
            return 0.5, 0.5, 0.5
        i_al = i_a
        i_be = (i_a + 2 * i_b) / math.sqrt(3)
        c, s = math.cos(theta), math.sin(theta)
        i_d, i_q = c * i_al + s * i_be, -s * i_al + c * i_be
        e_w = self.w_ref - w_m
        i_q_ref = max(-self.i_max, min(self.i_max, self.kp_w * e_w + self.x_w))
        self.x_w += self.ki_w * self.T_s * e_w
        self.x_w = max(-self.i_max, min(self.i_max, self.x_w))
        e_d, e_q = -i_d, i_q_ref - i_q
        u_d = self.kp_d * e_d + self.x_d
        u_q = self.kp_q * e_q + self.x_q
        self.x_d += self.ki_d * self.T_s * e_d
        self.x_q += self.ki_q * self.T_s * e_q
        # applied in period k + 1: rotate by the angle the rotor turns until its middle
        th = theta + 1.5 * self.n_p * w_m * self.T_s
        c, s = math.cos(th), math.sin(th)
        u_al, u_be = c * u_d - s * u_q, s * u_d + c * u_q
        u = (u_al, -0.5 * u_al + math.sqrt(3) / 2 * u_be, -0.5 * u_al - math.sqrt(3) / 2 * u_be)
        zero = -0.5 * (max(u) + min(u))  # min-max zero sequence (space-vector PWM)
        return tuple(0.5 + (x + zero) / u_dc for x in u)  # type: ignore[return-value]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--show", required=True, help="bench show SCENARIO --json output")
    ap.add_argument("-i", "--interface", default="udp_multicast")
    ap.add_argument("-c", "--channel", required=True)
    ap.add_argument("-p", "--port", type=int)
    ap.add_argument("--mistake", choices=MISTAKES)
    ap.add_argument("--idle-s", type=float, default=60.0)
    ap.add_argument("--protocol", choices=("2.1", "2.2"), default="2.2")
    ap.add_argument("--drop", type=float, default=0.0, help="share of frames thrown away")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument(
        "--deaf-samples", type=int, default=0, help="frames thrown away until N samples seen"
    )
    a = ap.parse_args()
    rng = random.Random(a.seed)
    dropped = 0
    show = json.loads(Path(a.show).read_text())
    wire = Wire(a.mistake)
    foc = Foc(show)
    kw = {"port": a.port} if a.port else {}
    bus = can.Bus(interface=a.interface, channel=a.channel, fd=True, **kw)
    samples: dict[int, dict[str, float]] = {}
    readings: dict[int, float] = {}  # PositionSensor.theta_m by step
    answers: dict[int, list[can.Message]] = {}
    commands: dict[int, dict[str, float]] = {}
    seen_cmds: set[tuple[int, int]] = set()
    # seq of the newest command held with no gap (-1: none), its step, and the ones beyond a gap
    ack, ack_step = -1, -1
    beyond: dict[int, int] = {}
    last_tel: dict[str, float] | None = None

    def telemetry(sig: dict[str, float]) -> can.Message:
        rep = a.protocol == "2.2" and ack >= 0
        return wire.encode(
            "CtrlTelemetry", {**sig, "cmd_ack_valid": int(rep), "cmd_ack": ack if rep else 0}
        )

    next_k = 0
    stop = False
    deaf = a.deaf_samples
    print("READY", flush=True)
    try:
        while not stop:
            msg = bus.recv(a.idle_s)
            if msg is None:
                print("ext_controller: no frame, giving up", file=sys.stderr)
                return 1
            d = wire.decode(msg)
            if d is None:
                continue
            name, sig = d
            if deaf > 0:  # not on the bus yet
                deaf -= 1 if name == "PhaseSamples" else 0
                continue
            if (
                name in ("BenchCommand", "PhaseSamples", "PositionSensor")
                and a.drop
                and rng.random() < a.drop
            ):
                dropped += 1
                continue
            if name == "BenchCommand":
                step = unwrap(int(sig["step"]), next_k, 16)
                seq = int(sig["seq"])
                # a step at or before the gap-free run's is a copy of a command held
                if step > ack_step and (step, seq) not in seen_cmds:
                    seen_cmds.add((step, seq))
                    commands[step] = sig
                    if (seq - ack - 1) % 16 < 8:  # not older than the gap-free run
                        beyond[seq] = step
                    moved = False
                    while (ack + 1) % 16 in beyond:
                        ack_step = beyond.pop((ack + 1) % 16)
                        ack = (ack + 1) % 16
                        moved = True
                    if moved and last_tel is not None:
                        bus.send(telemetry(last_tel))  # the acknowledgement moved: say so now
            elif name == "PhaseSamples":
                k = unwrap(int(sig["step"]), next_k, 10)
                if k < next_k:  # a resend (lockstep): the same duty again
                    cached = answers.get(k, [])
                    for m in cached[:1]:
                        bus.send(m)
                    if cached and k == next_k - 1 and last_tel is not None:
                        bus.send(telemetry(last_tel))  # with the acknowledgement held now
                    continue
                samples[k] = sig
            elif name == "PositionSensor":
                k = unwrap(int(sig["step"]), next_k, 10)
                if k >= next_k:
                    readings[k] = float(sig["theta_m"])
            else:
                continue
            # sample k, and its reading when the sensor reads in period k; none before
            # the start is held (2.2), else the first answer would be computed without it
            while (
                (ack >= 0 or a.protocol == "2.1")
                and next_k in samples
                and (next_k % foc.sensor_every or next_k in readings)
            ):
                k = next_k
                s = samples.pop(k)
                if k in readings:
                    foc.read(k, readings.pop(k))
                for c in sorted(st for st in commands if st <= k):
                    cmd = commands.pop(c)
                    foc.w_ref = float(cmd["speed_ref"]) * math.pi / 30.0
                    if int(cmd["cmd"]) in (1, 3, 4):  # start, reset, enable
                        foc.enabled = True
                    elif int(cmd["cmd"]) in (2, 5):  # stop, disable
                        foc.enabled = False
                        stop = stop or int(cmd["cmd"]) == 2
                theta, w_m = foc.angle(k)
                duty = foc.step(float(s["i_a"]), float(s["i_b"]), float(s["u_dc"]), theta, w_m)
                if a.mistake == "out-of-range":
                    duty = (1.2, duty[1], duty[2])
                else:
                    duty = tuple(min(1.0, max(0.0, x)) for x in duty)  # type: ignore[assignment]
                out = [
                    wire.encode(
                        "PwmDuty",
                        {
                            "duty_a": duty[0],
                            "duty_b": duty[1],
                            "duty_c": duty[2],
                            "enable": int(foc.enabled),
                            "step": (k if a.mistake == "step-k" else k + 1) % 1024,
                        },
                        strict=a.mistake != "out-of-range",
                    ),
                ]
                last_tel = {
                    "theta_hat": theta,
                    "w_hat": foc.n_p * w_m,
                    "err": 0.0,
                    "mode": 3 if foc.enabled else 0,
                    "step": k,
                    # DBC 2.1: the run's nonce is in PlantTruth, which a controller
                    # does not read: 0 (unknown)
                    "run_id": 0,
                }
                out.append(telemetry(last_tel))
                if a.mistake == "every-other" and k % 2:
                    out = []
                answers[k] = out
                answers.pop(k - 64, None)
                for m in out:
                    bus.send(m)
                next_k = k + 1
    finally:
        bus.shutdown()
    print(f"ext_controller: {next_k} periods, {dropped} frames dropped", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
