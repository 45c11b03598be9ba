"""Many runs: the paper suite, sweeps, reports, benchmarks and soak.

- ``_suite``: ``bench suite paper`` (every shipped scenario and estimator:
  the papers' and the full speed range's);
  ``_sweep``: the sweeps behind the papers' claims; ``_report``: the report
  and its claims; ``_extras``: what the report adds to a run's metrics.
- ``_grid``: ``bench sweep`` (a scenario's dotted keys on a grid or at
  random, resumable); ``_executors``: where its points run (local processes
  or Dask); ``_scale``: their throughput; ``_robustness``: ``bench suite
  robustness``.
- ``_perf``: ``bench perf``; ``_soak``: ``bench soak`` (fuzzing and faults);
  ``_reliability``: ``bench soak --processes`` (kills, signals, load, parallel
  runs) and ``docs/RELIABILITY.md``.
"""
