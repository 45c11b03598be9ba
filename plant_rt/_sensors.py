"""Current and DC-link voltage sensing: gain, offset, noise and ADC quantisation;
and the rotor-position sensor of a sensored drive (:func:`encoder_angle`).

Each measured value is ``quantise(gain * x + offset + noise)``. Noise is
white and Gaussian, drawn from one ``random.Random(seed)`` stream in a fixed
order (i_a, i_b, i_c, u_dc), so a run is reproducible from its seed.

``x`` is the true value at the sample instant ``k T_s`` or, with a sensor
delay ``t_delay``, at ``k T_s - t_delay`` (the plant records the state at
that instant while it integrates the previous period).
"""

from __future__ import annotations

import math
import random
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from plant_rt._engine import _cplant


@dataclass(frozen=True, slots=True)
class SensorPars:
    """Sensor and ADC errors. The defaults give ideal sensing.

    Parameters
    ----------
    bits : int or None
        ADC resolution (bits); None disables quantisation.
    i_fs : float
        Current full scale (A): the bipolar ADC spans [-i_fs, i_fs) with a
        step of ``2 i_fs / 2**bits`` and saturates at its end codes.
    u_fs : float
        DC-link voltage full scale (V): the unipolar ADC spans [0, u_fs)
        with a step of ``u_fs / 2**bits``.
    gain_abc : tuple of float
        Gain of the phase-current sensors a, b, c (-).
    offset_abc : tuple of float
        Offset of the phase-current sensors (A).
    gain_u_dc : float
        Gain of the DC-link voltage sensor (-).
    offset_u_dc : float
        Offset of the DC-link voltage sensor (V).
    noise_i : float
        Standard deviation of the current noise (A).
    noise_u : float
        Standard deviation of the voltage noise (V).
    seed : int
        Seed of the noise generator.
    t_delay : float
        Sensor delay (s), in [0, T_s): the sample taken at ``k T_s`` carries
        the currents and the DC-link voltage of ``k T_s - t_delay`` (the
        group delay of an anti-aliasing filter or of the sensor). The plant
        checks it against its period.
    encoder_counts : int
        Position sensor (encoder or resolver-to-digital converter) of a
        sensored drive: counts per mechanical revolution, at most 65536
        (the ``PositionSensor`` frame's 16 bits); 0: no position sensor.
    encoder_rate_hz : float
        Readings per second (the sensor interface's update rate); 0: one per
        PWM period. See :meth:`encoder_every`.
    encoder_delay_s : float
        Age of a reading (s): the angle read at ``t`` is the shaft's at
        ``t - encoder_delay_s`` (transmission and conversion of the sensor).

    Notes
    -----
    The keys of a scenario's ``[sensors]`` table map onto these fields
    through :meth:`from_keys` (``adc_bits`` -> ``bits``,
    ``current_full_scale_a`` -> ``i_fs``, ``current_offset_a`` ->
    ``offset_abc``, ``current_gain_error`` -> ``gain_abc - 1``,
    ``current_noise_a`` -> ``noise_i``, ``sample_delay_s`` -> ``t_delay``);
    the properties of the same names read them back.
    """

    bits: int | None = None
    i_fs: float = 50.0
    u_fs: float = 1000.0
    gain_abc: tuple[float, float, float] = (1.0, 1.0, 1.0)
    offset_abc: tuple[float, float, float] = (0.0, 0.0, 0.0)
    gain_u_dc: float = 1.0
    offset_u_dc: float = 0.0
    noise_i: float = 0.0
    noise_u: float = 0.0
    seed: int = 0
    t_delay: float = 0.0
    encoder_counts: int = 0
    encoder_rate_hz: float = 0.0
    encoder_delay_s: float = 0.0

    def __post_init__(self) -> None:
        if not 0 <= self.encoder_counts <= 1 << 16:
            raise ValueError(
                f"SensorPars.encoder_counts must be in 0..65536, got {self.encoder_counts}"
            )
        if not (self.encoder_rate_hz >= 0.0 and self.encoder_delay_s >= 0.0):
            raise ValueError("SensorPars.encoder_rate_hz and encoder_delay_s must be >= 0")
        if self.bits is not None and not 1 <= self.bits <= 32:
            raise ValueError(f"SensorPars.bits must be in 1..32 or None, got {self.bits}")
        if not (self.i_fs > 0.0 and self.u_fs > 0.0):
            raise ValueError("SensorPars.i_fs and SensorPars.u_fs must be > 0")
        if self.noise_i < 0.0 or self.noise_u < 0.0:
            raise ValueError("SensorPars.noise_i and SensorPars.noise_u must be >= 0")
        if len(self.gain_abc) != 3 or len(self.offset_abc) != 3:
            raise ValueError("SensorPars.gain_abc and SensorPars.offset_abc need three values")
        if not (self.t_delay >= 0.0 and math.isfinite(self.t_delay)):
            raise ValueError(f"SensorPars.t_delay must be finite and >= 0, got {self.t_delay}")

    @classmethod
    def from_keys(
        cls,
        *,
        adc_bits: int | None = None,
        current_full_scale_a: float = 50.0,
        current_offset_a: float | Sequence[float] = 0.0,
        current_gain_error: float | Sequence[float] = 0.0,
        current_noise_a: float = 0.0,
        sample_delay_s: float = 0.0,
        seed: int = 0,
        encoder_counts: int = 0,
        encoder_rate_hz: float = 0.0,
        encoder_delay_s: float = 0.0,
    ) -> SensorPars:
        """Sensor errors from the keys of a scenario's ``[sensors]`` table.

        Parameters
        ----------
        adc_bits : int or None
            ADC resolution (bits); None or 0: no quantisation.
        current_full_scale_a : float
            Current full scale (A), see ``i_fs``.
        current_offset_a : float or sequence of three floats
            Offset of each current sensor (A); one value applies to all three.
        current_gain_error : float or sequence of three floats
            Relative gain error of each current sensor (-): gain ``1 + e``.
        current_noise_a : float
            Standard deviation of the current noise (A).
        sample_delay_s : float
            Sensor delay (s), see ``t_delay``.
        seed : int
            Seed of the noise generator.
        encoder_counts, encoder_rate_hz, encoder_delay_s
            The position sensor, as the fields of the same names.
        """
        return cls(
            encoder_counts=int(encoder_counts),
            encoder_rate_hz=float(encoder_rate_hz),
            encoder_delay_s=float(encoder_delay_s),
            bits=adc_bits or None,
            i_fs=float(current_full_scale_a),
            offset_abc=_three(current_offset_a, "current_offset_a"),
            gain_abc=_three(current_gain_error, "current_gain_error", add=1.0),
            noise_i=float(current_noise_a),
            seed=int(seed),
            t_delay=float(sample_delay_s),
        )

    @property
    def adc_bits(self) -> int | None:
        """ADC resolution (bits), the ``[sensors]`` key of ``bits``."""
        return self.bits

    @property
    def current_full_scale_a(self) -> float:
        """Current full scale (A), the ``[sensors]`` key of ``i_fs``."""
        return self.i_fs

    @property
    def current_offset_a(self) -> tuple[float, float, float]:
        """Current-sensor offsets (A), the ``[sensors]`` key of ``offset_abc``."""
        return self.offset_abc

    @property
    def current_gain_error(self) -> tuple[float, float, float]:
        """Relative current-sensor gain errors ``gain_abc - 1`` (-)."""
        g = self.gain_abc
        return g[0] - 1.0, g[1] - 1.0, g[2] - 1.0

    @property
    def current_noise_a(self) -> float:
        """Current noise (A rms), the ``[sensors]`` key of ``noise_i``."""
        return self.noise_i

    @property
    def sample_delay_s(self) -> float:
        """Sensor delay (s), the ``[sensors]`` key of ``t_delay``."""
        return self.t_delay

    def encoder_every(self, T_s: float) -> int:
        """PWM periods between two position readings: ``round(1 / (rate T_s))``, at least 1."""
        if self.encoder_rate_hz <= 0.0:
            return 1
        return max(1, round(1.0 / (self.encoder_rate_hz * T_s)))

    @property
    def lsb_i(self) -> float:
        """Current ADC step (A); 0 without quantisation."""
        return 0.0 if self.bits is None else 2.0 * self.i_fs / 2**self.bits

    @property
    def lsb_u(self) -> float:
        """Voltage ADC step (V); 0 without quantisation."""
        return 0.0 if self.bits is None else self.u_fs / 2**self.bits


def encoder_angle(theta_m: float, w_m: float, pars: SensorPars) -> float:
    """The mechanical angle a position sensor reports (rad, [0, 2 pi)).

    The shaft's angle ``theta_m`` and speed ``w_m`` at the instant of the
    reading give the angle ``encoder_delay_s`` earlier, ``theta_m - w_m
    encoder_delay_s`` (exact at constant speed over the delay, the sensor's
    own transmission time being far shorter than a mechanical time constant);
    the sensor reports the whole count it has reached, ``floor(theta N / 2
    pi)`` of ``N = encoder_counts`` per revolution, as the angle of that count.
    Without a sensor (``encoder_counts`` 0) the angle itself.
    """
    return _cplant.encoder_angle(
        float(theta_m), float(w_m), float(pars.encoder_delay_s), int(pars.encoder_counts)
    )


def _three(v: float | Sequence[float], name: str, add: float = 0.0) -> tuple[float, float, float]:
    if isinstance(v, int | float):
        x = float(v) + add
        return x, x, x
    vals = [float(e) + add for e in v]
    if len(vals) != 3:
        raise ValueError(f"SensorPars.from_keys: {name} needs one value or three, got {len(vals)}")
    return vals[0], vals[1], vals[2]


class Sensors:
    """Stateful sensing chain (owns the noise generator).

    Parameters
    ----------
    pars : SensorPars
        Sensor errors.
    """

    __slots__ = ("_code_max", "_g", "_lsb_i", "_lsb_u", "_o", "_rng", "_ucode_max", "pars")

    def __init__(self, pars: SensorPars) -> None:
        self.pars = pars
        self._rng = random.Random(pars.seed)
        self._g = tuple(float(g) for g in pars.gain_abc)
        self._o = tuple(float(o) for o in pars.offset_abc)
        self._lsb_i = pars.lsb_i
        self._lsb_u = pars.lsb_u
        bits = pars.bits or 1
        self._code_max = 2 ** (bits - 1) - 1
        self._ucode_max = 2**bits - 1

    @property
    def rng(self) -> random.Random:
        """The noise generator."""
        return self._rng

    def constants(self) -> tuple[Any, ...]:
        """What the core's sensors need (``plant_sensors``, ``plant_rt/core/plant_sensors.h``)."""
        p = self.pars
        return (
            *self._g,
            *self._o,
            self._lsb_i,
            self._code_max,
            p.noise_i,
            p.gain_u_dc,
            p.offset_u_dc,
            self._lsb_u,
            self._ucode_max,
            p.noise_u,
            self._rng.gauss,
        )
