"""One run: processes, recording, scoring.

- ``_run``: ``run_scenario``, the orchestration of ``bench run``.
- ``_processes``: the node processes' command lines, start-up and end.
- ``_recorder``: every frame of the run's bus(es) into one capture file.
- ``_analysis``: frames to a per-step table; ``_metrics``: the metrics;
  ``_plots``: ``run.png``; ``_results``: ``finish_run`` (table, metrics,
  metadata and plots from frames, for a live run and a capture alike) and
  the printed summary.
"""
