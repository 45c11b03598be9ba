"""docs/examples/my_estimator.py's estimator written in C (my_estimator_c.c), as a plug-in.

Build the library first (my_estimator_c.c says how), then run it as any plug-in:
``bench run docs/examples/flux-known-angle.toml --estimator my_estimator_c:create``
from ``docs/examples``. ``MY_ESTIMATOR_C_LIB`` names another build of the library.
The per-period code is C; the design-time members a library has no place for (the
speed estimate's response, the gains) stay Python, in :class:`FluxPLLC`.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from my_estimator import INJECTION_FAMILY, Options

from controller import CEstimator, c_estimator

LIBRARY = Path(
    os.environ.get("MY_ESTIMATOR_C_LIB", Path(__file__).with_name("libmy_estimator_c.so"))
)


class FluxPLLC(CEstimator):
    """The library's estimator with my_estimator.FluxPLL's speed response and gains."""

    def __init__(self, library: Any, motor: Any, T_s: float, alpha_o: float, w_c: float) -> None:
        super().__init__(library, motor, T_s, alpha_o, w_c)
        self.alpha_o, self.w_c = alpha_o, w_c
        self.k_p, self.k_i = 2.0 * alpha_o, alpha_o * alpha_o

    def speed_response(self, w: Any) -> Any:
        """The PLL's ``k_i / (s^2 + k_p s + k_i)`` (my_estimator.FluxPLL.speed_response)."""
        s = 1j * w
        return self.k_i / (s * s + self.k_p * s + self.k_i)

    def gains(self) -> dict[str, float]:
        """Recorded in ``meta.json``."""
        return {"alpha_o": self.alpha_o, "k_p": self.k_p, "k_i": self.k_i, "w_c": self.w_c}


create = c_estimator(LIBRARY, family=INJECTION_FAMILY, options=Options, cls=FluxPLLC)
