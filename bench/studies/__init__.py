"""Many runs: the paper suite, sweeps, reports, benchmarks and soak.

- ``_suite``: ``bench suite paper`` (every paper scenario and estimator);
  ``_sweep``: the sweeps behind the papers' claims; ``_report``: the report
  and its claims; ``_extras``: what the report adds to a run's metrics.
- ``_perf``: ``bench perf``; ``_soak``: ``bench soak`` (fuzzing and faults);
  ``_reliability``: ``bench soak --processes`` (kills, signals, load, parallel
  runs) and ``docs/RELIABILITY.md``.
"""
