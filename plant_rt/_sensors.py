"""Current and DC-link voltage sensing: gain, offset, noise and ADC quantisation.

Each measured value is ``quantise(gain * x + offset + noise)``. Noise is
white and Gaussian, drawn from one ``random.Random(seed)`` stream in a fixed
order (i_a, i_b, i_c, u_dc), so a run is reproducible from its seed.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass


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

    def __post_init__(self) -> None:
        if self.bits is not None and not 1 <= self.bits <= 32:
            raise ValueError(f"SensorPars.bits must be in 1..32 or None, got {self.bits}")
        if not (self.i_fs > 0.0 and self.u_fs > 0.0):
            raise ValueError("SensorPars.i_fs and SensorPars.u_fs must be > 0")
        if self.noise_i < 0.0 or self.noise_u < 0.0:
            raise ValueError("SensorPars.noise_i and SensorPars.noise_u must be >= 0")
        if len(self.gain_abc) != 3 or len(self.offset_abc) != 3:
            raise ValueError("SensorPars.gain_abc and SensorPars.offset_abc need three values")

    @property
    def lsb_i(self) -> float:
        """Current ADC step (A); 0 without quantisation."""
        return 0.0 if self.bits is None else 2.0 * self.i_fs / 2**self.bits

    @property
    def lsb_u(self) -> float:
        """Voltage ADC step (V); 0 without quantisation."""
        return 0.0 if self.bits is None else self.u_fs / 2**self.bits


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

    def _quant_i(self, x: float) -> float:
        lsb = self._lsb_i
        if lsb == 0.0:
            return x
        code = math.floor(x / lsb + 0.5)
        code = max(-self._code_max - 1, min(self._code_max, code))
        return code * lsb

    def currents(self, i_a: float, i_b: float, i_c: float) -> tuple[float, float, float]:
        """Measured phase currents (A)."""
        g = self._g
        o = self._o
        m_a = g[0] * i_a + o[0]
        m_b = g[1] * i_b + o[1]
        m_c = g[2] * i_c + o[2]
        sd = self.pars.noise_i
        if sd > 0.0:
            gauss = self._rng.gauss
            m_a += gauss(0.0, sd)
            m_b += gauss(0.0, sd)
            m_c += gauss(0.0, sd)
        return self._quant_i(m_a), self._quant_i(m_b), self._quant_i(m_c)

    def voltage(self, u_dc: float) -> float:
        """Measured DC-link voltage (V)."""
        p = self.pars
        m = p.gain_u_dc * u_dc + p.offset_u_dc
        if p.noise_u > 0.0:
            m += self._rng.gauss(0.0, p.noise_u)
        lsb = self._lsb_u
        if lsb == 0.0:
            return m
        code = max(0, min(self._ucode_max, math.floor(m / lsb + 0.5)))
        return code * lsb
