"""The native node loop (issue 29): the parts in C that do not depend on the cores.

A node's whole per-period loop is to run in C, without Python or the GIL:
wait, receive, check E2E, decode, step, encode, send.  This folder holds the
parts of that loop that need neither the plant's nor the controller's
portable core, as a small C library (no allocation after the open and init
calls) and a test program:

- ``bn.h``: the one header (frames, transports, clock, counters).
- ``bn_bus.c``: the transports.  SocketCAN raw sockets, classic and CAN FD
  (``CAN_RAW_FD_FRAMES``), for vcan and real adapters; python-can's
  ``udp_multicast`` bus (the default transport of a host without CAN): the
  same multicast group, port, hop limit 1 and ``SO_REUSEADDR``/``SO_REUSEPORT``
  as python-can, so C and python-can nodes meet on one port.  Non-blocking
  receive up to an absolute deadline (``bn_recv_until``), and send.
- ``bn_msgpack.c``: python-can's udp_multicast datagram, the msgpack map of
  ``can/interfaces/udp_multicast/utils.py`` (eleven keys), written and read
  without allocation.
- ``bn_clock.c``: absolute ``clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME)``
  periods with an optional busy-wait tail, missed deadlines, late wake-ups,
  host stalls, busy time per period (median); ``bn_rt_apply``: SCHED_FIFO,
  ``mlockall``, CPU pin, with what was granted.  The counters are one struct
  (``bn_stats_t``) that Python reads with ctypes (:class:`._native.Stats`).
- ``bn_plant.h``, ``bn_plant.c``, ``bn_plant_loop.c``: the plant node's
  per-period logic on the plant core (transport-free: frames in, frames out)
  and its loop on a bus, lockstep and real time; built and driven by
  :mod:`._plant_native` (``--engine native``).
- ``echo.c``: answers each PhaseSamples with a PwmDuty (same step, E2E CRC),
  or pings (round-trip times): the transports, the codec and the E2E check
  end to end, from python-can or from itself.

The frames are packed and unpacked with the C code ``bench codegen`` writes
from ``dbc/bench.dbc`` (cantools, :mod:`bench.wire._ccodec`) and protected
with its E2E helper (:func:`bench.cli.codegen.generate_e2e`); firmware/ uses
the same two.  :func:`._native.build` generates them and compiles the library
(``libbench_native.so``) and the programs with the system's C compiler.

What is left for the loop of issue 29, once the portable cores are merged
(``plant_rt/core``, ``controller/core``):

- the node programs: the plant's and the controller's per-period step from
  the cores between ``bn_recv_until`` and ``bn_send``, in lockstep and on
  ``bn_clock_t``, with every counter the Python node reports
  (:class:`bench.nodes._counters.Counters`) in a block beside ``bn_stats_t``;
- ``--engine native`` on ``bench plant``, ``bench controller`` and
  ``bench run`` (the default where the build and the transport allow, else
  the Python node with one line saying why), and ``meta.json`` and the
  printed table saying which one ran;
- the in-process native runs and the ``bench perf`` keys
  (``realtime_native.*``, ``lockstep_native.steps_per_s``,
  ``inprocess_native.us_per_step_tt_dq``).
"""
