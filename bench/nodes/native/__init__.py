"""The native node loop (issue 29): a node's per-period loop in C.

A node's whole per-period loop is to run in C, without Python or the GIL:
wait, receive, check E2E, decode, step, encode, send.  This folder holds
that loop's parts and the controller node's loop on the controller core, as
a small C library (no allocation after the open and init calls) and a test
program:

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
- ``bn_ctl.h``, ``bn_ctl.c``: the controller node's per-period logic
  (:class:`bench.nodes._controller_node.ControllerNode` on frames in and
  out, no transport: ``bn_ctl_on_frame``) and its loop on a bus
  (``bn_ctl_serve``), stepping the controller core Python built (its
  ``cc_foc_t`` and ``cc_sup_t`` by address); ``controller_node.py``: the
  Python side (set-up, the bench commands, the report) and ``bench
  controller --engine native``.
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

- the plant node's program: the plant's per-period step from its core
  between ``bn_recv_until`` and ``bn_send``, in lockstep and on
  ``bn_clock_t``, with every counter the Python node reports
  (:class:`bench.nodes._counters.Counters`) in a block beside ``bn_stats_t``;
- ``--engine native`` on ``bench plant`` and ``bench run`` (the default
  where the build and the transport allow), and ``meta.json`` and the
  printed table saying which one ran (the controller's ``--report`` says it,
  ``node_engine``);
- the in-process native runs and the ``bench perf`` keys
  (``realtime_native.*``, ``lockstep_native.steps_per_s``,
  ``inprocess_native.us_per_step_tt_dq``).
"""
