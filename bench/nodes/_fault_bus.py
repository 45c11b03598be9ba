"""A scenario's fault timeline at the plant node: the plant's faults and the bus's.

The plant node (:class:`bench.nodes._plant_node.PlantNode`) is in every run
(in-process, two processes, an external controller), so the faults applied
here reach the bench's controller, a plug-in and an external controller
alike.  The machine and sensor faults are :class:`plant_rt._faults.PlantFaults`
(pure); the bus faults act on the node's frames:

- ``drop`` / ``corrupt`` of ``PwmDuty``: the duty for period ``t`` is lost
  when ``t`` lies in the window (``drop``: with probability ``prob``, drawn
  from a stream seeded by the scenario's seed, the fault's index and ``t``,
  so every resend of that duty meets the same fate).  A lockstep plant does
  not wait for a lost duty: it runs the period with the last duty it applied,
  counts it late, and trips its watchdog after the real-time number of
  periods without a duty, as a real-time plant would.
- ``drop`` of ``PhaseSamples`` / ``PositionSensor`` and ``silence``: the
  plant's sending of instant ``k`` is lost when ``k`` lies in the window (with
  probability ``prob``, drawn as for a duty, from ``k``). Real time: the frame
  is gone and the controller skips to the next sample it gets.  Lockstep,
  under its retransmission rules (a lockstep controller computes its samples
  in order): a lost ``PhaseSamples`` is kept and sent again, in order before
  the new one, with the first sending of a later instant that gets through;
  the controller never answers the lost sample in its period (its duty, come
  late, is counted lost: :meth:`NodeFaults.answer_lost`), so the plant runs that
  period with the last duty it applied, counts it late and trips its watchdog
  after the real-time number of periods, as a real-time plant would.  A lost
  ``PositionSensor`` is not sent again (as ``position_sensor_lost``: a sensor
  reading is of its instant only).
- ``delay`` of ``PwmDuty``: lockstep applies in period ``k`` the duty of
  ``k - steps``; real time holds each duty frame ``us`` microseconds from its
  arrival (:meth:`NodeFaults.held_until`) and a period takes the newest duty
  released by its start, so a delay below a period moves a duty to the next
  period only when it arrives within ``us`` of that period's start.
- ``babble``: a foreign ``PwmDuty`` (to the plant) and ``PhaseSamples`` (to
  the controller) with random payloads every ``round(f_sw / rate_hz)`` periods.
"""

from __future__ import annotations

import math
import random
from collections.abc import Sequence

import can

from bench.scenarios._faults import Fault
from bench.wire._codec import Codec
from plant_rt import Plant
from plant_rt._faults import FaultWindow, PlantFaults

#: Applied duties kept for a lockstep ``delay`` (at least the step counters' bound).
_HISTORY = 512


class NodeFaults:
    """The fault timeline of one plant node.

    Parameters
    ----------
    faults : sequence of Fault
        The scenario's timeline.
    plant : Plant
    seed : int
        The scenario's seed.
    """

    def __init__(self, faults: Sequence[Fault], plant: Plant, seed: int) -> None:
        T = plant.T_s
        self.T_s = T
        self.seed = seed
        self.windows: list[tuple[Fault, FaultWindow]] = []
        for f in faults:
            k0, k1 = f.periods(T)
            self.windows.append((f, FaultWindow(f.kind, k0, k1, dict(f.params))))
        self.plant = PlantFaults(plant, [w for _, w in self.windows])
        #: PwmDuty frames lost to a fault (drop, silence; corrupt counts as bad_crc).
        self.duties_lost = 0
        #: Frames the plant did not send because of a fault, by message.
        self.not_sent: dict[str, int] = {}
        self.babbled = 0
        self.history: dict[int, tuple[float, float, float, bool]] = {}

    def _bus(self, *kinds: str) -> list[tuple[Fault, FaultWindow]]:
        return [(f, w) for f, w in self.windows if f.kind in kinds]

    def duty_fate(self, t: int) -> str | None:
        """What happens to the duty for period ``t``: ``"lost"``, ``"corrupt"`` or None."""
        for f, w in self.windows:
            if not w.active(t):
                continue
            if f.kind == "silence" or (f.kind == "drop" and f.params["message"] == "PwmDuty"):
                p = float(f.params.get("prob", 1.0))
                if p >= 1.0 or random.Random(f"bench-fault/{self.seed}/{f.index}/{t}").random() < p:
                    return "lost"
            elif f.kind == "corrupt" and f.params["message"] == "PwmDuty":
                return "corrupt"
        return None

    def duty_shift(self, k: int, *, realtime: bool = False) -> int:
        """Periods a ``delay`` fault adds to the duty of period ``k``: ``steps`` in lockstep
        (``us`` rounded up to whole periods when only it is given); in real time ``steps``
        of a fault without ``us`` (one with ``us`` holds the frame: :meth:`duty_hold_s`)."""
        n = 0
        for f, w in self._bus("delay"):
            if not w.active(k):
                continue
            if realtime:
                n += 0 if "us" in f.params else int(f.params["steps"])
            elif "steps" not in f.params:
                n += math.ceil(float(f.params["us"]) * 1e-6 / self.T_s - 1e-9)
            else:
                n += int(f.params["steps"])
        return n

    def duty_hold_s(self, k: int) -> float:
        """Real time: how long (s) a duty frame that arrives in period ``k`` is held from its
        arrival before the plant may apply it (the ``us`` of the active ``delay`` faults)."""
        return sum(
            float(f.params["us"]) * 1e-6
            for f, w in self._bus("delay")
            if w.active(k) and "us" in f.params
        )

    def keep(self, t: int, duty: tuple[float, float, float, bool]) -> None:
        """Remember duty ``t`` for a lockstep ``delay``."""
        if self._bus("delay"):
            self.history[t] = duty
            self.history.pop(t - _HISTORY, None)

    def delayed(
        self, k: int, t: int, duty: tuple[float, float, float, bool]
    ) -> tuple[float, float, float, bool]:
        """Lockstep: the duty period ``k`` applies instead of ``duty`` (tag ``t``)."""
        n = self.duty_shift(k)
        if n == 0:
            return duty
        older = [s for s in self.history if s <= t - n]
        return self.history[max(older)] if older else (0.5, 0.5, 0.5, False)

    def lost(self, message: str, k: int) -> bool:
        """Whether the plant's sending of ``message`` at instant ``k`` is lost (position
        sensor, drops, silence); a pure function of ``k``."""
        for f, w in self.windows:
            if not w.active(k):
                continue
            lost = (
                f.kind == "silence"
                or (f.kind == "position_sensor_lost" and message == "PositionSensor")
                or (f.kind == "drop" and f.params["message"] == message)
            )
            if lost:
                p = float(f.params.get("prob", 1.0))
                if p >= 1.0 or random.Random(f"bench-fault/{self.seed}/{f.index}/{k}").random() < p:
                    return True
        return False

    def sends(self, message: str, k: int) -> bool:
        """Whether the plant sends ``message`` of instant ``k``; counts the frames not sent."""
        if self.lost(message, k):
            self.not_sent[message] = self.not_sent.get(message, 0) + 1
            return False
        return True

    def answer_lost(self, t: int) -> bool:
        """Lockstep: whether the duty tagged ``t`` (the answer to sample ``t - 1``) is lost
        because that sample's first sending was (module docstring)."""
        return t >= 1 and self.lost("PhaseSamples", t - 1)

    def babble(self, k: int, codec: Codec) -> tuple[can.Message | None, can.Message | None]:
        """Foreign frames of instant ``k``: (a PwmDuty for the plant, a PhaseSamples for the
        controller), or Nones."""
        for f, w in self._bus("babble"):
            every = max(1, round(1.0 / (float(f.params["rate_hz"]) * self.T_s)))
            if w.active(k) and (k - w.k0) % every == 0:
                rng = random.Random(f"bench-fault/{self.seed}/{f.index}/{k}")
                self.babbled += 2
                duty, smp = codec.message("PwmDuty"), codec.message("PhaseSamples")
                return (
                    can.Message(
                        arbitration_id=duty.frame_id,
                        data=rng.randbytes(duty.length),
                        is_extended_id=False,
                    ),
                    can.Message(
                        arbitration_id=smp.frame_id,
                        data=rng.randbytes(smp.length),
                        is_extended_id=False,
                    ),
                )
        return None, None

    def report(self) -> dict[str, object]:
        return {
            "duties_lost": self.duties_lost,
            "not_sent": dict(self.not_sent),
            "babbled": self.babbled,
        }
