"""Load-torque profiles.

A profile maps the simulation time ``t`` (s) and the mechanical speed
``w_m`` (rad/s) to the load torque ``tau_L`` (N m). Positive ``tau_L``
brakes positive rotation: ``J dw_m/dt = tau_e - tau_L - b w_m``.
Profiles are frozen and can be added: ``ConstantLoad(1.0) + StepLoad(...)``
is a :class:`LoadSum`.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Protocol, runtime_checkable


@runtime_checkable
class LoadProfile(Protocol):
    """Anything that gives a load torque (N m) from time (s) and speed (rad/s)."""

    def tau(self, t: float, w_m: float) -> float: ...


class _Addable:
    __slots__ = ()

    def __add__(self, other: LoadProfile) -> LoadSum:
        return LoadSum(self, other)  # type: ignore[arg-type]

    def __call__(self, t: float, w_m: float) -> float:
        return self.tau(t, w_m)  # type: ignore[attr-defined]


@dataclass(frozen=True, slots=True)
class ConstantLoad(_Addable):
    """Constant load torque.

    Parameters
    ----------
    tau_L : float
        Load torque (N m).
    """

    tau_L: float = 0.0

    def tau(self, t: float, w_m: float) -> float:
        return self.tau_L


@dataclass(frozen=True, slots=True)
class StepLoad(_Addable):
    """Load torque that steps at a given time.

    Parameters
    ----------
    t_step : float
        Step time (s); the new value holds from ``t >= t_step``.
    tau_after : float
        Load torque after the step (N m).
    tau_before : float
        Load torque before the step (N m).
    """

    t_step: float
    tau_after: float
    tau_before: float = 0.0

    def tau(self, t: float, w_m: float) -> float:
        return self.tau_after if t >= self.t_step else self.tau_before


@dataclass(frozen=True, slots=True)
class RampLoad(_Addable):
    """Load torque ramping linearly between two times, held outside them.

    Parameters
    ----------
    t_start, t_end : float
        Start and end of the ramp (s), ``t_end > t_start``.
    tau_start, tau_end : float
        Load torque at and before ``t_start`` and at and after ``t_end`` (N m).
    """

    t_start: float
    t_end: float
    tau_start: float
    tau_end: float

    def __post_init__(self) -> None:
        if not self.t_end > self.t_start:
            raise ValueError("RampLoad needs t_end > t_start")

    def tau(self, t: float, w_m: float) -> float:
        if t <= self.t_start:
            return self.tau_start
        if t >= self.t_end:
            return self.tau_end
        a = (t - self.t_start) / (self.t_end - self.t_start)
        return self.tau_start + a * (self.tau_end - self.tau_start)


@dataclass(frozen=True, slots=True)
class SpeedProportionalLoad(_Addable):
    """Load torque proportional to speed (e.g. a generator into a resistor).

    Parameters
    ----------
    k_w : float
        Torque per mechanical speed (N m s/rad).
    """

    k_w: float

    def tau(self, t: float, w_m: float) -> float:
        return self.k_w * w_m


@dataclass(frozen=True, slots=True, init=False)
class LoadSum(_Addable):
    """Sum of load profiles.

    Accepts the terms as arguments, ``LoadSum(a, b)``, or as one iterable,
    ``LoadSum([a, b])``.
    """

    terms: tuple[LoadProfile, ...]

    def __init__(self, *terms: LoadProfile | Iterable[LoadProfile]) -> None:
        flat: list[LoadProfile] = []
        for term in terms:
            if isinstance(term, LoadProfile):
                flat.append(term)
            else:
                flat.extend(term)
        for term in flat:
            if not isinstance(term, LoadProfile):
                raise TypeError(f"LoadSum term {term!r} has no tau(t, w_m) method")
        object.__setattr__(self, "terms", tuple(flat))

    def tau(self, t: float, w_m: float) -> float:
        total = 0.0
        for term in self.terms:
            total += term.tau(t, w_m)
        return total
