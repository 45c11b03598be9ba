"""The wire contract: one DBC file (``bench.dbc``), loadable by cantools.

The file is the only thing a drive controller on a real bus needs to talk to
the bench: frame identifiers, lengths, scalings, value tables, the E2E data IDs
(message attribute ``E2EDataId``) and which signals wrap (signal attribute
``SigModular``).
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["DBC_PATH"]

DBC_PATH: Path = Path(__file__).resolve().parent / "bench.dbc"
"""Absolute path of the bench's DBC file."""
