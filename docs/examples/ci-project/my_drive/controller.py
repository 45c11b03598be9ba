"""Our drive's speed controller, put on the bench's bus as the controller under test.

Written from the bench's wire protocol (docs/PROTOCOL.md) and its DBC
(``dbc/bench.dbc``, installed with the bench) with python-can and cantools;
it imports nothing of the bench.  It learns the scenario's motor, PWM period
and position sensor from ``bench show SCENARIO --json``, the documented way::

    python my_drive/controller.py SCENARIO -i socketcan -c vcan0
    python my_drive/controller.py SCENARIO -i udp_multicast -c GROUP -p PORT

What it does on the bus (lockstep, PROTOCOL.md):

- answers each ``PhaseSamples(k)`` with ``PwmDuty(step = k + 1)`` (one period of
  computation delay), once the ``PositionSensor`` reading of period ``k`` is in;
- answers a repeated sample with the duty it sent before (a cache), never by
  computing again;
- keeps ``BenchCommand`` frames by step and ``seq``, applies them before the
  period they name, and acknowledges the newest gap-free ``seq`` in every
  ``CtrlTelemetry`` (sent again when the acknowledgement moves);
- protects every frame with the E2E CRC (CRC-8 SAE J1850 over the data ID,
  low byte first, and bytes 1..n), and sends ``run_id`` 0.

A sensored field-oriented speed controller.  Gains from targets (internal-model
control, as a drive's commissioning sets them): the current PI's bandwidth
``alpha_c`` is a fiftieth of the PWM rate, so the loop's 1.5 periods of delay
cost it 2 pi 1.5 / 50 = 11 degrees of phase margin; ``k_p = alpha_c L``,
``k_i = alpha_c R_s`` cancel the winding's pole.  The speed PI's bandwidth
``alpha_s`` is a twentieth of that, ``k_p = alpha_s J / k_t`` and its integral
corner two octaves below (``k_i = alpha_s k_p / 4``: about 76 degrees of phase
margin).  The speed is the difference of two sensor readings through a
first-order filter at ``10 alpha_s``, which costs the speed loop atan(1/10) =
5.7 degrees at its crossover.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
from importlib.resources import files
from typing import Any

import can

LSB = 2 * math.pi / 65536  # of theta_hat; a theta in the last half LSB below 2 pi is raw 0


def crc8(data: bytes) -> int:
    """CRC-8 SAE J1850: polynomial 0x1D, initial value 0xFF, final XOR 0xFF."""
    reg = 0xFF
    for byte in data:
        reg ^= byte
        for _ in range(8):
            reg = ((reg << 1) ^ 0x1D) & 0xFF if reg & 0x80 else (reg << 1) & 0xFF
    return reg ^ 0xFF


class Wire:
    """The DBC's frames, with the E2E CRC in byte 0."""

    def __init__(self) -> None:
        import cantools  # after the bus is open (main)

        self.db: Any = cantools.database.load_file(str(files("dbc") / "bench.dbc"))

    def _head(self, m: Any) -> bytes:
        did = int(m.dbc.attributes["E2EDataId"].value)
        return bytes((did & 0xFF, did >> 8))

    def encode(self, name: str, sig: dict[str, float]) -> can.Message:
        m = self.db.get_message_by_name(name)
        data = bytearray(m.encode({"crc": 0, **sig}))
        data[0] = crc8(self._head(m) + bytes(data[1:]))
        return can.Message(
            arbitration_id=m.frame_id, data=bytes(data), is_extended_id=False, is_fd=m.length > 8
        )

    def decode(self, msg: can.Message) -> tuple[str, dict[str, float]] | None:
        try:
            m = self.db.get_message_by_frame_id(msg.arbitration_id)
        except KeyError:
            return None
        data = bytes(msg.data)
        if len(data) != m.length or crc8(self._head(m) + data[1:]) != data[0]:
            return None
        return m.name, dict(m.decode(data, decode_choices=False))


def unwrap(raw: int, expected: int, bits: int) -> int:
    """The counter nearest ``expected`` with the low ``bits`` of ``raw``."""
    mod = 1 << bits
    return expected + (raw - expected + mod // 2) % mod - mod // 2


class Foc:
    """Sensored FOC with the gains of the module docstring."""

    def __init__(self, show: dict[str, Any]) -> None:
        mo, ps = show["motor"], show["position_sensor"]
        self.T_s, self.n_p = float(show["pwm"]["T_s"]), int(mo["n_p"])
        self.i_max = float(mo["i_max"])
        a_c = 2 * math.pi / (50.0 * self.T_s)
        a_s = a_c / 20.0
        self.kp = (a_c * float(mo["L_d"]), a_c * float(mo["L_q"]))
        self.ki = a_c * float(mo["R_s"])
        self.kp_w = a_s * float(mo["J"]) / (1.5 * self.n_p * float(mo["psi_f"]))
        self.ki_w = a_s * self.kp_w / 4.0
        self.every, self.delay = int(ps["every"]), float(ps["delay_s"])
        self.half_count = math.pi / int(ps["counts"])  # the encoder floors
        T_r = self.every * self.T_s
        self.a_f, self.T_r = 1.0 - math.exp(-10.0 * a_s * T_r), T_r
        self.reading: tuple[int, float] | None = None
        self.w_m = 0.0
        self.x_d = self.x_q = self.x_w = 0.0
        self.w_ref, self.enabled = 0.0, False

    def read(self, k: int, theta_m: float) -> None:
        if self.reading is not None:
            d = (theta_m - self.reading[1] + math.pi) % (2 * math.pi) - math.pi
            self.w_m += self.a_f * (d / self.T_r - self.w_m)
        self.reading = (k, theta_m)

    def step(self, k: int, i_a: float, i_b: float, u_dc: float) -> tuple[float, tuple[float, ...]]:
        """The angle at sample ``k`` and the duties for period ``k + 1``."""
        k_r, th = self.reading or (k, 0.0)
        theta = self.n_p * (th + self.half_count + self.w_m * (self.delay + (k - k_r) * self.T_s))
        if not self.enabled:
            self.x_d = self.x_q = self.x_w = 0.0
            return theta, (0.5, 0.5, 0.5)
        i_al, i_be = i_a, (i_a + 2 * i_b) / math.sqrt(3)
        c, s = math.cos(theta), math.sin(theta)
        i_d, i_q = c * i_al + s * i_be, -s * i_al + c * i_be
        e_w = self.w_ref - self.w_m
        i_q_ref = max(-self.i_max, min(self.i_max, self.kp_w * e_w + self.x_w))
        self.x_w = max(-self.i_max, min(self.i_max, self.x_w + self.ki_w * self.T_s * e_w))
        e_d, e_q = -i_d, i_q_ref - i_q
        u_d, u_q = self.kp[0] * e_d + self.x_d, self.kp[1] * e_q + self.x_q
        self.x_d += self.ki * self.T_s * e_d
        self.x_q += self.ki * self.T_s * e_q
        th_u = theta + 1.5 * self.n_p * self.w_m * self.T_s  # the middle of period k + 1
        c, s = math.cos(th_u), math.sin(th_u)
        u_al, u_be = c * u_d - s * u_q, s * u_d + c * u_q
        u = (u_al, -0.5 * u_al + 0.5 * math.sqrt(3) * u_be, -0.5 * u_al - 0.5 * math.sqrt(3) * u_be)
        zero = -0.5 * (max(u) + min(u))  # space-vector PWM's zero sequence
        return theta, tuple(min(1.0, max(0.0, 0.5 + (x + zero) / u_dc)) for x in u)


def main() -> int:
    ap = argparse.ArgumentParser(description="our drive's controller on the bench's bus")
    ap.add_argument("scenario", help="the scenario (a name or file, as bench show takes it)")
    ap.add_argument("-i", "--interface", default="socketcan")
    ap.add_argument("-c", "--channel", default="vcan0")
    ap.add_argument("-p", "--port", default="", help="udp_multicast's port (empty: none)")
    a = ap.parse_args()
    # the bus first: the bench sends its start command as soon as its plant is up, and
    # the socket keeps the frames that come while the rest loads (one that joins later
    # still runs the clean run: the samples wait for the start, below)
    bus = can.Bus(
        interface=a.interface,
        channel=a.channel,
        fd=True,
        **({"port": int(a.port)} if a.port else {}),
    )
    bench_show = [sys.executable, "-m", "bench", "show", a.scenario, "--json"]
    show = json.loads(subprocess.run(bench_show, check=True, capture_output=True, text=True).stdout)
    wire, foc = Wire(), Foc(show)
    print(f"my-drive: on {a.interface} {a.channel} {a.port}, T_s {foc.T_s} s", flush=True)
    samples: dict[int, dict[str, float]] = {}
    readings: dict[int, float] = {}
    answers: dict[int, can.Message] = {}
    commands: dict[int, dict[str, float]] = {}
    seen: set[tuple[int, int]] = set()
    ack, ack_step, beyond = -1, -1, {}  # newest gap-free seq, its step; those beyond a gap
    tel: dict[str, float] | None = None
    next_k, stop = 0, False

    def telemetry() -> can.Message:
        assert tel is not None
        return wire.encode(
            "CtrlTelemetry", {**tel, "cmd_ack_valid": int(ack >= 0), "cmd_ack": max(ack, 0)}
        )

    try:
        while not stop:
            msg = bus.recv(30.0)
            if msg is None:
                print(f"my-drive: no frame for 30 s after period {next_k}", flush=True)
                return 1
            frame = wire.decode(msg)
            if frame is None:
                continue
            name, sig = frame
            if name == "BenchCommand":
                step, seq = unwrap(int(sig["step"]), next_k, 16), int(sig["seq"])
                if step > ack_step and (step, seq) not in seen:  # else a copy
                    seen.add((step, seq))
                    commands[step] = sig
                    if (seq - ack - 1) % 16 < 8:
                        beyond[seq] = step
                    moved = False
                    while (ack + 1) % 16 in beyond:
                        ack, ack_step, moved = (ack + 1) % 16, beyond.pop((ack + 1) % 16), True
                    if moved and tel is not None:
                        bus.send(telemetry())
            elif name == "PositionSensor":
                k = unwrap(int(sig["step"]), next_k, 10)
                if k >= next_k:
                    readings[k] = float(sig["theta_m"])
            elif name == "PhaseSamples":
                k = unwrap(int(sig["step"]), next_k, 10)
                if k < next_k:  # a resend: the same answer, and the telemetry as it is now
                    if k in answers:
                        bus.send(answers[k])
                        if tel is not None:
                            bus.send(telemetry())
                    continue
                samples[k] = sig
            # no sample is answered before the start is held: the plant sends sample 0
            # again every 50 ms and the bench its commands, so the first answer is
            # computed with the start however late this joined (PROTOCOL.md)
            while ack >= 0 and next_k in samples and (next_k % foc.every or next_k in readings):
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
                        foc.enabled, stop = False, stop or int(cmd["cmd"]) == 2
                theta, duty = foc.step(k, float(s["i_a"]), float(s["i_b"]), float(s["u_dc"]))
                answers[k] = wire.encode(
                    "PwmDuty",
                    {
                        "duty_a": duty[0],
                        "duty_b": duty[1],
                        "duty_c": duty[2],
                        "enable": int(foc.enabled),
                        "step": (k + 1) % 1024,
                    },
                )
                answers.pop(k - 16, None)  # PROTOCOL.md: keep the last 16 answers
                tel = {
                    "theta_hat": round(theta / LSB) % 65536 * LSB,  # on the raw grid
                    "w_hat": foc.n_p * foc.w_m,
                    "err": 0.0,
                    "mode": 3 if foc.enabled else 0,
                    "step": k,
                    "run_id": 0,
                }
                bus.send(answers[k])
                bus.send(telemetry())
                next_k = k + 1
    finally:
        bus.shutdown()
    print(f"my-drive: {next_k} periods", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
