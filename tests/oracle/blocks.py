"""The per-period kernels of the controller's blocks whose designs live in ``controller/``,
in Python: each a subclass of its design class adding the step the core runs in C.

Tolerance 0 (:data:`tests.oracle.TOLERANCE`): the core's block repeats these operations
in the same order.
"""

from __future__ import annotations

from controller._controller import ReferenceModel


class OracleReferenceModel(ReferenceModel):
    """:class:`controller._controller.ReferenceModel`'s step (``controller/core/cc_reference.c``):
    the designed response ``alpha_s / (s + alpha_s)`` to the speed reference, forward Euler,
    and its slope times ``n_p``, limited to ``a_max``."""

    __slots__ = ("w",)

    def __init__(self, alpha_s: float, n_p: int, J: float, tau_max: float, T_s: float) -> None:
        super().__init__(alpha_s, n_p, J, tau_max, T_s)
        self.w = 0.0

    @classmethod
    def of(cls, design: ReferenceModel) -> OracleReferenceModel:
        """The oracle of the designed ``design`` (its values, a fresh state)."""
        m = cls.__new__(cls)
        m.alpha_s, m.n_p, m.a_max, m.T_s = design.alpha_s, design.n_p, design.a_max, design.T_s
        m.w = 0.0
        return m

    def reset(self, w0: float = 0.0) -> None:
        """Start from the speed ``w0`` (rad/s, mechanical)."""
        self.w = w0

    def update(self, w_ref: float) -> float:
        """Advance one period with the reference ``w_ref`` (rad/s, mechanical); return the
        designed electrical acceleration (rad/s^2) of the period."""
        dw = self.alpha_s * (w_ref - self.w)
        a = self.n_p * dw
        a_max = self.a_max
        if a > a_max:
            a, dw = a_max, a_max / self.n_p
        elif a < -a_max:
            a, dw = -a_max, -a_max / self.n_p
        self.w += self.T_s * dw
        return a
