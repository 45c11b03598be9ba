"""The run's recorder follows the plant's step across counter wraps and retransmissions."""

from __future__ import annotations

import can

from bench.runs._recorder import Recorder
from bench.wire._codec import Codec

CODEC = Codec()


def _samples(step: int) -> can.Message:
    return CODEC.encode(
        "PhaseSamples", {"i_a": 0.0, "i_b": 0.0, "u_dc": 540.0, "step": step, "status": 1}
    )


class _NoFile(can.Listener):
    def on_message_received(self, msg: can.Message) -> None:
        pass


def test_step_unwraps_the_10_bit_counter_and_ignores_old_frames() -> None:
    m = 1 << CODEC.step_bits("PhaseSamples")
    rec = Recorder(CODEC, _NoFile(), 1)
    for k in range(3 * m + 5):  # three full cycles of the counter
        rec.on_message_received(_samples(k % m))
    assert rec.step == 3 * m + 4
    rec.on_message_received(_samples((3 * m - 10) % m))  # a retransmitted old sample
    assert rec.step == 3 * m + 4
    rec.on_message_received(_samples((3 * m + 7) % m))  # two lost frames: counted on
    assert rec.step == 3 * m + 7
    assert len(rec.frames) == 3 * m + 7
