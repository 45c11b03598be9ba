"""The bench: every side effect (CAN buses, processes, files, plots, CLI).

One subpackage per concern, lowest layer first (docs/ARCHITECTURE.md):
:mod:`bench.wire`, :mod:`bench.scenarios`, :mod:`bench.nodes`,
:mod:`bench.runs`, :mod:`bench.captures`, :mod:`bench.studies` and
:mod:`bench.cli`; a module imports only its own subpackage and the layers
below it (``tests/test_architecture.py``).
"""
