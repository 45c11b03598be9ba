"""Types of the compiled controller engine (controller/_cctl.c)."""

from typing import Any

KIND_TTDQ: int
KIND_TTAB: int
KIND_SFHF: int
KIND_SQW: int
KIND_SENSORED: int
KIND_HYB_TTDQ: int
KIND_HYB_SQW: int

class Core:
    dirty: bool
    def __init__(self, kind: int, measurement: type, output: type) -> None: ...
    def load(self, state: dict[str, Any]) -> None: ...
    def store(self, state: dict[str, Any]) -> None: ...
    def step(self, meas: Any) -> Any: ...
