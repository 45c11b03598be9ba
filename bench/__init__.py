"""The bench: every side effect (CAN buses, processes, files, plots, CLI)."""
