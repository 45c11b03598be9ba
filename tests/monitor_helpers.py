"""A known bench run for the monitor's tests: the frames of period k, encoded by the codec.

The rotor turns at SPEED_RPM (mechanical) with N_P pole pairs; the estimate
lags the true angle by ERR_DEG (electrical) and reads the same speed; the
currents, duties and the plant's counters are constants, so the view's
numbers are known to the digit.
"""

from __future__ import annotations

import math

import can

from bench.wire._codec import Codec

N_P = 4
SPEED_RPM = 150.0
ERR_DEG = 3.0
I_A, I_B = 1.25, -0.5
DUTIES = (0.5, 0.25, 0.75)
OVERRUNS, LATE_FRAMES = 7, 3
LOAD_NM = 1.5
TAU_E_NM = 1.6
#: Simulated PWM period of the known run (s): sets the angle's advance per period.
T_S = 1e-3

W_M = SPEED_RPM * 2.0 * math.pi / 60.0


def theta_e(k: int) -> float:
    return (N_P * W_M * k * T_S) % (2.0 * math.pi)


def period_frames(
    codec: Codec, k: int, *, state: int = 1, fault_code: int = 0, status: bool | None = None
) -> list[can.Message]:
    """The frames of period ``k``: a command and status every 100 periods, then
    samples, truth, telemetry and duties."""
    out = []
    if status if status is not None else k % 100 == 0:
        out.append(
            codec.encode(
                "BenchCommand",
                {
                    "cmd": 1 if k == 0 else 0,
                    "seq": (k // 100) % 16,
                    "step": k,
                    "speed_ref": SPEED_RPM,
                    "load_torque": LOAD_NM,
                },
            )
        )
        out.append(
            codec.encode(
                "PlantStatus",
                {
                    "state": state,
                    "fault_code": fault_code,
                    "overruns": OVERRUNS,
                    "late_frames": LATE_FRAMES,
                    "step": k,
                },
            )
        )
    th = theta_e(k)
    out += [
        codec.encode(
            "PhaseSamples", {"i_a": I_A, "i_b": I_B, "u_dc": 540.0, "status": state, "step": k}
        ),
        codec.encode(
            "PlantTruth",
            {
                "theta_e": th,
                "w_m": W_M,
                "tau_e": TAU_E_NM,
                "tau_L": LOAD_NM,
                "step": k,
                "duty_age": 1,
            },
        ),
        codec.encode(
            "CtrlTelemetry",
            {
                "theta_hat": th - math.radians(ERR_DEG),
                "w_hat": N_P * W_M,
                "err": 0.0,
                "mode": 3,
                "step": k,
            },
        ),
        codec.encode(
            "PwmDuty",
            {"duty_a": DUTIES[0], "duty_b": DUTIES[1], "duty_c": DUTIES[2], "enable": 1, "step": k},
        ),
    ]
    return out


def foreign_frame(arbitration_id: int = 0x123) -> can.Message:
    """A frame of an identifier the bench's DBC does not have."""
    return can.Message(arbitration_id=arbitration_id, data=bytes(8), is_extended_id=False)
