"""Recorded captures: read and analyse, replay onto a bus, rerun through an estimator.

- ``_read``: any python-can log read and analysed as the live run was.
- ``_replay``: a capture sent onto one or more buses with its recorded timing.
- ``_rerun``: the recorded samples fed into an estimator offline, scored.
"""
