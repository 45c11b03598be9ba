"""The bench: every side effect (CAN buses, processes, files, plots, CLI).

Subpackages lowest first (docs/ARCHITECTURE.md): :mod:`bench.wire`,
:mod:`bench.scenarios`, :mod:`bench.nodes`, :mod:`bench.runs`,
:mod:`bench.captures`, :mod:`bench.studies`, :mod:`bench.cli`.  The Python
API of :mod:`bench._api` (docs/TESTING.md) and :mod:`bench.testing` are
imported on first use: every node process imports this package.
"""

TYPE_CHECKING = False  # typing's would cost more than the rest of this file
if TYPE_CHECKING:
    from bench._api import (
        BenchError,
        CaptureError,
        DbcError,
        InterfaceError,
        Run,
        ScenarioError,
        analyze,
        estimators,
        list_scenarios,
        load_scenario,
        run,
    )

__all__ = ["BenchError", "CaptureError", "DbcError", "InterfaceError", "Run", "ScenarioError"]
__all__ += ["analyze", "estimators", "list_scenarios", "load_scenario", "run"]


def __getattr__(name: str) -> object:
    """``bench.run``, ``bench.Run``, ``bench.BenchError``, ...: :mod:`bench._api`'s, on first use."""
    if name not in __all__:
        raise AttributeError(f"module 'bench' has no attribute {name!r}")
    from bench import _api

    return getattr(_api, name)
