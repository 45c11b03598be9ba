"""The nodes on the bus: message-in / messages-out state machines and their loops.

- ``_plant_node``, ``_controller_node``: the DBC on one side, the pure
  ``plant_rt`` / ``controller`` on the other; no I/O of their own.
- ``_counters``: what every node counts, and the bench-command queue.
- ``_loops``: the nodes' loops on a python-can bus (lockstep and real time),
  the in-process reference loop, the scenario's command frames.
- ``_link``: the latency link between two buses (delay, jitter, loss).
- ``_send``: sending with retries; ``_rt``: real-time settings of a process;
  ``_clock``: the real-time plant's clock (absolute deadlines, host stalls).
"""
