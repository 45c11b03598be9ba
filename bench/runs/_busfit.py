"""Does a run's PWM rate fit its bus?  The bus load of the run's frames (issue 29, item 5).

vcan and udp_multicast have no bit rate; a real bus has one, given by
``--bitrate``/``--data-bitrate``, python-can's configuration (``bitrate``,
``data_bitrate``), or for a SocketCAN device what ``ip link`` has set.  With
a bit rate, a real-time run's frames per PWM period at the scenario's rate
(:func:`run_frames`) must fit the bus: the load is
:func:`bench.wire._busload.rate_fit`'s (the figures of ``bench busload``,
worst-case bit stuffing, low-rate frames included).  Above 100 % the run is
refused with one line naming the highest rate that fits; above
:data:`~bench.wire._busload.PRACTICAL_LOAD` (80 %) it warns.

A lockstep run is not real time: its periods go as fast as the bus carries
them, so an overfull bus only makes it slower than the scenario's time; it
gets one line saying how much slower, never a refusal.
"""

from __future__ import annotations

from bench._errors import BenchError
from bench.scenarios._schema import Scenario
from bench.scenarios._setup import plant_setup, sample_period, with_position_sensor
from bench.wire._bus import BusSpec
from bench.wire._busload import PRACTICAL_LOAD, bus_of, link_bitrates, rate_fit
from bench.wire._codec import Codec

__all__ = ["bus_rates", "check_bus_rate", "run_frames"]


def run_frames(scn: Scenario, *, external: bool) -> dict[str, float]:
    """Frames per PWM period of a ``bench run`` of ``scn`` (message name to count).

    Every period: ``PwmDuty``, ``PhaseSamples``, ``PlantTruth`` (the recorder's,
    every period in a run; with ``PlantCurrents`` when the scenario has a
    ``[[faults]]`` timeline) and the bench controller's ``CtrlTelemetry``; a
    controller under test's telemetry is its own choice and is not counted.
    ``PositionSensor`` every ``encoder_every`` periods when the plant has a
    position sensor (always for a controller under test).
    """
    frames = {"PwmDuty": 1.0, "PhaseSamples": 1.0, "PlantTruth": 1.0}
    if scn.faults:
        frames["PlantCurrents"] = 1.0
    if not external:
        frames["CtrlTelemetry"] = 1.0
    sensors = plant_setup(with_position_sensor(scn) if external else scn)[1].sensors
    if sensors.encoder_counts > 0:
        frames["PositionSensor"] = 1.0 / sensors.encoder_every(sample_period(scn))
    return frames


def bus_rates(spec: BusSpec) -> tuple[int, int | None, str] | None:
    """The bus's bit rates and where they come from, or None (no bit rate known)."""
    if spec.bitrate:
        return spec.bitrate, spec.data_bitrate, "--bitrate"
    if spec.interface == "socketcan" and (rates := link_bitrates(spec.channel)) is not None:
        return rates[0], rates[1], f"ip link {spec.channel}"
    return None


def check_bus_rate(
    scn: Scenario, spec: BusSpec, *, mode: str, external: bool, codec: Codec | None = None
) -> str | None:
    """Refuse a real-time run its bus cannot carry (:class:`BenchError`); a warning line or None.

    None also when the bus has no bit rate (vcan, udp_multicast, an adapter
    given none).
    """
    rates = bus_rates(spec)
    if rates is None:
        return None
    bitrate, data_bitrate, source = rates
    codec = codec or Codec()
    frames = run_frames(scn, external=external)
    f_sw = 1.0 / sample_period(scn)
    fit = rate_fit(codec, frames, bus_of(bitrate, data_bitrate), f_sw)
    where = f"{spec.describe()} ({fit.bus.name}, {source})"
    load = f"{100 * fit.load:.0f} % of {where}"
    if mode != "realtime":
        if fit.load <= 1.0:
            return None
        return (
            f"bus: lockstep at {f_sw / 1e3:g} kHz needs {load}: the bus carries at most "
            f"{fit.max_rate_hz / 1e3:.2f} kHz of periods, so the run takes at least "
            f"{f_sw / fit.max_rate_hz:.1f} times the scenario's time"
        )
    if fit.load > 1.0:
        raise BenchError(
            f"scenario {scn.name}: {f_sw / 1e3:g} kHz real time needs {load}; the highest "
            f"PWM rate that fits is {fit.max_rate_hz / 1e3:.2f} kHz "
            f"({fit.max_rate_hz_practical / 1e3:.2f} kHz at {100 * PRACTICAL_LOAD:.0f} %)"
        )
    if fit.load > PRACTICAL_LOAD:
        return (
            f"warning: bus: {f_sw / 1e3:g} kHz real time needs {load}, above "
            f"{100 * PRACTICAL_LOAD:.0f} % (late frames of lower priority); "
            f"{fit.max_rate_hz_practical / 1e3:.2f} kHz stays below it"
        )
    return None
